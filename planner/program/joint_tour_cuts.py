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
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, maximum_flow

from planner.program.joint_tour import TourBlock
from planner.program.model import RowKind

#: Edge values are scaled to integer capacities by this factor.
_SCALE = 10_000
#: A cut is added when it is lighter than its right-hand side by more than this.
_TOLERANCE = 1e-3


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
