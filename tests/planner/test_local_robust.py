"""The local requirement under marker losses: redundant mode (every single loss) and the
chance constraint (sampled losses), each against brute force over every layout of a tiny line
of stations, judged by an independent route (the plain rule on the layout without the lost
marker; the detected pairs marked unusable)."""

import itertools

import numpy as np
import pytest

from planner.accuracy.checks import evaluate_layout
from planner.accuracy.local import LocalAccuracy, LocalRequirement
from planner.accuracy.network import NetworkModel, network_model
from planner.config import PlanConfig
from planner.program import plan_sites
from planner.program.cuts_network import network_cuts
from planner.program.model import build_model
from tests.planner.test_local_markers import INCL, _line

RADIUS = 2.0


def _redundant_case(seed: int, factor: float, local_markers: bool = True):
    """An 8-site line of three stations, a distance requirement ``factor`` times the worst
    station pair's error with every site selected."""
    p = _line(3, n_sites=8, seed=seed)
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


@pytest.mark.parametrize(("seed", "factor"), [(1, 1.5), (3, 2.0)])
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
