"""The traverse inside the joint program: a closed tour from the route start through the chosen
stations and back, its drive priced in the objective.

Nodes are the route start (node 0) and the candidate stations (node ``1 + s``). On an
undirected edge set (:func:`tour_graph`) the tour is a degree-2 subgraph made connected by a
single-commodity flow (Gavish and Graves 1978):

- an integer ``z_e`` per edge: 0 or 1, and up to 2 on an edge from the route start (a tour of
  one station drives out and back along it);
- degree: ``sum_{e at s} z_e = 2 w_s`` at every candidate station, ``= 2`` at the route start;
- flow: the route start sends one unit to every chosen station: a continuous ``f`` per arc
  (both directions of an edge), ``sum_in f - sum_out f = w_s`` at every station, and
  ``f_ab + f_ba <= M z_e`` with ``M`` the most stations a layout can have
  (:func:`tour_block`'s ``max_stations``). A subtour away from the route start would receive
  no flow, so every solution is one closed tour;
- cost: each edge's drive, ``drive cost per metre x length``, in whole units of the program's
  cost (rounded to the nearest, so a proven optimum stays a whole number of units).

With every edge (:data:`COMPLETE_MAX_NODES`) the program's bound is a bound on every tour over
the ground-path lengths; above that each station keeps its :data:`NEIGHBOURS` nearest
neighbours by drive and its edge to the route start, and the bound holds for tours over those
edges only (the result says which).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from markerplan.errors import ConfigError
from planner.program.model import RowKind

#: Largest node count (route start included) for which the tour may use every edge.
COMPLETE_MAX_NODES = 320
#: Above it, the nearest neighbours (by drive length) each station keeps edges to.
NEIGHBOURS = 10


@dataclass(frozen=True)
class TourGraph:
    """The edges the joint program's tour may use.

    Attributes
    ----------
    edge : (e, 2) int
        Node pairs ``a < b``; node 0 is the route start, node ``1 + s`` candidate station ``s``.
    length_m : (e,) float
        Drive length of each edge, m.
    complete : bool
        Whether every pair of allowed nodes is an edge.
    """

    edge: np.ndarray
    length_m: np.ndarray
    complete: bool


def tour_graph(drive_m: np.ndarray, allowed: np.ndarray, extra_edges=()) -> TourGraph:
    """Edges among the route start and the allowed candidate stations.

    Parameters
    ----------
    drive_m : (s + 1, s + 1) float
        Ground-path drive lengths, node 0 the route start, m.
    allowed : (s,) bool
        Candidate stations the tour may visit.
    extra_edges : iterable of (int, int)
        Node pairs always kept (e.g. a baseline's tour), when both nodes are allowed.

    Returns
    -------
    graph : TourGraph

    Examples
    --------
    >>> d = np.array([[0, 1, 2, 3], [1, 0, 1, 2], [2, 1, 0, 1], [3, 2, 1, 0]], float)
    >>> tour_graph(d, np.array([True, False, True])).edge.tolist()
    [[0, 1], [0, 3], [1, 3]]
    """
    d = np.asarray(drive_m, float)
    nodes = np.r_[0, 1 + np.flatnonzero(allowed)]
    if d.shape != (len(allowed) + 1,) * 2:
        raise ConfigError(f"`drive_m` must be ({len(allowed) + 1}, {len(allowed) + 1}), got "
                          f"{d.shape}")
    complete = nodes.size <= COMPLETE_MAX_NODES
    if complete:
        a, b = np.triu_indices(nodes.size, 1)
        pairs = np.c_[nodes[a], nodes[b]]
    else:
        sub = d[np.ix_(nodes[1:], nodes[1:])]
        np.fill_diagonal(sub, np.inf)
        near = np.argsort(sub, axis=1, kind="stable")[:, :NEIGHBOURS]
        pairs = np.c_[np.repeat(nodes[1:], NEIGHBOURS), nodes[1:][near.ravel()]]
        keep = np.isin(np.asarray(list(extra_edges), np.int64).reshape(-1, 2), nodes).all(1)
        pairs = np.vstack([pairs, np.c_[np.zeros(nodes.size - 1, np.int64), nodes[1:]],
                           np.asarray(list(extra_edges), np.int64).reshape(-1, 2)[keep]])
        pairs = np.unique(np.sort(pairs, axis=1), axis=0)
        pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return TourGraph(edge=pairs.astype(np.int64), length_m=d[pairs[:, 0], pairs[:, 1]],
                     complete=bool(complete))


@dataclass(frozen=True)
class TourBlock:
    """The tour's columns and rows, to append to the joint program.

    Attributes
    ----------
    graph : TourGraph
    edge_var : (e,) int
        Variable index of each edge's ``z``.
    flow_var : (e, 2) int
        Variable index of the flow along each edge, from its first node and from its second.
    c, lb, ub : (q,) float
        Cost (program units), bounds of the ``q = 3 e`` new columns (edges, then flows).
    integrality : (q,) int
    A : (r, v) sparse
        The degree, flow and capacity rows over all ``v`` variables.
    row_lb, row_ub : (r,) float
    kinds : tuple of RowKind, (r,)
    """

    graph: TourGraph
    edge_var: np.ndarray
    flow_var: np.ndarray
    c: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    integrality: np.ndarray
    A: sp.csr_array
    row_lb: np.ndarray
    row_ub: np.ndarray
    kinds: tuple


def leg_cost_units(length_m, cost_per_m: float, unit: float) -> np.ndarray:
    """The program's cost of driving ``length_m``: whole units, rounded to the nearest.

    >>> leg_cost_units(np.array([10.0, 14.0]), 20.0, 60.0).tolist()
    [3.0, 5.0]
    """
    return np.rint(np.asarray(length_m, float) * cost_per_m / unit)


def tour_block(graph: TourGraph, station_var: np.ndarray, first_var: int, cost_per_m: float,
               unit: float, max_stations: int) -> TourBlock:
    """The tour's variables and rows (see the module docstring).

    Parameters
    ----------
    graph : TourGraph
    station_var : (s,) int
        Variable index of each candidate station's ``w``.
    first_var : int
        Index of the first new column (the model's variable count so far).
    cost_per_m : float
        Cost of one metre of drive, in the costs' own unit (e.g. s/m).
    unit : float
        The program's cost unit, in that unit.
    max_stations : int
        ``M``: no layout considered has more stations.

    Returns
    -------
    block : TourBlock
    """
    e = len(graph.edge)
    a, b = graph.edge.T
    edge_var = first_var + np.arange(e)
    flow_var = first_var + e + np.arange(2 * e).reshape(e, 2)
    n_vars = first_var + 3 * e
    ns = station_var.size
    # degree rows: node 0 (route start) then one per station
    deg = sp.csr_array((np.ones(2 * e), (np.r_[a, b], np.r_[edge_var, edge_var])),
                       shape=(ns + 1, n_vars))
    deg = deg + sp.csr_array((np.full(ns, -2.0), (1 + np.arange(ns), station_var)),
                             shape=(ns + 1, n_vars))
    # flow rows, one per station: in - out - w = 0 (arc a->b is flow_var[:, 0])
    into = np.r_[b, a]
    out = np.r_[a, b]
    arcs = np.r_[flow_var[:, 0], flow_var[:, 1]]
    on = np.r_[into, out] > 0
    flow = sp.csr_array((np.r_[np.ones(2 * e), -np.ones(2 * e)][on],
                         (np.r_[into, out][on] - 1, np.r_[arcs, arcs][on])), shape=(ns, n_vars))
    flow = flow + sp.csr_array((-np.ones(ns), (np.arange(ns), station_var)), shape=(ns, n_vars))
    # capacity: f_ab + f_ba - M z_e <= 0
    q = np.arange(e)
    cap = sp.csr_array((np.r_[np.ones(2 * e), np.full(e, -float(max_stations))],
                        (np.r_[q, q, q], np.r_[flow_var[:, 0], flow_var[:, 1], edge_var])),
                       shape=(e, n_vars))
    ub_edge = np.where(a == 0, 2.0, 1.0)
    flow_ub = np.full((e, 2), float(max_stations))
    flow_ub[:, 1][a == 0] = 0.0  # nothing flows back into the route start
    return TourBlock(
        graph=graph, edge_var=edge_var, flow_var=flow_var,
        c=np.r_[leg_cost_units(graph.length_m, cost_per_m, unit), np.zeros(2 * e)],
        lb=np.zeros(3 * e), ub=np.r_[ub_edge, flow_ub.ravel()],
        integrality=np.r_[np.ones(e, np.int64), np.zeros(2 * e, np.int64)],
        A=sp.csr_array(sp.vstack([deg, flow, cap])),
        row_lb=np.r_[2.0, np.zeros(ns), np.zeros(ns), np.full(e, -np.inf)],
        row_ub=np.r_[2.0, np.zeros(ns), np.zeros(ns), np.zeros(e)],
        kinds=(RowKind("tour-degree"),) + tuple(RowKind("tour-degree", s) for s in range(ns))
        + tuple(RowKind("tour-flow", s) for s in range(ns)) + (RowKind("tour-capacity"),) * e)


def tour_order(block: TourBlock, x: np.ndarray) -> np.ndarray:
    """The candidate stations of a solution's tour in driving order from the route start.

    Parameters
    ----------
    block : TourBlock
    x : (v,) float
        A solution of the program holding ``block``.

    Returns
    -------
    order : (k,) int
        Candidate-station indices (the direction taken is the one with the lower first index).
    """
    z = np.rint(x[block.edge_var]).astype(np.int64)
    used = block.graph.edge[z > 0]
    if not len(used):
        return np.zeros(0, np.int64)
    neighbours: dict[int, list[int]] = {}
    for (a, b), n in zip(used, z[z > 0], strict=True):
        for _ in range(n):
            neighbours.setdefault(int(a), []).append(int(b))
            neighbours.setdefault(int(b), []).append(int(a))
    order, prev, node = [], 0, min(neighbours[0])
    while node != 0:
        order.append(node)
        nxt = [n for n in neighbours[node] if n != prev] or [prev]
        prev, node = node, nxt[0]
    return np.array(order, np.int64) - 1


def tour_legs(order: np.ndarray) -> np.ndarray:
    """(k + 1, 2) int: the node pairs of the closed tour from the route start (node 0) through
    the candidate stations ``order`` ((k,) int, candidate indices) and back.

    >>> tour_legs(np.array([4, 2])).tolist()
    [[0, 5], [5, 3], [3, 0]]
    """
    nodes = np.r_[0, np.asarray(order, np.int64) + 1, 0]
    return np.c_[nodes[:-1], nodes[1:]]


def leg_lengths_m(drive_m: np.ndarray, order: np.ndarray) -> np.ndarray:
    """(k + 1,) float: the drive length of each leg of the closed tour through ``order``
    (:func:`tour_legs`) over ``drive_m`` ((s + 1, s + 1), route start 0), m."""
    legs = tour_legs(order)
    return np.asarray(drive_m, float)[legs[:, 0], legs[:, 1]]


def tour_start(block: TourBlock, order: np.ndarray) -> np.ndarray | None:
    """The tour's values (edges then flows, the block's columns) for stations driven in
    ``order`` (candidate indices), or None when a leg is not an edge of the graph."""
    index = {(int(a), int(b)): k for k, (a, b) in enumerate(block.graph.edge)}
    e = len(block.graph.edge)
    z, f = np.zeros(e), np.zeros((e, 2))
    remaining = len(order)
    for a, b in tour_legs(order):
        k = index.get((min(a, b), max(a, b)))
        if k is None:
            return None
        z[k] += 1
        f[k, 0 if a < b else 1] += remaining
        remaining -= 1
    return np.r_[z, f.ravel()]


def max_stations(incumbent_cost: float | None, station_cost: float, n_eligible: int) -> int:
    """``M``: the most stations of any layout that costs no more than the incumbent (every
    station costs ``station_cost``), or every eligible station without one.

    >>> max_stations(1000.0, 300.0, 50), max_stations(None, 300.0, 50)
    (3, 50)
    """
    if incumbent_cost is None or station_cost <= 0:
        return int(n_eligible)
    return int(min(n_eligible, math.floor(incumbent_cost / station_cost + 1e-9)))
