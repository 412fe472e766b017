"""The local requirement under marker losses: redundant mode (every single loss) and the
chance constraint (sampled losses), each against brute force over every layout of a tiny line
of stations, judged by an independent route (the plain rule on the layout without the lost
marker; the detected pairs marked unusable)."""

import itertools
from dataclasses import replace

import numpy as np
import pytest

from planner.accuracy.checks import evaluate_layout
from planner.accuracy.local import LocalAccuracy, LocalRequirement
from planner.accuracy.local_markers import LocalMarkerAccuracy
from planner.accuracy.network import NetworkModel, network_model
from planner.accuracy.network_chance import NetworkOdds
from planner.config import PlanConfig
from planner.program import plan_sites
from planner.program.cuts_network import network_cuts
from planner.program.model import build_model
from tests.planner.instances import station_line
from tests.planner.test_local_markers import INCL

RADIUS = 2.0


def _redundant_case(seed: int, factor: float, local_markers: bool = True):
    """An 8-site line of three stations, a distance requirement ``factor`` times the worst
    station pair's error with every site selected."""
    p = station_line(3, n_sites=8, seed=seed)
    net = NetworkModel(p, RADIUS, INCL)
    cov = net.covariance(net.information(np.ones(p.n_sites, bool)))
    worst = LocalAccuracy(net, LocalRequirement(1.0, within_m=25.0, kind="distance")).errors(cov)
    cfg = PlanConfig(network=True, min_markers=2, min_sectors=1, max_range_m=20,
                     working_radius_m=RADIUS, time_limit_s=60, chance_epsilon=None,
                     datum_requirement=False, local_requirement_m=float(factor * worst.max()),
                     local_within_m=25.0, local_kind="distance", local_markers=local_markers,
                     redundant=True)
    return p, cfg


def _layouts(n: int) -> np.ndarray:
    return np.array(list(itertools.product([0, 1], repeat=n)), bool)


def _survives_every_loss(p, cfg, layouts):
    """(L,) bool: the redundant rule by another route: the layout and, for each of its
    markers, the layout without it pass the plain rule (no marker lost)."""
    plain = cfg.replace(redundant=False)
    index = {row.tobytes(): i for i, row in enumerate(layouts)}
    ok = np.array([evaluate_layout(p, sel, plain).all_ok for sel in layouts])
    out = ok.copy()
    for i, sel in enumerate(layouts):
        for m in np.flatnonzero(sel):
            less = sel.copy()
            less[m] = False
            out[i] &= ok[index[less.tobytes()]]
    return out, ok


@pytest.mark.parametrize(("seed", "factor"), [
    (1, 1.5), pytest.param(3, 2.0, marks=pytest.mark.slow)])
def test_redundant_plan_is_the_fewest_layout_surviving_every_loss(seed, factor):
    """The plan is the brute-force optimum of "the layout and each single loss pass the local
    requirement (station and marker pairs)", which needs more sites than the layouts that
    only survive a loss at the stations; the redundant check agrees layout by layout."""
    p, cfg = _redundant_case(seed, factor)
    layouts = _layouts(p.n_sites)
    survives, _ = _survives_every_loss(p, cfg, layouts)
    best = int(layouts[survives].sum(axis=1).min())
    r = plan_sites(p, cfg)
    assert r.status == "optimal" and r.check.all_ok and r.selected.sum() == best
    assert survives[np.flatnonzero((layouts == r.selected).all(axis=1))[0]]
    stations_only = cfg.replace(local_requirement_m=None, local_markers=False,
                                datum_requirement=True, requirement_m=100.0)
    assert plan_sites(p, stations_only).selected.sum() < best
    checked = np.array([evaluate_layout(p, sel, cfg).all_ok for sel in layouts])
    np.testing.assert_array_equal(checked, survives)


def test_a_layout_failing_the_local_requirement_after_a_loss_is_cut_off():
    """Layouts that pass the local requirement with every marker and survive every loss at
    the stations, but fail a pair after losing one marker: each gets cuts it violates and no
    layout surviving every loss does (the cuts are valid)."""
    p, cfg = _redundant_case(1, 1.5)
    layouts = _layouts(p.n_sites)
    survives, plain_ok = _survives_every_loss(p, cfg, layouts)
    stations = cfg.replace(local_requirement_m=None, local_markers=False,
                           datum_requirement=True, requirement_m=100.0)
    no_local_loss = np.array([evaluate_layout(p, sel, stations).all_ok for sel in layouts])
    caught = np.flatnonzero(plain_ok & no_local_loss & ~survives)
    assert caught.size
    net = network_model(p, cfg)
    model = build_model(p, cfg)
    j_all = net.information(np.ones(p.n_sites, bool))
    x = np.zeros((len(layouts), model.n_vars))
    x[:, model.site_var] = layouts
    kinds = set()
    for i in caught:
        rows, lower, kind = network_cuts(p, model, layouts[i], cfg, net, j_all)
        assert rows is not None
        kinds |= {k.family for k in kind}
        value = x @ rows.toarray().T  # (L, c)
        assert np.any(value[i] < np.asarray(lower) - 1e-9)
        assert np.all(value[survives] >= np.asarray(lower) - 1e-9)
    assert kinds & {"cut-loss-pair", "cut-loss-marker-pair"}


def test_redundant_mode_accepts_a_local_requirement():
    cfg = PlanConfig(network=True, redundant=True, local_requirement_m=0.1, local_markers=True)
    assert cfg.redundant and cfg.local_markers


def _chance_case(local_markers: bool = True):
    """Two stations sharing five sites (ten pairs, detected with chance 0.93 to 0.995), no
    datum requirement, a marker-pair requirement 1.2 times the worst pair's error with every
    site selected (stations 12 m apart: no station pair within 11.5 m), epsilon 0.1."""
    from tests.planner.test_network_chance import _two_stations

    problem, config = _two_stations(0)
    rng = np.random.default_rng(10)
    problem = replace(problem, pair_detection_p=rng.uniform(0.93, 0.995,
                                                            problem.pair_station.size))
    config = config.replace(min_markers=2, min_sectors=1)
    net = network_model(problem, config)
    every = np.ones(problem.n_sites, bool)
    probe = LocalMarkerAccuracy(net, LocalRequirement(1.0, within_m=11.5))
    worst = probe.errors(net.covariance(net.information(every)), probe.pairs(every)).max()
    return problem, config.replace(local_requirement_m=float(1.2 * worst), local_within_m=11.5,
                                   local_markers=local_markers, chance_epsilon=0.1,
                                   datum_requirement=False)


def _outcome_passes(problem, config, pairs, kept_pairs):
    """Whether every rule passes with only ``kept_pairs`` (bool over ``pairs``, the usable
    pairs) detected, by another route: the problem with the others occluded, checked whole."""
    from tests.planner.test_network_chance import _lost

    every = np.ones(problem.n_sites, bool)
    return evaluate_layout(_lost(problem, pairs[~kept_pairs]), every, config).all_ok


def test_chance_judges_the_marker_pairs_left_in_each_outcome_exactly():
    """The 1024 detection outcomes: the judge agrees with the whole check of the problem with
    the lost pairs occluded (a marker with none detected drops its pairs; 160 outcomes), some
    outcome passes only because a marker was lost whole (passing is not monotone), and the
    enumeration's bounds are the brute-force chance of failing."""
    problem, config = _chance_case()
    odds = NetworkOdds(problem, np.ones(problem.n_sites, bool), config)
    assert not odds.monotone and odds.q.size == 10
    kept = np.array(list(itertools.product([False, True], repeat=odds.q.size)))
    judged = odds.passes(kept)
    some = np.random.default_rng(0).choice(len(kept), 160, replace=False)
    direct = [_outcome_passes(problem, config, odds.net.pair_index, k) for k in kept[some]]
    np.testing.assert_array_equal(judged[some], direct)
    # a failing outcome with a passing one that lost more pairs
    fails = np.flatnonzero(~judged)
    assert any(judged[(kept <= kept[f]).all(axis=1) & (kept.sum(axis=1) < kept[f].sum())].any()
               for f in fails)
    brute = float(np.sum(np.prod(np.where(kept, odds.q, 1 - odds.q), axis=1)[~judged]))
    c = odds.chance(1e-12)
    assert c.max_losses >= 9 and 0.01 < brute < 0.99
    assert c.fail_low - 1e-12 <= brute <= c.fail_high + 1e-12
    assert c.fail_high - c.fail_low < 1e-9


def test_chance_plan_with_marker_pairs_is_the_brute_force_optimum():
    """The plan is the fewest sites of any layout that passes whole and whose exact chance of
    failing (marker pairs judged in every outcome) meets epsilon; judging the marker pairs only
    with every marker detected would accept more layouts. The whole-network no-good rows of every
    failing layout keep every passing layout (valid despite marker pairs not being monotone)."""
    from planner.accuracy.checks import station_infos
    from planner.program.cuts_chance import chance_rule

    problem, config = _chance_case()
    rule = chance_rule(problem, config, station_infos(problem, config))
    naive = chance_rule(problem, config.replace(local_markers=False),
                        station_infos(problem, config))
    net = network_model(problem, config)
    layouts = _layouts(problem.n_sites)
    whole = np.array([evaluate_layout(problem, sel, config, net=net).all_ok for sel in layouts])
    meets, naive_meets = (np.array([bool(w) and r.layout_ok(sel)
                                    for w, sel in zip(whole, layouts, strict=True)])
                          for r in (rule, naive))
    for sel in layouts[whole]:  # every layout decided by certified bounds, not by samples
        assert rule.whole(sel).n_samples == 0
    fewest = int(layouts[meets].sum(axis=1).min())
    assert (naive_meets & ~meets).any()  # layouts the marker pairs' losses reject
    r = plan_sites(problem, config)
    assert r.status == "optimal" and int(r.selected.sum()) == fewest
    assert meets[np.flatnonzero((layouts == r.selected).all(axis=1))[0]]
    model = build_model(problem, config)
    x = np.zeros((len(layouts), model.n_vars))
    x[:, model.site_var] = layouts
    n_rows = n_plain_invalid = 0
    for sel in layouts[whole & ~meets]:
        rows, lower, _ = rule.whole_cuts(problem, model, sel)
        if rows is None:  # failing a station's own target, not the whole network's
            continue
        n_rows += 1
        value = x @ rows.toarray().T
        assert value[(layouts == sel).all(axis=1)][0, 0] < lower[0]
        assert np.all(value[meets, 0] >= lower[0] - 1e-9)
        # the monotone no-good "some site outside" would cut off a passing subset
        n_plain_invalid += bool(np.any(meets & ~(layouts & ~sel).any(axis=1)))
    assert n_rows and n_plain_invalid


def test_outputs_record_that_the_losses_judge_the_local_pairs():
    """plan.json's ``local`` says the redundant errors are the worst after a single loss (and
    they are: at least the plain ones, some larger), the report says so, and the chance
    section's network record names the local pairs every outcome judges."""
    from types import SimpleNamespace

    from planner.outputs.chance_report import chance_markdown
    from planner.outputs.local_report import local_markdown, local_record

    p, cfg = _redundant_case(1, 1.5)
    net = network_model(p, cfg)
    sel = np.ones(p.n_sites, bool)

    def record(config):
        return local_record(SimpleNamespace(config=config, problem=p, result=SimpleNamespace(
            selected=sel, check=evaluate_layout(p, sel, config, net=net))), net)

    local, plain = record(cfg), record(cfg.replace(redundant=False))
    assert local["after_any_single_loss"] and not plain["after_any_single_loss"]
    worst = np.array([r["predicted_error_m"] for r in local["marker_pairs"]])
    base = np.array([r["predicted_error_m"] for r in plain["marker_pairs"]])
    assert np.all(worst >= base - 1e-15) and np.any(worst > base * 1.01)
    doc = {"local": local, "requirement": {"error_figure_text": "ellipsoid"}}
    assert any("after the loss of any one" in line for line in local_markdown(doc))
    whole = {"fail_low": 0.01, "fail_high": 0.02, "pass_low": 0.98, "n_pairs": 10,
             "max_losses": 10, "exact": True,
             "judges_local": {"station_pairs": True, "marker_pairs": True}}
    ch = {"epsilon": 0.05, "station_target": 0.025, "plan_pass_probability": 0.98,
          "network": whole, "baselines": {}, "cuts": {"chance_undecided": 0}, "stations": {}}
    text = "\n".join(chance_markdown({"chance": ch, "detection": {"model": {"name": "m"}}}))
    assert "station pairs and the pairs of the selected markers" in text
