"""The integer program: fewest (cheapest) marker sites meeting directions and accuracy.

Build, solve and check are separate steps:

- :func:`build_model` turns a :class:`~planner.problem.usability.PlanProblem` into a :class:`Model`
  (plain data: ``c``, sparse ``A``, row and variable bounds, index maps);
- :func:`solve` runs HiGHS once (:func:`planner.program.highs.run_highs`; optionally the
  markers of identical site columns then move to the preferred sites,
  :func:`aggregate_columns`) -> :class:`Solution`;
- :func:`plan_sites` is the accuracy-cut loop: solve, check every station's predicted accuracy
  exactly (:class:`planner.accuracy.checks.StationInfo`), add valid cuts for stations that fail
  and re-solve until all pass. In known-control mode the first solve is the directions-only
  relaxation (:func:`_combinatorial_first`); the full model is built only when its
  layout fails a station.

Models are immutable: :meth:`Model.with_rows` returns a new model, so what-if studies re-use one
model with changed bounds (``dataclasses.replace``) or added rows. Every row carries a
:class:`RowKind` (its family and station), so no caller parses row labels.

Formulation
-----------
Variables: ``x_j`` in {0, 1} for every candidate site usable by at least one station (or
existing); ``y_sk`` in {0, 1} "station s has a selected usable marker in sector k"; in redundant
mode also ``z_sk`` "... at least two". For every station ``s`` with usable sites ``U_s``:

- count: ``sum_{j in U_s} x_j >= min_markers`` (``+ 1`` in redundant mode);
- sectors: ``y_sk <= sum_{j in U_s, sector(j) = k} x_j`` and ``sum_k y_sk >= min_sectors``;
  redundant: ``2 z_sk <= sum_{...} x_j``, ``z_sk <= y_sk`` and for every sector ``k'``:
  ``sum_k y_sk - y_sk' + z_sk' >= min_sectors`` (losing one marker of sector ``k'`` empties it
  only if it held one);
- information (necessary, valid): ``sum_j (3 / sigma_sj^2) x_j >= chi2_3(0.95) / requirement^2``
  (:func:`planner.accuracy.known_control.information_lower_bound`); its coefficients are scaled so
  the row reads ``>= 1`` and a what-if study can move the requirement by changing that bound alone;
- tightening rows added by :func:`plan_sites` (:func:`with_tightening_rows`, valid for the
  configured requirement only): heading information
  ``sum_j (3 |d_sj|^2 / sigma_sj^2) x_j >= chi2_3(0.95) R^2 / requirement^2`` and
  outer-approximation tangents at 9 rim points;
- accuracy cuts (added lazily): the predicted error is monotone in the marker set, so when
  station ``s`` fails with a set ``T`` every subset of ``T`` fails too. ``T`` is first grown
  greedily to a larger failing set ``T'`` (a stronger cut), then
  ``sum_{j in U_s \\ T'} x_j >= 1``. In redundant mode, when losing marker ``m`` leaves a failing
  set ``T`` (grown to ``T'`` without ``m``): ``sum_{j in U_s \\ T', j != m} x_j - x_m >= 0``.
  Each failing set also yields an outer-approximation cut (the tangent of the convex worst-case
  variance, :meth:`planner.accuracy.checks.StationInfo.oa_cuts`), which carries the geometry —
  which sites would fix the failing direction — and makes the loop converge in a few rounds.

Options: existing markers (lower bound 1, cost 0), forbidden sites (upper bound 0), a budget
row ``sum_j x_j <= budget``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from markerplan.errors import ConfigError, InfeasiblePlanError, PlanTimeLimitError
from planner.accuracy import known_control
from planner.accuracy.checks import (
    LayoutCheck,
    StationInfo,
    diagnose,
    evaluate_layout,
    station_infos,
)
from planner.accuracy.network import NetworkModel, network_model
from planner.problem.usability import PlanProblem, sector_index
from planner.program.highs import run_highs

if TYPE_CHECKING:
    from planner.program.baselines import Baseline


@dataclass(frozen=True)
class RowKind:
    """What one row of a :class:`Model` is.

    Attributes
    ----------
    family : str
        "count", "info", "sector", "sector2", "sector21", "directions", "directions-loss",
        "budget" (from :func:`build_model`), "heading", "oa0" (:func:`with_tightening_rows`), "cut",
        "oa", "cut-loss", "oa-loss", "info-loss", "heading-loss" (:func:`accuracy_cuts`);
        network mode: "upper-bound", "cut", "connect", "oa", "cut-marker", "oa-marker"
        (:func:`network_cuts`), redundant: "cut-loss", "oa-loss" (:func:`_network_loss_cuts`).
    station : int
        Index of the station the row belongs to, -1 for rows of no station (budget).
    """

    family: str
    station: int = -1


@dataclass(frozen=True)
class Model:
    """A mixed-integer linear program ``min c x  s.t.  row_lb <= A x <= row_ub, lb <= x <= ub``.

    Attributes
    ----------
    c : (v,) float
    A : (m, v) scipy.sparse.csr_array
    row_lb, row_ub : (m,) float
    lb, ub : (v,) float
    integrality : (v,) int
    var_site : (nx,) int
        Candidate-site index of each ``x`` variable (the first ``nx`` variables).
    site_var : (n,) int
        Variable index of each candidate site, -1 when the site is not in the model.
    row_kind : tuple of RowKind, (m,)
        Family and station of every row.
    """

    c: np.ndarray
    A: sp.csr_array
    row_lb: np.ndarray
    row_ub: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    integrality: np.ndarray
    var_site: np.ndarray
    site_var: np.ndarray
    row_kind: tuple[RowKind, ...]

    @property
    def n_vars(self) -> int:
        return self.c.shape[0]

    def with_rows(self, rows: sp.sparray, row_lb, row_ub, kinds) -> Model:
        """A new model with rows appended (this one is unchanged).

        Parameters
        ----------
        rows : (r, v) sparse
        row_lb, row_ub : (r,) float
        kinds : sequence of RowKind, (r,)
        """
        rows = sp.csr_array(rows)
        if rows.shape[1] != self.n_vars:
            raise ConfigError(f"`rows` must have {self.n_vars} columns, got {rows.shape[1]}")
        return replace(self, A=sp.csr_array(sp.vstack([self.A, rows])),
                       row_lb=np.concatenate([self.row_lb, np.asarray(row_lb, float)]),
                       row_ub=np.concatenate([self.row_ub, np.asarray(row_ub, float)]),
                       row_kind=self.row_kind + tuple(kinds))

    def site_row(self, site_index, coef=1.0) -> sp.csr_array:
        """One sparse row with ``coef`` on the ``x`` variables of the given candidate sites."""
        site_index = np.atleast_1d(np.asarray(site_index, dtype=np.int64))
        var = self.site_var[site_index]
        if np.any(var < 0):
            raise ConfigError("site_row: some sites are not variables of this model")
        data = np.broadcast_to(np.asarray(coef, float), var.shape)
        return sp.csr_array((data, (np.zeros_like(var), var)), shape=(1, self.n_vars))

    def implied_row(self, site: int, site_index, coef=1.0, rhs: float = 1.0) -> sp.csr_array:
        """One row for "a marker at ``site`` implies ``sum coef x >= rhs``" over the given
        sites: ``sum coef x - rhs x_site``, to be bounded below by 0."""
        coef = np.broadcast_to(np.asarray(coef, float), np.shape(site_index))
        return self.site_row(np.r_[site_index, site], np.r_[coef, -rhs])


@dataclass(frozen=True)
class Solution:
    """One HiGHS solve (:func:`solve`).

    Attributes
    ----------
    status : str
        "optimal", "time_limit" (a feasible answer, not proven optimal), "infeasible",
        "no_solution" (time limit with no feasible answer) or "error".
    selected : (n,) bool or None
        Candidate sites holding a marker.
    objective, dual_bound, gap : float
        Objective, HiGHS dual bound and relative gap (nan when unknown).
    solve_time_s : float
    message : str
    x : (v,) float or None
    """

    status: str
    selected: np.ndarray | None
    objective: float
    dual_bound: float
    gap: float
    solve_time_s: float
    message: str
    x: np.ndarray | None = None


@dataclass(frozen=True)
class PlanResult:
    """Result of the accuracy-cut loop.

    Attributes
    ----------
    selected : (n,) bool
    check : LayoutCheck
        Per-station directions and predicted errors of the selected layout.
    solution : Solution
        The final solve (status, objective, dual bound, gap).
    iterations : int
    n_cuts : int
    solve_time_s : float
        Total time in the solver over all iterations.
    model : Model
        The final model including every cut (known control, when the first solve passed:
        the directions-only relaxation it solved, see :func:`plan_sites`).
    history : list of dict
        Per solve: iteration, status, objective, dual bound, solve time, rows.
    greedy : planner.program.baselines.Baseline or None
        Network mode on large problems: the greedy layout the loop started from (its
        incumbent and upper bound), so callers need not run the greedy baseline again.
    """

    selected: np.ndarray
    check: LayoutCheck
    solution: Solution
    iterations: int
    n_cuts: int
    solve_time_s: float
    model: Model
    history: list = field(default_factory=list)
    greedy: Baseline | None = None

    @property
    def status(self) -> str:
        return self.solution.status


def build_model(problem: PlanProblem, config, information: bool = True) -> Model:
    """Build the integer program for a problem and a :class:`~planner.config.PlanConfig`.

    Built from whole arrays (no loop over stations): rows are laid out station by station
    (count, info, then per occupied sector its sector rows, directions, then in redundant
    mode the directions-loss rows), then the budget row; the ``y`` (and ``z``) variables
    follow the ``x`` variables in the same station and sector order.

    Parameters
    ----------
    problem : PlanProblem
    config : PlanConfig
        Uses ``min_markers``, ``n_sectors``, ``min_sectors``, ``requirement_m``, ``redundant``,
        ``budget``, ``existing``, ``forbidden``.
    information : bool
        Include the ``info`` rows; without them the model is the directions-only relaxation
        (same variables: rows of one fit the other).

    Returns
    -------
    model : Model
    """
    usable = problem.pair_usable
    existing = problem.site_mask(config.existing, "existing") | problem.site_existing
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    in_model = existing.copy()
    in_model[problem.pair_site[usable]] = True
    var_site = np.flatnonzero(in_model)
    site_var = np.full(problem.n_sites, -1, dtype=np.int64)
    site_var[var_site] = np.arange(var_site.size)
    nx, ns, redundant = var_site.size, problem.n_stations, bool(config.redundant)

    # usable pairs by station, then site; their column, and their (station, sector) key
    pairs = np.concatenate([problem.usable_pairs(s) for s in range(ns)] or [np.zeros(0, int)])
    station = problem.pair_station[pairs]
    col = site_var[problem.pair_site[pairs]]
    key = station * config.n_sectors + sector_index(problem.pair_bearing_rad[pairs],
                                                    config.n_sectors)
    occupied, sector_of = np.unique(key, return_inverse=True)  # (p,) sector of each pair
    occ_station = occupied // config.n_sectors
    n_occ = np.bincount(occ_station, minlength=ns)
    rank = np.arange(occupied.size) - np.searchsorted(occ_station, occ_station)
    y = nx + (2 if redundant else 1) * np.arange(occupied.size)  # z = y + 1 when redundant
    n_vars = nx + (2 if redundant else 1) * occupied.size

    # rows of each station: count, [info], per sector 1 (redundant: 3), directions,
    # [redundant: one directions-loss per sector]
    reference = _reference_index(problem, config)
    has_info = np.full(ns, information)
    if information and reference >= 0:
        has_info[reference] = False
    per_sector = 3 if redundant else 1
    size = 2 + has_info + n_occ * (per_sector + (1 if redundant else 0))
    start = np.r_[0, np.cumsum(size)]
    count_row = start[:-1]
    sector_row = (start[occ_station] + 1 + has_info[occ_station]) + per_sector * rank
    directions_row = count_row + 1 + has_info + per_sector * n_occ
    n_rows = int(start[-1]) + (config.budget is not None)

    ones_p, ones_o = np.ones(pairs.size), np.ones(occupied.size)
    parts = [(count_row[station], col, ones_p),                            # count
             (sector_row, y, ones_o),                                      # y - sum x <= 0
             (sector_row[sector_of], col, -ones_p),
             (directions_row[occ_station], y, ones_o)]                     # sum y >= min
    if information:
        w_t, _ = info_weights(problem, pairs, config)
        keep = has_info[station]
        parts.append((count_row[station[keep]] + 1, col[keep], w_t[keep]))  # info
    if redundant:
        z = y + 1
        loss_row = directions_row[occ_station] + 1 + rank
        # the directions-loss row of sector o holds y of its station's other occupied sectors
        reps = n_occ[occ_station]
        o = np.repeat(np.arange(occupied.size), reps)
        other = (np.arange(occupied.size) - rank)[o] + np.arange(o.size) \
            - np.repeat(np.cumsum(reps) - reps, reps)
        mask = other != o
        parts += [(sector_row + 1, z, 2 * ones_o),                         # 2 z - sum x <= 0
                  (sector_row[sector_of] + 1, col, -ones_p),
                  (sector_row + 2, z, ones_o), (sector_row + 2, y, -ones_o),  # z - y <= 0
                  (loss_row[o[mask]], y[other[mask]], np.ones(int(mask.sum()))),
                  (loss_row, z, ones_o)]
    if config.budget is not None:
        parts.append((np.full(nx, n_rows - 1), np.arange(nx), np.ones(nx)))
    i, j, v = (np.concatenate([np.asarray(p[k]) for p in parts]) for k in range(3))
    a = sp.csr_array((v, (i, j)), shape=(n_rows, n_vars))

    # bounds and kinds, row by row
    min_count = config.min_markers + (1 if redundant else 0)
    row_lb, row_ub = np.full(n_rows, -np.inf), np.zeros(n_rows)
    family = np.empty(n_rows, dtype=object)
    row_station = np.r_[np.repeat(np.arange(ns), size), np.full(n_rows - start[-1], -1)]
    family[count_row], row_lb[count_row], row_ub[count_row] = "count", min_count, np.inf
    info_row = count_row[has_info] + 1
    family[info_row], row_lb[info_row], row_ub[info_row] = "info", 1.0, np.inf
    family[sector_row] = "sector"
    family[directions_row] = "directions"
    row_lb[directions_row], row_ub[directions_row] = config.min_sectors, np.inf
    if redundant:
        family[sector_row + 1], family[sector_row + 2] = "sector2", "sector21"
        family[loss_row], row_lb[loss_row], row_ub[loss_row] = \
            "directions-loss", config.min_sectors, np.inf
    if config.budget is not None:
        family[-1], row_ub[-1] = "budget", float(config.budget)
    c = np.zeros(n_vars)
    c[:nx] = problem.site_cost[var_site]
    lb = np.zeros(n_vars)
    ub = np.ones(n_vars)
    lb[:nx][existing[var_site]] = 1.0
    ub[:nx][forbidden[var_site]] = 0.0
    return Model(c=c, A=a, row_lb=row_lb, row_ub=row_ub, lb=lb, ub=ub,
                 integrality=np.ones(n_vars, dtype=np.int64), var_site=var_site,
                 site_var=site_var,
                 row_kind=tuple(map(RowKind, family.tolist(), row_station.tolist())))


def _reference_index(problem: PlanProblem, config) -> int:
    """Index of the datum station in network mode, -1 in known-control mode."""
    if not config.network:
        return -1
    if config.reference_station is None:
        return 0
    if config.reference_station not in problem.station_ids:
        raise ConfigError(f"`reference_station` {config.reference_station!r} is not a station "
                          f"of this plan; valid ids are {', '.join(problem.station_ids[:20])}")
    return problem.station_ids.index(config.reference_station)


def _boundary_oa_cuts(problem: PlanProblem, s: int, config) -> list:
    """Initial outer-approximation cuts of station ``s``: tangents at the information of all its
    usable sites scaled down onto the requirement's boundary, at 9 rim points."""
    info = StationInfo(problem, s, config)
    if info.sites.size == 0:
        return []
    e_all = info.error(info.sites)
    if not np.isfinite(e_all) or e_all >= config.requirement_m:
        return []
    return info.oa_cuts(info.sites, config.requirement_m, scale=(e_all / config.requirement_m)
                        ** 2, rim="spread")


def with_tightening_rows(problem: PlanProblem, model: Model, config) -> Model:
    """``model`` with valid rows that tighten it for ``config.requirement_m`` before the first
    solve.

    Per station: the heading-information row
    (:func:`planner.accuracy.known_control.heading_information_lower_bound`) and outer-approximation
    tangents at 9 rim points (families ``"heading"``, ``"oa0"``). Unlike the ``info:`` rows of
    :func:`build_model` they do not rescale with the requirement, so a model re-used for another
    requirement level must leave them out.
    """
    rows, lower, kinds = [], [], []
    reference = _reference_index(problem, config)
    for s in range(problem.n_stations):
        idx = problem.usable_pairs(s)
        if idx.size == 0 or s == reference:
            continue
        if not (config.network and config.heading_prior_sigma_deg is not None):
            _, w_h = info_weights(problem, idx, config)
            rows.append(model.site_row(problem.pair_site[idx], w_h))
            lower.append(1.0)
            kinds.append(RowKind("heading", s))
        if config.network:
            continue
        for sites, coef, rhs in _boundary_oa_cuts(problem, s, config):
            rows.append(model.site_row(sites, coef))
            lower.append(rhs)
            kinds.append(RowKind("oa0", s))
    if not rows:
        return model
    return model.with_rows(sp.vstack(rows), lower, np.full(len(lower), np.inf), kinds)


def info_weights(problem: PlanProblem, pairs: np.ndarray, config
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients of the two necessary information cuts for some pairs of one station.

    Returns ``(w_t, w_h)``, each scaled so that a passing station needs ``sum w x >= 1``
    (:func:`planner.accuracy.known_control.information_lower_bound` and
    :func:`planner.accuracy.known_control.heading_information_lower_bound`). In network mode the
    weight of a pair is the station's diagonal share of the site's contribution, ``w (1 - w / W_j)``
    (``W_j`` the site's total weight): the station's information in the network is at most its
    diagonal, so the same two bounds stay necessary (and a site seen by this station alone
    counts nothing).
    """
    w = 3.0 / problem.pair_sigma_m[pairs] ** 2
    if config.network:
        usable = problem.pair_usable
        total = np.bincount(problem.pair_site[usable], 3.0 / problem.pair_sigma_m[usable] ** 2,
                            minlength=problem.n_sites)
        w = w * (1.0 - w / total[problem.pair_site[pairs]])
    d = problem.site_xyz[problem.pair_site[pairs], :2] \
        - problem.station_xyz[problem.pair_station[pairs], :2]
    w_t = w / known_control.information_lower_bound(config.requirement_m)
    w_h = w * np.sum(d**2, axis=1) / known_control.heading_information_lower_bound(
        config.requirement_m, config.working_radius_m)
    return w_t, w_h


def solve(model: Model, time_limit_s: float = 60.0, gap: float = 0.0,
          priority: np.ndarray | None = None) -> Solution:
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
        cost and bounds, :func:`aggregate_columns`) to its members of highest priority (then
        by variable order). Exact: ``A x`` and ``c x`` are unchanged. HiGHS gets the model
        as it is (merging the group into one integer column made its solve slower, see
        ``benchmarks/program_scale.py``).

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
                    integral_objective=integral)
    x = None if out.x is None else np.round(out.x)
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


def aggregate_columns(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Group the ``x`` columns of ``model`` that are identical: the same entries in every row,
    the same cost and the same bounds.

    ``A x`` and ``c x`` depend on such a group of ``k`` binaries only through how many of them
    are 1, so moving the ones within a group keeps every row and the objective
    (:func:`solve` with ``priority``).

    Returns
    -------
    group : (nx,) int
        Group of each ``x`` variable, numbered by first member.
    first : (g,) int
        First (lowest) variable of each group.
    """
    nx = model.var_site.size
    cols = sp.csc_array(model.A)[:, :nx]
    cols.sum_duplicates()
    # two fixed random projections identify columns; equality is then checked exactly
    proj = np.random.default_rng(0).standard_normal((2, cols.shape[0]))
    key = np.vstack([cols.T @ proj[0], cols.T @ proj[1], model.c[:nx], model.lb[:nx],
                     model.ub[:nx]])
    order = np.lexsort(key[::-1])  # stable: members of a group in variable order
    new_group = np.r_[np.ones(min(nx, 1), bool),
                      np.any(np.diff(key[:, order], axis=1) != 0, axis=0)]
    first = order[new_group]
    group = np.empty(nx, np.int64)
    group[order] = np.cumsum(new_group) - 1
    diff = cols - cols[:, first[group]]
    diff.eliminate_zeros()
    odd = np.unique(diff.tocoo().col) if diff.nnz else np.zeros(0, np.int64)
    odd = odd[first[group[odd]] != odd]
    group[odd] = first.size + np.arange(odd.size)  # a hash collision: kept on their own
    # number groups by first member
    _, first, group = np.unique(group, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[group.ravel()], first[order]


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


def accuracy_cuts(problem: PlanProblem, model: Model, selected: np.ndarray, config,
                  infos: list[StationInfo], outer_approximation: bool = False
                  ) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """Valid cuts for every station whose predicted accuracy fails with ``selected``.

    By default only the combinatorial (no-good) cuts, which stay valid for any looser
    requirement; with ``outer_approximation`` also the tangent cuts (``"oa"``, ``"oa-loss"``,
    ``"info-loss"``, ``"heading-loss"`` rows), valid for ``config.requirement_m`` only.

    Returns
    -------
    rows : (c, v) sparse or None
        ``None`` when every station passes.
    lower : list of float
        Row lower bounds (upper bounds are +inf).
    kinds : list of RowKind
    """
    rows, lower, kinds = [], [], []
    for s in range(problem.n_stations):
        info = infos[s]
        chosen = info.sites[selected[info.sites]]
        if info.error(chosen) > config.requirement_m:
            grown = info.grow_failing(chosen, None, config.requirement_m)
            rows.append(model.site_row(np.setdiff1d(info.sites, grown)))
            lower.append(1.0)
            kinds.append(RowKind("cut", s))
            for at in (chosen, grown) if outer_approximation else ():
                for oa in info.oa_cuts(at, config.requirement_m, rim="spread"):
                    rows.append(model.site_row(oa[0], oa[1]))
                    lower.append(oa[2])
                    kinds.append(RowKind("oa", s))
            continue
        if not config.redundant:
            continue
        for m in chosen:
            left = chosen[chosen != m]
            if info.error(left) > config.requirement_m:
                grown = info.grow_failing(left, int(m), config.requirement_m)
                rest = np.setdiff1d(info.sites, np.r_[grown, m])
                rows.append(model.implied_row(m, rest))
                lower.append(0.0)
                kinds.append(RowKind("cut-loss", s))
                if not outer_approximation:
                    continue
                for oa in info.oa_cuts(left, config.requirement_m, exclude=int(m)):
                    # if m is selected, the others alone must pass
                    rows.append(model.implied_row(m, oa[0], oa[1], oa[2]))
                    lower.append(0.0)
                    kinds.append(RowKind("oa-loss", s))
                # if m is selected, the others alone must carry the information cuts
                others = np.flatnonzero(problem.pair_site[info.pairs] != m)
                for w, name in zip(info_weights(problem, info.pairs[others], config),
                                   ("info", "heading"), strict=True):
                    rows.append(model.implied_row(m, info.sites[others], w))
                    lower.append(0.0)
                    kinds.append(RowKind(f"{name}-loss", s))
    block = sp.csr_array(sp.vstack(rows)) if rows else None
    return block, lower, kinds


#: Network mode: grow a failing station's set only when the problem's tie entries are fewer
#: (each growth step evaluates the network exactly).
_GROW_MAX_TIES = 250_000
#: Network mode: exact evaluations a growth may spend.
_GROW_MAX_EVALS = 14
#: Network mode: tangent cuts per round for at most this many failing stations (the worst;
#: their rows are dense over every tying site), and as many failing markers; a quarter of
#: that on large problems.
_MAX_OA_STATIONS = 20
#: Network mode, large problems: most terms of a cut row (see :func:`network_cuts`).
_MAX_TERMS = 500
#: Network mode, large problems: a sparse tangent row gives up at most this fraction of its
#: right-hand side (weaker rows, fewer terms: HiGHS slows badly on dense rows).
_SPARSE_SLACK = 0.9
#: Network mode: problems with more tying sites than this get sparse cut rows, under the
#: upper bound of the greedy layout's count.
_SPARSE_ABOVE_SITES = 8000
#: Network mode: most tying sites the integer program takes. Above it (``large`` at its 1 m grid
#: has about 86,000) the tangent rows touch tens of thousands of sites and HiGHS did not return
#: at its time limit in our runs; ``large`` at a 3 m grid (about 10,000) returns at the limit.
MAX_NETWORK_TYING_SITES = 20_000
#: Network mode, large problems: the greedy incumbent
#: (:func:`~planner.program.baselines.greedy_network`) starts no step after this fraction of the
#: time limit (it stops without a layout; the search goes on without an incumbent).
_GREEDY_TIME_FRACTION = 0.5
#: Network mode, large problems: the root relaxation (:func:`_root_relaxation`) spends at most
#: this fraction of the time left after the greedy incumbent, at most this many LP solves, and
#: stops when its bound rose less than this (relative) over 5 solves; its rows in the integer
#: program give up at most this fraction of their right-hand side.
_ROOT_TIME_FRACTION = 0.5
#: ... and at least this fraction of the whole time limit, even when the greedy incumbent took
#: the rest (a time-limited plan then still reports a proven bound; the run may exceed the
#: time limit by up to this fraction).
_ROOT_MIN_TIME_FRACTION = 0.1
_ROOT_MAX_ROUNDS = 100
_ROOT_STALL = 2e-3
_ROOT_SPARSE_SLACK = 0.05
#: Network mode, root relaxation: most moves of the in-point towards one LP solution.
_ROOT_MAX_STEPS = 8
#: Network mode: weight of the every-site information added to an undetermined layout's
#: information before linearising (any positive definite point gives valid tangents).
_REGULARISE = 0.05


def network_preflight(problem: PlanProblem, config, net: NetworkModel,
                      infos: list[StationInfo] | None = None) -> np.ndarray:
    """Network mode: sites whose marker can never meet the requirement, after checking that
    every station can.

    By monotonicity the best any layout can do is every allowed site selected: a marker whose
    error then exceeds the requirement can never be part of a passing layout (it is left out),
    and a station that then fails — or that no chain of shared sites ties to the reference —
    makes the plan infeasible.

    Returns
    -------
    hopeless : (n,) bool
        Sites to leave out.

    Raises
    ------
    InfeasiblePlanError
        Naming each station that cannot be satisfied and why (directions, disconnected,
        heading undetermined or too weak, too far from the reference), or an existing marker
        that cannot meet the requirement.
    """
    req = config.requirement_m
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    existing = problem.site_mask(config.existing, "existing") | problem.site_existing
    allowed = ~forbidden & (net.n_stations_seeing > 0)
    infos = infos or station_infos(problem, config)
    _raise_network_infeasible(problem, config, net, diagnose(problem, config, infos,
                                                              accuracy_check=False)
                              or net.diagnose(allowed, req))
    cov = net.covariance(net.information(allowed))
    sites = np.flatnonzero(allowed)
    err = net.marker_errors(cov, sites)
    hopeless = np.zeros(problem.n_sites, bool)
    hopeless[sites[err > req]] = True
    bad_existing = np.flatnonzero(hopeless & existing)
    if bad_existing.size:
        names = ", ".join(problem.site_ids[j] for j in bad_existing[:10])
        raise InfeasiblePlanError(f"existing marker(s) {names} cannot meet {req:g} m relative to "
                                  f"the reference {problem.station_ids[net.reference]} even with "
                                  "every usable site; relax the requirement")
    if hopeless.any():
        extra = tuple(problem.site_ids[j] for j in np.flatnonzero(hopeless & ~forbidden))
        _raise_network_infeasible(problem, config, net, diagnose(
            problem, config.replace(forbidden=config.forbidden + extra), infos,
            accuracy_check=False) or net.diagnose(allowed & ~hopeless, req))
    return hopeless


def _raise_network_infeasible(problem: PlanProblem, config, net: NetworkModel,
                              failing: dict[str, str]) -> None:
    """One-line :class:`InfeasiblePlanError` naming each failing station (none: return)."""
    req = config.requirement_m
    if failing:
        raise InfeasiblePlanError(
            f"no layout meets the requirement in network mode ({req:g} m relative to the "
            f"reference {problem.station_ids[net.reference]}, >= {config.min_markers} markers in "
            f">= {config.min_sectors} of {config.n_sectors} sectors) at station(s): "
            + "; ".join(f"{k}: {v}" for k, v in failing.items())
            + "; relax the configuration, add candidate sites or a heading prior")


def _sparse_tangent(coef: np.ndarray, rhs: float, upper_bound: int | None,
                    max_terms: int, slack: float = _SPARSE_SLACK
                    ) -> tuple[np.ndarray, np.ndarray, float]:
    """A tangent cut ``sum_j coef_j x_j >= rhs`` with fewer terms, valid for every layout of at
    most ``upper_bound`` sites.

    The terms are kept largest first: at least ``max_terms``, and as many more as it takes
    for the ``upper_bound`` largest dropped coefficients — the most the dropped terms can add
    — to sum to at most ``slack`` of ``rhs``; then
    ``sum_{kept} coef_j x_j >= rhs - (that sum)``.
    Returns ``(sites, coefficients, 1.0)`` normalised to ``>= 1``.
    """
    pos = np.flatnonzero(coef > 0)
    if upper_bound is None or pos.size <= max_terms:
        return pos, coef[pos] / rhs, 1.0
    order = pos[np.argsort(-coef[pos], kind="stable")]
    c = np.r_[coef[order], np.zeros(upper_bound)]
    cum = np.r_[0.0, np.cumsum(c)]
    k = np.arange(max_terms, order.size + 1)
    given_up = cum[k + upper_bound] - cum[k]  # the upper_bound largest after the first k
    k = int(k[np.argmax(given_up <= slack * rhs)])
    given_up = float(cum[k + upper_bound] - cum[k])
    keep = np.sort(order[:k])
    return keep, coef[keep] / (rhs - given_up), 1.0


def network_cuts(problem: PlanProblem, model: Model, selected: np.ndarray, config,
                 net: NetworkModel, j_all: np.ndarray, upper_bound: int | None = None
                 ) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """Valid cuts for every station and selected marker that fails with ``selected`` in
    network mode.

    Per failing station ``k`` (families): ``"cut"`` — the no-good cut: the selected tying
    sites ``T`` (grown to a larger failing ``T'`` on small problems) need one more site,
    ``sum_{j tying, j not in T'} x_j >= 1`` (monotonicity: every subset of ``T'`` fails);
    ``"connect"`` — a station cut off from the reference needs a selected site tying its
    component to the rest; ``"oa"`` — tangents of its convex worst-case variance
    (:meth:`planner.accuracy.network.NetworkModel.station_tangents`), linearised at the
    layout's information (plus ``_REGULARISE`` x the every-site information when the layout
    leaves a station undetermined; any positive definite point gives a valid tangent). Per
    failing selected marker ``m``: ``"cut-marker"`` ``sum_{j tying, not in T} x_j - x_m >= 0``
    and ``"oa-marker"`` ``sum_j c_j x_j - rhs x_m >= 0`` (enforced only when ``x_m = 1``).

    On large problems (``upper_bound`` given: no layout of interest has more sites, e.g. a
    feasible layout's count) tangent rows keep their ``_MAX_TERMS`` largest coefficients and
    lower their right-hand side by the most the dropped terms can add
    (:func:`_sparse_tangent`), and combinatorial rows over more than ``_MAX_TERMS`` sites are
    left out (valid, merely weak): every row is still valid for those layouts.

    Parameters
    ----------
    j_all : (P, P) float
        Information of every allowed site (the regularisation).
    upper_bound : int, optional
        Most sites a layout of interest selects (enables the sparse rows).

    Returns
    -------
    rows, lower, kinds
        As :func:`accuracy_cuts`; ``rows`` is ``None`` when everything passes.
    """
    req = config.requirement_m
    in_model = model.site_var >= 0
    open_site = in_model.copy()
    open_site[model.var_site[model.ub[:model.var_site.size] == 0]] = False
    tying = net.tying & open_site
    j_sel = net.information(selected)
    cov = net.covariance(j_sel)
    err = net.station_errors_from(cov)
    failing = np.flatnonzero(err > req)
    markers = np.flatnonzero(selected & open_site)
    merr = net.marker_errors(cov, markers)
    bad_markers = markers[merr > req]
    if failing.size == 0 and bad_markers.size == 0:
        if config.redundant:
            return _network_loss_cuts(model, selected, j_sel, config, net, tying, in_model,
                                      upper_bound)
        return None, [], []
    rows, lower, kinds = [], [], []

    def add(row, lo, kind):
        rows.append(row)
        lower.append(lo)
        kinds.append(kind)

    cov0 = cov if cov.determined.all() else net.covariance(j_sel + _REGULARISE * j_all)
    rim = "spread" if failing.size <= 10 else "worst"
    worst_first = failing[np.argsort(-np.nan_to_num(err[failing], posinf=1e300), kind="stable")]
    n_oa = _MAX_OA_STATIONS if upper_bound is None else _MAX_OA_STATIONS // 4
    tangents = net.station_tangents(cov0, worst_first[:n_oa], req, rim=rim)
    dense_ok = upper_bound is None

    for k, coef, rhs in tangents:
        cut = _sparse_tangent(np.where(in_model, coef, 0.0), rhs, upper_bound, _MAX_TERMS)
        add(model.site_row(cut[0], cut[1]), cut[2], RowKind("oa", k))
    grow = failing[np.argmax(err[failing])] if failing.size and \
        net.tie_a.size <= _GROW_MAX_TIES and np.isfinite(err[failing]).any() else -1
    linked = net.connected_to_reference(selected)

    def station_rows(stations: np.ndarray, dense: bool) -> None:
        """The "cut" and "connect" rows of failing ``stations`` (the short ones unless
        ``dense``)."""
        done_components = set()
        for k in stations:
            chosen = selected & tying
            if k == grow:
                first = [c for kk, c, _ in tangents if kk == k]
                chosen = _grow_network(net, chosen, int(k), req, tying & ~selected, j_sel,
                                       first[0] if first else None)
            rest = np.flatnonzero(tying & ~chosen)
            if dense or rest.size <= _MAX_TERMS:
                add(model.site_row(rest), 1.0, RowKind("cut", int(k)))
            if not linked[k]:
                comp = _component(net, selected, int(k))
                if comp in done_components:
                    continue
                done_components.add(comp)
                inside = np.zeros(problem.n_stations, bool)
                inside[list(comp)] = True
                a = np.bincount(net.pair_site, inside[net.pair_station],
                                minlength=problem.n_sites)
                b = net.n_stations_seeing - a
                bridge = np.flatnonzero(tying & (a > 0) & (b > 0))
                if dense or bridge.size <= 4 * _MAX_TERMS:
                    add(model.site_row(bridge), 1.0, RowKind("connect", int(k)))

    def marker_rows(markers: np.ndarray, dense: bool) -> None:
        """The "cut-marker" rows of failing ``markers`` (left out when long unless ``dense``)."""
        rest = np.flatnonzero(tying & ~selected)
        for m in markers if dense or rest.size <= _MAX_TERMS else ():
            add(model.implied_row(m, rest), 0.0, RowKind("cut-marker"))

    station_rows(failing, dense_ok)
    worst_m = bad_markers[np.argsort(-merr[merr > req], kind="stable")]
    if bad_markers.size:
        for m, coef, rhs in net.marker_tangents(cov, worst_m[:n_oa], req):
            cut = _sparse_tangent(np.where(in_model, coef, 0.0), rhs, upper_bound, _MAX_TERMS)
            add(model.implied_row(m, cut[0], cut[1]), 0.0, RowKind("oa-marker"))
    marker_rows(bad_markers, dense_ok)
    if not rows:  # no tangent is violated and every short row was left out: the worst
        # stations' and markers' long rows (valid; merely many terms)
        station_rows(worst_first[:n_oa], True)
        marker_rows(worst_m[:n_oa], True)
    if not rows:  # pragma: no cover - a failing station or marker always yields a no-good cut
        raise InfeasiblePlanError("network mode: the layout fails but no cut was found")
    return sp.csr_array(sp.vstack(rows)), lower, kinds


def _network_loss_cuts(model: Model, selected: np.ndarray, j_sel: np.ndarray, config,
                       net: NetworkModel, tying: np.ndarray, in_model: np.ndarray,
                       upper_bound: int | None
                       ) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """Redundant network mode: valid cuts for a layout that passes whole but fails at some
    station after losing one tying marker ``m``.

    ``"cut-loss"``: ``sum_{j tying, not selected} x_j - x_m >= 0`` (with ``m`` the layout needs a
    site outside the selected ones: every subset of the selected sites without ``m`` fails, by
    monotonicity); ``"oa-loss"``: the failing stations' tangents at the information without
    ``m``, enforced only when ``x_m = 1``: ``sum_{j != m} c_j x_j - x_m >= 0`` (normalised).
    Arguments as :func:`network_cuts` (``j_sel``: the layout's information, ``tying``: open
    tying sites, ``in_model``: sites that are variables). Returns ``(None, [], [])`` when
    every loss passes.
    """
    req = config.requirement_m
    markers, errors, covariances = net.loss_station_errors(selected, j_sel)
    rest = np.flatnonzero(tying & ~selected)
    rows, lower, kinds = [], [], []
    for m, err, cov in zip(markers, errors, covariances, strict=True):
        bad = np.flatnonzero(err > req)
        if bad.size == 0:
            continue
        rows.append(model.implied_row(m, rest))
        lower.append(0.0)
        kinds.append(RowKind("cut-loss", int(bad[0])))
        for k, coef, rhs in net.station_tangents(cov, bad, req):
            coef = np.where(in_model, coef, 0.0)
            coef[m] = 0.0
            sites, c, _ = _sparse_tangent(coef, rhs, upper_bound, _MAX_TERMS)
            rows.append(model.implied_row(m, sites, c))
            lower.append(0.0)
            kinds.append(RowKind("oa-loss", k))
    if not rows:
        return None, [], []
    return sp.csr_array(sp.vstack(rows)), lower, kinds


def _component(net: NetworkModel, selected: np.ndarray, k: int) -> frozenset:
    """Stations linked to station ``k`` by shared selected sites."""
    from scipy.sparse.csgraph import connected_components

    _, comp = connected_components(sp.csr_array(net.ties(selected) > 0), directed=False)
    return frozenset(np.flatnonzero(comp == comp[k]).tolist())


def _grow_network(net: NetworkModel, chosen: np.ndarray, k: int, requirement_m: float,
                  candidates: np.ndarray, j_chosen: np.ndarray, coef) -> np.ndarray:
    """Grow station ``k``'s failing set ``chosen`` by the candidate sites that help its worst
    direction least (``coef`` ascending; by site order without one), as far as it keeps
    failing: by monotonicity "the set plus the first ``m`` candidates fails" is monotone in
    ``m``, so the largest such ``m`` is found by bisection (at most ``_GROW_MAX_EVALS`` exact
    evaluations). Returns the grown (still failing) set, (n,) bool."""
    cand = np.flatnonzero(candidates)
    if cand.size == 0:
        return chosen
    order = cand[np.argsort(coef[cand], kind="stable")] if coef is not None else cand
    def fails(m: int) -> bool:
        x = np.zeros(net.problem.n_sites)
        x[order[:m]] = 1.0
        j = j_chosen + net.site_information(x)
        cov = net.covariance(j)
        if not cov.determined[k]:
            return True
        e = net.station_errors_from(cov)[k]
        return bool(e > requirement_m)

    lo, hi = 0, order.size
    for _ in range(_GROW_MAX_EVALS):
        if lo >= hi:
            break
        mid = (lo + hi + 1) // 2
        if fails(mid):
            lo = mid
        else:
            hi = mid - 1
    grown = chosen.copy()
    grown[order[:lo]] = True
    return grown


def plan_sites(problem: PlanProblem, config, model: Model | None = None) -> PlanResult:
    """The accuracy-cut loop: solve, check stations exactly, cut, re-solve until all pass.

    Parameters
    ----------
    problem : PlanProblem
    config : PlanConfig
        Also uses ``time_limit_s`` (for the whole loop) and ``mip_gap``.
    model : Model, optional
        A model built (and possibly modified) by the caller; default ``build_model``.

    Returns
    -------
    result : PlanResult

    Raises
    ------
    InfeasiblePlanError
        Naming each station that cannot be satisfied and why, or the budget;
        :class:`~markerplan.errors.PlanTimeLimitError` (a subclass) when the time limit ended
        the search before any layout passed.
    """
    infos = station_infos(problem, config)
    if config.network:
        return _plan_network(problem, config, model, infos)
    t0 = time.perf_counter()
    first = None
    if model is None:
        first, rows = _combinatorial_first(problem, config, infos)
        if rows is None:
            return first
        model = with_tightening_rows(problem, build_model(problem, config), config)
        if rows[0] is not None:
            model = model.with_rows(rows[0], rows[1], np.full(len(rows[1]), np.inf), rows[2])
    failing = diagnose(problem, config, infos)
    if failing:
        raise InfeasiblePlanError(
            f"no layout meets the requirement ({config.requirement_m:g} m, "
            f">= {config.min_markers} markers in >= {config.min_sectors} of {config.n_sectors} "
            "sectors) at station(s): "
            + "; ".join(f"{k}: {v}" for k, v in failing.items())
            + "; relax the configuration or add candidate sites")

    def cuts(selected):
        return accuracy_cuts(problem, model, selected, config, infos, outer_approximation=True)

    def check(selected):
        return evaluate_layout(problem, selected, config, infos)

    result = _cut_loop(problem, config, model, cuts, check, t0=t0)
    if first is None:
        return result
    return replace(result, iterations=result.iterations + first.iterations,
                   n_cuts=result.n_cuts + first.n_cuts,
                   solve_time_s=result.solve_time_s + first.solve_time_s,
                   history=first.history + result.history)


def _combinatorial_first(problem: PlanProblem, config, infos: list[StationInfo]
                         ) -> tuple[PlanResult | None, tuple | None]:
    """Known control: solve the directions rows alone first; done if that passes.

    :func:`build_model` without its information rows is the plain cover-plus-sector model. It
    is a relaxation of the full program (every row left out — information, tightening,
    accuracy cuts — holds for every passing layout), so its optimum bounds the full one from
    below: a layout that is optimal here and passes every station's exact check is optimal for the
    plan. In it many candidate sites have identical columns (same stations, same sectors):
    the markers of such a group go to its members with the most information
    (``sum 3 / sigma^2`` over their usable pairs).

    Returns
    -------
    result : PlanResult or None
        The plan when the layout passes (then ``rows`` is None), else the first solve's
        record (iterations, cuts, solver time, history) for the loop that follows.
    rows : tuple or None
        ``(rows, lower, kinds)`` of :func:`accuracy_cuts` for the failing layout (``rows``
        None when there was no layout), to add to the full model.
    """
    relaxed = build_model(problem, config, information=False)
    usable = np.flatnonzero(problem.pair_usable)
    info = np.bincount(problem.pair_site[usable], 3.0 / problem.pair_sigma_m[usable] ** 2,
                       minlength=problem.n_sites)
    sol = solve(relaxed, config.time_limit_s, config.mip_gap, priority=info[relaxed.var_site])
    history = [{"iteration": 1, "status": sol.status, "objective": sol.objective,
                "dual_bound": sol.dual_bound, "solve_time_s": sol.solve_time_s,
                "n_rows": int(relaxed.A.shape[0])}]
    rows, check = (None, [], []), None
    if sol.selected is not None:
        # the exact check first: a layout it passes needs no cuts
        check = evaluate_layout(problem, sol.selected, config, infos)
        if not check.all_ok:
            rows = accuracy_cuts(problem, relaxed, sol.selected, config, infos,
                                 outer_approximation=True)
    result = PlanResult(selected=sol.selected, check=check, solution=sol, iterations=1,
                        n_cuts=0 if rows[0] is None else rows[0].shape[0],
                        solve_time_s=sol.solve_time_s, model=relaxed, history=history)
    if sol.selected is not None and rows[0] is None:
        return result, None
    return result, rows


def _plan_network(problem: PlanProblem, config, model: Model | None,
                  infos: list[StationInfo]) -> PlanResult:
    """:func:`plan_sites` in network mode: the same build/solve/cut loop with the network's
    accuracy checks and cuts (:func:`network_cuts`)."""
    t0 = time.perf_counter()
    net = network_model(problem, config)
    n_tying = int(net.tying.sum())
    if n_tying > MAX_NETWORK_TYING_SITES:
        raise ConfigError(
            f"network mode takes at most {MAX_NETWORK_TYING_SITES:,} candidate sites seen by two "
            f"or more stations; this site has {n_tying:,}: coarsen the candidate grid "
            f"(grid_spacing_m in --config; {config.grid_spacing_m:g} m now, try "
            f"{config.grid_spacing_m * math.sqrt(n_tying / MAX_NETWORK_TYING_SITES) * 1.2:.1f} m)")
    hopeless = network_preflight(problem, config, net, infos)
    if model is None:
        model = with_tightening_rows(problem, build_model(problem, config), config)
    ub = model.ub.copy()
    var = model.site_var[np.flatnonzero(hopeless)]
    ub[var[var >= 0]] = 0.0
    model = replace(model, ub=ub)
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    j_all = net.information(~forbidden & ~hopeless & (net.n_stations_seeing > 0))
    upper_bound = greedy_selected = greedy = None
    root_bound = -np.inf
    existing = problem.site_mask(config.existing, "existing") | problem.site_existing
    if int(net.tying.sum()) > _SPARSE_ABOVE_SITES and not config.redundant \
            and np.all(problem.site_cost[~existing] == 1):
        # every layout at least as good as the greedy one has at most its number of sites
        from planner.program.baselines import network_baseline

        # a stuck greedy gives no starting layout: the search goes on without one
        greedy = network_baseline(problem, config.replace(
            forbidden=config.forbidden + tuple(
                problem.site_ids[j] for j in np.flatnonzero(hopeless & ~forbidden))), net,
            deadline=t0 + _GREEDY_TIME_FRACTION * config.time_limit_s)
    if greedy is not None and greedy.meets_requirement:
        in_model = model.site_var >= 0
        greedy_selected = greedy.selected
        upper_bound = int((greedy.selected & in_model).sum())
        nx = model.var_site.size
        row = sp.csr_array((np.ones(nx), (np.zeros(nx, np.int64), np.arange(nx))),
                           shape=(1, model.n_vars))
        model = model.with_rows(row, [-np.inf], [float(upper_bound)],
                                [RowKind("upper-bound")])
        budget_s = max(_ROOT_TIME_FRACTION * (config.time_limit_s - (time.perf_counter() - t0)),
                       _ROOT_MIN_TIME_FRACTION * config.time_limit_s)
        model, root_bound = _root_relaxation(problem, model, config, net, upper_bound, budget_s)

    def cuts(selected):
        return network_cuts(problem, model, selected, config, net, j_all, upper_bound)

    def check(selected):
        return evaluate_layout(problem, selected, config, infos, net=net)

    result = _cut_loop(problem, config, model, cuts, check, incumbent=greedy_selected, t0=t0,
                       bound=root_bound)
    return replace(result, greedy=greedy)


def _root_relaxation(problem: PlanProblem, model: Model, config, net: NetworkModel,
                     upper_bound: int, budget_s: float) -> tuple[Model, float]:
    """Tighten a large network model at its LP relaxation before branching; a lower bound.

    With ``x`` relaxed to ``[0, 1]``: first one tangent per station at the every-site
    information scaled onto the requirement's boundary, ``J_t = J_prior + t (J_all - J_prior)``
    with ``t = (e_all / requirement)^2``; then an in-out cutting-plane loop: linearise at
    ``x_lin = (x_LP + x_in) / 2`` (``x_in`` the last point where every station passes, at
    first every open site); where ``x_lin`` passes it becomes ``x_in``, otherwise its failing
    stations' tangents (:meth:`~planner.accuracy.network.NetworkModel.station_tangents`, worst
    rim point) are added and the LP is solved again. Linearising between the two points keeps
    the tangents informative where the LP solution alone leaves stations untied. Every
    tangent is valid for every layout (the error is convex in the information), so each LP
    optimum bounds the fewest markers from below. Stops after ``budget_s``, ``_ROOT_MAX_ROUNDS``
    solves, when the bound rose less than ``_ROOT_STALL`` (relative) over 5 solves, or when
    the LP solution passes every station (to ``_ROOT_MAX_STEPS`` halvings).

    The integer program gets the rows sparsified under ``upper_bound``
    (:func:`_sparse_tangent`, giving up at most ``_ROOT_SPARSE_SLACK`` of each right-hand
    side); the returned bound is the LP's with the full rows.

    Returns
    -------
    model : Model
        ``model`` with the rows (family ``"oa-root"``).
    bound : float
        Proven lower bound on the objective (``-inf`` when no LP solved).
    """
    t0 = time.perf_counter()
    req = config.requirement_m
    nx = model.var_site.size
    in_model = model.site_var >= 0
    x_in = np.zeros(problem.n_sites)
    x_in[model.var_site] = model.ub[:nx]
    x_in *= net.tying
    sites_all = net.site_information(x_in)
    prior = np.diag(net.prior)
    e_all = net.station_errors_from(net.covariance(prior + sites_all))
    cuts = []  # (station, coefficients (n,), rhs)
    tied = np.flatnonzero(np.isfinite(e_all) & (np.arange(problem.n_stations) != net.reference))
    try:  # every station determined: one decomposition for all the scaled informations
        scaled = net.scaled_covariances(sites_all, (e_all[tied] / req) ** 2, tied)
    except np.linalg.LinAlgError:
        scaled = ((int(k), net.covariance(prior + (e_all[k] / req) ** 2 * sites_all))
                  for k in tied)
    for k, cov_t in scaled:
        cuts += net.station_tangents(cov_t, [k], req)
    lp = replace(model, integrality=np.zeros_like(model.integrality))
    bound, history = -np.inf, []
    added = 0
    for _ in range(_ROOT_MAX_ROUNDS):
        if cuts[added:]:
            rows = sp.vstack([model.site_row(np.flatnonzero(in_model & (c > 0)),
                                             c[in_model & (c > 0)] / rhs)
                              for _, c, rhs in cuts[added:]])
            n = len(cuts) - added
            lp = lp.with_rows(rows, np.ones(n), np.full(n, np.inf), [RowKind("oa-root")] * n)
            added = len(cuts)
        remaining = budget_s - (time.perf_counter() - t0)
        if remaining <= 0:
            break
        sol = solve(lp, remaining, 0.0)
        if sol.status != "optimal" or sol.x is None:
            break
        bound = max(bound, sol.objective)
        history.append(bound)
        x_lp = np.zeros(problem.n_sites)
        x_lp[model.var_site] = sol.x[:nx]
        if len(history) > 5 and history[-1] - history[-6] < _ROOT_STALL * abs(history[-1]):
            break
        failing = np.zeros(0, np.int64)
        for _ in range(_ROOT_MAX_STEPS):
            x_lin = 0.5 * (x_lp + x_in)
            cov = net.covariance(net.information(x_lin))
            failing = np.flatnonzero(net.station_errors_from(cov) > req)
            if failing.size:
                break
            x_in = x_lin
        if failing.size == 0:  # the LP solution (nearly) passes: the relaxation is solved
            break
        cuts += net.station_tangents(cov, failing, req)
    kept = []
    for k, c, rhs in cuts:
        sites, coef, lo = _sparse_tangent(np.where(in_model, c, 0.0), rhs, upper_bound,
                                          _MAX_TERMS, _ROOT_SPARSE_SLACK)
        kept.append((model.site_row(sites, coef), lo, RowKind("oa-root", int(k))))
    if kept:
        rows, lower, kinds = zip(*kept, strict=True)
        model = model.with_rows(sp.vstack(rows), lower, np.full(len(lower), np.inf), kinds)
    return model, bound


def _cut_loop(problem: PlanProblem, config, model: Model, cuts, check,
              incumbent: np.ndarray | None = None, t0: float | None = None,
              bound: float = -np.inf) -> PlanResult:
    """Solve, cut with ``cuts(selected) -> (rows, lower, kinds)`` (``rows`` None: passes),
    re-solve until every check passes; ``check(selected) -> LayoutCheck``.

    ``incumbent`` ((n,) bool, a layout known to pass): when the time limit stops the loop, or
    when a proven lower bound reaches its cost (then with status ``"optimal"``), it is the
    answer, with status ``"time_limit"``, the best lower bound proved (``bound``, proved before
    the loop, and every solve's dual bound: every cut is valid) and their gap. ``t0``: when
    the time limit started (default now).
    """
    t0 = time.perf_counter() if t0 is None else t0
    solve_time = 0.0
    n_cuts = 0
    history = []
    iteration = 0
    while True:
        iteration += 1
        remaining = config.time_limit_s - (time.perf_counter() - t0)
        proven = incumbent is not None and np.isfinite(bound) \
            and math.ceil(bound - 1e-6) >= problem.site_cost[incumbent].sum() - 1e-9
        if (remaining <= 0 or proven) and incumbent is not None:
            obj = float(problem.site_cost[incumbent].sum())
            gap = max(obj - bound, 0.0) / max(abs(obj), 1e-9) if np.isfinite(bound) \
                else float("nan")
            sol = Solution(status="optimal" if proven else "time_limit", selected=incumbent,
                           objective=obj, dual_bound=float(bound), gap=0.0 if proven else gap,
                           solve_time_s=0.0,
                           message="the passing layout found first: proven optimal by the "
                                   "lower bound" if proven else
                                   "time limit: the passing layout found first, with the best "
                                   "proven bound")
            return PlanResult(selected=incumbent, check=check(incumbent), solution=sol,
                              iterations=iteration - 1, n_cuts=n_cuts,
                              solve_time_s=solve_time, model=model, history=history)
        if remaining <= 0:
            raise PlanTimeLimitError(
                f"time limit {config.time_limit_s:g} s reached after {iteration - 1} "
                "iteration(s) before every station met the accuracy requirement; "
                "raise --time-limit")
        sol = solve(model, remaining, config.mip_gap)
        solve_time += sol.solve_time_s
        if np.isfinite(sol.dual_bound):
            bound = max(bound, sol.dual_bound)
        history.append({"iteration": iteration, "status": sol.status,
                        "objective": sol.objective, "dual_bound": sol.dual_bound,
                        "solve_time_s": sol.solve_time_s, "n_rows": int(model.A.shape[0])})
        if sol.selected is None:
            if sol.status == "infeasible":
                why = (f"the marker budget ({config.budget}) is too small"
                       if config.budget is not None else
                       "the stations' direction and accuracy requirements conflict")
                raise InfeasiblePlanError(f"no layout is feasible: {why}; "
                                          "raise --budget or relax the configuration")
            if incumbent is not None:
                continue  # time limit: the incumbent is the answer
            raise PlanTimeLimitError(f"solver found no layout ({sol.status}: {sol.message}); "
                                     "raise --time-limit")
        rows, lower, kinds = cuts(sol.selected)
        if rows is None:
            return PlanResult(selected=sol.selected, check=check(sol.selected), solution=sol,
                              iterations=iteration, n_cuts=n_cuts, solve_time_s=solve_time,
                              model=model, history=history)
        n_cuts += rows.shape[0]
        model = model.with_rows(rows, lower, np.full(len(lower), np.inf), kinds)
