"""Each pair's chance of detection for the planner (planner.problem.detection_odds) and its
way into the plan problem (planner.problem.sight)."""

from types import SimpleNamespace

import numpy as np
import pytest

from error_model.detection import DetectionModel, Feature
from planner.problem.detection_odds import (
    pair_covariates,
    pair_detection_probability,
    rim_distance,
    terrain_normal,
)
from visibility.dem import DEM


def _plane(slope_x: float) -> DEM:
    x = np.arange(201) * 0.1 - 10.0
    heights = np.tile(slope_x * x, (201, 1))
    return DEM(heights, (-10.0, -10.0), 0.1)


def test_terrain_normal_of_a_tilted_plane():
    n = terrain_normal(_plane(0.5), np.array([[1.0, 2.0], [-3.0, 0.5]]))
    expected = np.array([-0.5, 0.0, 1.0]) / np.sqrt(1.25)
    np.testing.assert_allclose(n, [expected, expected], atol=1e-9)


def test_rim_distance_to_the_nearest_crater():
    craters = [SimpleNamespace(centre_xy_m=(0.0, 0.0), diameter_m=8.0),
               SimpleNamespace(centre_xy_m=(20.0, 0.0), diameter_m=4.0)]
    d = rim_distance(craters, np.array([[0.0, 0.0], [6.0, 0.0], [17.0, 0.0]]))
    np.testing.assert_allclose(d, [4.0, 2.0, 1.0])
    assert np.all(np.isinf(rim_distance([], np.zeros((2, 2)))))


def test_covariates_on_level_ground_follow_the_geometry():
    dem = _plane(0.0)
    station = np.array([[0.0, 0.0, 1.0]])
    sites = np.array([[3.0, 0.0, 0.1], [0.0, 8.0, 0.1]])
    dist = np.linalg.norm(sites - station, axis=1)
    elev = np.arcsin((sites[:, 2] - 1.0) / dist)
    vis = SimpleNamespace(station=np.array([0, 0]), site=np.array([0, 1]), distance_m=dist,
                          elevation_rad=elev, visible_fraction=np.array([1.0, 0.7]),
                          expected_points=np.array([900.0, 200.0]))
    cov = pair_covariates(dem, [], station, sites, vis)
    np.testing.assert_allclose(cov["slope_deg"], 0.0, atol=1e-9)
    # the line of sight meets level ground at 90 deg minus its depression
    np.testing.assert_allclose(cov["incidence_deg"], 90.0 - np.degrees(np.abs(elev)), atol=1e-9)
    np.testing.assert_allclose(cov["elevation_deg"], np.degrees(elev))
    assert np.all(np.isinf(cov["rim_distance_m"]))
    np.testing.assert_array_equal(cov["visible_fraction"], [1.0, 0.7])


def test_probability_is_the_models_times_the_chance_of_being_seen():
    model = DetectionModel((Feature("distance_m", "log"),), np.array([4.0, -1.0]))
    cov = {"distance_m": np.array([1.0, np.e ** 4])}
    p = pair_detection_probability(model, cov)
    np.testing.assert_allclose(p, [1 / (1 + np.exp(-4.0)), 0.5])
    np.testing.assert_allclose(pair_detection_probability(model, cov, np.array([0.5, 0.0])),
                               [0.5 / (1 + np.exp(-4.0)), 0.0])


@pytest.mark.slow
def test_the_default_site_problem_carries_the_shipped_models_chances():
    from error_model import default_detection_model, default_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.run import build_problem

    inputs = load_inputs("default")
    config = PlanConfig()
    problem, _, vis, _ = build_problem(inputs, config, default_model(), progress=False,
                                       detection_model=default_detection_model())
    cov = pair_covariates(inputs.dem, inputs.craters, inputs.station_xyz, problem.site_xyz, vis)
    np.testing.assert_allclose(problem.pair_detection_p,
                               default_detection_model().probability(**cov))
    usable = problem.pair_usable
    assert np.median(problem.pair_detection_p[usable]) > 0.9
    plain, *_ = build_problem(inputs, config, default_model(), progress=False)
    assert plain.pair_detection_p is None
    np.testing.assert_array_equal(plain.pair_reason, problem.pair_reason)
