"""The plan's rule for a station's detections (planner.verify.station_rule): counts and
sectors as the planner counts them, read from a plan's requirement."""

import numpy as np

from planner.config import PlanConfig
from planner.problem.usability import direction_status
from planner.verify.station_rule import StationRule
from tests.planner.instances import make_problem, ring


def test_defaults_are_the_planners():
    cfg = PlanConfig()
    assert StationRule() == StationRule(cfg.min_markers, cfg.min_sectors, cfg.n_sectors)
    assert StationRule.of({"requirement_m": 0.1, "min_markers": 4, "n_sectors": 8}) == \
        StationRule(4, cfg.min_sectors, 8)


def test_sectors_are_counted_as_the_planner_counts_them():
    rng = np.random.default_rng(0)
    station = np.array([3.0, -2.0, 1.0])
    for _ in range(30):
        bearings = rng.uniform(0, 360, rng.integers(1, 7))
        sites = ring(station[:2], 9.0, bearings)
        problem = make_problem([station[:2]], sites)
        count, sectors = direction_status(problem, np.ones(len(sites), bool), 6)
        xyz = np.column_stack([sites, np.full(len(sites), 0.1)])
        got = StationRule(3, 3, 6).judge(station, xyz)
        assert got == (int(count[0]), int(sectors[0]), bool(count[0] >= 3 and sectors[0] >= 3))


def test_three_markers_in_two_directions_break_the_rule():
    rule = StationRule(3, 3, 6)
    xyz = np.array([[10.0, 0.5, 0.1], [10.0, 1.0, 0.1], [-10.0, 0.0, 0.1]])
    assert rule.judge(np.zeros(3), xyz) == (3, 2, False)
    assert rule.broken(3, 2) == ("3 marker(s) in 2 of 6 sectors detected and accepted, the "
                                 "plan's rule asks >= 3 in >= 3")
    assert rule.judge(np.zeros(3), np.zeros((0, 3))) == (0, 0, False)
