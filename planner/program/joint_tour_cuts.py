"""Connectivity cuts that tighten the joint program's tour at its root.

The tour's flow rows (:mod:`planner.program.joint_tour`) make every integer solution one closed
tour, but their linear relaxation lets a fraction of an edge carry all the flow, so the bound
on the drive is weak. Two families of valid inequalities, separated on a relaxed solution by
maximum flow (:func:`scipy.sparse.csgraph.maximum_flow`, the edges' values as capacities),
close much of that:

- **subtour elimination** (generalised, for a tour that need not visit every node): for a set
  ``S`` of stations without the route start and a station ``i`` in it,
  ``z(delta(S)) >= 2 w_i``: a tour that stops at ``i`` enters and leaves ``S``;
- **cover cuts**: for a set ``S`` without the route start that holds every candidate station
  covering some AOI cell, ``z(delta(S)) >= 2``: some station of ``S`` must be visited.

:func:`connectivity_cuts` finds, for each station with ``w_i > 0`` and each coverage row, the
least cut between the route start and it; a cut lighter than its right-hand side gives a row.
:func:`tighten_tour` separates them round after round on the tour's own relaxation and returns
its bound on the stops and the drive; :func:`fewest_markers_bound` bounds the markers, the
other part of the joint program's cost.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, maximum_flow

from planner.program.joint_tour import TourBlock
from planner.program.model import Model, RowKind
from planner.program.solving import logged_solve

#: Edge values are scaled to integer capacities by this factor.
_SCALE = 10_000
#: A cut is added when it is lighter than its right-hand side by more than this.
_TOLERANCE = 1e-3
#: Most rounds of root cuts.
ROOT_ROUNDS = 40
#: The linear rounds stop when their bound grew by less than this share over this many rounds.
STALL_GAIN, STALL_ROUNDS = 0.01, 3


def connectivity_cuts(block: TourBlock, x: np.ndarray, station_var: np.ndarray,
                      cover_sets: list[np.ndarray], n_vars: int
                      ) -> tuple[sp.csr_array, np.ndarray, np.ndarray, tuple] | None:
    """The violated subtour and cover cuts of a (relaxed) solution.

    Parameters
    ----------
    block : TourBlock
    x : (v,) float
        The solution.
    station_var : (s,) int
        Variable index of each candidate station's ``w``.
    cover_sets : list of (k,) int
        Per coverage row, the candidate stations that cover its cells.
    n_vars : int

    Returns
    -------
    rows : (r, n_vars) sparse, row_lb : (r,) float, row_ub : (r,) float, kinds : tuple
        None when no cut is violated.
    """
    edge = block.graph.edge
    n_nodes = station_var.size + 1
    z = np.clip(x[block.edge_var], 0.0, None)
    w = np.clip(x[station_var], 0.0, None)
    cap = np.rint(z * _SCALE).astype(np.int32)
    seen: set[bytes] = set()
    rows, lbs, kinds = [], [], []

    def add(side: np.ndarray, station: int | None) -> None:
        key = np.packbits(side).tobytes() + (b"c" if station is None else b"s")
        if key in seen:
            return
        seen.add(key)
        crossing = np.flatnonzero(side[edge[:, 0]] != side[edge[:, 1]])
        cols = list(block.edge_var[crossing])
        data = [1.0] * crossing.size
        if station is not None:
            cols.append(station_var[station])
            data.append(-2.0)
        rows.append((np.array(data), np.array(cols, np.int64)))
        lbs.append(0.0 if station is not None else 2.0)
        kinds.append(RowKind("tour-cut", station) if station is not None
                     else RowKind("tour-cover-cut"))

    # subtours: the route start (node 0) to each station, strongest first
    graph = _capacity_graph(edge, cap, n_nodes)
    for s in np.argsort(-w, kind="stable"):
        if w[s] <= _TOLERANCE:
            break
        side = _sink_side(graph, 0, s + 1)
        if _weight(side, edge, z) < 2 * w[s] - _TOLERANCE:
            add(side, int(s))
    # covers: the route start to a sink joined to every station covering the row's cells
    sink = n_nodes
    for members in cover_sets:
        tie = np.c_[members + 1, np.full(members.size, sink)]
        g = _capacity_graph(np.vstack([edge, tie]),
                            np.r_[cap, np.full(members.size, 4 * _SCALE, np.int32)],
                            n_nodes + 1, directed_from=edge.shape[0])
        side = _sink_side(g, 0, sink)[:n_nodes]
        if _weight(side, edge, z) < 2.0 - _TOLERANCE:
            add(side, None)
    if not rows:
        return None
    data = np.concatenate([d for d, _ in rows])
    cols = np.concatenate([c for _, c in rows])
    indptr = np.r_[0, np.cumsum([len(d) for d, _ in rows])]
    A = sp.csr_array((data, cols, indptr), shape=(len(rows), n_vars))
    return A, np.array(lbs), np.full(len(rows), np.inf), tuple(kinds)


def _capacity_graph(edge: np.ndarray, cap: np.ndarray, n: int, directed_from: int | None = None
                    ) -> sp.csr_array:
    """(n, n) int32 capacities: each edge both ways, those from ``directed_from`` on one way
    only (first node to second)."""
    both = slice(None) if directed_from is None else slice(0, directed_from)
    a, b = edge[:, 0], edge[:, 1]
    rows = np.r_[a, b[both]]
    cols = np.r_[b, a[both]]
    data = np.r_[cap, cap[both]].astype(np.int32)
    g = sp.csr_array((data, (rows, cols)), shape=(n, n))
    g.sum_duplicates()
    return sp.csr_array(g.astype(np.int32))


def _sink_side(graph: sp.csr_array, source: int, sink: int) -> np.ndarray:
    """(n,) bool: the nodes a least source-sink cut leaves with the sink (those the source
    cannot reach in the residual graph of a maximum flow)."""
    result = maximum_flow(graph, source, sink)
    residual = sp.csr_array(graph - result.flow)
    residual.data[residual.data < 0] = 0
    residual.eliminate_zeros()
    reach = np.zeros(graph.shape[0], bool)
    reach[breadth_first_order(residual, source, directed=True, return_predecessors=False)] = True
    return ~reach


def _weight(side: np.ndarray, edge: np.ndarray, z: np.ndarray) -> float:
    """The cut's weight ``z(delta(S))``."""
    return float(z[side[edge[:, 0]] != side[edge[:, 1]]].sum())


def tighten_tour(model: Model, station_var: np.ndarray, tour: TourBlock, unit: float,
                 time_limit_s: float, history: list
                 ) -> tuple[Model, int, float, np.ndarray | None]:
    """The model with the tour's connectivity cuts (:mod:`planner.program.joint_tour_cuts`),
    how many were added, the best bound the relaxation proved on the stops and the drive
    (``-inf`` when none solved; the model's costs times ``unit``), and the stations' ``w`` of
    its last solution ((s,) float, None when none solved).

    They are separated on the relaxation of the tour's own part of the program (the station
    and edge variables and the rows over them alone: coverage and the degrees; the cuts take
    the flow's place), round after round: first its linear relaxation until no cut is
    violated or its bound stalls (:data:`STALL_GAIN`), then with whole stations and edges
    (subtours cut from each solution) until the solution is one tour, the rounds or the time
    run out. That relaxation solves in a
    fraction of the whole program's time, its bound is one on the stops and the drive, and its
    cuts are valid for the whole program.

    Parameters
    ----------
    model : Model
        The joint program with its tour block.
    station_var : (s,) int
        Variable index of each candidate station's ``w``.
    tour : TourBlock
    unit : float
        The costs' unit (the model's costs are in it).
    time_limit_s : float
    history : list
        Each solve's record is appended (iteration 0).
    """
    t0 = time.perf_counter()
    keep = np.r_[station_var, tour.edge_var]
    sub, rows_kept = _restricted(model, keep)
    cover = np.array([model.row_kind[r].family == "cover" for r in rows_kept])
    rows = sub.A[np.flatnonzero(cover)]
    cover_sets = [rows.indices[rows.indptr[r]:rows.indptr[r + 1]]
                  for r in range(rows.shape[0])]  # station columns come first in ``sub``
    added, bound, w, bounds = [], -np.inf, None, []
    integral = False
    for _ in range(ROOT_ROUNDS):
        remaining = time_limit_s - (time.perf_counter() - t0)
        if remaining <= 0:
            break
        sol = logged_solve(sub, remaining, 0.0, history, 0, unit=unit)
        if np.isfinite(sol.dual_bound):
            bound = max(bound, sol.dual_bound)
        if sol.x is None:
            break
        w = sol.x[:station_var.size]
        x = np.zeros(model.n_vars)
        x[keep] = sol.x
        cuts = connectivity_cuts(tour, x, station_var, cover_sets, model.n_vars)
        if cuts is None:
            if integral:
                break  # one tour: the stops and drive are optimal
            # no cut left for the relaxation: go on with whole stops and edges (still a
            # relaxation of the tour, its bound valid; each solution's subtours are cut)
            integral = True
            sub = replace(sub, integrality=np.ones_like(sub.integrality))
            continue
        added.append(cuts)
        sub = sub.with_rows(cuts[0][:, keep], *cuts[1:])
        bounds.append(bound)
        if not integral and len(bounds) > STALL_ROUNDS and \
                bounds[-1] - bounds[-1 - STALL_ROUNDS] < STALL_GAIN * abs(bounds[-1]):
            # the relaxation's bound creeps: go on with whole stops and edges
            integral = True
            sub = replace(sub, integrality=np.ones_like(sub.integrality))
    for cuts in added:
        model = model.with_rows(*cuts)
    return model, sum(c[0].shape[0] for c in added), bound, w


def fewest_markers_bound(model: Model, station_var: np.ndarray) -> float:
    """A lower bound on the markers' cost of every layout, in the model's units.

    Every layout has a station, and a station's count row (family "count", switched on by its
    ``w``: ``a x >= L`` when on) alone costs at least its fractional knapsack: the sites of
    least cost per unit of ``a`` filled up to ``L``. The least of those over the stations that
    may be chosen bounds the markers of any layout (0 when a row has a negative entry).

    Parameters
    ----------
    model : Model
        The joint program (its marker costs on the first ``model.var_site.size`` variables).
    station_var : (s,) int

    Returns
    -------
    bound : float
    """
    nx = model.var_site.size
    column_station = np.full(model.n_vars, -1, np.int64)
    column_station[station_var] = np.arange(station_var.size)
    best = np.inf
    A = sp.csr_array(model.A)
    for r in (r for r, k in enumerate(model.row_kind) if k.family == "count"):
        s = model.row_kind[r].station
        if model.ub[station_var[s]] < 0.5:
            continue  # fixed off
        cols, vals = A.indices[A.indptr[r]:A.indptr[r + 1]], A.data[A.indptr[r]:A.indptr[r + 1]]
        on_x = cols < nx
        switch = cols == station_var[s]
        if np.any(vals[on_x] < 0) or not switch.any():
            return 0.0
        need = model.row_lb[r] - vals[switch][0]  # L = row_lb - coef_w
        a, c = vals[on_x], model.c[cols[on_x]]
        order = np.argsort(c / a, kind="stable")
        filled = np.cumsum(a[order])
        k = int(np.searchsorted(filled, need - 1e-9))
        if k >= a.size:
            continue  # this station cannot meet its count: no layout holds it
        before = filled[k - 1] if k else 0.0
        cost = float(c[order][:k].sum() + c[order][k] * (need - before) / a[order][k])
        best = min(best, cost)
    return 0.0 if not np.isfinite(best) else best


def _restricted(model: Model, keep: np.ndarray) -> tuple[Model, np.ndarray]:
    """The linear relaxation of ``model`` over the variables ``keep`` ((k,) int) and the rows
    that involve no other, with no marker variable; and those rows' indices."""
    outside = np.ones(model.n_vars, bool)
    outside[keep] = False
    A = sp.csr_array(model.A)
    rows = np.flatnonzero((abs(A) @ outside.astype(float)) == 0)
    A = sp.csr_array(A[rows][:, keep])
    return Model(c=model.c[keep], A=A, row_lb=model.row_lb[rows], row_ub=model.row_ub[rows],
                 lb=model.lb[keep], ub=model.ub[keep], integrality=np.zeros(keep.size, np.int64),
                 var_site=np.zeros(0, np.int64), site_var=np.full(model.site_var.size, -1),
                 row_kind=tuple(model.row_kind[r] for r in rows)), rows
