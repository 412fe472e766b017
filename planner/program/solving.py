"""One solve of a :class:`~planner.program.model.Model` with HiGHS -> its
:class:`~planner.program.model.Solution`."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from markerplan.errors import ConfigError
from planner.program.highs import run_highs
from planner.program.model import Model, Solution, aggregate_columns


def solve(model: Model, time_limit_s: float = 60.0, gap: float = 0.0,
          priority: np.ndarray | None = None, start: np.ndarray | None = None) -> Solution:
    """Solve ``model`` once with HiGHS (:func:`planner.program.highs.run_highs`).

    Parameters
    ----------
    model : Model
    time_limit_s : float
        Wall-clock limit, s.
    gap : float
        Target relative MIP gap (0: prove optimality).
    priority : (nx,) float, optional
        Move the markers of every group of identical ``x`` columns (same entries in every row,
        cost and bounds, :func:`~planner.program.model.aggregate_columns`) to its members of
        highest priority (then by variable order). Exact: ``A x`` and ``c x`` are unchanged.
        HiGHS gets the model as it is (merging the group into one integer column made its solve
        slower, see ``benchmarks/program_scale.py``).
    start : (v,) float, optional
        Values HiGHS starts from, NaN where not given (it completes a partial start when it
        can).

    Returns
    -------
    solution : Solution
        A time-limited answer has status ``"time_limit"``, never ``"optimal"``. When the
        objective can only take integer values the dual bound is HiGHS' bound rounded up
        (a bound on an integer is one on its ceiling) and HiGHS stops once the incumbent is
        within less than 1 of its bound.
    """
    if not time_limit_s > 0:
        raise ConfigError(f"`time_limit_s` must be > 0, got {time_limit_s!r}")
    if not gap >= 0:
        raise ConfigError(f"`gap` must be >= 0, got {gap!r}")
    t0 = time.perf_counter()
    nx = model.var_site.size
    integrality, c = model.integrality, model.c
    integral = bool(np.all(integrality == 1) and np.all(np.abs(c - np.round(c)) < 1e-12))
    out = run_highs(c, model.A, model.row_lb, model.row_ub, model.lb, model.ub, integrality,
                    max(time_limit_s - (time.perf_counter() - t0), 1e-3), gap,
                    integral_objective=integral, start=start)
    # integer variables rounded (HiGHS returns them within its tolerance); continuous ones,
    # e.g. a linear relaxation's, as solved
    x = None if out.x is None else np.where(integrality == 1, np.round(out.x), out.x)
    if x is not None and priority is not None:
        group, first = aggregate_columns(model)
        count = np.r_[np.bincount(group, x[:nx], minlength=first.size), x[nx:]]
        x = _disaggregate(count, group, first.size, nx, priority)
    selected = None
    if x is not None:
        selected = np.zeros(model.site_var.shape[0], dtype=bool)
        selected[model.var_site[x[:nx] > 0.5]] = True
    status = out.status
    if status == "optimal" and gap > 0:
        status = "gap_reached"
    elif status in ("time_limit", "error") and x is None:
        status = "no_solution" if status == "time_limit" else "error"
    elif status == "error":
        status = "time_limit"
    dual = out.dual_bound
    if not np.any(integrality):  # a linear program: solved means bound = objective
        dual = out.objective if status == "optimal" else float("nan")
    elif integral and np.isfinite(dual):
        dual = float(math.ceil(dual - 1e-6))
    obj = out.objective
    mgap = max(obj - dual, 0.0) / max(abs(obj), 1e-9) if np.isfinite(obj) and np.isfinite(dual) \
        else float("nan")
    return Solution(status=status, selected=selected, objective=obj, dual_bound=dual, gap=mgap,
                    solve_time_s=time.perf_counter() - t0, message=out.message, x=x)



def logged_solve(model: Model, time_limit_s: float, gap: float, history: list, iteration: int,
                 start: np.ndarray | None = None, unit: float = 1.0) -> Solution:
    """One :func:`solve` of a cut loop, its objective and bound in ``unit`` (the model's cost
    unit, e.g. 60 s), and its record (iteration, status, objective, dual bound, solve time,
    rows) appended to ``history``."""
    sol = solve(model, time_limit_s, gap, start=start)
    if unit != 1.0:
        sol = replace(sol, objective=sol.objective * unit, dual_bound=sol.dual_bound * unit)
    history.append({"iteration": iteration, "status": sol.status,
                    "objective": sol.objective, "dual_bound": sol.dual_bound,
                    "solve_time_s": sol.solve_time_s, "n_rows": int(model.A.shape[0])})
    return sol


def _disaggregate(x: np.ndarray, group: np.ndarray, n_groups: int, nx: int,
                  priority: np.ndarray) -> np.ndarray:
    """Solution of the model from its markers per group (``x``: ``n_groups`` counts, then the
    other variables): each group's count goes to its members by ``priority`` (highest first),
    then by variable order."""
    prio = -np.asarray(priority, float)
    order = np.lexsort((np.arange(nx), prio, group))  # by group, then priority
    starts = np.searchsorted(group[order], np.arange(n_groups))
    rank = np.empty(nx, np.int64)
    rank[order] = np.arange(nx) - starts[group[order]]
    return np.r_[(rank < x[group]).astype(float), x[n_groups:]]

