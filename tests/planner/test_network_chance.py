"""The whole network's chance of passing when pairs are lost (planner.accuracy.network_chance)
against brute force over every detection outcome, and chance-constrained network planning
with it against brute force over every layout."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from planner.accuracy.checks import evaluate_layout, station_infos
from planner.accuracy.network import network_model
from planner.accuracy.network_chance import NetworkOdds, network_chance
from planner.accuracy.sampled_chance import sampled_chance
from planner.config import PlanConfig
from planner.problem.usability import OCCLUDED
from planner.program import plan_sites
from planner.program.cuts_chance import chance_rule
from tests.planner.instances import make_problem, ring

BASE = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                  working_radius_m=10, time_limit_s=60)


def _two_stations(seed: int, q_low: float = 0.7):
    """Two stations sharing five sites (ten pairs), random detection chances, a requirement
    that one or two losses can break."""
    rng = np.random.default_rng(seed)
    problem = make_problem([(0.0, 0.0), (12.0, 0.0)],
                           ring((6.0, 0.0), 7.0, np.arange(5) * 72.0 + rng.uniform(0, 30)),
                           max_range_m=16)
    problem = replace(problem, pair_detection_p=rng.uniform(q_low, 0.97,
                                                            problem.pair_station.size))
    every = np.ones(problem.n_sites, bool)
    best = network_model(problem, BASE).station_errors(every).max()
    return problem, BASE.replace(requirement_m=float(1.3 * best))


def _lost(problem, lost_pairs):
    """The problem with the given pairs (indices into its pairs) lost: another route to the
    network of the pairs left (a rebuilt network model and direction count)."""
    reason = problem.pair_reason.copy()
    reason[lost_pairs] = OCCLUDED
    return replace(problem, pair_reason=reason)


def _brute_fail(problem, config) -> float:
    """P(some station fails) over every detected subset of the pairs, each judged by
    ``evaluate_layout`` on the problem with the others lost."""
    pairs = np.flatnonzero(problem.pair_usable)
    q = problem.detection_p[pairs]
    every = np.ones(problem.n_sites, bool)
    total = 0.0
    for bits in itertools.product([False, True], repeat=pairs.size):
        kept = np.array(bits, bool)
        ok = evaluate_layout(_lost(problem, pairs[~kept]), every, config).ok.all()
        total += float(np.prod(np.where(kept, q, 1 - q))) * (not ok)
    return total


@pytest.mark.parametrize("seed", [0, 1])
def test_whole_network_chance_equals_brute_force(seed):
    problem, config = _two_stations(seed)
    brute = _brute_fail(problem, config)
    c = NetworkOdds(problem, np.ones(problem.n_sites, bool), config).chance(1e-12)
    assert c.n_pairs == 10 and c.exact
    assert 0.02 < brute < 0.98  # losses matter here
    assert c.fail_low == pytest.approx(brute, abs=1e-12)
    assert c.fail_high == pytest.approx(brute, abs=1e-12)


def test_a_small_budget_bounds_the_brute_force_value():
    problem, config = _two_stations(2, q_low=0.9)
    brute = _brute_fail(problem, config)
    c = NetworkOdds(problem, np.ones(problem.n_sites, bool), config).chance(1e-12, budget=60)
    assert not c.exact and c.max_losses == 2
    assert c.fail_low - 1e-12 <= brute <= c.fail_high + 1e-12
    assert c.fail_high - c.fail_low < 0.1


def test_kept_pairs_give_the_information_of_the_network_without_the_others():
    problem, config = _two_stations(3)
    net = network_model(problem, config)
    rng = np.random.default_rng(0)
    every = np.ones(problem.n_sites, bool)
    for _ in range(20):
        kept = rng.random(net.pair_index.size) < 0.6
        rebuilt = network_model(_lost(problem, net.pair_index[~kept]), config)
        np.testing.assert_allclose(net.information(every, kept), rebuilt.information(every),
                                   rtol=1e-12, atol=1e-9)


def test_the_judge_agrees_with_the_layout_check_on_random_outcomes():
    problem, config = _two_stations(4)
    odds = NetworkOdds(problem, np.ones(problem.n_sites, bool), config)
    rng = np.random.default_rng(1)
    kept = rng.random((200, odds.q.size)) < 0.75
    judged = odds.passes(kept)
    every = np.ones(problem.n_sites, bool)
    direct = [evaluate_layout(_lost(problem, odds.net.pair_index[~k]), every, config).ok.all()
              for k in kept]
    assert 0 < judged.sum() < kept.shape[0]
    np.testing.assert_array_equal(judged, direct)


def test_sampled_outcomes_fall_in_the_certified_interval():
    problem, config = _two_stations(5, q_low=0.8)
    every = np.ones(problem.n_sites, bool)
    c = network_chance(problem, every, config, epsilon=1e-9)
    s = sampled_chance(problem, every, config, 4000, seed=2)
    low, high = s.wilson_95
    assert c.pass_low <= high + 0.01 and 1 - c.fail_low >= low - 0.01


def _three_stations(seed=2):
    rng = np.random.default_rng(seed)
    stations = [[0, 0], [14, 0], [28, 0]]
    sites = np.vstack([rng.uniform([-8, -9], [36, 9], (9, 2)), [[7, 4], [21, -4]]])
    problem = make_problem(stations, sites, max_range_m=16)
    problem = replace(problem, pair_detection_p=rng.uniform(0.85, 1.0,
                                                            problem.pair_station.size))
    best = network_model(problem, BASE).station_errors(np.ones(problem.n_sites, bool)).max()
    return problem, BASE.replace(requirement_m=float(1.6 * best), chance_epsilon=0.1)


@pytest.mark.slow
def test_network_chance_plan_is_the_fewest_markers_by_brute_force():
    problem, config = _three_stations(7)
    result = plan_sites(problem, config)
    kinds = [k.family for k in result.model.row_kind]
    assert kinds.count("chance-network") >= 1  # the whole network's rule binds here
    rule = chance_rule(problem, config, station_infos(problem, config))
    assert result.status == "optimal" and result.check.all_ok
    assert network_chance(problem, result.selected, config).fail_high <= 0.1
    net = network_model(problem, config)
    fewest = None
    for k in range(1, problem.n_sites + 1):
        for combo in itertools.combinations(range(problem.n_sites), k):
            sel = np.zeros(problem.n_sites, bool)
            sel[list(combo)] = True
            if evaluate_layout(problem, sel, config, net=net).all_ok and rule.layout_ok(sel):
                fewest = k
                break
        if fewest is not None:
            break
    assert int(result.selected.sum()) == fewest
    # the stations' count-and-directions rule alone would take fewer markers
    plain = replace(rule, whole=None)
    assert any(evaluate_layout(problem, sel, config, net=net).all_ok and plain.layout_ok(sel)
               for combo in itertools.combinations(range(problem.n_sites), fewest - 1)
               for sel in [np.isin(np.arange(problem.n_sites), combo)])


def test_a_layout_the_bounds_cannot_reach_is_decided_by_samples():
    import planner.accuracy.network_chance as nc

    problem, config = _two_stations(6, q_low=0.9)
    every = np.ones(problem.n_sites, bool)
    brute = _brute_fail(problem, config)
    odds = NetworkOdds(problem, every, config)
    assert not odds.can_bound(0.05, budget=5)  # not even every single loss
    assert network_chance(problem, every, config, 0.05, budget=5).max_losses == 0
    loose, tight = 1.5 * brute + 0.05, 0.5 * brute
    for eps, expected in [(loose, True), (tight, False)]:
        c = odds.decide(eps, budget=5)
        assert c.max_losses == 0 and c.n_samples == nc.SAMPLES_TO_DECIDE
        rate = c.n_passed / c.n_samples  # the samples see the true chance (3.3 sigma)
        assert abs(rate - (1 - brute)) <= 3.3 * np.sqrt(brute * (1 - brute) / c.n_samples)
        assert c.meets(eps) is expected


def test_the_summary_and_report_say_when_a_network_has_no_certified_bound():
    from planner.cli.plan import chance_text
    from planner.outputs.chance_report import chance_markdown

    doc = {"detection": {"model": {"name": "default"}}, "chance": {
        "epsilon": 0.05, "station_target": 0.0005, "plan_pass_probability": 0.0,
        "network": {"fail_low": 0.0, "fail_high": 1.0, "pass_low": 0.0, "n_pairs": 3605,
                    "max_losses": 0, "exact": False},
        "sampled": {"n_samples": 2000, "seed": 0, "n_passed": 1962, "pass_rate": 0.981,
                    "wilson_95": [0.974, 0.986]},
        "baselines": {}, "cuts": {"chance_undecided": 0}, "stations": {}}}
    assert chance_text(doc) == ("P(pass) 98.1 % sampled (no certified bound: 3,605 pairs) "
                                "(epsilon 0.05); ")
    text = "\n".join(chance_markdown(doc))
    assert "no certified bound: 3,605 pairs" in text and "98.10 % passed" in text
    doc["chance"]["network"].update(max_losses=3, fail_high=0.0135, pass_low=0.9865)
    doc["chance"]["plan_pass_probability"] = 0.9865
    assert chance_text(doc).startswith("P(pass) >= 98.7 %")
    assert "losses of up to 3 of its 3605 pairs judged" in "\n".join(chance_markdown(doc))


def test_a_large_network_starts_from_the_greedy_layout_repaired_for_the_chances(monkeypatch):
    import planner.program.loop as loop
    from planner.program.baselines import network_baseline

    problem, config = _three_stations(7)
    rule = chance_rule(problem, config, station_infos(problem, config))
    greedy = network_baseline(problem, config)
    assert greedy.meets_requirement and not rule.layout_ok(greedy.selected)
    fewest = int(plan_sites(problem, config).selected.sum())
    monkeypatch.setattr(loop, "_SPARSE_ABOVE_SITES", 0)  # take the large networks' path
    result = plan_sites(problem, config)
    assert result.check.all_ok and rule.layout_ok(result.selected)
    assert result.status == "optimal" and int(result.selected.sum()) == fewest
    assert "upper-bound" in [k.family for k in result.model.row_kind]  # the repaired start
