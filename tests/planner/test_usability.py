from types import SimpleNamespace

import numpy as np
import pytest

from markerplan.errors import ConfigError
from planner.config import PlanConfig
from planner.problem.usability import (
    OCCLUDED,
    OUT_OF_DOMAIN,
    TOO_INACCURATE,
    USABLE,
    direction_status,
    problem_from_visibility,
    sector_index,
)
from tests.planner.instances import AnalyticModel, make_problem, ring


def test_sectors():
    assert sector_index(np.radians([0, 59.9, 60, 359.9, -1, 180]), 6).tolist() == [0, 0, 1, 5,
                                                                                      5, 3]


def _vis(distance, fraction):
    n = len(distance)
    return SimpleNamespace(station=np.zeros(n, int), site=np.arange(n),
                           distance_m=np.asarray(distance, float), elevation_rad=np.zeros(n),
                           bearing_rad=np.zeros(n), visible_fraction=np.asarray(fraction, float),
                           expected_points=np.full(n, 100.0))


def test_usability_reasons():
    vis = _vis([5.0, 5.0, 50.0, 35.0], [1.0, 0.2, 1.0, 1.0])
    sites = np.column_stack([np.arange(4.0), np.zeros(4), np.zeros(4)])
    cfg = PlanConfig(requirement_m=0.10, min_visible_fraction=0.5)
    p = problem_from_visibility(vis, AnalyticModel(40.0), cfg, ["S1"], [[0, 0, 1.0]],
                                ["a", "b", "c", "d"], sites)
    # sigma(35 m) = 0.0565 -> q95 = 0.113 > 0.10
    assert p.pair_reason.tolist() == [USABLE, OCCLUDED, OUT_OF_DOMAIN, TOO_INACCURATE]
    p2 = problem_from_visibility(vis, AnalyticModel(40.0), cfg.replace(allow_out_of_domain=True,
                                                                         requirement_m=0.5),
                                 ["S1"], [[0, 0, 1.0]], ["a", "b", "c", "d"], sites)
    assert p2.pair_reason.tolist() == [USABLE, OCCLUDED, USABLE, USABLE]


def test_model_needing_unknown_predictor_is_refused():
    model = AnalyticModel()
    model.predictors = ("distance_m", "elevation_rad", "roughness")
    with pytest.raises(ConfigError, match="roughness"):
        problem_from_visibility(_vis([5.0], [1.0]), model, PlanConfig(), ["S1"], [[0, 0, 1]],
                                ["a"], [[5, 0, 0]])


def test_direction_status_counts_only_usable_selected():
    p = make_problem([[0, 0]], ring([0, 0], 8.0, [10, 20, 100, 200]), occluded=[(0, 3)])
    count, sectors = direction_status(p, np.array([True, True, True, True]), 6)
    assert count.tolist() == [3] and sectors.tolist() == [2]


def test_site_ids_are_looked_up_strictly_and_sub_problems_keep_their_pairs():
    p = make_problem([[0, 0], [20, 0]], ring([0, 0], 8.0, [0, 90, 180, 270]))
    assert p.site_mask(("C001", "C003"), "existing").tolist() == [False, True, False, True]
    with pytest.raises(ConfigError, match="`forbidden` names unknown site id"):
        p.site_mask(("C001", "nope"), "forbidden")
    sub = p.restrict(np.array([False, True, False, True]))
    assert sub.site_ids == ("C001", "C003") and sub.n_stations == p.n_stations
    kept = np.isin(p.pair_site, [1, 3])
    assert sub.pair_station.tolist() == p.pair_station[kept].tolist()
    assert [sub.site_ids[j] for j in sub.pair_site] == [p.site_ids[j] for j in p.pair_site[kept]]
    assert np.array_equal(sub.pair_sigma_m, p.pair_sigma_m[kept])
    with pytest.raises(ConfigError, match="shape"):
        p.restrict(np.ones(3, bool))
