"""Chance-constrained planning: exact station probabilities, certified bounds, valid rows and
cuts, and the fewest markers against brute force (planner.accuracy.chance,
planner.program.cuts_chance, planner.accuracy.sampled_chance)."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from error_model.detection import wilson_interval
from markerplan.errors import InfeasiblePlanError
from planner.accuracy.chance import (
    more_losses_than,
    plan_chance,
    station_odds,
    station_target,
)
from planner.accuracy.checks import station_infos
from planner.accuracy.sampled_chance import sampled_chance
from planner.config import PlanConfig
from planner.problem.usability import sector_index
from planner.program import plan_sites
from planner.program.cuts_chance import (
    chance_count_rows,
    chance_rule,
    grow_failing_chance,
    min_markers_for_chance,
)
from tests.planner.instances import make_problem, ring


def _with_q(problem, q):
    return replace(problem, pair_detection_p=np.broadcast_to(
        np.asarray(q, float), problem.pair_station.shape).copy())


def _brute_pass(problem, s, sites, config):
    """P(station s passes) by summing over every detected subset, judged by StationInfo and
    the sector count directly (another route than the loss-set enumeration)."""
    info = station_infos(problem, config)[s]
    rows = info.rows(sites)
    q = problem.detection_p[info.pairs[rows]]
    sec = sector_index(problem.pair_bearing_rad[info.pairs[rows]], config.n_sectors)
    total = 0.0
    for bits in itertools.product([False, True], repeat=rows.size):
        kept = np.array(bits, bool)
        p = float(np.prod(np.where(kept, q, 1 - q)))
        ok = (kept.sum() >= config.min_markers
              and len(set(sec[kept].tolist())) >= config.min_sectors
              and info.error(info.sites[rows[kept]]) <= config.requirement_m)
        total += p * ok
    return total


def _one_station(n_sites=6, radius=8.0, q=0.9):
    bearings = np.arange(n_sites) * 360.0 / n_sites + 5.0
    problem = make_problem([(0.0, 0.0)], ring((0.0, 0.0), radius, bearings))
    return _with_q(problem, q)


def test_more_losses_than_is_the_poisson_binomial_tail():
    q = np.array([0.9, 0.8, 0.6])
    tail = more_losses_than(q)
    p0 = 0.9 * 0.8 * 0.6
    p1 = 0.1 * 0.8 * 0.6 + 0.9 * 0.2 * 0.6 + 0.9 * 0.8 * 0.4
    p3 = 0.1 * 0.2 * 0.4
    np.testing.assert_allclose(tail, [1 - p0, 1 - p0 - p1, p3, 0.0], atol=1e-15)


def test_three_markers_in_three_sectors_pass_only_when_all_are_detected():
    problem = _one_station(n_sites=3)
    q = np.array([0.95, 0.9, 0.8])
    problem = replace(problem, pair_detection_p=q)
    config = PlanConfig()
    odds = station_odds(problem, station_infos(problem, config), config)[0]
    c = odds.chance(np.arange(3), 0.01)
    assert c.exact
    assert c.fail_low == pytest.approx(1 - 0.95 * 0.9 * 0.8, abs=1e-12)
    assert c.fail_high == pytest.approx(c.fail_low, abs=1e-15)


def test_four_markers_fail_only_with_two_losses():
    problem = _one_station(n_sites=4)
    q = np.array([0.95, 0.9, 0.8, 0.7])
    problem = replace(problem, pair_detection_p=q)
    config = PlanConfig()
    c = station_odds(problem, station_infos(problem, config), config)[0].chance(
        np.arange(4), 0.01)
    none_lost = np.prod(q)
    one_lost = sum((1 - q[i]) * np.prod(np.delete(q, i)) for i in range(4))
    assert c.fail_low == pytest.approx(1 - none_lost - one_lost, abs=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_enumeration_matches_brute_force_with_accuracy_and_sectors(seed):
    rng = np.random.default_rng(seed)
    bearings = np.sort(rng.uniform(0, 360, 8))
    radii = rng.uniform(4, 28, 8)
    sites = np.array([ring((0.0, 0.0), r, [b])[0] for r, b in zip(radii, bearings, strict=True)])
    problem = make_problem([(0.0, 0.0)], sites)
    problem = replace(problem, pair_detection_p=rng.uniform(0.5, 1.0, problem.pair_station.size))
    config = PlanConfig(requirement_m=0.03)  # accuracy matters: some subsets fail it
    odds = station_odds(problem, station_infos(problem, config), config)[0]
    c = odds.chance(np.arange(8), 1e-6)
    assert c.exact
    assert 1 - c.fail_low == pytest.approx(_brute_pass(problem, 0, np.arange(8), config),
                                           abs=1e-12)


def test_a_small_budget_gives_bounds_around_the_exact_value():
    problem = _one_station(n_sites=12, q=0.7)
    config = PlanConfig()
    odds = station_odds(problem, station_infos(problem, config), config)[0]
    exact = odds.chance(np.arange(12), 1e-9)
    assert exact.exact
    rough = odds.chance(np.arange(12), 1e-9, budget=100)
    assert not rough.exact
    assert rough.fail_low <= exact.fail_low + 1e-12 <= rough.fail_high + 2e-12
    assert rough.fail_high - rough.fail_low > 1e-4  # the bound is a bound, not the answer


def test_sampled_outcomes_agree_with_the_exact_probability():
    rng = np.random.default_rng(4)
    stations = [(0.0, 0.0), (14.0, 0.0)]
    sites = np.vstack([ring((7.0, 0.0), 9.0, np.arange(0, 360, 40) + 3.0)])
    problem = make_problem(stations, sites)
    problem = replace(problem, pair_detection_p=rng.uniform(0.6, 1.0, problem.pair_station.size))
    config = PlanConfig()
    selected = np.ones(problem.n_sites, bool)
    exact = plan_chance(problem, selected, config,
                        station_odds(problem, station_infos(problem, config), config))
    sampled = sampled_chance(problem, selected, config, n_samples=1500, seed=1)
    low, high = wilson_interval(sampled.n_passed, sampled.n_samples, z=3.3)
    assert low <= exact.pass_low <= high
    assert all(c.fail_high - c.fail_low < 1e-4 for c in exact.stations)  # tail left tiny


def test_min_markers_for_chance():
    problem = _one_station(n_sites=8, q=0.9)
    config = PlanConfig()
    odds = station_odds(problem, station_infos(problem, config), config)[0]
    # 3 of k detected with q = 0.9: k = 3 gives 0.729, k = 4 0.9477, k = 5 0.99144
    assert min_markers_for_chance(odds, 0.1) == 4
    assert min_markers_for_chance(odds, 0.01) == 5
    assert min_markers_for_chance(odds, 1e-12) == 9  # more than the 8 usable sites


def test_chance_rows_hold_for_every_layout_that_meets_the_targets():
    rng = np.random.default_rng(7)
    problem = make_problem([(0.0, 0.0), (10.0, 0.0)],
                           ring((5.0, 0.0), 8.0, np.arange(0, 360, 36) + 2.0))
    problem = replace(problem, pair_detection_p=rng.uniform(0.8, 1.0, problem.pair_station.size))
    config = PlanConfig(chance_epsilon=0.2)
    infos = station_infos(problem, config)
    rule = chance_rule(problem, config, infos)
    from planner.program.model import build_model

    model = build_model(problem, config, information=False)
    rows, lower, upper, kinds = chance_count_rows(problem, model, rule.odds, rule.target)
    assert {k.family for k in kinds} >= {"chance-critical"}
    nx = model.var_site.size
    checked = 0
    for k in range(3, 7):
        for combo in itertools.combinations(range(problem.n_sites), k):
            sel = np.zeros(problem.n_sites, bool)
            sel[list(combo)] = True
            if not rule.layout_ok(sel):
                continue
            x = np.zeros(model.n_vars)
            x[:nx] = sel[model.var_site]
            value = rows @ x
            assert np.all(value >= np.asarray(lower) - 1e-9)
            assert np.all(value <= np.asarray(upper) + 1e-9)
            checked += 1
    assert checked > 10


def test_grown_failing_set_still_fails_and_holds_the_layout():
    problem = _one_station(n_sites=10, q=0.85)
    config = PlanConfig()
    odds = station_odds(problem, station_infos(problem, config), config)[0]
    target = 0.01
    chosen = np.array([0, 3, 6])
    assert odds.chance(chosen, target).fail_low > target
    grown = grow_failing_chance(odds, chosen, target)
    assert set(chosen) <= set(grown.tolist()) and grown.size > chosen.size
    assert odds.chance(grown, target).fail_low > target


def test_the_plan_is_the_fewest_markers_meeting_the_targets_by_brute_force():
    rng = np.random.default_rng(3)
    stations = [(0.0, 0.0), (12.0, 0.0)]
    sites = ring((6.0, 0.0), 9.0, np.arange(0, 360, 36) + 4.0)
    base = make_problem(stations, sites)
    problem = replace(base, pair_detection_p=rng.uniform(0.85, 1.0, base.pair_station.size))
    config = PlanConfig(chance_epsilon=0.05)
    result = plan_sites(problem, config)
    rule = chance_rule(problem, config, station_infos(problem, config))
    assert rule.layout_ok(result.selected) and result.check.all_ok
    naive = plan_sites(problem, config.replace(chance_epsilon=None))
    fewest = None
    for k in range(1, problem.n_sites + 1):
        for combo in itertools.combinations(range(problem.n_sites), k):
            sel = np.zeros(problem.n_sites, bool)
            sel[list(combo)] = True
            if rule.layout_ok(sel):
                from planner.accuracy.checks import evaluate_layout

                if evaluate_layout(problem, sel, config).all_ok:
                    fewest = k
                    break
        if fewest is not None:
            break
    assert int(result.selected.sum()) == fewest
    assert fewest > int(naive.selected.sum())  # the chances cost markers here
    assert result.status == "optimal"


def test_without_detection_chances_the_plan_is_the_naive_one():
    problem = make_problem([(0.0, 0.0)], ring((0.0, 0.0), 8.0, np.arange(0, 360, 45)))
    a = plan_sites(problem, PlanConfig())
    b = plan_sites(problem, PlanConfig(chance_epsilon=None))
    assert np.array_equal(a.selected, b.selected)


def test_a_station_no_layout_can_make_likely_enough_is_named():
    problem = _one_station(n_sites=6, q=0.5)
    with pytest.raises(InfeasiblePlanError, match=r"S1: .*chance of passing of at most"):
        plan_sites(problem, PlanConfig(chance_epsilon=0.01))


def test_station_target_is_a_union_bound():
    assert station_target(0.05, 7) == pytest.approx(0.05 / 7)


def test_enumeration_of_more_than_62_items_prunes_by_the_right_sets():
    from planner.accuracy.chance import enumerate_losses

    q = np.linspace(0.95, 0.995, 70)
    # fails exactly when item 65 is lost (a 64-bit mask would alias it with item 1)
    c = enumerate_losses(q, lambda kept: kept[:, 65], tail_tolerance=0.0)
    assert c.max_losses == 2
    assert c.fail_low <= 1 - q[65] + 1e-12 <= c.fail_high + 2e-12
    assert c.fail_low == pytest.approx(1 - q[65] - (1 - q[65]) * more_losses_than(
        np.delete(q, 65))[1], abs=1e-12)
