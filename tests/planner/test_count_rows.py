"""Per-station count rows (:mod:`planner.program.cuts_count`) never cut off a passing layout."""

import itertools
import time

import numpy as np

from planner.accuracy.checks import evaluate_layout
from planner.accuracy.network import network_model
from planner.config import PlanConfig
from planner.program import build_model
from tests.planner.instances import make_problem


def _instance(seed):
    """Three stations in a row and 11 sites around them: 2048 layouts to enumerate."""
    rng = np.random.default_rng(seed)
    sites = np.vstack([rng.uniform([-8, -9], [36, 9], (9, 2)), [[7, 4], [21, -4]]])
    return make_problem([[0, 0], [14, 0], [28, 0]], sites, max_range_m=16)


def test_count_rows_and_their_tangents_keep_every_passing_layout():
    """Every row has coefficients >= 0 and passing is monotone (a site added never fails a
    station), so checking the minimal passing layouts checks them all: layouts are enumerated
    by size and supersets of a passing one are skipped."""
    import planner.program.loop as loop

    p = _instance(2)
    base = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=16,
                      working_radius_m=10)
    every = np.ones(p.n_sites, bool)
    cfg = base.replace(requirement_m=float(
        1.15 * network_model(p, base).station_errors(every).max()))
    net = network_model(p, cfg)
    model = build_model(p, cfg)
    cuts, (rows, lower, kinds), bound, record = loop._root_relaxation(
        p, model, net, time.perf_counter() + 10)
    assert rows is not None and {k.family for k in kinds} == {"count"}
    assert record["count_rows"] == len(lower)
    nx = model.var_site.size
    minimal = []
    for k in range(1, p.n_sites + 1):
        for combo in itertools.combinations(range(p.n_sites), k):
            if any(m.issubset(combo) for m in minimal):
                continue
            sel = np.zeros(p.n_sites, bool)
            sel[list(combo)] = True
            if not evaluate_layout(p, sel, cfg, net=net).all_ok:
                continue
            minimal.append(frozenset(combo))
            x = np.zeros(model.n_vars)
            x[:nx] = sel[model.var_site]
            assert np.all(rows @ x >= np.asarray(lower) - 1e-9), combo
            assert all(c @ sel >= rhs * (1 - 1e-9) for _, c, rhs in cuts), combo
    assert minimal and bound <= min(len(m) for m in minimal)
