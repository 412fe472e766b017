import itertools

import numpy as np
import pytest

from markerplan.errors import ConfigError, InfeasiblePlanError, PlanTimeLimitError
from planner.accuracy.checks import evaluate_layout
from planner.accuracy.network import network_model
from planner.config import PlanConfig
from planner.problem.usability import directions_ok
from planner.program import plan_sites
from tests.planner.instances import brute_force_optimum, make_problem, ring


def _instance(seed):
    rng = np.random.default_rng(seed)
    stations = [[0, 0], [14, 0], [28, 0]]
    sites = np.vstack([rng.uniform([-8, -9], [36, 9], (9, 2)), [[7, 4], [21, -4]]])
    return make_problem(stations, sites, max_range_m=16)


@pytest.mark.parametrize("seed,figure", [(2, "ellipsoid"), (5, "ellipsoid"), (2, "quantile")])
def test_network_plan_matches_the_brute_force_optimum(seed, figure):
    p = _instance(seed)
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                      working_radius_m=10, time_limit_s=60, error_figure=figure)
    net = network_model(p, base)
    best = net.station_errors(np.ones(p.n_sites, bool)).max()
    cfg = base.replace(requirement_m=float(1.15 * best))  # some markers cannot meet it
    r = plan_sites(p, cfg)
    assert r.check.all_ok and r.status == "optimal"
    assert r.selected.sum() == brute_force_optimum(p, cfg)
    # the known-control optimum fails the network's requirement here, or needs as many
    kc = plan_sites(p, cfg.replace(network=False)).selected
    assert kc.sum() <= r.selected.sum()
    assert kc.sum() == r.selected.sum() or not evaluate_layout(p, kc, cfg, net=net).all_ok


def test_redundant_network_plan_survives_any_loss_and_matches_thebrute_force_optimum():
    p = _instance(5)
    base = PlanConfig(network=True, redundant=True, min_markers=3, min_sectors=2,
                      max_range_m=16, working_radius_m=10, time_limit_s=60)
    net = network_model(p, base)
    every = np.ones(p.n_sites, bool)
    worst_loss = max(net.station_errors(every & (np.arange(p.n_sites) != j)).max()
                     for j in range(p.n_sites))
    cfg = base.replace(requirement_m=float(1.1 * worst_loss))
    r = plan_sites(p, cfg)
    assert r.check.all_ok and r.status == "optimal"
    assert r.selected.sum() == brute_force_optimum(p, cfg)
    # independently of the loss check: without any one marker, every station still passes
    plain = cfg.replace(redundant=False)
    for j in np.flatnonzero(r.selected):
        without = r.selected & (np.arange(p.n_sites) != j)
        assert (net.station_errors(without) <= cfg.requirement_m).all()
        assert directions_ok(p, without, plain).all()
    # and it needs more markers than the plain network plan
    assert plan_sites(p, plain).selected.sum() < r.selected.sum()


def test_infeasible_network_names_the_station_and_why():
    sites = np.vstack([ring([0, 0], 8.0, [0, 120, 240]), [[7, 3], [7, -3]],
                       ring([200, 0], 8.0, [0, 120, 240])])
    p = make_problem([[0, 0], [15, 0], [200, 0]], sites, max_range_m=12)
    cfg = PlanConfig(network=True, max_range_m=12, min_markers=2, min_sectors=1)
    with pytest.raises(InfeasiblePlanError) as exc:
        plan_sites(p, cfg)
    msg = str(exc.value)
    assert not isinstance(exc.value, PlanTimeLimitError)
    assert "\n" not in msg and "S3: disconnected" in msg and "datum, station S1" in msg
    with pytest.raises(InfeasiblePlanError, match="S2: (heading too weak|too far)"):
        plan_sites(make_problem([[0, 0], [15, 0]], sites[:5], max_range_m=12), cfg)


def test_too_many_tying_sites_are_refused_with_the_grid_to_use(monkeypatch):
    import planner.program.loop as loop

    p = _instance(2)
    cfg = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16)
    n_tying = int(network_model(p, cfg).tying.sum())
    monkeypatch.setattr(loop, "MAX_NETWORK_TYING_SITES", n_tying - 1)
    spacing = f"{1.2 * np.sqrt(n_tying / (n_tying - 1)):.1f}".replace(".", r"\.")
    with pytest.raises(ConfigError, match=f"this site has {n_tying}: coarsen the candidate grid "
                       rf"\(grid_spacing_m .* 1 m now, try {spacing} m\)"):
        plan_sites(p, cfg)


def test_a_sparse_tangent_removes_no_layout_the_full_one_keeps():
    from planner.program.cuts_network import sparse_tangent

    rng = np.random.default_rng(0)
    coef = rng.exponential(1.0, 12) ** 3
    rhs = float(np.sort(coef)[-3:].sum() * 0.8)
    sites, c, lo = sparse_tangent(coef, rhs, upper_bound=3, max_terms=5)
    assert 5 <= sites.size < 12
    for combo in itertools.chain.from_iterable(itertools.combinations(range(12), k)
                                               for k in range(4)):
        x = np.zeros(12)
        x[list(combo)] = 1.0
        if x @ coef >= rhs:
            assert x[sites] @ c >= lo - 1e-12


def test_time_limit_returns_the_incumbent_with_the_proven_bound():
    from planner.program import RowKind, build_model
    from planner.program.loop import _cut_loop

    p = _instance(2)
    cfg = PlanConfig(min_markers=3, min_sectors=2, max_range_m=16, time_limit_s=1.0)
    model = build_model(p, cfg)
    useless = model.site_row(np.arange(2))

    def never_done(selected):  # a cut that removes nothing: the loop runs to the time limit
        return useless, [0.0], [RowKind("cut")]

    every = np.ones(p.n_sites, bool)
    r = _cut_loop(p, cfg, model, never_done, lambda sel: evaluate_layout(p, sel, cfg),
                  incumbent=every)
    assert r.status == "time_limit" and r.selected is every
    assert r.solution.objective == p.n_sites and r.iterations >= 1
    assert r.solution.dual_bound == pytest.approx(plan_sites(p, cfg).selected.sum())
    assert r.solution.gap == pytest.approx((p.n_sites - r.solution.dual_bound) / p.n_sites)
    # without an incumbent the time limit is its own error type (not "proven infeasible")
    with pytest.raises(PlanTimeLimitError, match="raise `time_limit_s`"):
        _cut_loop(p, cfg, model, never_done, lambda sel: evaluate_layout(p, sel, cfg))


def test_network_greedy_in_redundant_mode_survives_any_loss():
    from planner.program.baselines import greedy_network

    p = _instance(5)
    cfg = PlanConfig(network=True, redundant=True, min_markers=3, min_sectors=2,
                     max_range_m=16, working_radius_m=10, requirement_m=0.2)
    g = greedy_network(p, cfg)
    assert evaluate_layout(p, g.selected, cfg).all_ok
    assert not evaluate_layout(p, greedy_network(p, cfg.replace(redundant=False)).selected,
                               cfg).all_ok


@pytest.mark.parametrize("seed", [2, 7, 13])
def test_large_problem_path_bound_never_exceeds_the_brute_force_optimum(seed, monkeypatch):
    """The path for large problems (greedy incumbent, root relaxation, sparse rows), forced on
    a small instance: its proven lower bound is at most the true optimum, and the answer
    passes and is optimal or reports its gap honestly."""
    import planner.program.loop as loop

    monkeypatch.setattr(loop, "_SPARSE_ABOVE_SITES", 0)
    p = _instance(seed)
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                      working_radius_m=10, time_limit_s=60)
    net = network_model(p, base)
    cfg = base.replace(requirement_m=float(1.15 * net.station_errors(np.ones(p.n_sites,
                                                                           bool)).max()))
    best = brute_force_optimum(p, cfg)
    r = plan_sites(p, cfg)
    assert r.greedy is not None and r.check.all_ok
    assert r.solution.dual_bound <= best + 1e-6
    assert r.selected.sum() >= best and r.selected.sum() <= r.greedy.n_markers
    # the greedy's layout was pruned to a subset before the search started from it
    assert r.pruning is not None and not np.any(r.pruning.selected & ~r.greedy.selected)
    assert r.pruning.start_markers == r.greedy.n_markers
    assert r.selected.sum() <= r.pruning.selected.sum()
    if r.status == "optimal":
        assert r.selected.sum() == best
    assert any(k.family == "oa-root" for k in r.model.row_kind)
    # the root relaxation's own bound (a whole number: unit costs) is valid too
    assert r.root["bound"] <= best and r.root["bound"] == round(r.root["bound"])
    assert r.root["lp_solves"] >= 1 and r.root["stopped"] in ("budget", "rounds", "stall",
                                                              "solved")


def _reachable_network_case(time_limit_s: float):
    """The two-group instance in network mode, with a requirement 15 % above what every site
    together reaches (so it can be met)."""
    p = _instance(2)
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                      working_radius_m=10, time_limit_s=time_limit_s)
    net = network_model(p, base)
    cfg = base.replace(requirement_m=float(1.15 * net.station_errors(np.ones(p.n_sites,
                                                                           bool)).max()))
    return p, cfg


def test_a_greedy_that_takes_the_whole_time_limit_still_leaves_a_root_bound(monkeypatch):
    """When the greedy incumbent uses up the time limit, the root relaxation still gets its
    minimum share: the answer is the greedy layout, time-limited, with a finite proven bound
    at most the optimum and its gap."""
    import time

    import planner.program.baselines as baselines
    import planner.program.loop as loop

    monkeypatch.setattr(loop, "_SPARSE_ABOVE_SITES", 0)
    p, cfg = _reachable_network_case(5)
    greedy = baselines.greedy_network

    def slow_greedy(*args, **kwargs):  # e.g. a directions-only cover that takes it all
        time.sleep(cfg.time_limit_s)
        return greedy(*args, **{**kwargs, "deadline": None})

    monkeypatch.setattr(baselines, "greedy_network", slow_greedy)
    r = plan_sites(p, cfg)
    assert r.status == "time_limit" and r.selected is r.greedy.selected
    assert np.isfinite(r.solution.dual_bound)
    assert r.solution.dual_bound <= brute_force_optimum(p, cfg) + 1e-6
    obj = r.selected.sum()
    assert r.solution.gap == pytest.approx(max(obj - r.solution.dual_bound, 0) / obj)


def test_a_stuck_greedy_leaves_the_large_problem_path_without_a_starting_layout(monkeypatch):
    """When the greedy incumbent gets stuck, the plan goes on without it (no upper bound, no
    root relaxation) and still finds the optimum; the greedy is reported as not meeting the
    requirement, as it is when planning runs the greedy itself (small problems)."""
    import planner.program.baselines as baselines
    import planner.program.loop as loop

    monkeypatch.setattr(loop, "_SPARSE_ABOVE_SITES", 0)
    p, cfg = _reachable_network_case(60)
    greedy = baselines.greedy_network
    monkeypatch.setattr(baselines, "greedy_network",
                        lambda *a, **k: greedy(*a, **{**k, "max_steps": 0}))
    r = plan_sites(p, cfg)
    assert r.greedy is not None and not r.greedy.meets_requirement
    assert r.check.all_ok and r.status == "optimal"
    assert r.selected.sum() == brute_force_optimum(p, cfg)
    assert not any(k.family in ("oa-root", "upper-bound") for k in r.model.row_kind)
    b = baselines.network_baseline(p, cfg)
    assert not b.meets_requirement and b.n_markers == r.greedy.n_markers


def test_the_greedy_incumbent_starts_no_step_after_its_share_of_the_time_limit(monkeypatch):
    """With no time share the greedy stops where its directions-only cover left it, says why,
    and the plan goes on without it to the optimum."""
    import planner.program.loop as loop

    monkeypatch.setattr(loop, "_SPARSE_ABOVE_SITES", 0)
    monkeypatch.setattr(loop, "_GREEDY_TIME_FRACTION", 0.0)
    p, cfg = _reachable_network_case(60)
    r = plan_sites(p, cfg)
    assert not r.greedy.meets_requirement
    assert r.greedy.note.endswith(": its share of the time limit ran out")
    assert r.check.all_ok and r.selected.sum() == brute_force_optimum(p, cfg)


def test_when_no_tangent_applies_and_rows_are_long_the_long_no_good_rows_are_cut(monkeypatch):
    """On large problems long combinatorial rows are left out; when no tangent applies either,
    the worst stations' long rows are cut instead of failing with 'no cut was found', and the
    plan still passes."""
    import planner.program.cuts_network as cuts_network
    import planner.program.loop as loop
    from planner.accuracy.network import NetworkModel

    monkeypatch.setattr(loop, "_SPARSE_ABOVE_SITES", 0)
    monkeypatch.setattr(cuts_network, "MAX_TERMS", 1)
    monkeypatch.setattr(loop, "MAX_TERMS", 1)
    monkeypatch.setattr(NetworkModel, "station_tangents", lambda *a, **k: [])
    monkeypatch.setattr(NetworkModel, "marker_tangents", lambda *a, **k: [])
    p, cfg = _reachable_network_case(60)
    r = plan_sites(p, cfg)
    assert r.check.all_ok
    assert any(k.family in ("cut", "connect", "cut-marker") for k in r.model.row_kind)


@pytest.mark.parametrize("figure", ["ellipsoid", "quantile"])
def test_a_ppm_requirement_is_met_station_by_station_and_matches_the_brute_force_optimum(figure):
    """Network accuracy growing with the distance from the datum (a + b ppm): the plan is the
    fewest passing layout (brute force), each station's error is within a + b ppm of its own
    distance from the reference (computed here from the coordinates), and the allowance it
    grants the far stations saves markers over the constant a."""
    p = _instance(5)
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                      working_radius_m=10, time_limit_s=60, error_figure=figure)
    every = network_model(p, base).station_errors(np.ones(p.n_sites, bool))
    a = float(1.05 * every.max())
    ppm = 0.5 * a / 28.0 * 1e6  # the far station (28 m away) is allowed 1.5 a
    constant = plan_sites(p, base.replace(requirement_m=a))
    grown_cfg = base.replace(requirement_m=a, requirement_ppm=ppm)
    grown = plan_sites(p, grown_cfg)
    assert grown.status == "optimal" and grown.check.all_ok
    assert grown.selected.sum() == brute_force_optimum(p, grown_cfg)
    distance = np.hypot(*(p.station_xyz[:, :2] - p.station_xyz[0, :2]).T)
    net = network_model(p, grown_cfg)
    err = net.station_errors(grown.selected)
    assert np.all(err <= a + ppm * 1e-6 * distance)
    assert grown.selected.sum() < constant.selected.sum()
    # the same layout judged against the constant requirement fails: the allowance was used
    assert not evaluate_layout(p, grown.selected, base.replace(requirement_m=a)).all_ok


def test_a_ppm_requirement_needs_network_mode():
    with pytest.raises(ConfigError, match="network mode"):
        PlanConfig(requirement_ppm=200.0)
    assert PlanConfig(network=True, requirement_ppm=200.0).requirement_ppm == 200.0
