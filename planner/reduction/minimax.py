"""The integer program behind the trade-off curve: "is there a ``k``-subset with every station
<= ``eps``?", answered exactly.

Known control (:class:`MinimaxModel`): the planner's integer program
(:func:`planner.program.model.build_model`: count and sector rows, the necessary information
rows, lazily added accuracy cuts) with the requirement set to ``eps`` and a row
``sum_j x_j = k``. One model is built and re-used: each query only changes row bounds —

- the budget row: ``k <= sum_j x_j <= k`` (padding never hurts, so "= k" equals "<= k");
- the information rows: ``sum_j (3 / sigma_sj^2) x_j >= chi2_3(0.95) / eps^2``;
- each accuracy cut says "station ``s`` fails on the grown set ``T'``", i.e. it is valid for every
  ``eps`` below the error of ``T'`` (its *threshold*): it is switched on (lower bound 1) for such
  ``eps`` and off (lower bound 0, always satisfied) otherwise; cuts accumulate across queries.

Network mode (:class:`NetworkMinimax`): the errors are the network's relative to the datum
(:mod:`planner.accuracy.network`) and each question is the planner's own network program
(:func:`planner.program.loop.plan_sites`, requirement ``eps``, budget row ``= k``).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from markerplan.errors import InfeasiblePlanError, PlanTimeLimitError
from planner.accuracy.checks import LayoutCheck, evaluate_layout, station_infos
from planner.accuracy.network import network_model
from planner.accuracy.requirement import NetworkRequirement
from planner.problem.usability import PlanProblem
from planner.program import (
    Model,
    RowKind,
    accuracy_cuts,
    build_model,
    plan_sites,
    solve,
    with_tightening_rows,
)
from planner.reduction.losses import check_worst, local_ok


class MinimaxModel:
    """One integer program answering "is there a k-subset with every station <= eps?"
    (known-control mode)."""

    #: The worst error never grows when a marker is added (so W*(k+1) bounds W*(k) below).
    monotone = True
    #: Bisect on eps (cheap queries); else descend from the incumbent, each query asking for
    #: a strictly better subset, until one is infeasible.
    bisect = True

    def __init__(self, problem: PlanProblem, config, deadline: float) -> None:
        self.problem = problem
        self.config = config
        self.deadline = deadline
        self.infos = station_infos(problem, config)
        self.net = None
        base = build_model(problem, config)
        nx = base.var_site.size
        self.nx = nx
        self.model: Model = base.with_rows(base.site_row(base.var_site), [0.0], [float(nx)],
                                           [RowKind("budget")])
        self.budget_row = self.model.A.shape[0] - 1
        self.info_rows = np.array([i for i, k in enumerate(self.model.row_kind)
                                   if k.family == "info"], dtype=np.int64)
        self.cut_rows: list[int] = []
        self.cut_threshold: list[float] = []
        self.solve_time_s = 0.0
        self.solve_cap_s = np.inf  # longest single solve, s

    @property
    def n_cuts(self) -> int:
        """Accuracy cuts generated so far."""
        return len(self.cut_rows)

    def check(self, selected: np.ndarray) -> LayoutCheck:
        """Count, directions and predicted errors of a subset."""
        return evaluate_layout(self.problem, selected, self.config, self.infos, net=self.net)

    def worst(self, selected: np.ndarray) -> float:
        """Worst predicted error of a subset, m (:func:`~planner.reduction.losses.check_worst`)."""
        return float(max(info.error(info.sites[selected[info.sites]]) for info in self.infos))

    def floor(self, allowed: np.ndarray) -> float:
        """No subset of ``allowed`` has a worst error below this, m."""
        return self.worst(allowed)

    def _bounded(self, k: int | None, eps: float, count_objective: bool) -> Model:
        lb, ub = self.model.row_lb.copy(), self.model.row_ub.copy()
        if k is not None:
            lb[self.budget_row] = ub[self.budget_row] = float(min(k, self.nx))
        lb[self.info_rows] = (self.config.requirement_m / eps) ** 2 if np.isfinite(eps) else 0.0
        if self.cut_rows:
            lb[self.cut_rows] = np.where(np.asarray(self.cut_threshold) > eps, 1.0, 0.0)
        c = np.zeros(self.model.n_vars)
        if count_objective:
            c[: self.nx] = 1.0
        return replace(self.model, row_lb=lb, row_ub=ub, c=c)

    def _solve(self, model: Model):
        remaining = min(self.deadline - time.perf_counter(), self.solve_cap_s)
        if remaining <= 0:
            return None
        sol = solve(model, remaining, 0.0)
        self.solve_time_s += sol.solve_time_s
        return sol

    def min_count_directions(self) -> int | None:
        """Fewest markers meeting every count and sector row (accuracy ignored); ``None`` when
        infeasible."""
        sol = self._solve(self._bounded(None, np.inf, count_objective=True))
        if sol is None or sol.status not in ("optimal", "infeasible"):
            raise PlanTimeLimitError(
                "time limit reached before the fewest markers meeting the direction rows were "
                "proven; raise `time_limit_s`")
        return None if sol.selected is None else int(sol.selected.sum())

    def query(self, k: int, eps: float, statuses: list[str]):
        """A ``k``-subset with every station error <= ``eps``, or ``None``.

        Returns ``(selected, proven)``: ``selected`` is ``None`` when infeasible; ``proven`` is
        False when a solve hit its time limit without an answer.
        """
        cfg = self.config.replace(requirement_m=eps) if np.isfinite(eps) else None
        while True:
            sol = self._solve(self._bounded(k, eps, count_objective=False))
            if sol is None:
                statuses.append("time_limit")
                return None, False
            statuses.append(sol.status)
            if sol.selected is None:
                return None, sol.status == "infeasible"
            if cfg is None:
                return sol.selected, True
            rows, _, kinds = accuracy_cuts(self.problem, self.model, sol.selected, cfg,
                                           self.infos)
            if rows is None:
                return sol.selected, True
            # accuracy_cuts found each grown set failing at eps: its threshold is above eps
            # even where a re-summed error rounds differently
            thresholds = [max(self._threshold(rows[r:r + 1], kinds[r]), np.nextafter(eps, np.inf))
                          for r in range(rows.shape[0])]
            start = self.model.A.shape[0]
            self.model = self.model.with_rows(rows, np.ones(len(kinds)),
                                              np.full(len(kinds), np.inf), kinds)
            self.cut_rows.extend(range(start, start + len(kinds)))
            self.cut_threshold.extend(thresholds)

    def _threshold(self, row, kind: RowKind) -> float:
        """Error of the failing set a cut row excludes: the cut is valid for eps below it."""
        info = self.infos[kind.station]
        support = self.model.var_site[row.indices[row.indices < self.nx]]
        return info.error(np.setdiff1d(info.sites, support))

    def pad(self, selected: np.ndarray, k: int, pool: np.ndarray) -> np.ndarray:
        """Add unused ``pool`` sites (in order) until ``k`` are selected (never hurts a
        station)."""
        out = selected.copy()
        for j in np.flatnonzero(pool & ~out)[: max(0, k - int(out.sum()))]:
            out[j] = True
        return out


#: Requirement standing for "none" when the network oracle is asked for any k-subset, m: far
#: above any station's error on a site tied to its datum, yet small enough that the program's
#: information rows, which scale with its square, stay within what HiGHS accepts (1e15; at
#: 1e9 m they did not, and every such query failed).
_NO_REQUIREMENT_M = 1e3


class NetworkMinimax(MinimaxModel):
    """Network mode: "is there a k-subset with every station and every kept marker <= eps,
    relative to the datum?", answered by the planner's own network program
    (:func:`planner.program.loop.plan_sites`, its network accuracy cuts) with the requirement set to
    eps and the budget row bounded to exactly ``k`` on both sides.

    The known-control model's count and sector rows still answer the direction questions
    (:meth:`min_count_directions`). A kept marker's own error counts, so adding a marker may
    raise the worst error: the curve need not be monotone and no count's optimum bounds
    another's (:attr:`monotone` is False). A query is a whole cut loop, and one near the
    optimum that proves infeasibility costs the most, so the search descends from the
    incumbent instead of bisecting (:attr:`bisect` is False): on the default site's as-built
    layout that takes less than half the queries.
    """

    monotone = False
    bisect = False

    def __init__(self, problem: PlanProblem, config, deadline: float) -> None:
        super().__init__(problem, config, deadline)
        self.net = network_model(problem, config)
        self._n_cuts = 0

    @property
    def n_cuts(self) -> int:
        return self._n_cuts

    def worst(self, selected: np.ndarray) -> float:
        """The subset's worst error relative to the datum, m
        (:func:`~planner.reduction.losses.check_worst`), with ``requirement_ppm`` scaled to the
        constant part of the allowance (``requirement_m`` times the worst ratio of error to
        allowance, so that "<= eps" is the requirement ``eps`` plus proportionally scaled
        ppm); ``inf`` when it fails a local requirement (station or marker pairs, held as rows
        by the program), so a subset failing them is never an incumbent; 0 when nothing is
        judged relative to the datum (``datum_requirement`` false: then any subset meeting the
        local requirement is optimal)."""
        check = self.check(selected)
        if not local_ok(check):
            return np.inf
        if not self.config.datum_requirement:
            return 0.0
        if not self.config.requirement_ppm:
            return check_worst(check)
        allowed, allowed_site = self.net.allowances(NetworkRequirement.of(self.config))
        ratio = np.r_[check.error_m / allowed,
                      (check.marker_error_m / allowed_site)[selected]]
        return float(self.config.requirement_m * np.max(ratio))

    def floor(self, allowed: np.ndarray) -> float:
        """The stations' worst error with every allowed site, scaled as :meth:`worst` (a
        marker's own error may make a larger set worse, never a station's); 0 without a datum
        requirement."""
        if not self.config.datum_requirement:
            return 0.0
        station_allowed, _ = self.net.allowances(NetworkRequirement.of(self.config))
        return float(self.config.requirement_m
                     * np.max(self.net.station_errors(allowed) / station_allowed))

    def _exact_model(self, k: int, cfg) -> Model:
        """The planner's model for ``cfg`` with ``sum x = k`` and its tightening rows."""
        model = build_model(self.problem, cfg)
        lb = model.row_lb.copy()
        lb[[i for i, r in enumerate(model.row_kind) if r.family == "budget"]] = float(k)
        return with_tightening_rows(self.problem, replace(model, row_lb=lb), cfg)

    def query(self, k: int, eps: float, statuses: list[str]):
        """As :meth:`MinimaxModel.query`. ``plan_sites`` raises when no layout exists (proven
        infeasible) or :class:`~markerplan.errors.PlanTimeLimitError` when its time limit ends
        the search (not proven)."""
        limit = min(self.deadline - time.perf_counter(), self.solve_cap_s)
        if limit <= 0:
            statuses.append("time_limit")
            return None, False
        k = min(k, self.nx)
        eps = float(eps) if np.isfinite(eps) else _NO_REQUIREMENT_M
        cfg = self.config.replace(  # the allowance scaled as a whole (:meth:`worst`)
            requirement_m=eps, budget=k, time_limit_s=float(limit),
            requirement_ppm=self.config.requirement_ppm * eps / self.config.requirement_m)
        t = time.perf_counter()
        try:
            result = plan_sites(self.problem, cfg, self._exact_model(k, cfg))
        except InfeasiblePlanError as exc:
            self.solve_time_s += time.perf_counter() - t
            proven = not isinstance(exc, PlanTimeLimitError)
            statuses.append("infeasible" if proven else "time_limit")
            return None, proven
        self.solve_time_s += result.solve_time_s
        self._n_cuts += result.n_cuts
        statuses.append(result.status)
        if int(result.selected.sum()) != k:  # a time-limited incumbent of another size
            return None, False
        return result.selected, True
