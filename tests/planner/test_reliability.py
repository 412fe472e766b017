"""Predicted outer reliability of a network layout (:mod:`planner.accuracy.reliability`), checked
by an independent re-computation: the network adjustment itself.

A noise-free simulated network is both a plan and the adjustment's input
(:func:`tests.planner.test_covariance_consistency._network`). Adding a bias of the predicted MDB
to one observation component and re-adjusting with :func:`pipeline.network.adjustment.adjust`
must move the stations by the predicted effect; the redundancy numbers must be the
adjustment's and sum to its degrees of freedom.
"""

import itertools
import math

import numpy as np
import pytest

from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.observations import Datum, NetworkObservations, NominalPoses
from pipeline.scans.rig import rot_z
from planner.accuracy.checks import evaluate_layout
from planner.accuracy.network import NetworkModel, network_model
from planner.accuracy.reliability import (
    RELIABILITY_COLUMNS,
    layout_reliability,
    reliability_rows,
    station_bias_record,
)
from planner.config import PlanConfig
from planner.problem.usability import USABLE, PlanProblem
from planner.program import plan_sites
from planner.program.cuts_network import bias_cuts
from planner.program.model import build_model
from tests.planner.instances import brute_force_optimum, make_problem
from tests.planner.test_covariance_consistency import INCL, _network

#: The adjustment converges to the exact solution; a bias of centimetres turns the network by
#: milliradians, so the linear prediction holds to ~1e-4 of the shift.
RTOL_SHIFT = 2e-3
#: Three markers between stations at (0, 0) and (20, 0), in general position (every component
#: controlled).
TIES = [(8, 6), (12, -5), (15, 2)]


def _adjusted(obs, truth, reference, heading_prior):
    return adjust(obs, Datum(reference_station=obs.station_ids[reference]),
                  AdjustmentSettings(inclinometer_sigma_rad=INCL,
                                     heading_prior_sigma_rad=heading_prior, snooping=False),
                  nominal=NominalPoses(truth.pose[:, :3], truth.pose[:, 3]))


def _biased(obs, truth, row, axis, bias_m):
    """``obs`` with observation ``row`` biased by ``bias_m`` along site axis ``axis`` (the
    observation is in the station's levelled frame: turned by the station's heading)."""
    b = np.zeros(3)
    b[axis] = bias_m
    xyz = obs.xyz_m.copy()
    xyz[row] += rot_z(np.array([truth.pose[obs.station[row], 3]]))[0].T @ b
    return NetworkObservations(obs.station_ids, obs.marker_ids, obs.station, obs.marker, xyz,
                               obs.sigma_m)


@pytest.mark.parametrize("seed, reference, heading_prior", [
    (1, 0, None),
    (5, 1, math.radians(0.5)),
])
def test_redundancy_is_the_adjustments_and_sums_to_the_dof(seed, reference, heading_prior):
    obs, truth, problem = _network(seed)
    net = NetworkModel(problem, 10.0, INCL, reference=reference,
                       heading_prior_sigma_rad=heading_prior)
    rel = layout_reliability(net, np.ones(problem.n_sites, bool))
    result = _adjusted(obs, truth, reference, heading_prior)
    # the adjustment also counts the heading prior of the reference, whose heading the datum
    # fixes: a pseudo-observation of a constant (redundancy 1), which the planner leaves out
    assert rel.dof == result.dof - (heading_prior is not None)
    assert rel.redundancy.sum() + rel.prior_redundancy.sum() == pytest.approx(rel.dof, rel=1e-9)
    # the adjustment's rows are in observation order; the planner's by site, then station
    row = {(s, m): i for i, (s, m) in enumerate(zip(obs.station, obs.marker, strict=True))}
    order = [row[(s, j)] for s, j in zip(rel.station, rel.site, strict=True)]
    np.testing.assert_allclose(rel.redundancy, result.redundancy[order], atol=1e-9)
    np.testing.assert_allclose(rel.mdb_m, result.mdb_m[order], rtol=1e-7)


@pytest.mark.parametrize("seed, reference, heading_prior", [
    (1, 0, None),
    (3, 2, None),
    (5, 1, math.radians(0.5)),
])
def test_a_bias_of_mdb_size_moves_the_stations_as_predicted(seed, reference, heading_prior):
    obs, truth, problem = _network(seed)
    net = NetworkModel(problem, 10.0, INCL, reference=reference,
                       heading_prior_sigma_rad=heading_prior)
    rel = layout_reliability(net, np.ones(problem.n_sites, bool))
    base = _adjusted(obs, truth, reference, heading_prior)
    row = {(s, m): i for i, (s, m) in enumerate(zip(obs.station, obs.marker, strict=True))}
    k = problem.n_stations - 1
    # the observation with the largest effect, and the one that moves the last station most
    for i in (int(np.argmax(rel.effect_m)), int(rel.station_cause[k])):
        shifts = []
        for axis in range(3):
            moved = _adjusted(_biased(obs, truth, row[(rel.station[i], rel.site[i])], axis,
                                      rel.mdb_m[i, axis]), truth, reference, heading_prior)
            shifts.append(moved.pose[:, :3] - base.pose[:, :3])
            assert np.abs(shifts[-1][reference]).max() < 1e-9
        shift = np.linalg.norm(np.array(shifts), axis=2)  # (3 axes, s stations)
        assert rel.effect_m[i] > 1e-3  # a real shift, not two zeros agreeing
        assert rel.effect_m[i] == pytest.approx(shift.max(), rel=RTOL_SHIFT)
        assert rel.effect_station[i] == np.unravel_index(np.argmax(shift), shift.shape)[1]
    horizontal = np.linalg.norm(np.array(shifts)[:, :, :2], axis=2)
    assert rel.station_effect_m[k] == pytest.approx(shift[:, k].max(), rel=RTOL_SHIFT)
    if rel.station_cause_horizontal[k] == i:
        assert rel.station_effect_horizontal_m[k] == pytest.approx(horizontal[:, k].max(),
                                                                   rel=RTOL_SHIFT)


def test_a_marker_seen_by_one_station_is_uncontrolled_and_moves_no_station():
    _, _, problem = _network(1)
    extra = problem.station_xyz[2] + np.array([3.0, 1.0, -1.2])
    one = PlanProblem(
        station_ids=problem.station_ids, station_xyz=problem.station_xyz,
        site_ids=(*problem.site_ids, "LONE"), site_xyz=np.vstack([problem.site_xyz, extra]),
        site_existing=np.zeros(problem.n_sites + 1, bool), site_cost=np.ones(problem.n_sites + 1),
        pair_station=np.r_[problem.pair_station, 2], pair_site=np.r_[problem.pair_site,
                                                                     problem.n_sites],
        pair_distance_m=np.r_[problem.pair_distance_m,
                              np.linalg.norm(extra - problem.station_xyz[2])],
        pair_bearing_rad=np.r_[problem.pair_bearing_rad, 0.3],
        pair_sigma_m=np.r_[problem.pair_sigma_m, 0.005],
        pair_reason=np.full(problem.pair_station.size + 1, USABLE, dtype=np.int8))
    net = NetworkModel(one, 10.0, INCL)
    with_lone = layout_reliability(net, np.ones(one.n_sites, bool))
    without = layout_reliability(net, np.r_[np.ones(problem.n_sites, bool), False])
    lone = np.flatnonzero(with_lone.site == problem.n_sites)
    assert lone.size == 1
    assert np.all(with_lone.redundancy[lone] == 0.0)
    assert np.all(np.isinf(with_lone.mdb_m[lone]))
    assert with_lone.effect_m[lone[0]] == 0.0 and with_lone.effect_station[lone[0]] == -1
    assert with_lone.dof == without.dof  # 3 observations, 3 unknowns
    np.testing.assert_allclose(with_lone.station_effect_m, without.station_effect_m, rtol=1e-9)
    assert np.isfinite(without.mdb_m).all()


def test_rows_report_an_uncontrolled_observation_as_such_and_name_the_causes():
    # two stations tied by C000..C002; C003 only S2 sees (25 m; 45 m from S1)
    problem = make_problem([(0, 0), (20, 0)], [*TIES, (45, 0)])
    net = NetworkModel(problem, 10.0, INCL)
    rel = layout_reliability(net, np.ones(4, bool))
    rows = reliability_rows(net, rel)
    assert [tuple(r) for r in rows] == [RELIABILITY_COLUMNS] * 7
    lone = rows[-1]
    assert (lone["station"], lone["site"], lone["controlled"]) == ("S2", "C003", False)
    assert lone["mdb_x_m"] is None and lone["effect_m"] == 0.0 and lone["effect_station"] is None
    assert all(r["controlled"] and r["effect_station"] == "S2" for r in rows[:6])
    record = station_bias_record(net, rel)
    assert record["S1"]["bias_effect_m"] == 0.0 and record["S1"]["bias_effect_caused_by"] is None
    worst = max(rows[:6], key=lambda r: r["effect_m"])
    assert record["S2"]["bias_effect_m"] == worst["effect_m"] > 0
    assert record["S2"]["bias_effect_caused_by"] == {"station": worst["station"],
                                                     "site": worst["site"]}


def test_an_untied_station_has_an_infinite_effect_and_no_cause():
    problem = make_problem([(0, 0), (20, 0), (200, 0)], [*TIES, (205, 0)])
    net = NetworkModel(problem, 10.0, INCL)
    rel = layout_reliability(net, np.ones(4, bool))
    assert np.isinf(rel.station_effect_m[2]) and rel.station_cause[2] == -1
    assert np.isfinite(rel.station_effect_m[:2]).all()
    assert station_bias_record(net, rel)["S3"]["bias_effect_m"] is None


def _network_instance():
    """A 3-station network plan (the seed-2 instance of the program tests) and its config
    with a requirement some markers cannot meet."""
    from tests.planner.test_network_program import _instance

    problem = _instance(2)
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                      working_radius_m=10, time_limit_s=60)
    best = network_model(problem, base).station_errors(np.ones(problem.n_sites, bool)).max()
    return problem, base.replace(requirement_m=float(1.15 * best))


def test_the_check_bounds_every_stations_mdb_effect():
    problem, cfg = _network_instance()
    net = network_model(problem, cfg)
    plan = plan_sites(problem, cfg).selected
    effect = layout_reliability(net, plan).station_effect_m
    assert evaluate_layout(problem, plan, cfg, net=net).bias_effect_m is None
    loose = evaluate_layout(problem, plan, cfg.replace(max_bias_effect_m=float(effect.max())),
                            net=net)
    np.testing.assert_array_equal(loose.bias_effect_m, effect)
    assert loose.all_ok
    tight = evaluate_layout(problem, plan, cfg.replace(
        max_bias_effect_m=float(0.99 * effect.max())), net=net)
    assert not tight.all_ok
    assert np.flatnonzero(~tight.ok).tolist() == [int(np.argmax(effect))]


def test_the_bias_no_good_cuts_off_the_layouts_tying_set_only():
    problem, cfg = _network_instance()
    net = network_model(problem, cfg)
    model = build_model(problem, cfg)
    plan = plan_sites(problem, cfg).selected
    effect = layout_reliability(net, plan).station_effect_m.max()
    variables = net.tying & (model.site_var >= 0)
    assert bias_cuts(model, plan, cfg.replace(max_bias_effect_m=float(effect)), net,
                     variables)[0] is None
    rows, lower, kinds = bias_cuts(model, plan, cfg.replace(
        max_bias_effect_m=float(0.9 * effect)), net, variables)
    assert [k.family for k in kinds] == ["cut-bias"]
    tying = np.flatnonzero(variables)
    for bits in itertools.product([False, True], repeat=tying.size):
        x = np.zeros(model.n_vars)
        x[model.site_var[tying[list(bits)]]] = 1.0
        x[model.site_var[~net.tying & (model.site_var >= 0)]] = 1.0  # non-tying: irrelevant
        same = np.array_equal(np.array(bits), plan[tying])
        assert (float((rows @ x)[0]) >= lower[0]) == (not same)


@pytest.mark.slow
def test_a_plan_with_a_bias_bound_is_the_brute_force_optimum():
    problem, cfg = _network_instance()
    net = network_model(problem, cfg)
    plain = plan_sites(problem, cfg).selected
    bound = float(0.9 * layout_reliability(net, plain).station_effect_m.max())
    bounded = cfg.replace(max_bias_effect_m=bound)
    r = plan_sites(problem, bounded)
    assert r.status == "optimal" and r.check.all_ok
    assert r.check.bias_effect_m.max() <= bound
    assert r.selected.sum() == brute_force_optimum(problem, bounded)
    assert not np.array_equal(r.selected, plain)
