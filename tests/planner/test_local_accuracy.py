"""Local accuracy (relative error between neighbouring stations): the pair figures against
brute force and plain Monte-Carlo, the cuts against every layout, the plans against the
fewest passing layout."""

import itertools

import numpy as np
import pytest

from markerplan.errors import ConfigError, InfeasiblePlanError
from planner.accuracy.checks import evaluate_layout
from planner.accuracy.figure import ErrorFigure
from planner.accuracy.known_control import rim_design_blocks
from planner.accuracy.local import (
    LocalAccuracy,
    LocalRequirement,
    pair_quantile,
    pair_worst,
    point_pairs,
)
from planner.accuracy.network import NetworkModel, network_model
from planner.config import PlanConfig
from planner.program import plan_sites
from tests.planner.instances import brute_force_optimum, station_line

INCL = np.radians(0.01)
RADIUS = 10.0


def _covariances(seed, k=3):
    """(k, 12, 12) random joint pose covariances: cm translations, mrad angles."""
    a = np.random.default_rng(seed).normal(size=(k, 12, 12))
    a *= np.r_[[0.01] * 3, [1e-3] * 3, [0.01] * 3, [1e-3] * 3][:, None]
    return a @ np.swapaxes(a, 1, 2)


def _draw_worst(cov, direction, kind, n, seed):
    """Plain Monte-Carlo: the worst relative error over both rims of ``n`` draws."""
    g = rim_design_blocks(RADIUS)
    d = np.random.default_rng(seed).normal(size=(n, 12)) @ np.linalg.cholesky(cov).T
    ek = np.einsum("iac,nc->nia", g, d[:, :6])
    el = np.einsum("iac,nc->nia", g, d[:, 6:])
    if kind == "distance":
        a, b = ek @ direction, el @ direction
        return np.maximum(a.max(1) - b.min(1), b.max(1) - a.min(1))
    out = np.empty(n)
    for lo in range(0, n, 500):
        x, y = ek[lo:lo + 500], el[lo:lo + 500]
        sq = (x * x).sum(-1)[:, :, None] + (y * y).sum(-1)[:, None, :] \
            - 2 * x @ np.swapaxes(y, 1, 2)
        out[lo:lo + 500] = np.sqrt(sq.reshape(len(x), -1).max(1))
    return out


def test_the_worst_point_pair_is_found_by_brute_force():
    cov = _covariances(0)
    direction = np.tile([0.6, 0.8, 0.0], (3, 1))
    g = rim_design_blocks(RADIUS)
    for kind in ("position", "distance"):
        var, qi, qj, u = pair_worst(cov, direction, RADIUS, kind)
        for p in range(3):
            best = 0.0
            for i, j in itertools.product(range(0, 73, 4), range(0, 73, 4)):
                m = np.hstack([g[i], -g[j]])
                s = m @ cov[p] @ m.T
                best = max(best, np.linalg.eigvalsh(s)[-1] if kind == "position"
                           else direction[p] @ s @ direction[p])
            assert var[p] >= best * (1 - 1e-12)
            m = np.hstack([g[qi[p]], -g[qj[p]]])
            at = m @ cov[p] @ m.T
            assert u[p] @ at @ u[p] == pytest.approx(var[p], rel=1e-9)


@pytest.mark.parametrize("kind", ["position", "distance"])
def test_pair_quantile_matches_plain_monte_carlo(kind):
    """The spherical-radial quantile against plain sampling of the same worst error (20,000
    draws: the sample quantile's own spread is about 0.5 %)."""
    cov = _covariances(1)
    direction = np.tile([1.0, 0.0, 0.0], (3, 1))
    q = pair_quantile(cov, direction, RADIUS, kind, 2048)
    for p in range(3):
        sample = np.quantile(_draw_worst(cov[p], direction[p], kind, 20_000, seed=p), 0.95)
        assert q[p] == pytest.approx(sample, rel=0.02)
    # and it lies inside its bracket of the ellipsoid figure
    var = pair_worst(cov, direction, RADIUS, kind)[0]
    assert np.all(q >= np.sqrt(3.84 * var) * 0.999) and np.all(q <= np.sqrt(21.03 * var))


def test_station_pairs_and_requirement_bounds():
    pairs = point_pairs(np.array([[0, 0, 1], [30, 40, 1], [0, 40, 1.0]]),
                          LocalRequirement(0.05, 1000.0, 50.0))
    assert pairs.first.tolist() == [0, 0, 1] and pairs.second.tolist() == [1, 2, 2]
    np.testing.assert_allclose(pairs.allowed_m, 0.05 + 1e-3 * np.array([50, 40, 30.0]))
    np.testing.assert_allclose(pairs.direction[0], [0.6, 0.8, 0.0])
    with pytest.raises(ConfigError, match="within_m"):
        LocalRequirement(0.1, within_m=0.0)
    with pytest.raises(ConfigError, match="network mode"):
        PlanConfig(local_requirement_m=0.1)
    with pytest.raises(ConfigError, match="local_requirement_m"):
        PlanConfig(network=True, datum_requirement=False)
    with pytest.raises(ConfigError, match="local_within_m"):
        PlanConfig(network=True, local_requirement_m=0.1, local_within_m=-5.0)


@pytest.mark.parametrize(("figure", "kind"), [("ellipsoid", "position"),
                                              ("ellipsoid", "distance"),
                                              ("quantile", "position")])
def test_pair_tangent_cuts_never_remove_a_passing_layout(figure, kind):
    """Brute force over every layout of a 10-site line of stations: every layout whose pairs
    all pass satisfies every pair tangent taken at any failing layout (the quantile on 8
    sites: its figure is the costly one)."""
    p = station_line(3, n_sites=8 if figure == "quantile" else 10)
    net = NetworkModel(p, RADIUS, INCL, figure=ErrorFigure(figure))
    probe = LocalAccuracy(net, LocalRequirement(1.0, within_m=20.0, kind=kind))
    best = probe.errors(net.covariance(net.information(np.ones(p.n_sites, bool))))
    local = LocalAccuracy(net, LocalRequirement(float(1.3 * best.max()), within_m=20.0,
                                                kind=kind))
    assert local.pairs.size == 2
    passing, cuts = [], []
    for bits in itertools.product([0, 1], repeat=p.n_sites):
        sel = np.array(bits, bool)
        cov = net.covariance(net.information(sel))
        ok = local.within(cov)
        if ok.all():
            passing.append(sel)
        elif len(cuts) < 60 and cov.determined.all():
            cuts += local.tangents(cov, np.flatnonzero(~ok))
    assert passing and cuts
    x = np.asarray(passing, float)
    for _, coef, rhs in cuts:
        assert np.all(x @ coef >= rhs * (1 - 1e-9))


def test_within_agrees_with_the_computed_errors():
    p = station_line(4, n_sites=14, seed=3)
    for figure in ("ellipsoid", "quantile"):
        net = NetworkModel(p, RADIUS, INCL, figure=ErrorFigure(figure))
        cov = net.covariance(net.information(np.ones(p.n_sites, bool)))
        probe = LocalAccuracy(net, LocalRequirement(1.0, within_m=40.0))
        err = probe.errors(cov)
        assert np.isfinite(err).all() and probe.pairs.size == 5
        for scale in (0.9, 1.0 / 0.97, 3.0):  # failing, barely passing, screened
            local = LocalAccuracy(net, LocalRequirement(float(np.median(err) * scale),
                                                        within_m=40.0))
            assert local.within(cov).tolist() == (err <= local.pairs.allowed_m).tolist()


@pytest.mark.parametrize("figure", ["ellipsoid", "quantile"])
def test_a_local_plan_is_the_fewest_passing_layout(figure):
    """Local accuracy alone (no datum requirement): the plan equals the brute-force optimum,
    every pair's relative error recomputed here meets it, and it needs fewer markers than the
    same figure relative to the datum."""
    p = station_line(4, n_sites=11, seed=2) if figure == "ellipsoid" \
        else station_line(4, n_sites=9, seed=6)
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=20,
                      working_radius_m=RADIUS, time_limit_s=60, error_figure=figure,
                      chance_epsilon=None)
    net = network_model(p, base)
    every = np.ones(p.n_sites, bool)
    cov = net.covariance(net.information(every))
    rel = LocalAccuracy(net, LocalRequirement(1.0, within_m=20.0)).errors(cov)
    req = float(1.3 * rel.max())
    cfg = base.replace(datum_requirement=False, local_requirement_m=req, local_within_m=20.0)
    r = plan_sites(p, cfg)
    assert r.status == "optimal" and r.check.all_ok and r.check.pairs_ok
    assert r.selected.sum() == brute_force_optimum(p, cfg)
    cov = net.covariance(net.information(r.selected))
    assert np.all(LocalAccuracy(net, LocalRequirement(req, within_m=20.0)).errors(cov) <= req)
    datum = base.replace(requirement_m=req)
    if evaluate_layout(p, every, datum).all_ok:
        assert plan_sites(p, datum).selected.sum() >= r.selected.sum()


def test_a_local_requirement_no_layout_meets_is_refused_naming_the_pairs():
    p = station_line(3, n_sites=10)
    cfg = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=20,
                     working_radius_m=RADIUS, chance_epsilon=None, local_requirement_m=1e-4,
                     local_within_m=20.0, datum_requirement=False)
    with pytest.raises(InfeasiblePlanError, match=r"2 station pair\(s\).*S1-S2: .* m > 0.0001 m"):
        plan_sites(p, cfg)


def test_a_local_plan_ignores_the_datum_requirement_it_does_not_judge():
    """Without the datum requirement, ``requirement_m`` judges nothing: its information and
    heading rows must not be in the program (at 1 mm they made the plan infeasible although
    a 6-site layout meets the local requirement)."""
    p = station_line(4, n_sites=11, seed=2)
    cfg = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=20,
                     working_radius_m=RADIUS, time_limit_s=60, chance_epsilon=None,
                     datum_requirement=False, local_requirement_m=0.3626,
                     local_within_m=20.0, requirement_m=0.001)
    r = plan_sites(p, cfg)
    assert r.status == "optimal" and r.check.pairs_ok
    assert r.selected.sum() == brute_force_optimum(p, cfg) == 6
