"""Shortest drives over trafficable ground between points.

The trafficable nodes of a :class:`~planner.traverse.trafficability.TrafficMap` form an
8-connected graph: a node links to its trafficable neighbours across a side (length
``grid_m``) and across a corner (``sqrt(2) grid_m``) when both nodes beside that diagonal are
trafficable too (no corner cutting past a hazard); with a DEM, each edge is the 3-D length
``sqrt(d^2 + dz^2)`` between the nodes' ground heights. Dijkstra's algorithm
(:func:`scipy.sparse.csgraph.dijkstra`) gives the drive length between every pair of points
and each leg's polyline. A point is joined to its nearest node by a straight step (at most half
a node diagonal), counted in the length. Octile paths are at most 8 % longer than the straight
line in open ground (none at multiples of 45 deg).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from markerplan.errors import DataError
from planner.traverse.trafficability import LIMITS

__all__ = ["GroundGraph", "GroundPaths", "ground_graph", "ground_paths", "reachable_nodes"]

#: Bytes of Dijkstra distance rows held at once (sources are taken in chunks of this size).
_ROW_BYTES = 64 * 2 ** 20


@dataclass(frozen=True)
class GroundPaths:
    """Drive lengths between points over trafficable ground, site frame.

    Attributes
    ----------
    ids : tuple of str
        The points' ids.
    xy : (k, 2) float
        The points, metres.
    distance_m : (k, k) float
        Drive length from point ``i`` to point ``j`` (symmetric, zero diagonal), metres.
    """

    ids: tuple[str, ...]
    xy: np.ndarray
    distance_m: np.ndarray
    _graph: csr_matrix
    _node: np.ndarray  # (k,) graph node of each point
    _node_xy: np.ndarray  # (N, 2) site coordinates of the graph's nodes
    _step_m: np.ndarray  # (k,) length of each point's step onto its node

    def polyline(self, i: int, j: int) -> np.ndarray:
        """(p, 2) the drive from point ``i`` to point ``j``: the point, the nodes of its
        shortest path, the other point (repeated vertices dropped), site frame, metres."""
        a, b = int(self._node[i]), int(self._node[j])
        limit = self.distance_m[i, j] - self._step_m[i] - self._step_m[j]
        _, pred = dijkstra(self._graph, indices=a, return_predecessors=True,
                           limit=limit * (1 + 1e-9) + 1e-9)
        path = [b]
        while path[-1] != a:
            path.append(int(pred[path[-1]]))
        line = np.vstack([self.xy[i], self._node_xy[path[::-1]], self.xy[j]])
        return line[np.r_[True, np.any(np.diff(line, axis=0) != 0, axis=1)]]


@dataclass(frozen=True)
class GroundGraph:
    """The trafficable nodes' graph of a trafficability map (build it once with
    :func:`ground_graph` and hand it to every :func:`ground_paths` on that map).

    Attributes
    ----------
    graph : (N, N) scipy.sparse.csr_matrix
        Edge lengths, m.
    index : (nr * nc,) int64
        Graph node of each grid node, -1 where not trafficable.
    node_xy : (N, 2) float
        Site coordinates of the graph's nodes, m.
    with_heights : bool
        Whether the edge lengths include the height change (built with a DEM).
    """

    graph: csr_matrix
    index: np.ndarray
    node_xy: np.ndarray
    with_heights: bool


def ground_graph(traffic_map, dem=None) -> GroundGraph:
    """The trafficable nodes' graph (see the module docstring); with ``dem`` the edges are
    3-D lengths."""
    return GroundGraph(*_graph(traffic_map, dem), with_heights=dem is not None)


def _graph(traffic_map, dem=None) -> tuple[csr_matrix, np.ndarray, np.ndarray]:
    """The trafficable nodes' graph: ``(graph (N, N) csr, index (nr * nc,) int64 of each grid
    node in the graph or -1, node_xy (N, 2))``."""
    t = traffic_map.trafficable
    nr, nc = t.shape
    index = np.full(nr * nc, -1, np.int64)
    index[t.ravel()] = np.arange(int(t.sum()))
    node_xy = traffic_map.node_xy()[t.ravel()]
    z = None if dem is None else dem.height_at(node_xy)
    rows, cols, lengths = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        lo, hi = max(0, -dc), nc - max(0, dc)  # columns of the edges' first nodes
        ok = t[:nr - dr, lo:hi] & t[dr:, lo + dc:hi + dc]
        if dr and dc:  # no corner cutting: both nodes beside the diagonal trafficable
            ok &= t[dr:, lo:hi] & t[:nr - dr, lo + dc:hi + dc]
        r, c = np.nonzero(ok)
        c = c + lo
        u = index[r * nc + c]
        v = index[(r + dr) * nc + c + dc]
        step = traffic_map.grid_m * np.hypot(dr, dc)
        length = np.full(len(u), step) if z is None else np.hypot(step, z[v] - z[u])
        rows += [u, v]
        cols += [v, u]
        lengths += [length, length]
    n = len(node_xy)
    graph = csr_matrix((np.concatenate(lengths), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(n, n))
    return graph, index, node_xy


def reachable_nodes(traffic_map, start_xy) -> np.ndarray:
    """(nr, nc) bool: the trafficable nodes the rover can drive to from ``start_xy`` (its
    nearest node's connected patch; all False when that node is not trafficable)."""
    graph, index, _ = _graph(traffic_map)
    flat, on_grid = traffic_map.node_of(np.asarray(start_xy, float).reshape(1, 2))
    out = np.zeros(traffic_map.shape, bool)
    start = index[flat[0]]
    if not on_grid[0] or start < 0:
        return out
    _, label = connected_components(graph, directed=False)
    out.ravel()[index >= 0] = label == label[start]
    return out


def ground_paths(traffic_map, xy, ids, dem=None, label: str = "point",
                 graph: GroundGraph | None = None) -> GroundPaths:
    """Shortest drives between every pair of points over trafficable ground.

    Parameters
    ----------
    traffic_map : planner.traverse.trafficability.TrafficMap
    xy : (k, 2) float
        Points (the route start and the stations), site frame, metres.
    ids : sequence of str
        Their ids, for messages.
    dem : visibility.dem.DEM, optional
        With it, edge lengths include the height change between nodes; without, horizontal.
    label : str
        What the points are, for messages (``"station"``).
    graph : GroundGraph, optional
        ``traffic_map``'s graph, built with the same ``dem`` (default built here).

    Returns
    -------
    paths : GroundPaths

    Raises
    ------
    DataError
        A point whose nearest node is off the map or not trafficable (naming the point, its
        position and the reason), or one on a trafficable patch cut off from the first point.

    Examples
    --------
    >>> from planner.traverse.trafficability import TrafficMap, TrafficSettings
    >>> ok = np.ones((3, 3), bool); ok[1, 1] = False
    >>> tm = TrafficMap(ok, (~ok).astype(np.uint8), (0.0, 0.0), 1.0, TrafficSettings())
    >>> p = ground_paths(tm, np.array([[0.0, 1.0], [2.0, 1.0]]), ["A", "B"])
    >>> float(p.distance_m[0, 1]), p.polyline(0, 1).tolist()
    (4.0, [[0.0, 1.0], [0.0, 2.0], [1.0, 2.0], [2.0, 2.0], [2.0, 1.0]])
    """
    xy = np.atleast_2d(np.asarray(xy, dtype=float))
    ids = tuple(str(i) for i in ids)
    if xy.ndim != 2 or xy.shape[1] != 2 or len(ids) != len(xy):
        raise DataError(f"`xy` must have shape (k, 2) with one id per point, got {xy.shape} "
                        f"and {len(ids)} ids")
    if graph is None:
        graph = ground_graph(traffic_map, dem)
    elif graph.with_heights != (dem is not None):
        raise DataError("`graph` was built with" + ("" if graph.with_heights else "out")
                        + " a DEM, but the drive lengths are asked for the other way")
    graph, index, node_xy = graph.graph, graph.index, graph.node_xy
    flat, on_grid = traffic_map.node_of(xy)
    node = index[flat]
    why = traffic_map.why_not(xy)
    off = np.flatnonzero(~on_grid | (node < 0))
    if len(off):
        k = off[0]
        raise DataError(f"{label} {ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m is not on "
                        f"trafficable ground ({why[k]}); move it onto trafficable ground")
    _, comp = connected_components(graph, directed=False)
    apart = np.flatnonzero(comp[node] != comp[node[0]])
    if len(apart):
        k = apart[0]
        raise DataError(f"{label} {ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m stands on a "
                        f"trafficable patch cut off from {ids[0]} (hazards all around it); "
                        f"drop it or relax {LIMITS}")
    step = np.hypot(*(xy - node_xy[node]).T)
    dist = np.empty((len(xy), len(xy)))
    chunk = max(1, _ROW_BYTES // (8 * max(len(node_xy), 1)))
    for s in range(0, len(xy), chunk):
        rows = dijkstra(graph, indices=node[s:s + chunk])
        dist[s:s + chunk] = rows[:, node]
    dist += step[:, None] + step[None, :]
    np.fill_diagonal(dist, 0.0)
    dist = np.minimum(dist, dist.T)  # exactly symmetric (sums along a path differ in rounding)
    return GroundPaths(ids=ids, xy=xy, distance_m=dist, _graph=graph, _node=node,
                       _node_xy=node_xy, _step_m=step)
