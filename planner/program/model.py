"""The integer program as data: its rows, variables and bounds, built from a plan problem.

:func:`build_model` turns a :class:`~planner.problem.usability.PlanProblem` into a :class:`Model`
(plain data: ``c``, sparse ``A``, row and variable bounds, index maps);
:func:`with_tightening_rows` adds the valid rows that tighten it for one requirement level, and
:func:`aggregate_columns` groups its identical site columns. Models are immutable:
:meth:`Model.with_rows` returns a new model, so what-if studies re-use one model with changed
bounds (``dataclasses.replace``) or added rows. Every row carries a :class:`RowKind` (its family
and station), so no caller parses row labels. :class:`Solution` (one solve) and
:class:`PlanResult` (the cut loop) are the records the other modules return.

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
- tightening rows added by :func:`~planner.program.loop.plan_sites` (:func:`with_tightening_rows`,
  valid for the configured requirement only): heading information
  ``sum_j (3 |d_sj|^2 / sigma_sj^2) x_j >= chi2_3(0.95) R^2 / requirement^2`` and
  outer-approximation tangents at 9 rim points;
- accuracy cuts (added lazily, :func:`planner.program.cuts_known.accuracy_cuts`): the predicted
  error is monotone in the marker set, so when station ``s`` fails with a set ``T`` every subset
  of ``T`` fails too. ``T`` is first grown greedily to a larger failing set ``T'`` (a stronger
  cut), then ``sum_{j in U_s \\ T'} x_j >= 1``. In redundant mode, when losing marker ``m`` leaves
  a failing set ``T`` (grown to ``T'`` without ``m``):
  ``sum_{j in U_s \\ T', j != m} x_j - x_m >= 0``. Each failing set also yields an
  outer-approximation cut (the tangent of the convex worst-case variance,
  :meth:`planner.accuracy.checks.StationInfo.oa_cuts`), which carries the geometry — which sites
  would fix the failing direction — and makes the loop converge in a few rounds.

Options: existing markers (lower bound 1, cost 0), forbidden sites (upper bound 0), a budget
row ``sum_j x_j <= budget``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

from markerplan.errors import ConfigError
from pipeline.network.observations import Datum
from planner.accuracy import known_control
from planner.accuracy.checks import LayoutCheck, StationInfo
from planner.accuracy.figure import error_figure
from planner.problem.usability import PlanProblem, sector_index

if TYPE_CHECKING:
    from planner.program.baselines import Baseline
    from planner.program.local_search import Pruning


@dataclass(frozen=True)
class RowKind:
    """What one row of a :class:`Model` is.

    Attributes
    ----------
    family : str
        "count", "info", "sector", "sector2", "sector21", "directions", "directions-loss",
        "budget" (from :func:`build_model`), "heading", "oa0" (:func:`with_tightening_rows`), "cut",
        "oa", "cut-loss", "oa-loss", "info-loss", "heading-loss"
        (:func:`~planner.program.cuts_known.accuracy_cuts`);
        network mode: "upper-bound", "cut", "connect", "oa", "cut-marker", "oa-marker",
        "cut-pair", "oa-pair", "cut-marker-pair", "oa-marker-pair"
        (:func:`~planner.program.cuts_network.network_cuts`), redundant:
        "cut-loss", "oa-loss", "cut-loss-pair", "oa-loss-pair", "cut-loss-marker-pair",
        "oa-loss-marker-pair" (:func:`~planner.program.cuts_network._network_loss_cuts`),
        "cut-bias"
        (:func:`~planner.program.cuts_network.bias_cuts`); chance-constrained:
        "chance-count", "chance-critical", "chance", "chance-undecided"
        (:mod:`planner.program.cuts_chance`).
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
    """One HiGHS solve (:func:`~planner.program.solving.solve`).

    Attributes
    ----------
    status : str
        "optimal", "gap_reached" (a feasible answer within the target MIP gap), "time_limit" (a
        feasible answer, not proven optimal), "infeasible", "no_solution" (time limit with no
        feasible answer) or "error".
    selected : (n,) bool or None
        Candidate sites holding a marker.
    objective, dual_bound, gap : float
        Objective, HiGHS dual bound and relative gap (nan when unknown).
    solve_time_s : float
    message : str
    x : (v,) float or None
        The solution: integer variables rounded to whole numbers, continuous ones (a linear
        relaxation's) as solved.
    """

    status: str
    selected: np.ndarray | None
    objective: float
    dual_bound: float
    gap: float
    solve_time_s: float
    message: str
    x: np.ndarray | None = None

    @property
    def success(self) -> bool:
        """Whether the solver reached a proven optimum (status ``"optimal"``), the meaning of
        :attr:`scipy.optimize.OptimizeResult.success`: a feasible answer within the target gap
        (``"gap_reached"``) or at the time limit is no success, however good.

        Examples
        --------
        >>> Solution("optimal", None, 3.0, 3.0, 0.0, 0.1, "").success
        True
        >>> Solution("time_limit", None, 4.0, 3.0, 0.25, 60.0, "").success
        False
        """
        return self.status == "optimal"


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
        the directions-only relaxation it solved, see :func:`~planner.program.loop.plan_sites`).
    history : list of dict
        Per solve: iteration, status, objective, dual bound, solve time, rows.
    greedy : planner.program.baselines.Baseline or None
        Network mode on large problems: the greedy layout the loop started from (its
        incumbent and upper bound), so callers need not run the greedy baseline again.
    pruning : planner.program.local_search.Pruning or None
        Network mode on large problems: the local search that pruned the greedy layout.
    root : dict or None
        Network mode on large problems: the root relaxation's record
        (:func:`~planner.program.loop._root_relaxation`: proven bound, LP solves, rows, wall
        time s, why it stopped).
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
    pruning: Pruning | None = None
    root: dict | None = None

    @property
    def status(self) -> str:
        return self.solution.status

    @property
    def success(self) -> bool:
        """Whether the final solve proved its layout optimal (:attr:`Solution.success`, the
        meaning of :attr:`scipy.optimize.OptimizeResult.success`); the layout meets every
        station's requirement either way, only its marker count may not be the fewest."""
        return self.solution.success


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
        (same variables: rows of one fit the other). They are sized for the requirement
        relative to the datum, so a network plan that does not judge it
        (``datum_requirement`` false) has none.

    Returns
    -------
    model : Model
    """
    information = information and judges_datum(config)
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
    return Datum(reference_station=config.reference_station).resolve(problem.station_ids)


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
    requirement level must leave them out. None when the plan does not judge the datum
    requirement (:func:`judges_datum`).
    """
    rows, lower, kinds = [], [], []
    reference = _reference_index(problem, config)
    for s in range(problem.n_stations if judges_datum(config) else 0):
        idx = problem.usable_pairs(s)
        if idx.size == 0 or s == reference:
            continue
        if not config.heading_observed:
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


def judges_datum(config) -> bool:
    """Whether the plan judges each station relative to the datum (always in known-control
    mode; in network mode unless ``datum_requirement`` is false): the ``info``, ``heading`` and
    ``oa0`` rows are necessary for that requirement only, and would cut off layouts that meet a
    local requirement alone."""
    return not config.network or bool(config.datum_requirement)


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
    figure = error_figure(config)
    w_t = w / known_control.information_lower_bound(config.requirement_m, figure)
    w_h = w * np.sum(d**2, axis=1) / known_control.heading_information_lower_bound(
        config.requirement_m, config.working_radius_m, figure)
    return w_t, w_h



def aggregate_columns(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Group the ``x`` columns of ``model`` that are identical: the same entries in every row,
    the same cost and the same bounds.

    ``A x`` and ``c x`` depend on such a group of ``k`` binaries only through how many of them
    are 1, so moving the ones within a group keeps every row and the objective
    (:func:`~planner.program.solving.solve` with ``priority``).

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

