"""The covariance of a network layout's pose parameters, with the stations it determines
(:class:`NetworkCovariance`, made by :meth:`planner.accuracy.network.NetworkModel.covariance`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class NetworkCovariance:
    """Covariance of a layout's pose parameters.

    Attributes
    ----------
    full : (6 s, 6 s) float
        Covariance of every station's ``POSE_PARAMETERS`` (fixed parameters have zero rows);
        rows of undetermined stations are meaningless (see ``determined``).
    determined : (s,) bool
        Stations whose pose the layout determines (tied to the datum).
    """

    full: np.ndarray
    determined: np.ndarray

    def station(self, k) -> np.ndarray:
        """(6, 6) or (m, 6, 6) pose covariance blocks of station(s) ``k``."""
        k = np.asarray(k)
        idx = 6 * k[..., None] + np.arange(6)
        return self.full[idx[..., :, None], idx[..., None, :]]
