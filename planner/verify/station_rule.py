"""The plan's rule for one station's detections, as ``verify`` judges it in both modes.

A plan promises more than an error: every station sees at least ``min_markers`` markers in at
least ``min_sectors`` of ``n_sectors`` equal sectors around it (the design card's "markers in
at least three directions"), and meets the requirement. The planner's chance of passing
(:mod:`planner.accuracy.chance`) is the chance of that whole promise, so ``verify`` judges the
markers a station actually detected and accepted by the same rule, with the planner's sectors
(:func:`planner.problem.usability.sector_index`, bearings of the planned marker positions from
the planned station, site frame): a station that registers well on two markers still broke the
promise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.config import PlanConfig
from planner.problem.usability import sector_index

_DEFAULT = PlanConfig()


@dataclass(frozen=True)
class StationRule:
    """How many markers in how many directions a plan asks of every station.

    Attributes
    ----------
    min_markers, min_sectors, n_sectors : int
        As :class:`~planner.config.PlanConfig` (defaults: its defaults).
    """

    min_markers: int = _DEFAULT.min_markers
    min_sectors: int = _DEFAULT.min_sectors
    n_sectors: int = _DEFAULT.n_sectors

    @classmethod
    def of(cls, requirement: dict) -> StationRule:
        """The rule of a plan's ``requirement`` section (keys it lacks: the defaults)."""
        return cls(**{k: int(requirement[k]) for k in ("min_markers", "min_sectors",
                                                       "n_sectors") if k in requirement})

    def judge(self, station_xyz: np.ndarray, marker_xyz: np.ndarray) -> tuple[int, int, bool]:
        """``(count, sectors, ok)`` of the detected markers at ``marker_xyz`` ((k, 3), planned
        positions, site frame, m) seen from the station at ``station_xyz`` ((3,))."""
        marker_xyz = np.asarray(marker_xyz, float).reshape(-1, 3)
        d = marker_xyz[:, :2] - np.asarray(station_xyz, float)[:2]
        sectors = int(np.unique(sector_index(np.arctan2(d[:, 1], d[:, 0]),
                                             self.n_sectors)).size)
        count = len(marker_xyz)
        return count, sectors, count >= self.min_markers and sectors >= self.min_sectors

    def broken(self, count: int, sectors: int) -> str:
        """Why ``count`` markers in ``sectors`` sectors break the rule, for a station's reason."""
        return (f"{count} marker(s) in {sectors} of {self.n_sectors} sectors detected and "
                f"accepted, the plan's rule asks >= {self.min_markers} in >= "
                f"{self.min_sectors}")

    def verdict(self, station_xyz: np.ndarray, marker_xyz: np.ndarray, achieved_m: float,
                requirement_m: float) -> tuple[bool, str]:
        """``(passed, reason)`` of a station whose detected markers are at ``marker_xyz`` (as
        :meth:`judge`) and whose achieved error is ``achieved_m`` against ``requirement_m``
        (m): ``"ok"``, or what failed, the rule first."""
        count, sectors, rule_ok = self.judge(station_xyz, marker_xyz)
        why = ([] if rule_ok else [self.broken(count, sectors)]) \
            + ([] if achieved_m <= requirement_m else
               [f"achieved {achieved_m:.3f} m > requirement {requirement_m:g} m"])
        return not why, "; ".join(why) or "ok"
