"""The planner's predicted network covariance is the one the adjustment reports on that geometry.

A noise-free simulated network without tilt is both a plan (stations at their true positions,
candidate sites at the markers, every observation a usable pair with its sigma) and the
adjustment's input; with the same sigmas, the same reference-station datum, the same
inclinometer prior and the same heading prior, :class:`planner.accuracy.network.NetworkModel`
(linearised at the nominal layout, markers eliminated analytically) and
:func:`pipeline.network.adjustment.adjust` (Gauss-Newton to the exact solution, full normal
matrix) must give the same station and marker covariances. The adjustment's roll and pitch are
about each station's own axes, the planner's about the site axes, so the adjustment's tilt
block is turned by the station's heading before comparing.
"""

import math
from dataclasses import replace

import numpy as np
import pytest

from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.aids import HeadingReadings, OdometryReadings
from pipeline.network.observations import ControlPoint, Datum, NominalPoses
from pipeline.network.simulation import simulated_network
from planner.accuracy.aids import Odometry
from planner.accuracy.network import NetworkModel
from planner.problem.usability import USABLE, PlanProblem
from planner.studies.figure_calibration import site_axes

INCL = math.radians(0.01)
#: They agree to ~1e-14; a 0.1 % error in any design column or weight is far above this.
RTOL = 1e-9


def _sigma(distance_m):
    """A sigma that grows with distance, so every pair has its own weight."""
    return 0.004 + 0.0005 * distance_m


def _network(seed):
    """A noise-free, tilt-free network and the plan of the same geometry."""
    obs, truth = simulated_network(n_stations=5, seed=seed, sigma_m=_sigma,
                                   inclinometer_sigma_rad=0.0, noise_scale=0.0,
                                   odometry_sigma_m=0.0, odometry_heading_sigma_rad=0.0)
    station_xyz, site_xyz = truth.pose[:, :3], truth.marker_xyz_m
    diff = site_xyz[obs.marker] - station_xyz[obs.station]
    problem = PlanProblem(
        station_ids=obs.station_ids, station_xyz=station_xyz, site_ids=obs.marker_ids,
        site_xyz=site_xyz, site_existing=np.zeros(len(obs.marker_ids), bool),
        site_cost=np.ones(len(obs.marker_ids)), pair_station=obs.station, pair_site=obs.marker,
        pair_distance_m=np.linalg.norm(diff, axis=1),
        pair_bearing_rad=np.arctan2(diff[:, 1], diff[:, 0]), pair_sigma_m=obs.sigma_m,
        pair_reason=np.full(obs.n, USABLE, dtype=np.int8))
    return obs, truth, problem


def _with_control(problem, truth, control, sigma_c):
    """``problem`` with the sites ``control`` as control points known to ``sigma_c`` per axis
    (existing, at their true positions), and those points for the adjustment's datum."""
    sigma = np.zeros(problem.n_sites)
    sigma[list(control)] = sigma_c
    problem = replace(problem, site_existing=sigma > 0, site_control_sigma_m=sigma)
    points = tuple(ControlPoint(problem.site_ids[j], truth.marker_xyz_m[j], np.full(3, sigma_c))
                   for j in control)
    return problem, points


def _assert_same_covariance(predicted, adjusted):
    """Equal diagonals to ``RTOL``; off-diagonals to ``RTOL`` of ``sqrt(c_ii c_jj)``."""
    d = np.sqrt(np.diag(adjusted))
    np.testing.assert_allclose(np.diag(predicted), np.diag(adjusted), rtol=RTOL, atol=0.0)
    scale = np.outer(d, d)
    scale[scale == 0] = 1.0
    assert float(np.max(np.abs(predicted - adjusted) / scale)) < RTOL


@pytest.mark.parametrize("seed, reference, heading_prior", [
    (1, 0, None),
    (3, 2, None),
    (5, 1, math.radians(0.5)),
])
def test_planner_predicts_the_adjustments_covariance(seed, reference, heading_prior):
    obs, truth, problem = _network(seed)
    net = NetworkModel(problem, 10.0, INCL, reference=reference,
                       heading_prior_sigma_rad=heading_prior)
    cov = net.covariance(net.information(np.ones(problem.n_sites, bool)))
    assert cov.determined.all()

    result = adjust(obs, Datum(reference_station=obs.station_ids[reference]),
                    AdjustmentSettings(inclinometer_sigma_rad=INCL,
                                       heading_prior_sigma_rad=heading_prior, snooping=False),
                    nominal=NominalPoses(truth.pose[:, :3], truth.pose[:, 3]))
    assert np.abs(result.marker_xyz_m - truth.marker_xyz_m).max() < 1e-9
    n6 = 6 * problem.n_stations
    assert not cov.full[6 * reference:6 * reference + 4].any()
    assert not result.covariance[6 * reference:6 * reference + 4, :n6].any()
    _assert_same_covariance(cov.full, site_axes(result.covariance[:n6, :n6],
                                                          truth.pose[:, 3]))
    predicted = net.marker_covariances(cov, np.arange(problem.n_sites))
    for j in range(problem.n_sites):
        _assert_same_covariance(predicted[j], result.marker_covariance(j))


@pytest.mark.parametrize("seed, reference, heading, bias, odometry, loop", [
    (1, 0, None, None, (0.02, math.radians(0.05)), None),
    (3, 2, math.radians(0.1), math.radians(0.05), None, None),
    (5, 1, math.radians(0.1), math.radians(0.05), (0.01, None), None),
    (7, 4, math.radians(0.2), None, (None, math.radians(0.1)), None),
    (9, 0, None, None, (0.02, math.radians(0.05)), 70.0),
    (11, 2, math.radians(0.1), None, (0.01, None), 50.0),
])
def test_planner_predicts_the_adjustments_covariance_with_pose_aids(seed, reference, heading,
                                                                    bias, odometry, loop):
    """Odometry between consecutive stations (on a closed traverse also from the last station
    back to the first, over ``loop`` m) and a heading reference with a boresight bias: the
    planner's constant information (linearised at headings 0) and the adjustment's non-linear
    observations (at the true headings) give the same covariance."""
    obs, truth, problem = _network(seed)
    ratio, rate = odometry or (None, None)
    net = NetworkModel(problem, 10.0, INCL, reference=reference,
                       heading_prior_sigma_rad=heading, heading_bias_sigma_rad=bias or 0.0,
                       odometry=Odometry(ratio, rate, loop) if odometry else None)
    cov = net.covariance(net.information(np.ones(problem.n_sites, bool)))
    assert cov.determined.all()

    s = problem.n_stations
    readings = (OdometryReadings.from_poses(np.arange(s), truth.pose[:, :3], truth.pose[:, 3],
                                            loop) if odometry else None)
    result = adjust(obs, Datum(reference_station=obs.station_ids[reference]),
                    AdjustmentSettings(inclinometer_sigma_rad=INCL,
                                       heading_prior_sigma_rad=heading,
                                       heading_bias_sigma_rad=bias, odometry_ratio=ratio,
                                       odometry_heading_rad_per_m=rate, snooping=False),
                    nominal=NominalPoses(truth.pose[:, :3], truth.pose[:, 3]),
                    odometry=readings,
                    heading=HeadingReadings(truth.pose[:, 3]) if heading else None)
    assert np.abs(result.marker_xyz_m - truth.marker_xyz_m).max() < 1e-9
    assert result.sigma0_squared < 1e-12  # exact data: every row closes, the aids' too
    n6 = 6 * s
    _assert_same_covariance(cov.full, site_axes(result.covariance[:n6, :n6],
                                                          truth.pose[:, 3]))
    predicted = net.marker_covariances(cov, np.arange(problem.n_sites))
    for j in range(problem.n_sites):
        _assert_same_covariance(predicted[j], result.marker_covariance(j))


@pytest.mark.parametrize("seed, control, sigma_c", [
    (1, (0, 3, 5), 0.002),
    (3, (2, 4), 0.01),
    (5, (1,), 0.0005),
])
def test_planner_predicts_the_adjustments_covariance_with_a_control_datum(seed, control,
                                                                           sigma_c):
    """Control points (a lander's fiducials, known to ``sigma_c`` per axis) as the datum: no
    station fixed. The planner folds each control point's prior into its site's
    ``J^(j)`` (``T_j = W_j + 1 / sigma_c^2``); the adjustment carries the markers as unknowns
    with the prior as observations. With one control point the headings hang on the tilts and
    the lever arms of the network alone, so a single point is the hardest case."""
    obs, truth, problem = _network(seed)
    problem, points = _with_control(problem, truth, control, sigma_c)
    heading = math.radians(0.5) if len(control) == 1 else None
    net = NetworkModel(problem, 10.0, INCL, heading_prior_sigma_rad=heading)
    assert net.reference is None
    np.testing.assert_allclose(net.datum_xyz, truth.marker_xyz_m[list(control)].mean(axis=0))
    cov = net.covariance(net.information(np.ones(problem.n_sites, bool)))
    assert cov.determined.all()

    result = adjust(obs, Datum(kind="control", control=points),
                    AdjustmentSettings(inclinometer_sigma_rad=INCL,
                                       heading_prior_sigma_rad=heading, snooping=False),
                    nominal=NominalPoses(truth.pose[:, :3], truth.pose[:, 3]),
                    heading=HeadingReadings(truth.pose[:, 3]) if heading else None)
    assert np.abs(result.marker_xyz_m - truth.marker_xyz_m).max() < 1e-9
    n6 = 6 * problem.n_stations
    _assert_same_covariance(cov.full, site_axes(result.covariance[:n6, :n6],
                                                truth.pose[:, 3]))
    predicted = net.marker_covariances(cov, np.arange(problem.n_sites))
    for j in range(problem.n_sites):
        _assert_same_covariance(predicted[j], result.marker_covariance(j))
