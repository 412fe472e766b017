"""Marker-reduction studies: exact minimax curve, drop order, per-marker losses."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from markerplan.errors import ConfigError, InfeasiblePlanError
from planner.accuracy.checks import evaluate_layout, station_infos
from planner.config import PlanConfig
from planner.program import plan_sites
from planner.reduction.curve import tradeoff_curve
from planner.reduction.losses import drop_order, failure_reason, marker_losses
from planner.reduction.study import run_study
from tests.planner.instances import make_problem, ring

CONFIG = PlanConfig(requirement_m=0.03, working_radius_m=10.0)


def _brute_force(problem, config, k, keep=None, drop=None):
    """Least worst-station error over all k-subsets meeting count and directions (holding site
    ``keep`` and not site ``drop``)."""
    infos = station_infos(problem, config)
    best = np.inf
    for sub in itertools.combinations(range(problem.n_sites), k):
        if (keep is not None and keep not in sub) or drop in sub:
            continue
        sel = np.zeros(problem.n_sites, bool)
        sel[list(sub)] = True
        chk = evaluate_layout(problem, sel, config, infos)
        if np.all((chk.count >= config.min_markers) & (chk.sectors >= config.min_sectors)):
            best = min(best, float(chk.error_m.max()))
    return best


def _random_problem(seed, n_stations=3, n_sites=8):
    rng = np.random.default_rng(seed)
    return make_problem(rng.uniform(-12, 12, (n_stations, 2)), rng.uniform(-18, 18, (n_sites, 2)))


@pytest.fixture(scope="module")
def tiny():
    """Two stations, eight sites on rings around them: small enough to enumerate."""
    stations = [[0.0, 0.0], [14.0, 0.0]]
    sites = np.vstack([ring([0, 0], 6.0, [20, 100, 200, 290]),
                       ring([14, 0], 9.0, [0, 80, 170, 260])])
    return make_problem(stations, sites, occluded=[(0, 7), (1, 2)])


def test_curve_matches_brute_force_on_tiny_instance(tiny):
    curve = tradeoff_curve(tiny, CONFIG)
    assert curve.proven
    assert [p.k for p in curve.points] == list(range(8, curve.k_directions - 1, -1))
    for p in curve.points:
        assert p.selected.sum() == p.k
        assert p.worst_error_m == pytest.approx(_brute_force(tiny, CONFIG, p.k), rel=1e-9)
        # the reported errors are those of the reported subset
        chk = evaluate_layout(tiny, p.selected, CONFIG)
        np.testing.assert_allclose(p.error_m, chk.error_m)
        assert p.lower_bound_m <= p.worst_error_m
    assert curve.k_feasible_minimal
    # starting from the full layout (as the CLI does) gives the same optimum
    started = tradeoff_curve(tiny, CONFIG, start=np.ones(tiny.n_sites, bool))
    np.testing.assert_allclose([p.worst_error_m for p in started.points],
                               [p.worst_error_m for p in curve.points], rtol=1e-9)


@pytest.mark.parametrize("seed", [3, 11])
def test_curve_matches_brute_force_on_random_instances(seed):
    problem = _random_problem(seed, n_stations=4, n_sites=9)
    try:
        curve = tradeoff_curve(problem, CONFIG)
    except InfeasiblePlanError:
        pytest.skip("instance has no direction-feasible subset")
    for p in curve.points:
        assert p.worst_error_m == pytest.approx(_brute_force(problem, CONFIG, p.k), rel=1e-9)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 10_000), n_sites=st.integers(5, 8),
       requirement=st.sampled_from([0.025, 0.03, 0.05]))
def test_curve_is_monotone_and_its_smallest_feasible_k_is_the_plan(seed, n_sites, requirement):
    problem = _random_problem(seed, n_sites=n_sites)
    config = CONFIG.replace(requirement_m=requirement)
    try:
        curve = tradeoff_curve(problem, config)
    except InfeasiblePlanError:
        with pytest.raises(InfeasiblePlanError):
            plan_sites(problem, config)
        return
    worst = [p.worst_error_m for p in curve.points]  # k decreasing
    assert all(b >= a * (1 - 1e-9) for a, b in zip(worst, worst[1:], strict=False))
    assert curve.points[-1].k == curve.k_directions
    try:
        plan = plan_sites(problem, config)
    except InfeasiblePlanError:
        assert curve.k_feasible is None
    else:
        assert curve.k_feasible == int(plan.selected.sum())
        # meeting the requirement is monotone in k too
        ok = [p.meets_requirement for p in curve.points]
        assert ok == sorted(ok, reverse=True)


def test_drop_order_is_nested_and_never_beats_the_curve(tiny):
    layout = np.ones(tiny.n_sites, bool)
    steps = drop_order(tiny, CONFIG, layout)
    curve = tradeoff_curve(tiny, CONFIG)
    prev = layout
    for s in steps:
        assert prev[s.removed] and not s.selected[s.removed]
        assert (s.selected <= prev).all() and s.selected.sum() == s.k
        assert s.worst_error_m >= curve.at(s.k).worst_error_m * (1 - 1e-9)
        prev = s.selected
    assert steps[-1].k >= curve.k_directions  # a nested order may stop above the optimum


def test_marker_losses_name_the_stations_that_fail(tiny):
    layout = np.zeros(tiny.n_sites, bool)
    layout[[0, 1, 2, 3, 4, 5, 6]] = True
    losses = marker_losses(tiny, CONFIG, layout)
    assert [m.marker for m in losses] == [0, 1, 2, 3, 4, 5, 6]
    for m in losses:
        trial = layout.copy()
        trial[m.marker] = False
        chk = evaluate_layout(tiny, trial, CONFIG)
        assert m.failing == tuple(np.flatnonzero(~chk.ok))
        np.testing.assert_allclose(m.check.error_m, chk.error_m)


def test_losing_any_marker_of_a_minimal_layout_fails_a_station_with_a_reason(tiny):
    curve = tradeoff_curve(tiny, CONFIG)
    minimal = curve.at(curve.k_directions).selected  # 3 markers: count rows are tight
    for m in marker_losses(tiny, CONFIG, minimal):
        assert m.failing
        for s in m.failing:
            assert "usable markers < 3" in failure_reason(m.check, s, CONFIG)


def test_k_out_of_range_is_refused(tiny):
    with pytest.raises(ConfigError, match="k_max"):
        tradeoff_curve(tiny, CONFIG, k_max=99)
    with pytest.raises(ConfigError, match="k_min"):
        tradeoff_curve(tiny, CONFIG, k_min=1)


def test_redundant_mode_and_existing_markers_are_refused(tiny):
    with pytest.raises(ConfigError, match="redundant"):
        tradeoff_curve(tiny, CONFIG.replace(redundant=True))
    fixed = make_problem([[0.0, 0.0]], ring([0, 0], 6.0, [0, 120, 240]),
                         existing=[True, False, False])
    with pytest.raises(ConfigError, match="existing"):
        tradeoff_curve(fixed, CONFIG)


def test_no_direction_feasible_subset_names_the_station():
    problem = make_problem([[0.0, 0.0]], ring([0, 0], 6.0, [0, 10]))
    with pytest.raises(InfeasiblePlanError, match="S1"):
        tradeoff_curve(problem, CONFIG)


def test_kept_and_dropped_markers_are_honoured(tiny):
    config = CONFIG.replace(existing=("C005",), forbidden=("C001",))
    curve = tradeoff_curve(tiny, config)
    assert curve.points[0].k == 7  # C001 must go
    for p in curve.points:
        assert p.selected[5] and not p.selected[1]
        assert p.worst_error_m == pytest.approx(
            _brute_force(tiny, config, p.k, keep=5, drop=1), rel=1e-9)
    steps = drop_order(tiny, config, np.ones(tiny.n_sites, bool))
    assert all(s.removed != 5 and not s.selected[1] for s in steps)
    with pytest.raises(ConfigError, match="unknown site id"):
        drop_order(tiny, CONFIG.replace(forbidden=("nope",)), np.ones(tiny.n_sites, bool))


def test_free_choice_is_never_worse_than_the_layout(tiny):
    layout = np.zeros(tiny.n_sites, bool)
    layout[[0, 1, 2, 4, 5, 6]] = True
    sub = tiny.restrict(layout)
    fixed = run_study(sub, CONFIG, np.ones(sub.n_sites, bool))
    free = run_study(tiny, CONFIG, layout, free=True)
    assert free.n_layout == 6 and free.curve.points[0].k == 6
    for p in free.curve.points:
        try:
            q = fixed.curve.at(p.k)
        except ConfigError:
            continue  # below the layout's own direction minimum
        assert p.worst_error_m <= q.worst_error_m * (1 + 1e-9)
    assert free.curve.k_directions <= fixed.curve.k_directions
    assert len(free.losses) == 6
    assert [p.k for p in free.layout_curve.points] == [p.k for p in fixed.curve.points]
    assert sub.site_ids == tuple(tiny.site_ids[j] for j in (0, 1, 2, 4, 5, 6))


def test_an_unproven_point_is_repaired_from_a_better_smaller_subset(tiny):
    import time
    from dataclasses import replace

    from planner.reduction.curve import _monotone
    from planner.reduction.minimax import MinimaxModel

    curve = tradeoff_curve(tiny, CONFIG)
    mm = MinimaxModel(tiny, CONFIG, time.perf_counter() + 10)
    # pretend the 6-marker search stopped early with the worst 6-subset meeting the directions
    worst6 = max((np.isin(np.arange(8), sub) for sub in itertools.combinations(range(8), 6)),
                 key=lambda sel: evaluate_layout(tiny, sel, CONFIG).error_m.max()
                 if evaluate_layout(tiny, sel, CONFIG).sectors.min() >= 3 else -1)
    chk = evaluate_layout(tiny, worst6, CONFIG)
    points = [replace(p, selected=worst6, error_m=chk.error_m, proven=False) if p.k == 6 else p
              for p in curve.points]
    assert points[2].worst_error_m > points[3].worst_error_m  # k=6 worse than k=5
    fixed = _monotone(mm, points, np.ones(8, bool))
    assert fixed[2].selected.sum() == 6 and (fixed[2].selected >= points[3].selected).all()
    assert fixed[2].worst_error_m == pytest.approx(curve.at(6).worst_error_m, rel=1e-9)


# --- network mode --------------------------------------------------------------------------

def _network_instance():
    """Three stations in a row, 9 sites (as tests/planner/test_network_program.py's)."""
    rng = np.random.default_rng(5)
    sites = np.vstack([rng.uniform([-8, -9], [36, 9], (7, 2)), [[7, 4], [21, -4]]])
    return make_problem([[0, 0], [14, 0], [28, 0]], sites, max_range_m=16)


NETWORK = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                     working_radius_m=10.0, requirement_m=1.0)


def _network_brute_force(problem, config, k):
    """Least worst error (stations and kept markers, relative to the datum) over all k-subsets
    meeting count and directions."""
    from planner.accuracy.network import network_model

    net = network_model(problem, config)
    best = np.inf
    for sub in itertools.combinations(range(problem.n_sites), k):
        sel = np.zeros(problem.n_sites, bool)
        sel[list(sub)] = True
        chk = evaluate_layout(problem, sel, config, net=net)
        if np.all((chk.count >= config.min_markers) & (chk.sectors >= config.min_sectors)):
            best = min(best, max(float(chk.error_m.max()), float(np.nanmax(chk.marker_error_m))))
    return best


@pytest.fixture(scope="module")
def network_curves():
    problem = _network_instance()
    return problem, tradeoff_curve(problem, NETWORK), tradeoff_curve(
        problem, NETWORK.replace(network=False))


def test_network_curve_is_the_exact_minimax_of_the_networks_errors(network_curves):
    from planner.accuracy.network import network_model

    problem, curve, _ = network_curves
    net = network_model(problem, NETWORK)
    assert curve.proven and curve.k_directions == curve.points[-1].k
    for p in curve.points:
        assert p.selected.sum() == p.k
        assert p.worst_error_m == pytest.approx(_network_brute_force(problem, NETWORK, p.k),
                                                rel=1e-9)
        # every station's and kept marker's error is NetworkModel's, relative to S1
        cov = net.covariance(net.information(p.selected))
        np.testing.assert_allclose(p.error_m, net.station_errors_from(cov), rtol=1e-12)
        kept = np.flatnonzero(p.selected)
        np.testing.assert_allclose(p.marker_error_m[kept], net.marker_errors(cov, kept),
                                   rtol=1e-12)
        assert np.isnan(p.marker_error_m[~p.selected]).all()
        assert p.worst_error_m == max(p.error_m.max(), p.marker_error_m[kept].max())


def test_network_curve_needs_more_markers_and_its_fewest_passing_is_the_network_plan(
        network_curves):
    problem, curve, known = network_curves
    by_k = {p.k: p for p in known.points}
    # the network's errors exceed known control's at every count (markers are unknowns)
    for p in curve.points:
        assert p.worst_station_error_m > by_k[p.k].worst_error_m
    # worst errors (m), network / known control: 9-7 markers 0.114 / 0.033, 6: 0.116 / 0.033,
    # 5: 0.124 / 0.035; at 0.12 m known control needs 5 markers, the network 6
    config = NETWORK.replace(requirement_m=0.12)
    net_curve = tradeoff_curve(problem, config)
    kc_curve = tradeoff_curve(problem, config.replace(network=False))
    assert (kc_curve.k_feasible, net_curve.k_feasible) == (5, 6)
    assert net_curve.k_feasible_minimal
    assert net_curve.k_feasible == int(plan_sites(problem, config).selected.sum())


def test_network_drop_order_and_losses_judge_the_network(network_curves):
    problem, curve, _ = network_curves
    layout = np.ones(problem.n_sites, bool)
    steps = drop_order(problem, NETWORK, layout)
    assert steps and all(s.check.marker_error_m is not None for s in steps)
    for s in steps:
        best = next(p for p in curve.points if p.k == s.k)
        assert s.worst_error_m >= best.worst_error_m * (1 - 1e-9)
    losses = marker_losses(problem, NETWORK, layout)
    assert all(m.worst_error_m >= curve.points[0].worst_error_m * (1 - 1e-9) for m in losses)
