import numpy as np

from planner.baselines import greedy_cover, regular_grid
from planner.config import PlanConfig
from planner.program import plan_sites
from planner.station_checks import evaluate_layout
from tests.planner.instances import make_problem


def test_baselines_meet_the_requirement_and_never_beat_the_optimum():
    rng = np.random.default_rng(7)
    g = np.arange(0.5, 30, 1.0)
    xx, yy = np.meshgrid(g, g)
    p = make_problem(rng.uniform(5, 25, (5, 2)), np.column_stack([xx.ravel(), yy.ravel()]),
                     max_range_m=20)
    cfg = PlanConfig(requirement_m=0.04, working_radius_m=10, max_range_m=20)
    opt = int(plan_sites(p, cfg).selected.sum())
    greedy = greedy_cover(p, cfg)
    grid = regular_grid(p, cfg, (0.0, 0.0, 30.0, 30.0))
    for b in (greedy, grid):
        assert b.meets_requirement
        assert evaluate_layout(p, b.selected, cfg).all_ok
        assert b.n_markers >= opt
    assert grid.spacing_m is not None and grid.spacing_m >= 1.0
    # a wider grid than the one returned fails at every phase tried
    wider = regular_grid(p, cfg, (0.0, 0.0, 30.0, 30.0),
                         spacings_m=np.array([grid.spacing_m + 0.5]))
    assert not wider.meets_requirement or grid.spacing_m + 0.5 > cfg.max_range_m
