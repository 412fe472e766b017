"""Pose aids in the network adjustment (pipeline.network.aids): odometry between consecutive
stations and a heading reference with a common boresight bias.

The planner's prediction of the same covariance is tests/planner/test_covariance_consistency.py.
"""

import math

import numpy as np
import pytest
from scipy.stats import binom, chi2

from markerplan.errors import ConfigError
from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.aids import HeadingReadings, OdometryReadings, wrap
from pipeline.network.simulation import simulated_network

RATIO, RATE = 0.01, math.radians(0.05)
HEADING, BIAS = math.radians(0.1), math.radians(0.3)
AIDED = dict(odometry_ratio=RATIO, odometry_heading_rad_per_m=RATE, heading_sigma_rad=HEADING,
             heading_bias_sigma_rad=BIAS)
SETTINGS = AdjustmentSettings(heading_prior_sigma_rad=HEADING, heading_bias_sigma_rad=BIAS,
                              odometry_ratio=RATIO, odometry_heading_rad_per_m=RATE,
                              snooping=False)


def _aided(noise_seed, settings=SETTINGS, **kw):
    obs, truth = simulated_network(n_stations=5, seed=4, markers_per_station=2.0,
                                   noise_seed=noise_seed, **AIDED, **kw)
    result = adjust(obs, settings=settings, nominal=truth.nominal, odometry=truth.odometry,
                    heading=HeadingReadings(truth.heading_reading_rad))
    return obs, truth, result


def test_adjusted_poses_agree_with_the_stated_covariance_monte_carlo():
    """200 draws of the simulator (measurements, tilts, odometry, heading readings with a new
    bias each time): the free stations' (x, y, z, heading) errors, 16 in all, against the
    adjustment's covariance: the share inside the 95 % chi-square region lies in the binomial
    99.9 % interval, and the mean squared Mahalanobis distance is 16 within 4 of its standard
    errors. Ignoring the bias's correlation (heading readings off by 3 of their sigmas) fails
    both by far."""
    draws, s = 200, 5
    free = (6 * np.arange(1, s)[:, None] + np.arange(4)).ravel()
    d2 = np.empty(draws)
    biases = np.empty(draws)
    for i in range(draws):
        _, truth, result = _aided(1000 + i)
        error = (result.pose - truth.pose)[1:, :4].copy()
        error[:, 3] = wrap(error[:, 3])
        cov = result.covariance[np.ix_(free, free)]
        d2[i] = error.ravel() @ np.linalg.solve(cov, error.ravel())
        biases[i] = truth.heading_bias_rad
    assert np.std(biases) > 0.5 * BIAS  # the bias does vary between draws
    dof = free.size
    inside = int(np.sum(d2 <= chi2.ppf(0.95, dof)))
    low, high = binom.interval(0.999, draws, 0.95)
    assert low <= inside <= high, (inside, low, high)
    assert abs(d2.mean() - dof) < 4 * math.sqrt(2 * dof / draws), d2.mean()


def test_exact_aids_recover_the_truth_through_a_turning_traverse():
    """No measurement noise and exact aids: Gauss-Newton from the dead-reckoned poses (metres
    and degrees off) recovers the true poses, and every row (markers and aids) closes."""
    obs, truth = simulated_network(n_stations=6, seed=2, noise_scale=0.0,
                                   inclinometer_sigma_rad=0.0, turn_sigma_rad=1.0,
                                   odometry_ratio=None, odometry_heading_rad_per_m=0.0,
                                   heading_sigma_rad=0.0)
    assert truth.odometry is not None and truth.heading_bias_rad == 0.0
    result = adjust(obs, settings=SETTINGS, nominal=truth.nominal, odometry=truth.odometry,
                    heading=HeadingReadings(truth.heading_reading_rad))
    np.testing.assert_allclose(result.pose[:, :4], truth.pose[:, :4], atol=1e-9)
    assert result.sigma0_squared < 1e-15
    # rows: points, tilt priors, odometry (4 per step), headings; less the free parameters
    assert result.dof == 3 * obs.n + 2 * 6 + 4 * 5 + 6 - (6 * 6 - 4) - 3 * len(obs.marker_ids)


def test_the_aids_only_lower_the_variances():
    """Weak markers (5 cm): odometry and the heading reference then carry real weight."""
    obs, truth, aided = _aided(7, sigma_m=0.05)
    plain = adjust(obs, settings=AdjustmentSettings(snooping=False), nominal=truth.nominal)
    n6 = 6 * 5
    assert np.all(np.diag(aided.covariance)[:n6] <= np.diag(plain.covariance)[:n6] * (1 + 1e-9))
    assert np.trace(aided.covariance[:n6, :n6]) < 0.9 * np.trace(plain.covariance[:n6, :n6])
    # with the datum heading fixed, a heading reference alone leaves each heading
    # sigma_r^2 + 1 / (1 / sigma_b^2 + 1 / sigma_r^2) (planner.accuracy.aids); more aids: less
    h = 6 * np.arange(1, 5) + 3
    alone = HEADING**2 + 1 / (1 / BIAS**2 + 1 / HEADING**2)
    assert np.all(np.diag(aided.covariance)[h] < alone)


def test_a_vanishing_bias_is_the_plain_heading_prior_and_no_aids_change_nothing():
    obs, truth = simulated_network(n_stations=4, seed=3, heading_sigma_rad=HEADING,
                                   heading_bias_sigma_rad=BIAS)
    reading = HeadingReadings(truth.heading_reading_rad)
    plain = AdjustmentSettings(heading_prior_sigma_rad=HEADING, snooping=False)
    tiny = AdjustmentSettings(heading_prior_sigma_rad=HEADING, heading_bias_sigma_rad=1e-9,
                              snooping=False)
    a = adjust(obs, settings=plain, nominal=truth.nominal, heading=reading)
    b = adjust(obs, settings=tiny, nominal=truth.nominal, heading=reading)
    np.testing.assert_allclose(b.covariance, a.covariance, rtol=1e-6, atol=1e-20)
    np.testing.assert_allclose(b.pose, a.pose, atol=1e-9)
    assert b.dof == a.dof
    # the readings, not the nominal headings, centre the prior
    c = adjust(obs, settings=plain, nominal=truth.nominal)
    assert np.abs(c.pose[:, 3] - a.pose[:, 3]).max() > 1e-4
    # asking the simulator for aids draws them after everything else
    obs0, truth0 = simulated_network(n_stations=4, seed=3)
    np.testing.assert_array_equal(obs0.xyz_m, obs.xyz_m)
    np.testing.assert_array_equal(truth0.nominal.position_m, truth.nominal.position_m)
    assert truth0.odometry is None and truth0.heading_reading_rad is None


def test_odometry_readings_from_poses_are_the_relative_poses():
    rng = np.random.default_rng(0)
    p, h = rng.normal(0, 10, (4, 3)), rng.uniform(-np.pi, np.pi, 4)
    r = OdometryReadings.from_poses(np.arange(4), p, h)
    for k in range(3):
        c, s = math.cos(h[k]), math.sin(h[k])
        back = p[k] + np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ r.delta_xyz_m[k]
        np.testing.assert_allclose(back, p[k + 1], atol=1e-12)
        assert abs(wrap(h[k] + r.delta_heading_rad[k] - h[k + 1])) < 1e-12


@pytest.mark.parametrize("settings, match", [
    (dict(odometry_ratio=0.0), "odometry_ratio must be a number > 0"),
    (dict(odometry_heading_rad_per_m=-1.0), "odometry_heading_rad_per_m must be"),
    (dict(heading_prior_sigma_rad=0.01, heading_bias_sigma_rad=0.0), "heading_bias_sigma_rad"),
    (dict(heading_bias_sigma_rad=0.01), "needs a heading reference"),
])
def test_bad_aid_settings_are_one_line_errors(settings, match):
    with pytest.raises(ConfigError, match=match) as err:
        AdjustmentSettings(**settings)
    assert "\n" not in str(err.value)


def test_aids_that_do_not_fit_the_settings_are_one_line_errors():
    obs, truth = simulated_network(n_stations=3, seed=1, odometry_ratio=0.01)
    odo = truth.odometry
    cases = [
        (AdjustmentSettings(), dict(odometry=odo), "need their sigmas"),
        (AdjustmentSettings(odometry_ratio=0.01), {}, "no odometry readings"),
        (AdjustmentSettings(), dict(heading=HeadingReadings(np.zeros(3))),
         "need heading_prior_sigma_rad"),
        (AdjustmentSettings(heading_prior_sigma_rad=0.01),
         dict(heading=HeadingReadings(np.zeros(2))), "all 3 stations"),
        (AdjustmentSettings(odometry_ratio=0.01),
         dict(odometry=OdometryReadings([0, 5], [[1.0, 0, 0]], [0.0])), "must index the 3"),
    ]
    for settings, kw, match in cases:
        with pytest.raises(ConfigError, match=match) as err:
            adjust(obs, settings=settings, nominal=truth.nominal, **kw)
        assert "\n" not in str(err.value)
    with pytest.raises(ConfigError, match="drove no distance"):
        OdometryReadings([0, 1], [[0.0, 0, 0]], [0.0])
    with pytest.raises(ConfigError, match="lists a station twice"):
        OdometryReadings([0, 1, 0], [[1.0, 0, 0]] * 2, [0.0] * 2)


def test_sparse_marginals_with_aids_equal_the_dense_covariance():
    """The aids touch only the stations' block of the normal matrix, so the markers'
    elimination and the sparse marginal covariance hold unchanged (snooping on: the
    downdates too)."""
    obs, truth = simulated_network(n_stations=5, seed=4, noise_seed=11, **AIDED)
    kw = dict(heading_prior_sigma_rad=HEADING, heading_bias_sigma_rad=BIAS,
              odometry_ratio=RATIO, odometry_heading_rad_per_m=RATE)
    run = {kind: adjust(obs, settings=AdjustmentSettings(covariance=kind, **kw),
                        nominal=truth.nominal, odometry=truth.odometry,
                        heading=HeadingReadings(truth.heading_reading_rad))
           for kind in ("dense", "sparse")}
    dense, sparse = run["dense"], run["sparse"]
    np.testing.assert_allclose(sparse.pose, dense.pose, atol=1e-12)
    for i in range(5):
        np.testing.assert_allclose(sparse.station_covariance(i), dense.station_covariance(i),
                                   rtol=1e-9, atol=1e-20)
    for j in range(len(obs.marker_ids)):
        np.testing.assert_allclose(sparse.marker_covariance(j), dense.marker_covariance(j),
                                   rtol=1e-9, atol=1e-20)
    assert sparse.dof == dense.dof and sparse.sigma0_squared == pytest.approx(
        dense.sigma0_squared, rel=1e-9)
