"""Local search on a passing network layout: drop the sites it does not need, then replace
pairs of sites by one.

The network greedy (:func:`planner.program.baselines.greedy_network`) adds sites until every
station passes and never looks back, so a site it took early may be redundant once later ones
are in. :func:`prune` removes such sites one at a time: the layout without site ``j`` has the
information ``J - U U^T`` (:meth:`~planner.accuracy.network.NetworkModel.site_factor`), whose
covariance is the Woodbury downdate ``C + C U (I - U^T C U)^-1 U^T C`` (a removal that leaves
``I - U^T C U`` singular would untie a station and is refused). A removal is kept when the
smaller layout still meets every rule the planner judges here: each station's count and
directions, each station's and selected marker's error within its allowance, and every local
pair. Sites are tried in order of how little their removal costs (the worst station's error over
its allowance without them, computed for every site first), and the covariance is recomputed
afresh every :data:`REFRESH` removals so round-off does not accumulate. Every removal is a
move to a subset, so the layout stays passing and only shrinks. :func:`swap_pairs` then tries
2-for-1 swaps: two neighbouring sites out, the open site that most reduces the worst station's
worst variance in (one marker fewer when the result meets every rule). :func:`local_search` runs
both; the planner re-checks its result with :func:`planner.accuracy.checks.evaluate_layout`
before using it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from planner.accuracy.local import local_accuracy
from planner.accuracy.local_markers import local_marker_accuracy
from planner.accuracy.network import NetworkCovariance, NetworkModel
from planner.problem.usability import PlanProblem, directions_ok

#: Removals between fresh covariances.
REFRESH = 25
#: A pivot of ``I - U^T C U`` below this marks the site as one that ties a station.
_TIE_PIVOT = 1e-9
#: 2-for-1 swaps (:func:`swap_pairs`): the cheapest sites tried, and neighbours of each.
SWAP_FIRST = 40
SWAP_NEIGHBOURS = 6


@dataclass(frozen=True)
class Pruning:
    """What :func:`prune` did.

    Attributes
    ----------
    selected : (n,) bool
        The pruned layout (a subset of the start).
    removed : tuple of int
        Sites removed, in order.
    swaps : int
        2-for-1 swaps made after the removals (:func:`swap_pairs`).
    start_markers : int
        Markers of the start layout.
    time_s : float
        Wall time, s.
    finished : bool
        Every site was tried (``False``: the deadline stopped it).
    """

    selected: np.ndarray
    removed: tuple[int, ...]
    swaps: int
    start_markers: int
    time_s: float
    finished: bool

    def record(self) -> dict:
        """JSON-ready summary (``plan.json``'s ``solver.local_search``)."""
        return {"start_markers": self.start_markers, "removed": len(self.removed),
                "swaps": self.swaps, "markers": int(self.selected.sum()),
                "time_s": round(self.time_s, 3), "finished": self.finished}


def prune(problem: PlanProblem, config, net: NetworkModel, selected: np.ndarray,
          deadline: float | None = None) -> Pruning:
    """Remove the sites a passing network layout does not need (see the module doc).

    Parameters
    ----------
    problem : PlanProblem
    config : planner.config.PlanConfig
        Network mode, not redundant (the loss of a marker is not judged here).
    net : NetworkModel
        ``problem``'s network model for ``config``.
    selected : (n,) bool
        A layout that passes.
    deadline : float, optional
        A :func:`time.perf_counter` value after which no further removal is tried.

    Returns
    -------
    Pruning
    """
    t0 = time.perf_counter()
    sel = np.asarray(selected, bool).copy()
    fixed = problem.site_mask(config.existing, "existing") | problem.site_existing
    judge = _Judge(problem, config, net)
    cov = net.covariance(net.information(sel)).full
    removed: list[int] = []
    candidates = np.flatnonzero(sel & ~fixed)
    cost = _costs(judge, cov, candidates, deadline)
    finished = cost is not None
    for j in candidates[np.argsort(cost, kind="stable")] if finished else ():
        if deadline is not None and time.perf_counter() > deadline:
            finished = False
            break
        smaller = sel.copy()
        smaller[j] = False
        after = judge.passing(smaller, cov, int(j))
        if after is None:
            continue
        sel, cov = smaller, after
        removed.append(int(j))
        if len(removed) % REFRESH == 0:
            cov = net.covariance(net.information(sel)).full
    return Pruning(sel, tuple(removed), 0, int(np.sum(selected)), time.perf_counter() - t0,
                   finished)


def local_search(problem: PlanProblem, config, net: NetworkModel, selected: np.ndarray,
                 deadline: float | None = None) -> Pruning:
    """:func:`prune`, then rounds of :func:`swap_pairs` on what is left until a round swaps
    nothing (arguments as :func:`prune`); ``finished`` is ``False`` when the deadline stopped
    it first."""
    t0 = time.perf_counter()
    pruned = prune(problem, config, net, selected, deadline)
    sel, swaps, found = pruned.selected, 0, pruned.finished
    while found and (deadline is None or time.perf_counter() <= deadline):
        sel, found = swap_pairs(problem, config, net, sel, deadline)
        swaps += found
    finished = pruned.finished and (deadline is None or time.perf_counter() <= deadline)
    return Pruning(sel, pruned.removed, swaps, pruned.start_markers, time.perf_counter() - t0,
                   finished)


def swap_pairs(problem: PlanProblem, config, net: NetworkModel, selected: np.ndarray,
               deadline: float | None = None, first: int = SWAP_FIRST,
               neighbours: int = SWAP_NEIGHBOURS) -> tuple[np.ndarray, int]:
    """Replace two sites of a passing layout by one: 2-for-1 swaps.

    For each of the ``first`` sites whose removal costs least (as in :func:`prune`), and each
    of its ``neighbours`` cheapest selected neighbours (sites a station shares with it), both
    are removed and the one open site with the largest first-order gain at the worst station's
    worst direction (:meth:`~planner.accuracy.network.NetworkModel.worst_direction_gain`) is
    added; the swap is kept when the layout meets every rule. Covariances follow by Woodbury
    updates.

    Parameters
    ----------
    problem, config, net, deadline
        As :func:`prune`.
    selected : (n,) bool
        A passing layout.
    first, neighbours : int
        How many sites, and neighbours of each, to try.

    Returns
    -------
    selected : (n,) bool
        The layout after the swaps.
    swaps : int
        Swaps made (each one marker fewer).
    """
    sel = np.asarray(selected, bool).copy()
    fixed = problem.site_mask(config.existing, "existing") | problem.site_existing
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    judge = _Judge(problem, config, net)
    cov = net.covariance(net.information(sel)).full
    use = sp.csr_array((np.ones(net.pair_site.size), (net.pair_station, net.pair_site)),
                       shape=(problem.n_stations, problem.n_sites))
    candidates = np.flatnonzero(sel & ~fixed & net.tying)
    cost = _costs(judge, cov, candidates, deadline)
    if cost is None:
        return sel, 0
    rank = np.full(problem.n_sites, np.inf)
    rank[candidates] = cost
    swaps = 0
    for a in candidates[np.argsort(cost, kind="stable")][:first]:
        if deadline is not None and time.perf_counter() > deadline:
            break
        if not sel[a]:
            continue
        near = np.flatnonzero((use[:, [a]].T @ use).toarray().ravel() > 0)
        near = near[sel[near] & ~fixed[near] & (near != a)]
        for b in near[np.argsort(rank[near], kind="stable")][:neighbours]:
            done = _swap(problem, config, net, judge, sel, cov, int(a), int(b),
                         net.tying & ~forbidden)
            if done is not None:
                sel, cov = done
                swaps += 1
                break
    return sel, swaps


def _costs(judge: _Judge, cov: np.ndarray, sites: np.ndarray,
           deadline: float | None) -> np.ndarray | None:
    """(k,) :meth:`_Judge.cost` of removing each of ``sites``; ``None`` when ``deadline``
    passes first."""
    out = np.empty(sites.size)
    for i, j in enumerate(sites):
        if deadline is not None and time.perf_counter() > deadline:
            return None
        out[i] = judge.cost(cov, int(j))
    return out


def _swap(problem, config, net, judge, sel, cov, a: int, b: int, open_site: np.ndarray):
    """``(layout, covariance)`` with ``a`` and ``b`` replaced by the best single site, when
    that layout meets every rule; else ``None``."""
    cov_ab = judge.without(cov, a)
    cov_ab = None if cov_ab is None else judge.without(cov_ab, b)
    if cov_ab is None:
        return None
    smaller = sel.copy()
    smaller[[a, b]] = False
    ab = NetworkCovariance(cov_ab, judge.determined)
    err = net.station_errors_from(ab) / net.allowed_station_m
    gain = net.worst_direction_gain(ab, int(np.argmax(err)))
    gain = np.where(open_site & ~sel, gain, 0.0)
    c = int(np.argmax(gain))
    if gain[c] <= 0:
        return None
    smaller[c] = True
    if not directions_ok(problem, smaller, config).all():
        return None
    cov_c = judge.without(cov_ab, c, sign=+1.0)
    return None if cov_c is None or not judge.meets(smaller, cov_c) else (smaller, cov_c)


class _Judge:
    """The rules a removal must keep, on a layout and its covariance."""

    def __init__(self, problem: PlanProblem, config, net: NetworkModel) -> None:
        self.problem, self.config, self.net = problem, config, net
        self.local = local_accuracy(net, config)
        self.local_markers = local_marker_accuracy(net, config)
        self.determined = np.ones(problem.n_stations, bool)

    def without(self, cov: np.ndarray, site: int, sign: float = -1.0) -> np.ndarray | None:
        """(6 s, 6 s) covariance of the layout ``cov`` belongs to without ``site`` (``None``:
        the removal unties a station); with ``sign=+1`` with it added instead."""
        index, u = self.net.site_factor(site)
        if u.shape[1] == 0:
            return cov  # a site one station uses adds no information
        cu = cov[:, index] @ u  # rows and columns of fixed parameters are zero
        inner = np.eye(u.shape[1]) + sign * (u.T @ cu[index])
        try:
            lower = np.linalg.cholesky(inner)
        except np.linalg.LinAlgError:
            return None
        if np.min(np.diag(lower)) ** 2 < _TIE_PIVOT:
            return None
        z = scipy.linalg.solve_triangular(lower, cu.T, lower=True)
        return cov - sign * (z.T @ z)

    def cost(self, cov: np.ndarray, site: int) -> float:
        """The worst station's error over its allowance once ``site`` is removed (``inf``
        when the removal unties a station)."""
        after = self.without(cov, site)
        if after is None:
            return np.inf
        err = self.net.station_errors_from(NetworkCovariance(after, self.determined))
        return float(np.max(err / self.net.allowed_station_m))

    def passing(self, smaller: np.ndarray, cov: np.ndarray, site: int) -> np.ndarray | None:
        """The covariance of ``smaller`` (the layout of ``cov`` without ``site``) when it meets
        every rule, else ``None``."""
        if not directions_ok(self.problem, smaller, self.config).all():
            return None
        after = self.without(cov, site)
        return None if after is None or not self.meets(smaller, after) else after

    def meets(self, sel: np.ndarray, cov: np.ndarray) -> bool:
        """Whether the layout ``sel`` with covariance ``cov`` meets the accuracy rules (its
        stations, its markers, the local pairs of stations and of markers)."""
        full = NetworkCovariance(cov, self.determined)
        net = self.net
        if net.stations_failing(net.station_errors_from(full)).any():
            return False
        markers = np.flatnonzero(sel)
        if np.any(net.marker_errors(full, markers) > net.allowed_site_m[markers]):
            return False
        if self.local_markers is not None and self.local_markers.failing(full, sel)[1].size:
            return False
        return self.local is None or not self.local.failing(full).size
