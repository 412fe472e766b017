"""Options of ``markerplan verify --trials N`` that only ``verify`` takes: the tolerances of the
rig's mounting offsets (:class:`planner.verify.rig_draws.OffsetTolerance`), each trial drawing its
rig from N(given offsets, tolerance) with its seed.

Each is named after the mounting offset it widens
(:func:`planner.cli._common.mounting_offset_options`: ``--vertical-axis-error-deg`` ->
``--vertical-axis-error-tolerance-deg``, ...), 1 sigma, in the offset's unit; the command
receives one ``tolerance`` argument (``None`` when none is given).
"""

from __future__ import annotations

import functools
import math

import click

from planner.cli._common import FiniteRange
from planner.verify.rig_draws import (
    MAX_ANGLE_TOLERANCE_DEG,
    MAX_AXIS_TOLERANCE_MM,
    OffsetTolerance,
)


def offset_tolerance_options(command):
    """Add ``--vertical-axis-error-tolerance-deg``, ``--lframe-tilt-tolerance-deg`` and
    ``--axis-offset-tolerance-mm`` to a command, which receives them as one ``tolerance``
    argument (:class:`~planner.verify.rig_draws.OffsetTolerance`, SI; ``None`` when none is
    given)."""
    @functools.wraps(command)
    def with_tolerance(*args, vertical_axis_error_tolerance_deg, lframe_tilt_tolerance_deg,
                       axis_offset_tolerance_mm, **kwargs):
        given = (vertical_axis_error_tolerance_deg, lframe_tilt_tolerance_deg,
                 axis_offset_tolerance_mm)
        tolerance = None if all(v is None for v in given) else OffsetTolerance(
            math.radians(vertical_axis_error_tolerance_deg or 0.0),
            math.radians(lframe_tilt_tolerance_deg or 0.0),
            (axis_offset_tolerance_mm or 0.0) / 1e3)
        return command(*args, tolerance=tolerance, **kwargs)

    angle = FiniteRange(0.0, MAX_ANGLE_TOLERANCE_DEG)
    for option in reversed([
        click.option("--vertical-axis-error-tolerance-deg", type=angle, metavar="DEG",
                     help="With --trials: each trial draws the rig's vertical-axis error from "
                          "N(--vertical-axis-error-deg, this), 1 sigma, degrees."),
        click.option("--lframe-tilt-tolerance-deg", type=angle, metavar="DEG",
                     help="With --trials: each trial draws the L-frame tilt from "
                          "N(--lframe-tilt-deg, this), 1 sigma, degrees."),
        click.option("--axis-offset-tolerance-mm", type=FiniteRange(0.0, MAX_AXIS_TOLERANCE_MM),
                     metavar="MM",
                     help="With --trials: each trial draws each of the axis offset's DX and DY "
                          "from N(--axis-offset-mm, this), 1 sigma, mm."),
    ]):
        with_tolerance = option(with_tolerance)
    return with_tolerance
