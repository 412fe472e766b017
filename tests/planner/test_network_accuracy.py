import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from markerplan.errors import ConfigError
from planner.accuracy import known_control
from planner.accuracy.figure import MONOTONE_TOLERANCE, ErrorFigure
from planner.accuracy.growing import GrowingCovariance
from planner.accuracy.known_control import CHI2_3_95
from planner.accuracy.network import NetworkModel, network_model
from planner.accuracy.network_diagnosis import diagnose_network
from planner.accuracy.requirement import NetworkRequirement
from planner.config import PlanConfig
from tests.planner.instances import make_problem, ring, station_line

INCL = np.radians(0.01)


def _full_adjustment(model, selected):
    """Pose and marker covariance of a layout from the full normal equations (poses + markers)."""
    p = model.problem
    sites = np.flatnonzero(selected & model.tying | selected & (model.n_stations_seeing > 0))
    n6 = 6 * p.n_stations
    npar = n6 + 3 * sites.size
    n = np.zeros((npar, npar))
    for m, j in enumerate(sites):
        for q in range(model.site_start[j], model.site_start[j + 1]):
            a = np.zeros((3, npar))
            s = model.pair_station[q]
            a[:, 6 * s:6 * s + 6] = model.design[q]
            a[:, n6 + 3 * m:n6 + 3 * m + 3] = -np.eye(3)
            n += model.weight[q] * a.T @ a
    keep = np.r_[model.free, n6 + np.arange(3 * sites.size)]
    nn = n[np.ix_(keep, keep)]
    nn[:model.n_params, :model.n_params] += model.prior_information
    c = np.linalg.inv(nn)
    return c, sites


def test_schur_contribution_matches_the_full_adjustment():
    p = station_line(3, seed=0, n_sites=14)
    model = NetworkModel(p, 10.0, INCL)
    sel = np.zeros(p.n_sites, bool)
    sel[:10] = True
    c_full, sites = _full_adjustment(model, sel)
    cov = model.covariance(model.information(sel))
    assert cov.determined.all()
    pp = model.n_params
    np.testing.assert_allclose(cov.full[np.ix_(model.free, model.free)], c_full[:pp, :pp],
                               rtol=1e-6, atol=1e-14)
    mc = model.marker_covariances(cov, sites)
    for m in range(sites.size):
        blk = c_full[pp + 3 * m:pp + 3 * m + 3, pp + 3 * m:pp + 3 * m + 3]
        np.testing.assert_allclose(mc[m], blk, rtol=1e-6, atol=1e-14)
    # v^T J^(j) v, vectorised, equals the quadratic form of each site's own contribution
    v = np.random.default_rng(1).normal(size=(2, pp))
    coef = model.site_coefficients(v)
    for j in range(p.n_sites):
        one = np.zeros(p.n_sites)
        one[j] = 1.0
        jj = model.information(one) - model.prior_information
        np.testing.assert_allclose(coef[:, j], np.einsum("ma,ab,mb->m", v, jj, v),
                                   rtol=1e-8, atol=1e-6)


def test_six_parameter_errors_equal_known_control_with_the_tilt_as_parameters():
    """The ellipsoid figure of the 6-parameter covariance equals known control's 4-parameter
    one with the inclinometer's vertical variance |q|^2 s^2 added at each rim point, built here
    by hand from the 4 x 4 design blocks."""
    rng = np.random.default_rng(2)
    j = known_control.pair_information([0, 0], rng.uniform(-20, 20, (5, 2)),
                                       rng.uniform(0.005, 0.02, 5)).sum(axis=0)
    c4 = np.linalg.inv(j)
    phi = np.linspace(0.0, 2 * np.pi, 72, endpoint=False)
    q = np.vstack([[0.0, 0.0], 10.0 * np.column_stack([np.cos(phi), np.sin(phi)])])
    worst = 0.0
    for qx, qy in q:
        g = np.array([[1, 0, 0, -qy], [0, 1, 0, qx], [0, 0, 1, 0]], float)
        sig = g @ c4 @ g.T + np.diag([0, 0, (qx * qx + qy * qy) * INCL**2])
        worst = max(worst, np.linalg.eigvalsh(sig)[-1])
    c6 = known_control.pose_covariance(c4[None], INCL)
    np.testing.assert_allclose(ErrorFigure("ellipsoid").station_errors(c6, 10.0),
                               np.sqrt(CHI2_3_95 * worst), rtol=1e-9)
    for figure in ("ellipsoid", "quantile"):  # known control's 4 x 4 with its tilts: the same
        np.testing.assert_allclose(ErrorFigure(figure).station_errors(c4[None], 10.0, INCL),
                                   ErrorFigure(figure).station_errors(c6, 10.0), rtol=1e-9)
    with pytest.raises(ConfigError, match="shape"):
        ErrorFigure("quantile").station_errors(np.zeros((2, 5, 5)), 10.0)
    with pytest.raises(ConfigError, match="inclinometer"):
        ErrorFigure().station_errors(c4[None], 10.0)


def test_a_site_seen_by_one_station_adds_nothing_and_ties_are_counted():
    p = make_problem([[0, 0], [15, 0]], [[-8, 0], [7, 3], [7, -3], [25, 0]], max_range_m=12)
    model = NetworkModel(p, 10.0, INCL)
    assert model.tying.tolist() == [False, True, True, False]
    one = np.array([1.0, 0, 0, 1.0])
    np.testing.assert_allclose(model.information(one), model.prior_information)
    assert model.ties(np.ones(4, bool))[0, 1] == 2
    # one shared site: heading of S2 is free; two shared sites: determined
    err1 = model.station_errors(np.array([True, True, False, True]))
    assert err1[0] < 0.01 and np.isinf(err1[1])
    err2 = model.station_errors(np.ones(4, bool))
    assert np.isfinite(err2).all()


def test_diagnose_names_disconnected_weak_and_far_stations():
    sites = np.vstack([ring([0, 0], 8.0, [0, 120, 240]), [[7, 3], [7, -3]],
                       ring([200, 0], 8.0, [0, 120, 240])])
    p = make_problem([[0, 0], [15, 0], [200, 0]], sites, max_range_m=12)
    model = NetworkModel(p, 10.0, INCL, requirement=NetworkRequirement(0.10))
    why = diagnose_network(model, np.ones(p.n_sites, bool))
    assert list(why) == ["S3"] and why["S3"].startswith("disconnected") and "S1" in why["S3"]
    p2 = make_problem([[0, 0], [15, 0]], sites[:5], max_range_m=12)
    loose = NetworkModel(p2, 10.0, INCL, requirement=NetworkRequirement(1.0))
    assert diagnose_network(loose, np.ones(5, bool)) == {}
    weak = diagnose_network(NetworkModel(p2, 10.0, INCL), np.ones(5, bool))
    assert list(weak) == ["S2"] and weak["S2"].split(":")[0] in ("heading too weak",
                                                          "too far from the datum")
    with pytest.raises(ConfigError, match="reference_station"):
        network_model(p2, PlanConfig(network=True, reference_station="S9"))
    assert network_model(p2, PlanConfig(network=True, reference_station="S2")).reference == 1


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n_stations=st.integers(2, 4),
       figure=st.sampled_from(["quantile", "ellipsoid"]))
def test_adding_a_site_never_worsens_any_station_or_marker(seed, n_stations, figure):
    p = station_line(n_stations, seed=seed, n_sites=12)
    model = NetworkModel(p, 10.0, INCL, figure=ErrorFigure(figure))
    tol = MONOTONE_TOLERANCE if figure == "quantile" else 1e-9
    rng = np.random.default_rng(seed)
    sel = rng.random(p.n_sites) < 0.5
    extra = int(rng.integers(p.n_sites))
    more = sel.copy()
    more[extra] = True
    c0 = model.covariance(model.information(sel))
    c1 = model.covariance(model.information(more))
    e0, e1 = model.station_errors_from(c0), model.station_errors_from(c1)
    assert np.all((e1 <= e0 * (1 + tol) + 1e-12) | np.isinf(e0))
    markers = np.flatnonzero(sel & (model.n_stations_seeing > 0))
    m0, m1 = model.marker_errors(c0, markers), model.marker_errors(c1, markers)
    assert np.all((m1 <= m0 * (1 + tol) + 1e-12) | np.isinf(m0))


@pytest.mark.parametrize(("figure", "ppm"), [("ellipsoid", 0.0), ("quantile", 0.0),
                                             ("ellipsoid", 2000.0), ("quantile", 2000.0)])
def test_tangent_cuts_never_remove_a_passing_layout(figure, ppm):
    """Brute force on a tiny network: every layout whose stations and markers pass satisfies
    every tangent cut taken at any failing layout (marker cuts when the marker is selected);
    for the quantile the cuts are its one-direction necessary condition. With a ppm term each
    station and marker is judged against its own allowance, and the cuts stay valid."""
    p = station_line(3, seed=5, n_sites=10)
    probe = NetworkModel(p, 10.0, INCL, figure=ErrorFigure(figure))
    layouts = [np.array(b, bool) for b in itertools.product([0, 1], repeat=p.n_sites)]
    best = probe.covariance(probe.information(np.ones(p.n_sites, bool)))
    req = 1.3 * max(probe.station_errors_from(best).max(),
                    probe.marker_errors(best, np.arange(p.n_sites)).max())
    # a ppm term that lets the far stations pass with about 20 % more
    model = NetworkModel(p, 10.0, INCL, figure=ErrorFigure(figure),
                         requirement=NetworkRequirement(req / (1 + 0.1 * ppm / 2000), ppm))
    allowed, allowed_site = model.allowed_station_m, model.allowed_site_m
    assert (np.ptp(allowed) > 0.05 * req) == (ppm > 0)
    passing, cuts = [], []
    for sel in layouts:
        cov = model.covariance(model.information(sel))
        e = model.station_errors_from(cov)
        markers = np.flatnonzero(sel)
        me = model.marker_errors(cov, markers)
        if np.all(e <= allowed) and np.all(me <= allowed_site[markers]):
            passing.append(sel)
        elif len(cuts) < 80 and cov.determined.all():
            cuts += [(None, c, r) for _, c, r in
                     model.station_tangents(cov, np.flatnonzero(e > allowed), rim="spread")]
            cuts += model.marker_tangents(cov, markers[me > allowed_site[markers]])
    assert passing and any(c[0] is None for c in cuts) and any(c[0] is not None for c in cuts)
    x = np.asarray(passing, float)
    for owner, coef, rhs in cuts:
        applies = np.ones(len(x), bool) if owner is None else x[:, owner] > 0
        assert np.all(x[applies] @ coef >= rhs * (1 - 1e-9))


def test_site_factor_reproduces_each_sites_information():
    net = NetworkModel(station_line(4, seed=3, n_sites=20), 10.0, INCL)
    pos = np.full(6 * 4, -1)
    pos[net.free] = np.arange(net.n_params)
    for j in range(net.problem.n_sites):
        one = np.zeros(net.problem.n_sites)
        one[j] = 1.0
        index, u = net.site_factor(j)
        assert u.shape == (6 * net.n_stations_seeing[j], 3 * max(net.n_stations_seeing[j] - 1, 0))
        got = np.zeros((net.n_params, net.n_params))
        keep = pos[index] >= 0
        got[np.ix_(pos[index][keep], pos[index][keep])] = u[keep] @ u[keep].T
        np.testing.assert_allclose(got, net.site_information(one), atol=1e-9 * (1 + np.abs(
            got).max()))


@pytest.mark.parametrize("refresh", [1, 3, 1000])
def test_growing_covariance_matches_a_fresh_inverse_at_every_step(refresh):
    # four stations tied one site at a time, from nothing: undetermined stations first (the
    # tracked null space must flag the same stations), then Woodbury updates
    net = NetworkModel(station_line(4, seed=5, n_sites=30), 10.0, INCL)
    selected = np.zeros(net.problem.n_sites, bool)
    grow = GrowingCovariance(net, net.information(selected), refresh=refresh)
    seen_undetermined = seen_woodbury = False
    for j in np.flatnonzero(net.tying):
        selected[j] = True
        grow.add(int(j))
        fresh = net.covariance(net.information(selected))
        np.testing.assert_allclose(grow.j, net.information(selected), rtol=1e-12, atol=1e-6)
        np.testing.assert_array_equal(grow.determined, fresh.determined)
        if fresh.determined.all():
            seen_woodbury |= grow._updates > 0
            np.testing.assert_allclose(grow.cov.full, fresh.full, rtol=1e-7,
                                       atol=1e-9 * np.abs(fresh.full).max())
        else:
            seen_undetermined = True
    assert seen_undetermined and (seen_woodbury or refresh == 1)
    with pytest.raises(ConfigError, match="refresh"):
        GrowingCovariance(net, net.information(selected), refresh=0)


def _null_dimension(j):
    """Null dimension of an information matrix, by the eigenvalues of its diagonally scaled
    form (the criterion of ``NetworkModel.covariance``)."""
    scale = np.sqrt(np.maximum(np.diag(j), 1e-300))
    lam = np.linalg.eigvalsh(j / scale[:, None] / scale[None, :])
    return int(np.sum(lam <= 1e-10 * lam[-1]))


def test_null_reductions_count_the_free_movements_each_site_removes():
    # five stations, two tying sites added: some stations still turn or slide freely; for
    # every site, the count equals the drop of the null dimension of a fresh information
    net = NetworkModel(station_line(5, seed=7, n_sites=40), 10.0, INCL)
    selected = np.zeros(net.problem.n_sites, bool)
    selected[np.flatnonzero(net.tying)[:2]] = True
    grow = GrowingCovariance(net, net.information(selected))
    before = _null_dimension(net.information(selected))
    assert before > 0
    sites = np.arange(net.problem.n_sites)
    removed = grow.null_reductions(sites[::-1])[::-1]  # any order
    expected = []
    for j in sites:
        one = selected.copy()
        one[j] = True
        expected.append(before - _null_dimension(net.information(one)))
    np.testing.assert_array_equal(removed, expected)
    assert len(set(expected)) > 1  # some sites remove movements, others none
    determined = GrowingCovariance(net, net.information(net.tying))
    assert not determined.null_reductions(sites).any()


def test_scaled_covariances_match_each_fresh_inverse():
    net = NetworkModel(station_line(4, seed=5, n_sites=30), 10.0, INCL)
    # a requirement no station meets: every tangent is active
    tight = NetworkModel(net.problem, 10.0, INCL, requirement=NetworkRequirement(1e-4))
    sites = net.site_information(net.tying)
    stations, scales = np.array([1, 2, 3]), np.array([0.3, 1.0, 4.0])
    got = list(net.scaled_covariances(sites, scales, stations))
    assert [k for k, _ in got] == [1, 2, 3]
    for (k, cov), t in zip(got, scales, strict=True):
        fresh = net.covariance(net.prior_information + t * sites)
        rows = 6 * k + np.arange(6)
        tol = 1e-8 * np.abs(fresh.full).max()
        np.testing.assert_allclose(cov.full[rows], fresh.full[rows], atol=tol)
        np.testing.assert_allclose(cov.full[:, rows], fresh.full[:, rows], atol=tol)
        assert not np.any(np.delete(np.delete(cov.full, rows, 0), rows, 1))
        (_, coef, rhs), = tight.station_tangents(cov, [k])
        (_, coef0, rhs0), = tight.station_tangents(fresh, [k])
        np.testing.assert_allclose(coef, coef0, rtol=1e-6, atol=1e-9 * coef0.max())
        assert rhs == pytest.approx(rhs0, rel=1e-6)
    with pytest.raises(np.linalg.LinAlgError):  # a station with no shared site: singular
        list(net.scaled_covariances(np.zeros_like(sites), scales, stations))
