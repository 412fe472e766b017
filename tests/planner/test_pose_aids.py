"""Pose aids of a network (planner.accuracy.aids): a heading reference with a boresight bias and
odometry between consecutive stations, checked against an explicit bias parameter, a
Monte-Carlo of the dead-reckoned chain (exact rotations), the brute-force optimum and the CLI."""

import itertools

import numpy as np
import pytest

from markerplan.errors import ConfigError
from planner.accuracy.aids import Odometry, pose_aids
from planner.accuracy.figure import ErrorFigure
from planner.accuracy.network import NetworkModel, network_model
from planner.accuracy.requirement import NetworkRequirement
from planner.config import PlanConfig
from planner.program import plan_sites
from tests.planner.instances import brute_force_optimum, make_problem

INCL = np.radians(0.01)


def _path(n=5, seed=0):
    """Stations along a bent path (the order the rover drives), with sites around them."""
    rng = np.random.default_rng(seed)
    st = np.cumsum(np.vstack([[0, 0], rng.uniform([8, -6], [14, 6], (n - 1, 2))]), axis=0)
    sites = np.vstack([st + rng.uniform(-7, 7, st.shape), st + rng.uniform(-7, 7, st.shape)])
    return make_problem(st, sites, max_range_m=16.0)


def test_heading_bias_information_equals_an_explicit_bias_parameter_eliminated():
    """The correlated heading weight ``(I - c 1 1^T) / sigma_r^2`` is the bias eliminated from
    observations ``psi_s + b`` (weight 1 / sigma_r^2) with the prior ``b ~ N(0, sigma_b^2)``,
    computed here as a Schur complement of the augmented normal matrix."""
    xyz = np.array([[0.0, 0, 0], [10, 0, 0], [10, 12, 0], [0, 9, 1]])
    s, sr, sb = 4, 0.002, 0.005
    aids = pose_aids(xyz, INCL, sr, sb)
    n6 = 6 * s
    a = np.zeros((s + 1, n6 + 1))  # headings, then the bias prior
    for k in range(s):
        a[k, 6 * k + 3] = a[k, n6] = 1.0
    a[s, n6] = 1.0
    w = np.diag([1 / sr**2] * s + [1 / sb**2])
    n = a.T @ w @ a
    schur = n[:n6, :n6] - np.outer(n[:n6, n6], n[n6, :n6]) / n[n6, n6]
    for k in range(s):  # the tilt rows
        schur[6 * k + 4, 6 * k + 4] += 1 / INCL**2
        schur[6 * k + 5, 6 * k + 5] += 1 / INCL**2
    np.testing.assert_allclose(aids.information(np.arange(n6)), schur, rtol=1e-10, atol=1e-6)


@pytest.mark.parametrize("bias", [0.0, 0.003, 1.0])
def test_a_heading_with_the_datum_fixed_is_its_reading_less_the_bias_the_datum_reveals(bias):
    """No markers: a station's heading variance is ``sigma_r^2 + 1 / (1/sigma_b^2 +
    1/sigma_r^2)`` (analytic), from ``sigma_r^2`` without bias to ``2 sigma_r^2`` for a large
    one."""
    p = _path(4)
    sr = 0.002
    net = NetworkModel(p, 10.0, INCL, heading_prior_sigma_rad=sr, heading_bias_sigma_rad=bias)
    heading = net.free_position[6 * np.arange(1, 4) + 3]
    cov = np.linalg.inv(net.prior_information[np.ix_(heading, heading)])
    expected = sr**2 + (1 / (1 / bias**2 + 1 / sr**2) if bias > 0 else 0.0)
    np.testing.assert_allclose(np.diag(cov), expected, rtol=1e-9)


def test_odometry_covariance_matches_a_monte_carlo_of_the_dead_reckoned_chain():
    """Odometry alone (no markers) predicts each station's pose covariance; drawn here by
    composing noisy relative poses with exact rotations (not the linear model), 4,000 draws."""
    p = _path(5, seed=3)
    ratio, rate = 0.02, np.radians(0.05)
    net = NetworkModel(p, 10.0, 0.0, odometry=Odometry(ratio, rate))
    cov = net.covariance(net.prior_information)
    assert cov.determined.all()
    xyz = p.station_xyz
    rng = np.random.default_rng(1)
    draws, s = 4000, xyz.shape[0]
    pose = np.zeros((draws, s, 4))  # x, y, z, heading (nominal headings 0, the datum exact)
    pose[:, 0, :3] = xyz[0]
    for k in range(s - 1):
        d = xyz[k + 1] - xyz[k]
        dist = np.linalg.norm(d)
        meas = d + rng.normal(0.0, ratio * dist, (draws, 3))
        h = pose[:, k, 3]
        c, sn = np.cos(h), np.sin(h)
        pose[:, k + 1, 0] = pose[:, k, 0] + c * meas[:, 0] - sn * meas[:, 1]
        pose[:, k + 1, 1] = pose[:, k, 1] + sn * meas[:, 0] + c * meas[:, 1]
        pose[:, k + 1, 2] = pose[:, k, 2] + meas[:, 2]
        pose[:, k + 1, 3] = h + rng.normal(0.0, rate * dist, draws)
    for k in range(1, s):
        sampled = np.cov(pose[:, k].T)
        predicted = cov.station(k)[:4, :4]
        scale = np.sqrt(np.outer(np.diag(predicted), np.diag(predicted)))
        assert np.all(np.abs(sampled - predicted) / scale < 0.08), (k, sampled, predicted)


def test_odometry_ties_every_station_to_the_datum():
    p = _path(4)
    plain = NetworkModel(p, 10.0, INCL)
    driven = NetworkModel(p, 10.0, INCL, odometry=Odometry(0.02, None))
    none = np.zeros(p.n_sites, bool)
    assert plain.connected_to_reference(none).tolist() == [True, False, False, False]
    assert driven.connected_to_reference(none).all()
    assert not plain.covariance(plain.information(none)).determined[1:].any()
    # its relative positions alone leave each heading free (turning the next stations with it)
    assert driven.covariance(driven.information(none)).determined.tolist() == [True] + [False] * 3
    both = NetworkModel(p, 10.0, INCL, odometry=Odometry(0.02, np.radians(0.01)))
    assert both.covariance(both.information(none)).determined.all()


def test_aids_keep_the_tangent_cuts_valid_and_only_lower_the_errors():
    """Brute force over every layout of a small path: no tangent cut taken at a failing layout
    removes a passing one, with a biased heading reference and odometry; and the aids never
    raise a station's error."""
    q = _path(3, seed=5)
    p = make_problem(q.station_xyz[:, :2], q.site_xyz[:9, :2], max_range_m=16.0)
    aids = dict(heading_prior_sigma_rad=np.radians(0.2), heading_bias_sigma_rad=np.radians(0.1),
                odometry=Odometry(0.05, np.radians(0.02)))
    probe = NetworkModel(p, 10.0, INCL, figure=ErrorFigure("ellipsoid"), **aids)
    req = 1.5 * probe.station_errors(np.ones(p.n_sites, bool)).max()
    aided = NetworkModel(p, 10.0, INCL, figure=ErrorFigure("ellipsoid"),
                         requirement=NetworkRequirement(float(req)), **aids)
    plain = NetworkModel(p, 10.0, INCL, figure=ErrorFigure("ellipsoid"))
    passing, cuts = [], []
    for b in itertools.product([0, 1], repeat=p.n_sites):
        sel = np.array(b, bool)
        cov = aided.covariance(aided.information(sel))
        e = aided.station_errors_from(cov)
        assert np.all(e <= plain.station_errors(sel) * (1 + 1e-9) + 1e-12)
        if np.all(e <= req):
            passing.append(sel)
        elif len(cuts) < 60:
            cuts += aided.station_tangents(cov, np.flatnonzero(e > req), rim="spread")
    assert passing and cuts
    x = np.asarray(passing, float)
    for _, coef, rhs in cuts:
        assert np.all(x @ coef >= rhs * (1 - 1e-9))


def test_a_plan_with_aids_is_the_brute_force_optimum_and_needs_no_more_markers():
    p = _path(4, seed=2)
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                      working_radius_m=10, time_limit_s=60, error_figure="ellipsoid")
    every = network_model(p, base).station_errors(np.ones(p.n_sites, bool)).max()
    base = base.replace(requirement_m=float(1.2 * every))
    aided_cfg = base.replace(heading_aid="sun-sensor", odometry_percent=2.0)
    plain, aided = plan_sites(p, base), plan_sites(p, aided_cfg)
    assert aided.status == "optimal" and aided.check.all_ok
    assert aided.selected.sum() == brute_force_optimum(p, aided_cfg)
    assert aided.selected.sum() <= plain.selected.sum()


def test_bad_aid_settings_are_one_line_errors():
    with pytest.raises(ConfigError, match="network mode"):
        PlanConfig(odometry_percent=2.0)
    with pytest.raises(ConfigError, match="heading_aid"):
        PlanConfig(network=True, heading_aid="compass")
    with pytest.raises(ConfigError, match="no.*heading reference|none is set"):
        PlanConfig(network=True, heading_bias_sigma_deg=0.1)
    with pytest.raises(ConfigError, match=r"heading_prior_sigma_deg.*\(0, 10\]"):
        PlanConfig(network=True, heading_prior_sigma_deg=0.0)
    with pytest.raises(ConfigError, match="one position"):
        pose_aids(np.zeros((2, 3)), INCL, odometry=Odometry(0.02, None))
    cfg = PlanConfig(network=True, heading_aid="star-tracker", heading_prior_sigma_deg=0.001)
    assert cfg.heading_sigmas_deg == (0.001, 20 / 3600)  # the setting over the class


def test_the_aids_are_recorded_as_used():
    cfg = PlanConfig(network=True, heading_aid="sun-sensor", odometry_percent=2.0)
    assert cfg.aids_record() == {
        "inclinometer_sigma_deg": 0.01, "heading_prior_sigma_deg": 0.1,
        "heading_aid": "sun-sensor", "heading_bias_sigma_deg": 0.05, "odometry_percent": 2.0,
        "odometry_heading_deg_per_m": None, "odometry_loop_m": None}
