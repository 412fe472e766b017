"""A closed traverse's odometry (planner.accuracy.aids, pipeline.network.aids): the closing
reading from the last station back to the first, its sigma over the distance driven along the
closing legs, checked against rows built by hand, finite differences of the adjustment's
observation, the analytic covariance of a loop of equal legs, a Monte-Carlo of the adjustment
on the simulated chain, verify's simulated readings and the AOI design plan."""

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import binom, chi2

from markerplan.errors import ConfigError
from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.aids import OdometryReadings, aid_model, wrap
from pipeline.network.simulation import simulated_network
from planner.accuracy.aids import Odometry, closing_distance_m, pose_aids
from planner.accuracy.network import NetworkModel
from planner.config import PlanConfig
from planner.problem.usability import USABLE, PlanProblem
from planner.verify.network_aids import PlanAids

INCL = math.radians(0.01)
RATIO, RATE = 0.02, math.radians(0.05)
#: A bent open path of 5 stations (drive order), m.
PATH = np.array([[0.0, 0, 0], [11, 3, 0.5], [20, -4, 1.0], [27, 6, 0.2], [15, 14, -0.3]])


def test_the_closing_reading_is_one_more_relative_pose_row_built_by_hand():
    """Closed minus open information is ``A^T W A`` of the rows of the first station's pose in
    the last's levelled frame, linearised at headings 0 (d/dpsi of ``Rz(psi)^T d`` is
    ``(d_y, -d_x, 0)``), weighted over the closing legs' distance, not the straight one."""
    loop, s = 37.0, PATH.shape[0]
    closed = pose_aids(PATH, 0.0, odometry=Odometry(RATIO, RATE, loop))
    opened = pose_aids(PATH, 0.0, odometry=Odometry(RATIO, RATE))
    every = np.arange(6 * s)
    d = PATH[0] - PATH[-1]
    a = np.zeros((4, 6 * s))
    for axis in range(3):
        a[axis, axis] = 1.0                    # t_first
        a[axis, 6 * (s - 1) + axis] = -1.0     # t_last
    a[:3, 6 * (s - 1) + 3] = [d[1], -d[0], 0.0]  # the lever on the last station's heading
    a[3, 3], a[3, 6 * (s - 1) + 3] = 1.0, -1.0
    w = np.diag([1 / (RATIO * loop) ** 2] * 3 + [1 / (RATE * loop) ** 2])
    np.testing.assert_allclose(closed.information(every) - opened.information(every),
                               a.T @ w @ a, rtol=1e-9, atol=1e-9)
    assert closed.links().tolist() == [[0, 1], [1, 2], [2, 3], [3, 4], [4, 0]]


def test_the_adjustments_closing_row_is_the_derivative_of_its_observation():
    """At turned headings the design of every reading, the closing one too, equals central
    differences of the misclosure ``Rz(psi_from)^T (t_to - t_from) - dp`` and the headings'."""
    rng = np.random.default_rng(5)
    s = PATH.shape[0]
    heading = rng.uniform(-np.pi, np.pi, s)
    readings = OdometryReadings.from_poses(np.arange(s), PATH, heading, 40.0)
    model = aid_model(s, readings, RATIO, RATE, None, None, None)
    pose = np.zeros((s, 6))
    pose[:, :3] = PATH + rng.normal(0.0, 0.3, PATH.shape)
    pose[:, 3] = heading + rng.normal(0.0, 0.05, s)
    design, f = model.linearise(pose)
    assert f.size == 4 * s  # 3 position rows and one heading row per reading, closing included
    numeric = np.zeros_like(design.toarray())
    h = 1e-6
    for col in range(6 * s):
        step = np.zeros(6 * s)
        step[col] = h
        up = model.linearise(pose + step.reshape(s, 6))[1]
        down = model.linearise(pose - step.reshape(s, 6))[1]
        numeric[:, col] = (up - down) / (2 * h)
    np.testing.assert_allclose(design.toarray(), numeric, atol=1e-6)
    np.testing.assert_allclose(np.diag(model.weight.toarray())[[3 * s - 1, 4 * s - 1]],
                               [1 / (RATIO * 40.0) ** 2, 1 / (RATE * 40.0) ** 2])


def test_a_loop_of_equal_legs_has_the_analytic_covariance_and_is_symmetric():
    """Stations on a circle, the lander midway between the last and the first, so the closing
    legs are as long as every other leg ``c``: with headings known the positions are a loop of
    equal readings, each axis' variance at station ``j`` (from the datum ``S1``)
    ``(ratio c)^2 j (k - j) / k``, equal at ``j`` and ``k - j``; the open traverse's is
    ``(ratio c)^2 j``, its worst station far worse."""
    k, radius = 12, 30.0
    angle = 2 * np.pi * np.arange(k) / k
    xyz = np.column_stack([radius * np.cos(angle), radius * np.sin(angle), np.zeros(k)])
    chord = 2 * radius * np.sin(np.pi / k)
    lander = 0.5 * (xyz[0] + xyz[-1])
    loop = np.linalg.norm(xyz[-1] - lander) + np.linalg.norm(lander - xyz[0])
    assert loop == pytest.approx(chord)
    positions = (6 * np.arange(1, k)[:, None] + np.arange(3)).ravel()  # S1 fixed, headings known
    var = {}
    for name, odometry in (("closed", Odometry(RATIO, None, loop)), ("open", Odometry(RATIO))):
        cov = np.linalg.inv(pose_aids(xyz, 0.0, odometry=odometry).information(positions))
        var[name] = np.diag(cov).reshape(k - 1, 3)
    j = np.arange(1, k)
    expected = (RATIO * chord) ** 2 * j * (k - j) / k
    np.testing.assert_allclose(var["closed"], np.repeat(expected[:, None], 3, axis=1), rtol=1e-9)
    np.testing.assert_allclose(var["closed"], var["closed"][::-1], rtol=1e-9)
    np.testing.assert_allclose(var["open"][:, 0], (RATIO * chord) ** 2 * j, rtol=1e-9)
    assert var["open"].max() > 3.5 * var["closed"].max()


def test_closing_the_traverse_lowers_the_worst_station_of_odometry_alone():
    """Odometry alone (relative positions and headings, no markers, no tilt): the closed
    traverse's worst station error is well below the open one's and no station gets worse; a
    longer drive home closes it less."""
    xyz = np.vstack([PATH, [[5, 12, 0.0], [-4, 5, 0.0]]])
    problem = _problem(xyz, np.zeros((0, 3)), np.zeros(0, int), np.zeros(0, int), np.zeros(0))
    worst = {}
    for loop in (None, 8.0, 80.0):
        net = NetworkModel(problem, 10.0, 0.0, odometry=Odometry(RATIO, RATE, loop))
        cov = net.covariance(net.prior_information)
        assert cov.determined.all()
        worst[loop] = [np.sqrt(np.trace(cov.station(i)[:3, :3])) for i in range(len(xyz))]
    assert max(worst[8.0]) < 0.6 * max(worst[None])
    assert np.all(np.array(worst[8.0]) <= np.array(worst[80.0]) + 1e-12)
    assert np.all(np.array(worst[80.0]) <= np.array(worst[None]) + 1e-12)


def _problem(station_xyz, site_xyz, station, site, sigma):
    diff = site_xyz[site] - station_xyz[station]
    n = site_xyz.shape[0]
    return PlanProblem(
        station_ids=tuple(f"S{i + 1}" for i in range(len(station_xyz))), station_xyz=station_xyz,
        site_ids=tuple(f"M{j}" for j in range(n)), site_xyz=site_xyz,
        site_existing=np.zeros(n, bool), site_cost=np.ones(n), pair_station=station,
        pair_site=site, pair_distance_m=np.linalg.norm(diff, axis=1),
        pair_bearing_rad=np.arctan2(diff[:, 1], diff[:, 0]), pair_sigma_m=sigma,
        pair_reason=np.full(station.size, USABLE, dtype=np.int8))


#: A curling traverse whose last station ends 4 m from its first (weak 0.5 m markers, so the
#: odometry carries weight), driven home over 12 m.
CHAIN = dict(n_stations=6, seed=58, spacing_m=12.0, turn_sigma_rad=1.0, markers_per_station=3.0,
             sigma_m=0.5, odometry_ratio=0.005, odometry_heading_rad_per_m=math.radians(0.005))
LOOP_M = 12.0


def test_adjusted_closed_chain_matches_the_planners_prediction_monte_carlo():
    """300 draws of the simulated chain (markers, tilts, odometry with the closing reading)
    adjusted with the closing reading: the free stations' (x, y, z, heading) errors, 20 in all,
    against the planner's predicted covariance of the closed traverse: the share inside the
    95 % chi-square region lies in the binomial 99.9 % interval and the mean squared
    Mahalanobis distance is 20 within 4 of its standard errors. The open traverse's
    prediction (the loop left out) fails the mean by far."""
    obs, truth = simulated_network(**CHAIN, odometry_loop_m=LOOP_M, noise_seed=0)
    assert np.linalg.norm(truth.pose[-1, :3] - truth.pose[0, :3]) < 0.5 * LOOP_M
    problem = _problem(truth.pose[:, :3], truth.marker_xyz_m, obs.station, obs.marker,
                       obs.sigma_m)
    s = len(obs.station_ids)
    free = (6 * np.arange(1, s)[:, None] + np.arange(4)).ravel()
    predicted = {}
    for loop in (LOOP_M, None):
        net = NetworkModel(problem, 10.0, INCL, odometry=Odometry(
            CHAIN["odometry_ratio"], CHAIN["odometry_heading_rad_per_m"], loop))
        cov = net.covariance(net.information(np.ones(problem.n_sites, bool)))
        predicted[loop] = cov.full[np.ix_(free, free)]
    settings = AdjustmentSettings(inclinometer_sigma_rad=INCL,
                                  odometry_ratio=CHAIN["odometry_ratio"],
                                  odometry_heading_rad_per_m=CHAIN["odometry_heading_rad_per_m"],
                                  snooping=False)
    draws = 300
    error = np.empty((draws, free.size))
    for i in range(draws):
        obs, truth = simulated_network(**CHAIN, odometry_loop_m=LOOP_M, noise_seed=1000 + i)
        assert truth.odometry.loop_driven_m == LOOP_M
        result = adjust(obs, settings=settings, nominal=truth.nominal, odometry=truth.odometry)
        e = (result.pose - truth.pose)[1:, :4].copy()
        e[:, 3] = wrap(e[:, 3])
        error[i] = e.ravel()
    dof, tol = free.size, 4 * math.sqrt(2 * free.size / draws)
    d2 = {loop: np.einsum("ij,ij->i", error, np.linalg.solve(c, error.T).T)
          for loop, c in predicted.items()}
    inside = int(np.sum(d2[LOOP_M] <= chi2.ppf(0.95, dof)))
    low, high = binom.interval(0.999, draws, 0.95)
    assert low <= inside <= high, (inside, low, high)
    assert abs(d2[LOOP_M].mean() - dof) < tol, d2[LOOP_M].mean()
    assert d2[None].mean() < dof - tol, d2[None].mean()


def test_verify_reads_the_closing_reading_over_the_closing_legs():
    """verify's simulated readings: the closing reading from the last adjusted station to the
    first over ``odometry_loop_m`` (plus the straight steps to stations left out at the
    ends), with noise of that size; the consecutive readings are those of the open traverse
    drawn with the same seed."""
    rng = np.random.default_rng(2)
    ids = [f"S{i + 1}" for i in range(PATH.shape[0])]
    pose = np.zeros((len(ids), 6))
    pose[:, :3], pose[:, 3] = PATH, rng.uniform(-3, 3, len(ids))
    closed = PlanAids(odometry_percent=1.0, odometry_heading_deg_per_m=0.05,
                      odometry_loop_m=30.0)
    opened = PlanAids(odometry_percent=1.0, odometry_heading_deg_per_m=0.05)
    every = SimpleNamespace(station_ids=tuple(ids))
    got = closed.readings(ids, pose, 3)(every)[0]
    plain = opened.readings(ids, pose, 3)(every)[0]
    assert got.loop_driven_m == 30.0 and got.pairs[-1].tolist() == [4, 0]
    np.testing.assert_array_equal(got.delta_xyz_m[:-1], plain.delta_xyz_m)
    # the documented draws (planner.verify.network_aids): the bias, a heading noise per
    # station, then four odometry noises per station; the closing reading takes the last's
    draws = np.random.default_rng([29, 3])
    draws.normal(0.0, 0.0)
    draws.normal(size=5)
    noise = draws.normal(size=(5, 4))[4]
    exact = OdometryReadings.from_poses(np.arange(5), PATH, pose[:, 3], 30.0)
    np.testing.assert_allclose(got.delta_xyz_m[-1] - exact.delta_xyz_m[-1],
                               noise[:3] * 0.01 * 30.0, atol=1e-12)
    np.testing.assert_allclose(got.delta_heading_rad[-1] - exact.delta_heading_rad[-1],
                               noise[3] * math.radians(0.05) * 30.0, atol=1e-12)
    without_first = SimpleNamespace(station_ids=tuple(ids[1:]))
    got = closed.readings(ids, pose, 3)(without_first)[0]
    assert got.loop_driven_m == pytest.approx(30.0 + np.linalg.norm(PATH[1] - PATH[0]))
    assert got.pairs[-1].tolist() == [3, 0]


def test_closing_distance_of_kept_stations():
    assert closing_distance_m(PATH, 30.0, [0, 2, 4]) == 30.0
    steps = np.linalg.norm(np.diff(PATH, axis=0), axis=1)
    assert closing_distance_m(PATH, 30.0, [1, 3]) == pytest.approx(30.0 + steps[0] + steps[3])


@dataclass
class _Stations:
    """What :func:`planner.design.plan.design_plan` replaces in the inputs and outcome."""

    station_ids: list = field(default_factory=list)
    station_xyz: object = None
    station_heading_rad: object = None
    sources: dict = field(default_factory=dict)
    design: object = None
    timings_s: dict = field(default_factory=dict)


def test_the_design_plan_closes_its_route(monkeypatch):
    """In network mode with odometry the AOI plan's stations are planned with the route's
    last and first legs as ``odometry_loop_m``; not without odometry; a value given is
    refused (the route sets it)."""
    import planner.design.plan as module

    seen = []
    design = SimpleNamespace(station_ids=["S1", "S2", "S3"], station_position_m=PATH[:3],
                             station_heading_rad=np.zeros(3), order=np.array([2, 0, 1]),
                             route=SimpleNamespace(leg_m=np.array([4.0, 10, 11, 6.5])),
                             timings_s={})
    monkeypatch.setattr(module, "design_survey", lambda *args, **kwargs: design)
    monkeypatch.setattr(module, "make_plan",
                        lambda inputs, config, *args, **kwargs: seen.append(config) or _Stations())
    for config, loop in ((PlanConfig(network=True, odometry_percent=2.0), 10.5),
                         (PlanConfig(network=True), None),
                         (PlanConfig(network=True, odometry_heading_deg_per_m=0.1), 10.5)):
        module.design_plan(_Stations(), config, None, None)
        assert seen[-1].odometry_loop_m == loop
    with pytest.raises(ConfigError, match="`odometry_loop_m`.*set from the route"):
        module.design_plan(_Stations(), PlanConfig(network=True, odometry_percent=2.0,
                                                   odometry_loop_m=9.0), None, None)


def test_the_loop_is_a_setting_of_network_odometry_and_is_recorded():
    cfg = PlanConfig(network=True, odometry_percent=2.0, odometry_loop_m=25.0)
    assert cfg.odometry == Odometry(0.02, None, 25.0)
    assert cfg.aids_record()["odometry_loop_m"] == 25.0
    assert cfg.to_dict()["odometry_loop_m"] == 25.0
    assert cfg.as_known_control().odometry_loop_m is None
    with pytest.raises(ConfigError, match="`odometry_loop_m` is the distance"):
        PlanConfig(network=True, odometry_loop_m=25.0)
    with pytest.raises(ConfigError, match="`odometry_loop_m` must be"):
        PlanConfig(network=True, odometry_percent=2.0, odometry_loop_m=0.0)
    with pytest.raises(ConfigError, match="`odometry_loop_m` is a pose aid of network mode"):
        PlanConfig(odometry_loop_m=25.0)
    with pytest.raises(ConfigError, match="`loop_driven_m` must be"):
        OdometryReadings([0, 1], [[1.0, 0, 0]] * 2, [0.0] * 2, -1.0)
    with pytest.raises(ConfigError, match=r"\(2, 3\)"):
        OdometryReadings([0, 1], [[1.0, 0, 0]], [0.0], 5.0)


def test_reduce_keeps_the_plans_loop_for_the_stations_it_studies():
    """A study of some of a closed plan's stations closes over the plan's loop plus the steps
    to the stations left out at the ends; stations out of the plan's drive order (or not the
    plan's) are an open traverse."""
    from planner.reduction.study import _closing_of

    plan = {"stations": [{"id": f"S{i + 1}", "x_m": x, "y_m": y, "z_m": z}
                         for i, (x, y, z) in enumerate(PATH)]}
    ids = [f"S{i + 1}" for i in range(5)]
    steps = np.linalg.norm(np.diff(PATH, axis=0), axis=1)
    assert _closing_of(plan, ids, 30.0) == pytest.approx(30.0)
    assert _closing_of(plan, ids[1:4], 30.0) == pytest.approx(30.0 + steps[0] + steps[3])
    assert _closing_of(plan, ["S2", "S1", "S3"], 30.0) is None
    assert _closing_of(plan, ["S1", "X9"], 30.0) is None
