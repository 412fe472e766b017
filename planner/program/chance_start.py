"""A starting layout for chance-constrained planning: repair a layout until every station
meets its chance target.

The cut loop (:func:`planner.program.loop._cut_loop`) proves a chance-constrained plan optimal
when its lower bound reaches a layout known to pass; without one it can spend its time limit
cutting off near-misses one by one. :func:`repair_layout` turns the loop's first failing
layout into a passing one greedily: while some station misses its target, the worst one gets
the site that lowers its chance of failing most (among its ``MAX_CANDIDATES`` likeliest, most
informative usable sites; ties go to the site more failing stations can use). Adding sites
never hurts a station (more information, more directions), so a layout that passed the
accuracy check still passes it; the result is checked again anyway, and while it fails (the
exact check, or in network mode the whole network's chance) the most informative sites left
are added, in doubling batches.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from planner.program.cuts_chance import ChanceRule

#: Candidate sites tried per repair step.
MAX_CANDIDATES = 40
#: Most sites a repair adds.
MAX_ADDED = 200


def repair_layout(selected: np.ndarray, rule: ChanceRule, allowed: np.ndarray,
                  passes: Callable[[np.ndarray], bool]) -> np.ndarray | None:
    """A superset of ``selected`` meeting every chance target and ``passes``, or ``None``.

    Parameters
    ----------
    selected : (n,) bool
        The layout to start from.
    rule : ChanceRule
    allowed : (n,) bool
        Sites a marker may take (not forbidden).
    passes : callable
        ``passes(selected) -> bool``: the plan's exact check (count, directions, accuracy).
    """
    sel = np.asarray(selected, bool).copy()
    target = rule.target
    for _ in range(MAX_ADDED):
        fails = {}
        for s, o in enumerate(rule.odds):
            c = o.chance(o.info.sites[sel[o.info.sites]], target)
            if c.fail_high > target:
                fails[s] = c.fail_high
        if not fails:
            return _grow_until(sel, rule, allowed, passes)
        worst = max(fails, key=lambda s: (fails[s], -s))
        o = rule.odds[worst]
        free = np.flatnonzero(~sel[o.info.sites] & allowed[o.info.sites])
        if not free.size:
            return None
        value = o.q[free] / o.info.sigma_m[free] ** 2
        free = free[np.argsort(-value, kind="stable")[:MAX_CANDIDATES]]
        chosen = o.info.sites[sel[o.info.sites]]
        helps = np.zeros(sel.size, np.int64)
        for s in fails:
            helps[rule.odds[s].info.sites] += 1
        best, best_key = None, None
        for k in free:
            site = o.info.sites[k]
            fail = o.chance(np.r_[chosen, site], target).fail_high
            key = (fail, -helps[site], site)
            if best_key is None or key < best_key:
                best, best_key = site, key
        sel[best] = True
    return None


def _grow_until(selected: np.ndarray, rule: ChanceRule, allowed: np.ndarray,
                passes: Callable[[np.ndarray], bool]) -> np.ndarray | None:
    """``selected`` (meeting every station's target) grown until ``passes`` (the exact check
    and, in network mode, the whole network's chance) holds, or ``None``: the allowed sites
    not yet chosen are added by their summed ``q / sigma^2`` over the stations that can use
    them, 1, 2, 4, ... at a time, so the costly check runs a few times only."""
    sel = selected.copy()
    value = np.zeros(sel.size)
    for o in rule.odds:
        np.add.at(value, o.info.sites, o.q / o.info.sigma_m ** 2)
    batch = 1
    while not passes(sel):
        free = np.flatnonzero(allowed & ~sel & (value > 0))
        if not free.size or int(sel.sum()) - int(selected.sum()) >= MAX_ADDED:
            return None
        sel[free[np.argsort(-value[free], kind="stable")[:batch]]] = True
        batch *= 2
    return sel
