"""One mixed-integer program handed to HiGHS directly (highspy), and what came back.

:func:`run_highs` passes the arrays of a program ``min c x  s.t.  row_lb <= A x <= row_ub,
lb <= x <= ub`` to HiGHS in one row-wise call (the CSR arrays as they are: no
``scipy.optimize.milp`` wrapping, no transposing copy in Python), with a thread count, a time
limit and a relative gap; :func:`solver_record` gives the name, version and limits a plan
records. :class:`WarmLP` keeps a linear program in HiGHS between solves, so rows added later
are solved from the last optimal basis (dual simplex) instead of from scratch.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from highspy import _core

#: Threads HiGHS may use (the parallel parts of its MIP search; the result does not depend on
#: it). Fixed per process: HiGHS keeps one global scheduler.
THREADS = 2
#: Absolute gap at which HiGHS stops when the objective is integral: below 1 (no integer lies
#: strictly between bound and incumbent), with 1e-3 to spare for the LP's rounding error.
INTEGRAL_ABS_GAP = 1.0 - 1e-3


@dataclass(frozen=True)
class HighsOutcome:
    """What one HiGHS run returned.

    Attributes
    ----------
    status : str
        "optimal" (proven within the gap asked for), "time_limit" (stopped by the limit),
        "infeasible" or "error".
    x : (v,) float or None
        The best solution found (as HiGHS gives it: integer variables within its tolerance);
        None when there is none.
    objective, dual_bound, gap : float
        Objective of ``x``, HiGHS' proven lower bound and their relative gap (nan if unknown).
    solve_time_s : float
        Wall clock of the run, s.
    message : str
        HiGHS' model status in words.
    """

    status: str
    x: np.ndarray | None
    objective: float
    dual_bound: float
    gap: float
    solve_time_s: float
    message: str


def reset_after_fork() -> None:
    """In a forked child: drop HiGHS' global thread scheduler inherited from the parent (its
    worker threads do not exist in the child); the next run starts a new one."""
    _core._Highs.resetThreadScheduler(False)


def highs_version() -> str:
    """The HiGHS version highspy runs, e.g. ``"1.16.0"``."""
    return _core._Highs().version()


def solver_record(time_limit_s: float, mip_gap: float) -> dict:
    """The solver's name and limits as a plan records them (no timings).

    Parameters
    ----------
    time_limit_s : float
        Wall-clock limit of the planning loop, s.
    mip_gap : float
        Relative gap asked for (0: proven optimality).
    """
    return {"name": "HiGHS via highspy", "version": highs_version(), "threads": THREADS,
            "time_limit_s": time_limit_s, "target_gap": mip_gap}


def run_highs(c: np.ndarray, a: sp.sparray, row_lb: np.ndarray, row_ub: np.ndarray,
              lb: np.ndarray, ub: np.ndarray, integrality: np.ndarray, time_limit_s: float,
              gap: float, integral_objective: bool = False,
              start: np.ndarray | None = None) -> HighsOutcome:
    """Minimise ``c x`` subject to ``row_lb <= a x <= row_ub``, ``lb <= x <= ub`` in HiGHS.

    Parameters
    ----------
    c, lb, ub : (v,) float
    a : (m, v) sparse
    row_lb, row_ub : (m,) float
        Infinite entries are open sides.
    integrality : (v,) int
        1 for integer variables, 0 for continuous.
    time_limit_s : float
        Wall-clock limit, s (> 0).
    gap : float
        Relative MIP gap at which to stop (0: prove optimality).
    integral_objective : bool
        Every feasible objective value is an integer (integer costs on integer variables): then
        an incumbent less than 1 above the bound is optimal, and HiGHS stops there
        (``mip_abs_gap`` :data:`INTEGRAL_ABS_GAP`).
    start : (v,) float, optional
        Values to start from, NaN where not given: HiGHS completes a partial start into its
        first incumbent when it can.

    Returns
    -------
    outcome : HighsOutcome
    """
    t0 = time.perf_counter()
    h = _loaded(c, a, row_lb, row_ub, lb, ub, integrality)
    h.setOptionValue("time_limit", float(time_limit_s))
    h.setOptionValue("mip_rel_gap", float(gap))
    if integral_objective:
        h.setOptionValue("mip_abs_gap", INTEGRAL_ABS_GAP)
    if start is not None:
        given = np.flatnonzero(np.isfinite(start)).astype(np.int32)
        h.setSolution(int(given.size), given, np.ascontiguousarray(start[given], float))
    h.run()
    return _outcome(h, t0)


def _loaded(c, a, row_lb, row_ub, lb, ub, integrality):
    """A quiet HiGHS instance on :data:`THREADS` threads holding the model ``min c x  s.t.
    row_lb <= a x <= row_ub, lb <= x <= ub`` (``integrality`` (v,) int: 1 integer, 0
    continuous)."""
    a = _canonical(a)
    h = _core._Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("threads", THREADS)
    h.passModel(c.shape[0], a.shape[0], int(a.nnz), int(_core.MatrixFormat.kRowwise),
                int(_core.ObjSense.kMinimize), 0.0, np.ascontiguousarray(c, float),
                np.ascontiguousarray(lb, float), np.ascontiguousarray(ub, float),
                np.ascontiguousarray(row_lb, float), np.ascontiguousarray(row_ub, float),
                a.indptr.astype(np.int32), a.indices.astype(np.int32),
                np.ascontiguousarray(a.data, float), np.asarray(integrality, np.int32))
    return h


def _outcome(h, t0: float) -> HighsOutcome:
    """The :class:`HighsOutcome` of HiGHS instance ``h``'s last run, started at ``t0``."""
    model_status = h.getModelStatus()
    info = h.getInfo()
    has_x = info.primal_solution_status == int(_core.SolutionStatus.kSolutionStatusFeasible)
    x = np.asarray(h.getSolution().col_value, float) if has_x else None
    ms = _core.HighsModelStatus
    if model_status == ms.kOptimal:
        status = "optimal"
    elif model_status == ms.kInfeasible:
        status = "infeasible"
    elif model_status in (ms.kTimeLimit, ms.kInterrupt, ms.kSolutionLimit,
                          ms.kIterationLimit):
        status = "time_limit"
    else:
        status = "error"
    nan = float("nan")
    return HighsOutcome(status=status, x=x,
                        objective=float(info.objective_function_value) if has_x else nan,
                        dual_bound=float(info.mip_dual_bound), gap=float(info.mip_gap),
                        solve_time_s=time.perf_counter() - t0,
                        message=h.modelStatusToString(model_status))


class WarmLP:
    """A linear program ``min c x  s.t.  row_lb <= A x <= row_ub, lb <= x <= ub`` kept in one
    HiGHS instance: :meth:`add_rows` appends rows, :meth:`solve` re-solves from the last basis.

    Parameters
    ----------
    c, lb, ub : (v,) float
    a : (m, v) sparse
    row_lb, row_ub : (m,) float
        Infinite entries are open sides.
    """

    def __init__(self, c: np.ndarray, a: sp.sparray, row_lb: np.ndarray, row_ub: np.ndarray,
                 lb: np.ndarray, ub: np.ndarray):
        self._h = _loaded(c, a, row_lb, row_ub, lb, ub, np.zeros(c.shape[0], np.int32))

    def add_rows(self, a: sp.sparray, row_lb, row_ub) -> None:
        """Append rows ``row_lb <= a x <= row_ub`` (``a``: (r, v) sparse)."""
        a = _canonical(a)
        self._h.addRows(a.shape[0], np.ascontiguousarray(row_lb, float),
                        np.ascontiguousarray(row_ub, float), int(a.nnz),
                        a.indptr[:-1].astype(np.int32), a.indices.astype(np.int32),
                        np.ascontiguousarray(a.data, float))

    def solve(self, time_limit_s: float) -> HighsOutcome:
        """Solve (from the last basis) for at most ``time_limit_s`` s of wall clock."""
        t0 = time.perf_counter()
        # HiGHS' time limit counts the instance's whole run time: move it on by what is spent
        self._h.setOptionValue("time_limit", float(self._h.getRunTime() + time_limit_s))
        self._h.run()
        return _outcome(self._h, t0)


def _canonical(a: sp.sparray) -> sp.csr_array:
    """``a`` as CSR with each row's columns sorted and distinct (what HiGHS wants)."""
    a = sp.csr_array(a)
    if not a.has_canonical_format:
        a = a.copy()
        a.sum_duplicates()
    return a
