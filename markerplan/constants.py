"""Numeric constants shared by the packages."""

import numpy as np

#: The golden angle ``pi (3 - sqrt 5)`` (about 137.5 deg), radians: successive multiples of it
#: spread points evenly around a circle (sunflower / Vogel patterns).
GOLDEN_ANGLE_RAD = np.pi * (3 - np.sqrt(5))
