"""The network layout's local search (planner.program.local_search): every removal keeps a
passing layout, the result is 1-minimal (checked by the planner's own layout evaluation), the
downdated covariance equals a fresh inverse, and a 2-for-1 swap improves a 1-minimal layout
above the optimum."""

import itertools

import numpy as np

from planner.accuracy.checks import evaluate_layout
from planner.accuracy.network import network_model
from planner.config import PlanConfig
from planner.program.local_search import _Judge, local_search, prune, swap_pairs
from tests.planner.instances import brute_force_optimum, make_problem


def _instance(seed=5):
    rng = np.random.default_rng(seed)
    stations = [[0, 0], [14, 0], [28, 0]]
    sites = np.vstack([rng.uniform([-8, -9], [36, 9], (9, 2)), [[7, 4], [21, -4]]])
    return make_problem(stations, sites, max_range_m=16)


def _config(p):
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                      working_radius_m=10, chance_epsilon=None)
    every = network_model(p, base).station_errors(np.ones(p.n_sites, bool)).max()
    return base.replace(requirement_m=float(1.3 * every))


def test_pruning_every_site_leaves_a_passing_layout_no_single_site_can_leave():
    p = _instance()
    cfg = _config(p)
    net = network_model(p, cfg)
    every = np.ones(p.n_sites, bool)
    assert evaluate_layout(p, every, cfg, net=net).all_ok
    out = prune(p, cfg, net, every)
    assert out.finished and len(out.removed) == p.n_sites - out.selected.sum() > 0
    assert evaluate_layout(p, out.selected, cfg, net=net).all_ok
    for j in np.flatnonzero(out.selected):  # 1-minimal, by the planner's own judge
        smaller = out.selected & (np.arange(p.n_sites) != j)
        assert not evaluate_layout(p, smaller, cfg, net=net).all_ok
    assert out.selected.sum() >= brute_force_optimum(p, cfg)
    assert out.record()["markers"] == out.selected.sum()


def test_the_downdated_covariance_equals_a_fresh_inverse_and_untying_is_refused():
    p = _instance()
    cfg = _config(p)
    net = network_model(p, cfg)
    judge = _Judge(p, cfg, net)
    sel = np.ones(p.n_sites, bool)
    cov = net.covariance(net.information(sel)).full
    refused = 0
    for j in range(p.n_sites):
        smaller = sel & (np.arange(p.n_sites) != j)
        fresh = net.covariance(net.information(smaller))
        after = judge.without(cov, j)
        if after is None:
            refused += 1
            assert not fresh.determined.all()
            continue
        assert fresh.determined.all()
        np.testing.assert_allclose(after, fresh.full, rtol=1e-7, atol=1e-12)
    # a layout of only the sites a station needs to be tied: removing one unties it
    tied = np.zeros(p.n_sites, bool)
    for j in np.argsort(-net.n_stations_seeing):
        if net.covariance(net.information(tied)).determined.all():
            break
        tied[j] = True
    cov = net.covariance(net.information(tied)).full
    assert any(judge.without(cov, int(j)) is None for j in np.flatnonzero(tied & net.tying))


def test_a_one_minimal_layout_above_the_optimum_is_improved_by_a_two_for_one_swap():
    """Layouts one above the optimum (6 sites of 11 here; brute force) that no single removal
    improves: the swap replaces two sites by one and the result passes the planner's own
    evaluation."""
    p = _instance(2)
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                      working_radius_m=10, chance_epsilon=None)
    every = network_model(p, base).station_errors(np.ones(p.n_sites, bool)).max()
    cfg = base.replace(requirement_m=float(1.3 * every))
    net = network_model(p, cfg)
    best = brute_force_optimum(p, cfg)

    def passes(sel):
        return evaluate_layout(p, sel, cfg, net=net).all_ok

    stuck = []
    for sites in itertools.combinations(range(p.n_sites), best + 1):
        sel = np.zeros(p.n_sites, bool)
        sel[list(sites)] = True
        if passes(sel) and not any(passes(sel & (np.arange(p.n_sites) != j)) for j in sites):
            stuck.append(sel)
        if len(stuck) == 3:
            break
    assert stuck
    for sel in stuck:
        assert prune(p, cfg, net, sel).removed == ()  # 1-minimal indeed
        out, swaps = swap_pairs(p, cfg, net, sel)
        assert swaps == 1 and out.sum() == best and passes(out)
        joint = local_search(p, cfg, net, sel)
        assert joint.swaps == 1 and joint.record()["markers"] == best
