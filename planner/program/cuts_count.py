"""Network mode: per-station count rows — station ``k`` needs at least ``m_k`` of the tying sites
it sees, ``m_k`` a whole number proven from its tangent rows (:func:`station_count_rows`).

A tangent row ``sum_j c_j x_j >= rhs`` (``c >= 0``) holds for every passing layout. With every
site station ``k`` does not see at its upper bound the row asks the least of ``k``'s own sites,
so ``min sum_{j in V_k} x_j`` over ``k``'s tangent rows so reduced (a small LP over ``V_k``, the
open tying sites ``k`` sees) bounds the count of ``k``'s sites in every passing layout from below;
that count is a whole number, so it is at least the LP value rounded up. The rounding is what
the row adds to the relaxation (a station whose LP asks for 2.2 of its sites gets 3).
Before rounding, each station's LP is tightened by tangents at its own LP point (its sites as
the LP says, every other site at its upper bound), while that point fails the station: those
tangents are valid for every layout as well (convexity), and are returned for the caller's
relaxation too.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from planner.accuracy.network import NetworkModel
from planner.program.model import Model, RowKind

#: Tangent rounds per station at its own LP point (each one covariance of the whole network).
COUNT_ROUNDS = 4
#: A station's LP value above a whole number by less than this is taken as that number (the
#: LP's tolerance): the row then asks for that number, not one more.
_ROUND_TOL = 1e-6


def station_count_rows(model: Model, net: NetworkModel, cuts, deadline: float | None = None
                       ) -> tuple[sp.csr_array | None, list[float], list[RowKind], list]:
    """Count rows ``sum_{j in V_k} x_j >= m_k`` for every station with a tangent in ``cuts``.

    Parameters
    ----------
    model : Model
        Its variables, bounds (``ub`` 0: a closed site) and ``site_row``.
    net : NetworkModel
    cuts : list of (station, coef (n,), rhs)
        Tangent rows ``sum_j coef_j x_j >= rhs`` valid for every passing layout (``coef >= 0``;
        e.g. the root relaxation's).
    deadline : float, optional
        :func:`time.perf_counter` value after which no station is started.

    Returns
    -------
    rows : (r, v) sparse or None
        One row per station whose rows ask for some of its sites (``m_k >= 1``); ``None``:
        none.
    lower : list of float
        ``m_k`` per row.
    kinds : list of RowKind
        Family ``"count"``, the station.
    tangents : list of (station, coef (n,), rhs)
        The tangents added at the stations' own LP points (valid for every layout).
    """
    nx = model.var_site.size
    ub = np.zeros(net.problem.n_sites)
    ub[model.var_site] = model.ub[:nx]
    lb = np.zeros(net.problem.n_sites)
    lb[model.var_site] = model.lb[:nx]
    open_tying = net.tying & (ub > 0)
    owners = np.array([k for k, _, _ in cuts], np.int64)
    rows, lower, kinds, extra = [], [], [], []
    for k in np.unique(owners):
        if deadline is not None and time.perf_counter() > deadline:
            break
        mine = np.zeros(net.problem.n_sites, bool)
        mine[net.pair_site[net.pair_station == k]] = True
        own = np.flatnonzero(mine & open_tying)
        if own.size == 0:
            continue
        others = np.where(mine, 0.0, ub)
        station_cuts = [(c, rhs) for (kk, c, rhs) in cuts if kk == k]
        value = x_own = None
        for r in range(COUNT_ROUNDS + 1):
            value, x_own = _count_lp(station_cuts, own, others, lb[own], ub[own])
            if value is None or r == COUNT_ROUNDS:
                break
            x = others.copy()
            x[own] = x_own
            cov = net.covariance(net.information(x))
            if not cov.determined[k] or not net.stations_failing(
                    net.station_errors_from(cov))[k]:
                break
            new = [t for t in net.station_tangents(cov, [k]) if t[0] == k]
            if not new:
                break
            extra += new
            station_cuts += [(c, rhs) for _, c, rhs in new]
        if value is None:
            continue
        m = math.ceil(value - _ROUND_TOL)
        if m >= 1:
            rows.append(model.site_row(own))
            lower.append(float(m))
            kinds.append(RowKind("count", int(k)))
    if not rows:
        return None, [], [], extra
    return sp.csr_array(sp.vstack(rows)), lower, kinds, extra


def _count_lp(station_cuts, own: np.ndarray, others: np.ndarray, lb: np.ndarray,
              ub: np.ndarray) -> tuple[float | None, np.ndarray | None]:
    """``min sum x`` over ``own`` sites (bounds ``lb``, ``ub``) subject to each row
    ``sum_{own} c_j x_j >= rhs - sum_{others} c_j others_j``; ``(value, x)``, or ``(None,
    None)`` when no row asks anything (or the LP fails)."""
    a, b = [], []
    for c, rhs in station_cuts:
        need = rhs - float(c @ others)
        if need > 0:
            a.append(c[own])
            b.append(need)
    if not a:
        return None, None
    res = linprog(np.ones(own.size), A_ub=-np.asarray(a), b_ub=-np.asarray(b),
                  bounds=np.c_[lb, ub], method="highs")
    if res.status != 0:
        return None, None
    return float(res.fun), res.x
