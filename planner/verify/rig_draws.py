"""Each trial's rig: mounting offsets drawn from the user's tolerances.

``verify --trials N`` may widen the rig's mounting offsets (:class:`pipeline.scans.rig.
MountingOffsets`) by 1-sigma tolerances (:class:`OffsetTolerance`): every trial draws its rig
from N(given, tolerance) with its own seed, on a stream apart from the simulation's
(:func:`draw_offsets`, :func:`trial_offsets`). Kept apart from :mod:`planner.verify.trials` so
that the command-line options can use it without importing the station chain.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from markerplan.errors import ConfigError
from pipeline.scans.rig import MountingOffsets

#: The :class:`numpy.random.SeedSequence` key that keeps a trial's rig-offset draw apart from
#: its simulation seed's streams.
OFFSET_STREAM = 0x0FF5E7

#: Largest tolerances (1 sigma): an angle of 5 degrees, an axis offset of 100 mm; beyond them
#: the rig is not the one planned for.
MAX_ANGLE_TOLERANCE_DEG = 5.0
MAX_AXIS_TOLERANCE_MM = 100.0


@dataclass(frozen=True)
class OffsetTolerance:
    """1-sigma tolerances of the rig's mounting offsets (a :class:`MountingOffsets`).

    Attributes
    ----------
    vertical_axis_error_rad, lframe_tilt_rad : float
        Of the two angles, radians (at most :data:`MAX_ANGLE_TOLERANCE_DEG`).
    axis_offset_m : float
        Of each of the axis offset's ``dx`` and ``dy``, metres (at most
        :data:`MAX_AXIS_TOLERANCE_MM`).

    Raises
    ------
    ConfigError
        A tolerance negative, not finite or above its bound.
    """

    vertical_axis_error_rad: float = 0.0
    lframe_tilt_rad: float = 0.0
    axis_offset_m: float = 0.0

    def __post_init__(self):
        angle = math.radians(MAX_ANGLE_TOLERANCE_DEG)
        for name, high, unit in (("vertical_axis_error_rad", angle, "rad"),
                                 ("lframe_tilt_rad", angle, "rad"),
                                 ("axis_offset_m", MAX_AXIS_TOLERANCE_MM / 1e3, "m")):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and 0.0 <= v <= high):  # NaN fails too
                raise ConfigError(f"the tolerance `{name}` must be in [0, {high:.4g}] {unit}, "
                                  f"got {v!r:.40}")

    def to_dict(self) -> dict:
        return asdict(self)


def draw_offsets(nominal: MountingOffsets, tolerance: OffsetTolerance, seed: int
                 ) -> MountingOffsets:
    """One trial's rig: each mounting offset drawn from N(``nominal``, ``tolerance``), the
    four independently, with ``seed``'s own stream (:data:`OFFSET_STREAM`).

    >>> t = OffsetTolerance(axis_offset_m=0.002)
    >>> a = draw_offsets(MountingOffsets(), t, 7); a == draw_offsets(MountingOffsets(), t, 7)
    True
    >>> a.vertical_axis_error_rad, a.axis_offset_m == draw_offsets(MountingOffsets(), t, 8)
    (0.0, False)
    """
    z = np.random.default_rng(np.random.SeedSequence([int(seed), OFFSET_STREAM])
                              ).standard_normal(4)
    dx, dy = nominal.axis_offset_m
    return MountingOffsets(
        float(nominal.vertical_axis_error_rad + tolerance.vertical_axis_error_rad * z[0]),
        float(nominal.lframe_tilt_rad + tolerance.lframe_tilt_rad * z[1]),
        (float(dx + tolerance.axis_offset_m * z[2]), float(dy + tolerance.axis_offset_m * z[3])))


def trial_offsets(nominal: MountingOffsets | None, tolerance: OffsetTolerance | None,
                  seeds: Sequence[int]) -> list[MountingOffsets]:
    """Every trial's rig: ``nominal`` (default none), or drawn (:func:`draw_offsets`) with
    each trial's seed when a ``tolerance`` is given."""
    nominal = nominal or MountingOffsets()
    if tolerance is None:
        return [nominal] * len(seeds)
    return [draw_offsets(nominal, tolerance, s) for s in seeds]
