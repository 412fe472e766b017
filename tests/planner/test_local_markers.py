"""Local accuracy between markers: the marker cross-covariance against the full normal
matrix, the cuts against every layout, the plan against the fewest passing layout."""

import itertools
from dataclasses import replace

import numpy as np
import pytest

from markerplan.errors import ConfigError
from planner.accuracy.checks import evaluate_layout
from planner.accuracy.figure import ErrorFigure
from planner.accuracy.local import LocalAccuracy, LocalRequirement
from planner.accuracy.local_markers import (
    LocalMarkerAccuracy,
    marker_cross_covariance,
    marker_pairs,
)
from planner.accuracy.network import NetworkModel
from planner.config import PlanConfig
from planner.program import plan_sites
from tests.planner.instances import brute_force_optimum, station_line

INCL = np.radians(0.01)
RADIUS = 10.0


def _dense_marker_covariance(net, sites):
    """(m, m, 3, 3) from the inverse of the full normal matrix with the poses' free parameters
    and the markers at ``sites`` as unknowns (every usable observation of them, weight
    ``w I``, plus the pose aids' prior): independent of the Schur complement."""
    s6, m, free = 6 * net.problem.n_stations, sites.size, net.free
    pos = {int(j): i for i, j in enumerate(sites)}
    keep = np.r_[free, s6 + np.arange(3 * m)]
    n = np.zeros((keep.size, keep.size))
    n[:free.size, :free.size] = net.prior_information
    # a control point's known coordinates: a prior on its marker
    prior = np.repeat(net.site_prior_weight[sites], 3)
    n[free.size:, free.size:] += np.diag(prior)
    for q in np.flatnonzero(np.isin(net.pair_site, sites)):
        a = np.zeros((3, s6 + 3 * m))
        st, j = net.pair_station[q], pos[int(net.pair_site[q])]
        a[:, 6 * st:6 * st + 6] = net.design[q]
        a[:, s6 + 3 * j:s6 + 3 * j + 3] = -np.eye(3)
        a = a[:, keep]
        n += net.weight[q] * a.T @ a
    q = np.linalg.inv(n)[free.size:, free.size:]
    return q.reshape(m, 3, m, 3).transpose(0, 2, 1, 3)


@pytest.mark.parametrize("subset, control", [(False, False), (True, False), (False, True)])
def test_marker_cross_covariance_is_the_full_normal_matrix_inverse(subset, control):
    p = station_line()
    if control:  # two sites as control points (a lander's fiducials), no station fixed
        sigma = np.zeros(p.n_sites)
        sigma[[2, 7]] = 0.003
        p = replace(p, site_existing=sigma > 0, site_control_sigma_m=sigma)
    net = NetworkModel(p, RADIUS, INCL)
    sel = np.ones(p.n_sites, bool)
    if subset:
        sel[::3] = False
    cov = net.covariance(net.information(sel))
    assert cov.determined.all()
    sites = np.flatnonzero(sel & (net.site_weight > 0))
    got = marker_cross_covariance(net, cov, sites)
    want = _dense_marker_covariance(net, sites)
    assert np.abs(got - want).max() <= 1e-9 * np.abs(want).max()
    # the diagonal blocks are the network's own marker covariances
    idx = np.arange(sites.size)
    np.testing.assert_allclose(got[idx, idx], net.marker_covariances(cov, sites), rtol=1e-9,
                               atol=1e-15)


def test_marker_pairs_and_configuration():
    req = LocalRequirement(0.05, 100.0, 30.0)
    p = marker_pairs(np.array([[0, 0, 0], [10, 0, 5], [50, 0, 0.0]]), [0, 1, 2], req)
    assert p.first.tolist() == [0] and p.second.tolist() == [1]
    np.testing.assert_allclose(p.direction[0], np.array([10, 0, 5]) / np.hypot(10, 5))
    assert p.allowed_m[0] == pytest.approx(0.051)
    assert marker_pairs(np.zeros((2, 3)), [], req).size == 0
    with pytest.raises(ConfigError, match="local_markers.*local_requirement_m"):
        PlanConfig(network=True, local_markers=True)
    with pytest.raises(ConfigError, match="local_markers` must be true or false"):
        PlanConfig(network=True, local_requirement_m=0.1, local_markers="yes")


def test_a_pair_seen_from_an_undetermined_station_is_infinite():
    p = station_line(3, n_sites=10)
    net = NetworkModel(p, RADIUS, INCL)
    cov = net.covariance(net.information(np.zeros(p.n_sites, bool)))
    local = LocalMarkerAccuracy(net, LocalRequirement(1.0, within_m=100.0))
    pairs = local.pairs(np.ones(p.n_sites, bool) & (net.site_weight > 0))
    assert pairs.size and np.isinf(local.errors(cov, pairs)).any()


def _cut_value(row_sites, coef, first, second, lower, x):
    return x[:, row_sites] @ coef - x[:, first] - x[:, second] >= lower - 1e-9


@pytest.mark.parametrize(("figure", "kind"), [("ellipsoid", "position"),
                                              ("ellipsoid", "distance"),
                                              ("quantile", "position")])
def test_marker_pair_cuts_never_remove_a_passing_layout(figure, kind):
    """Brute force over every layout of a 9-site line: every layout whose marker pairs all
    pass satisfies every no-good row and tangent taken at any layout with a failing pair."""
    p = station_line(3, n_sites=9, seed=4)
    net = NetworkModel(p, RADIUS, INCL, figure=ErrorFigure(figure))
    every = np.ones(p.n_sites, bool)
    probe = LocalMarkerAccuracy(net, LocalRequirement(1.0, within_m=25.0, kind=kind))
    cov = net.covariance(net.information(every))
    err = probe.errors(cov, probe.pairs(every & (net.site_weight > 0)))
    local = LocalMarkerAccuracy(net, LocalRequirement(float(np.quantile(err, 0.6)),
                                                      within_m=25.0, kind=kind))
    layouts = np.array(list(itertools.product([0, 1], repeat=p.n_sites)), bool)
    passing, nogood, tangent = [], [], []
    j_all = net.information(every)
    for sel in layouts:
        cov = net.covariance(net.information(sel))
        pairs, bad = local.failing(cov, sel)
        if bad.size == 0:
            passing.append(sel)
            continue
        rest = np.flatnonzero(net.tying & ~sel)
        nogood += [(rest, np.ones(rest.size), pairs.first[b], pairs.second[b]) for b in bad]
        if len(tangent) < 80:
            cov0 = cov if cov.determined.all() else \
                net.covariance(net.information(sel) + 0.05 * j_all)
            tangent += [(np.arange(p.n_sites), c / rhs, pairs.first[b], pairs.second[b])
                        for b, c, rhs in local.tangents(cov0, pairs, bad)]
    assert len(passing) > 10 and nogood and tangent
    x = np.asarray(passing, float)
    for sites, coef, a, b in nogood + tangent:
        assert _cut_value(sites, coef, a, b, -1.0, x).all()


def test_a_plan_with_local_markers_is_the_fewest_passing_layout():
    """A 2 m working disc (station pairs near points, so marker pairs bind): the plan equals
    the brute-force optimum and its every marker pair passes, while the plan that judges the
    stations alone fails some marker pair."""
    radius, kind = 2.0, "distance"
    p = station_line(3, n_sites=10, seed=6)
    net = NetworkModel(p, radius, INCL)
    every = np.ones(p.n_sites, bool)
    cov = net.covariance(net.information(every))
    stations = LocalAccuracy(net, LocalRequirement(1.0, within_m=25.0, kind=kind)).errors(cov)
    probe = LocalMarkerAccuracy(net, LocalRequirement(1.0, within_m=25.0, kind=kind))
    err = probe.errors(cov, probe.pairs(every & (net.site_weight > 0)))
    req = float(max(1.1 * stations.max(), np.quantile(err, 0.9)))
    cfg = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=20,
                     working_radius_m=radius, time_limit_s=60, chance_epsilon=None,
                     datum_requirement=False, local_requirement_m=req, local_within_m=25.0,
                     local_kind=kind, local_markers=True)
    r = plan_sites(p, cfg)
    assert r.status == "optimal" and r.check.all_ok and r.check.marker_pairs_ok
    assert r.check.marker_pair_error_m.size and r.check.marker_pair_error_m.max() <= req
    assert r.selected.sum() == brute_force_optimum(p, cfg)
    loose = plan_sites(p, cfg.replace(local_markers=False))
    assert not evaluate_layout(p, loose.selected, cfg).marker_pairs_ok


@pytest.mark.parametrize("covariance", ["dense", "sparse"])
def test_planner_and_adjustment_agree_on_marker_pairs(covariance):
    """The planner's marker-pair covariances and figures are the adjustment's on the same
    noise-free geometry (:mod:`tests.planner.test_covariance_consistency`), from its dense
    covariance and from the sparse marginals' exact columns."""
    from pipeline.network.adjustment import AdjustmentSettings, adjust
    from pipeline.network.observations import Datum, NominalPoses
    from pipeline.network.relative import marker_pair_covariances, relative_figures
    from tests.planner.test_covariance_consistency import _network

    obs, truth, problem = _network(3)
    net = NetworkModel(problem, RADIUS, INCL, figure=ErrorFigure("ellipsoid"))
    every = np.ones(problem.n_sites, bool)
    cov = net.covariance(net.information(every))
    result = adjust(obs, Datum(reference_station=obs.station_ids[0]),
                    AdjustmentSettings(inclinometer_sigma_rad=INCL, snooping=False,
                                       covariance=covariance),
                    nominal=NominalPoses(truth.pose[:, :3], truth.pose[:, 3]))
    for kind in ("position", "distance"):
        local = LocalMarkerAccuracy(net, LocalRequirement(1.0, within_m=40.0, kind=kind))
        pairs = local.pairs(every)
        assert pairs.size > 10
        predicted = local.difference_covariances(cov, pairs)
        adjusted = marker_pair_covariances(result.covariance, 6 * problem.n_stations,
                                           pairs.first, pairs.second)
        np.testing.assert_allclose(predicted, adjusted, rtol=1e-8,
                                   atol=1e-9 * np.abs(adjusted).max())
        fig = relative_figures(adjusted, pairs.direction)
        want = fig.ellipsoid_m if kind == "position" \
            else fig.along_m * np.sqrt(net.figure.cut_chi2) / 1.959963984540054
        np.testing.assert_allclose(local.errors(cov, pairs), want, rtol=1e-7)


def test_plan_json_and_verify_record_the_marker_pairs(tmp_path):
    """plan.json's ``local`` lists every judged marker pair (ids, separation, prediction);
    marker_pairs.csv holds them; verify's record measures them (``markers``/``markers_passed``)."""
    from types import SimpleNamespace

    from planner.outputs.local_report import local_record, write_pairs_csv
    from planner.verify.local_pairs import marker_pair_outcomes, pairs_record

    p = station_line(3, n_sites=10, seed=6)
    cfg = PlanConfig(network=True, working_radius_m=RADIUS, chance_epsilon=None,
                     datum_requirement=False, local_requirement_m=0.05, local_within_m=25.0,
                     local_markers=True)
    net = NetworkModel(p, RADIUS, INCL)
    sel = net.site_weight > 0
    outcome = SimpleNamespace(config=cfg, problem=p, result=SimpleNamespace(
        selected=sel, check=SimpleNamespace(pair_error_m=None, marker_pair_error_m=None)))
    local = local_record(outcome, net)
    pairs = LocalMarkerAccuracy(net, LocalRequirement(0.05, within_m=25.0)).pairs(sel)
    assert local["n_marker_pairs"] == pairs.size > 0
    assert [r["markers"] for r in local["marker_pairs"]] == [
        [p.site_ids[a], p.site_ids[b]] for a, b in zip(pairs.first, pairs.second, strict=True)]
    assert local["markers_meet_requirement"] == all(
        r["predicted_error_m"] <= 0.05 for r in local["marker_pairs"])
    write_pairs_csv({"local": local}, tmp_path / "marker_pairs.csv", markers=True)
    assert len((tmp_path / "marker_pairs.csv").read_text().splitlines()) == pairs.size + 1
    no_error = [SimpleNamespace(marker_id=i, achieved_xyz_m=(0.0, 0.0, 0.0)) for i in p.site_ids]
    outcomes = marker_pair_outcomes(local, dict(zip(p.site_ids, p.site_xyz, strict=True)),
                                    no_error[1:])  # the first site's marker was not adjusted
    rec = pairs_record(local, [], outcomes)
    assert len(rec["marker_pairs"]) == pairs.size and "markers" in rec["marker_pairs"][0]
    lacking = [r["passed"] for r in rec["marker_pairs"] if p.site_ids[0] in r["markers"]]
    assert rec["markers_passed"] == (not lacking) and not any(lacking)
