"""Local search on a passing network layout: drop the sites it does not need.

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
move to a subset, so the layout stays passing and only shrinks; the planner re-checks the result
with :func:`planner.accuracy.checks.evaluate_layout` before using it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from planner.accuracy.local import local_accuracy
from planner.accuracy.network import NetworkCovariance, NetworkModel
from planner.problem.usability import PlanProblem, directions_ok

#: Removals between fresh covariances.
REFRESH = 25
#: A pivot of ``I - U^T C U`` below this marks the site as one that ties a station.
_TIE_PIVOT = 1e-9


@dataclass(frozen=True)
class Pruning:
    """What :func:`prune` did.

    Attributes
    ----------
    selected : (n,) bool
        The pruned layout (a subset of the start).
    removed : tuple of int
        Sites removed, in order.
    start_markers : int
        Markers of the start layout.
    time_s : float
        Wall time, s.
    finished : bool
        Every site was tried (``False``: the deadline stopped it).
    """

    selected: np.ndarray
    removed: tuple[int, ...]
    start_markers: int
    time_s: float
    finished: bool

    def record(self) -> dict:
        """JSON-ready summary (``plan.json``'s ``solver.local_search``)."""
        return {"start_markers": self.start_markers, "removed": len(self.removed),
                "markers": int(self.selected.sum()), "time_s": round(self.time_s, 3),
                "finished": self.finished}


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
    order = np.argsort([judge.cost(sel, cov, int(j)) for j in candidates], kind="stable")
    finished = True
    for j in candidates[order]:
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
    return Pruning(sel, tuple(removed), int(np.sum(selected)), time.perf_counter() - t0,
                   finished)


class _Judge:
    """The rules a removal must keep, on a layout and its covariance."""

    def __init__(self, problem: PlanProblem, config, net: NetworkModel) -> None:
        self.problem, self.config, self.net = problem, config, net
        self.local = local_accuracy(net, config)
        self.determined = np.ones(problem.n_stations, bool)

    def without(self, cov: np.ndarray, site: int) -> np.ndarray | None:
        """(6 s, 6 s) covariance of the layout ``cov`` belongs to without ``site`` (``None``:
        the removal unties a station)."""
        index, u = self.net.site_factor(site)
        if u.shape[1] == 0:
            return cov  # a site one station uses adds no information
        cu = cov[:, index] @ u  # rows and columns of fixed parameters are zero
        inner = np.eye(u.shape[1]) - u.T @ cu[index]
        try:
            lower = np.linalg.cholesky(inner)
        except np.linalg.LinAlgError:
            return None
        if np.min(np.diag(lower)) ** 2 < _TIE_PIVOT:
            return None
        z = scipy.linalg.solve_triangular(lower, cu.T, lower=True)
        return cov + z.T @ z

    def cost(self, sel: np.ndarray, cov: np.ndarray, site: int) -> float:
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
        if after is None:
            return None
        full = NetworkCovariance(after, self.determined)
        net = self.net
        if net.stations_failing(net.station_errors_from(full)).any():
            return None
        markers = np.flatnonzero(smaller)
        if np.any(net.marker_errors(full, markers) > net.allowed_site_m[markers]):
            return None
        if self.local is not None and self.local.failing(full).size:
            return None
        return after
