"""The joint program: where the rover stops and where markers go, chosen together.

:func:`plan_stations_and_sites` chooses, among candidate stations, the ones the rover stops at
and, among candidate sites, the ones that get a marker, at the least stated cost, such that
every cell of the area of interest is covered and every chosen station meets the marker
program's rules (count, directions and, in known-control mode, accuracy).

Formulation
-----------
The marker program of :func:`~planner.program.model.build_model` over every candidate
station, plus a binary ``w_s`` per candidate station ("the rover stops at s"):

- every row of station ``s`` is switched on by ``w_s`` (:func:`switched_rows`): a row
  ``a x >= L`` becomes ``a x - (L + N) w_s >= -N``, with ``N`` the sum of the magnitudes of its
  negative coefficients (the least ``a x`` can be over binary ``x``), so it reads ``a x >= L``
  when ``w_s = 1`` and holds for every ``x`` when ``w_s = 0``; a row ``a x <= U`` likewise
  with ``P``, the sum of its positive coefficients. The rows that bound a station's own
  sector variables (``y <= sum x``: families "sector", "sector2", "sector21") need no switch:
  with the station off, its sector variables are free to be 0;
- coverage: ``sum_{s covers c} w_s >= k`` for every AOI cell ``c`` (cells with the same
  covering stations share one row);
- cost: ``station_cost sum_s w_s + marker_cost sum_j site_cost_j x_j``;
- known control: the accuracy cuts of :func:`planner.program.cuts_known.accuracy_cuts` for the
  chosen stations that fail, switched on by their ``w_s``: valid, since a station's predicted
  accuracy depends only on its own markers;
- clearance: ``x_j + w_s <= 1`` for a site ``j`` too near candidate station ``s`` (the rover
  does not stop on a marker);
- stations that no layout can satisfy (:func:`planner.accuracy.checks.diagnose`) are fixed off;
- with a drive priced (``JointCosts.drive_per_m`` and the drive lengths), the closed tour from
  the route start through the chosen stations (:mod:`planner.program.joint_tour`), its drive
  in the cost, tightened at the root by connectivity cuts whose relaxation, with the fewest
  markers any station needs, bounds the whole cost (:mod:`planner.program.joint_tour_cuts`).

Network mode judges the network (every station's pose depends on the others), which this
program does not model: there it chooses stations by coverage, count and directions, and the
caller plans the network's markers for the chosen stations.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from markerplan.errors import ConfigError, InfeasiblePlanError, PlanTimeLimitError
from planner.accuracy.checks import diagnose, station_infos
from planner.problem.usability import PlanProblem
from planner.program.cuts_known import accuracy_cuts
from planner.program.joint_tour import (
    TourBlock,
    leg_cost_units,
    leg_lengths_m,
    max_stations,
    tour_block,
    tour_graph,
    tour_legs,
    tour_order,
    tour_start,
)
from planner.program.joint_tour_cuts import fewest_markers_bound, tighten_tour
from planner.program.model import Model, RowKind, Solution, build_model, with_tightening_rows
from planner.program.solving import logged_solve

#: Row families that bound a station's own sector variables and need no switch.
_OWN_VARIABLE_FAMILIES = frozenset({"sector", "sector2", "sector21"})


@dataclass(frozen=True)
class StationCover:
    """Which cells of the area of interest each candidate station covers.

    Attributes
    ----------
    pair_station, pair_cell : (p,) int
        Candidate-station index and cell index of every covering pair.
    n_cells : int
    min_stations : int
        Stations that must cover every cell (1, or 2 for a double cover).
    """

    pair_station: np.ndarray
    pair_cell: np.ndarray
    n_cells: int
    min_stations: int = 1

    def counts(self, stations: np.ndarray) -> np.ndarray:
        """(n_cells,) int: how many of the given stations ((s,) bool) cover each cell."""
        on = np.asarray(stations, bool)[self.pair_station]
        return np.bincount(self.pair_cell[on], minlength=self.n_cells)

    def covered(self, stations: np.ndarray) -> bool:
        """Whether the given stations ((s,) bool) cover every cell ``min_stations`` times."""
        return bool(np.all(self.counts(stations) >= self.min_stations))


@dataclass(frozen=True)
class JointCosts:
    """The stated cost the joint program minimises (any unit, the same for all; seconds of
    mission time in :mod:`planner.design.run`).

    Attributes
    ----------
    station : float
        Cost of one stop (scan and set-up), >= 0 (0: the program counts markers only, e.g. for
        the fewest markers any layout needs).
    marker : float
        Cost of one marker placed, > 0.
    drive_per_m : float
        Cost of one metre driven, >= 0 (0: the drive is not in the program; with it, the
        program also chooses the tour, :mod:`planner.program.joint_tour`).
    """

    station: float
    marker: float
    drive_per_m: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.marker) and self.marker > 0):
            raise ConfigError(f"the cost per marker must be finite and > 0, got "
                              f"{self.marker!r}")
        if not (np.isfinite(self.station) and self.station >= 0):
            raise ConfigError(f"the cost per station must be finite and >= 0, got "
                              f"{self.station!r}")
        if not (np.isfinite(self.drive_per_m) and self.drive_per_m >= 0):
            raise ConfigError(f"the cost per metre driven must be finite and >= 0, got "
                              f"{self.drive_per_m!r}")

    @property
    def unit(self) -> float:
        """The program's unit of cost: the greatest common divisor of the station and marker
        costs when both are whole numbers and nothing is driven (every objective value is then
        a whole number of units, so HiGHS proves an optimum once its bound is within one unit);
        else 1 (with a drive, each leg's cost is rounded to whole units,
        :func:`~planner.program.joint_tour.leg_cost_units`).

        >>> JointCosts(300.0, 180.0).unit, JointCosts(1.5, 1.0).unit
        (60.0, 1.0)
        >>> JointCosts(300.0, 180.0, drive_per_m=20.0).unit
        1.0
        """
        if not self.integral or self.drive_per_m > 0:
            return 1.0
        return float(math.gcd(int(self.station), int(self.marker)))

    @property
    def integral(self) -> bool:
        """Whether every objective value is a whole number of :attr:`unit` (the station and
        marker costs are whole numbers; each leg's cost is rounded to whole units)."""
        return all(float(v).is_integer() for v in (self.station, self.marker))

    def of(self, n_stations: int, n_markers: int, drive_units: float = 0.0) -> float:
        """Cost of a layout with that many stations and (new) markers, and a drive costing
        ``drive_units`` units of :attr:`unit`."""
        return self.station * n_stations + self.marker * n_markers + drive_units * self.unit


@dataclass(frozen=True)
class JointModel:
    """The joint program as data.

    Attributes
    ----------
    model : Model
        The marker program's variables first (``model.var_site`` maps them), then one ``w``
        per candidate station; costs in units of :attr:`JointCosts.unit`.
    station_var : (s,) int
        Variable index of each candidate station's ``w``.
    excluded : dict
        Candidate stations fixed off, by id, with the reason no layout can satisfy them.
    tour : TourBlock or None
        The tour's columns and rows (after the ``w``), when the drive is priced.
    """

    model: Model
    station_var: np.ndarray
    excluded: dict
    tour: TourBlock | None = None


@dataclass(frozen=True)
class JointResult:
    """The joint plan.

    Attributes
    ----------
    stations : (s,) bool
        Candidate stations the rover stops at.
    selected : (n,) bool
        Candidate sites holding a marker.
    solution : Solution
        The final solve (status, objective, dual bound, gap), or the incumbent's record.
    iterations, n_cuts : int
    solve_time_s : float
    excluded : dict
        Candidate stations fixed off, by id, with the reason.
    history : list of dict
        Per solve: iteration, status, objective, dual bound, solve time, rows.
    tour : (k,) int or None
        With the drive priced: the chosen candidate stations in the program's driving order.
    tour_complete : bool or None
        With the drive priced: whether the tour could use every edge (the bound then holds
        for every tour; else for tours over the kept edges,
        :func:`~planner.program.joint_tour.tour_graph`).
    """

    stations: np.ndarray
    selected: np.ndarray
    solution: Solution
    iterations: int
    n_cuts: int
    solve_time_s: float
    excluded: dict
    history: list = field(default_factory=list)
    tour: np.ndarray | None = None
    tour_complete: bool | None = None

    @property
    def status(self) -> str:
        return self.solution.status


def switched_rows(A: sp.csr_array, row_lb: np.ndarray, row_ub: np.ndarray,
                  row_station: np.ndarray, station_var: np.ndarray, n_vars: int
                  ) -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    """Rows of stations switched on by their station variable (see the module docstring).

    Parameters
    ----------
    A : (m, v0) sparse
        The rows, over the first ``v0 <= n_vars`` variables.
    row_lb, row_ub : (m,) float
        Their bounds; a switched row has exactly one of them finite.
    row_station : (m,) int
        Candidate station of each row; -1 leaves the row as it is.
    station_var : (s,) int
        Variable index of each candidate station's switch.
    n_vars : int
        Columns of the result.

    Returns
    -------
    A, row_lb, row_ub
        ``(m, n_vars)`` rows and their bounds.

    Examples
    --------
    >>> A = sp.csr_array(np.array([[1.0, 1.0, 0.0], [1.0, -1.0, 0.0]]))
    >>> B, lb, ub = switched_rows(A, np.array([2.0, 0.0]), np.array([np.inf, np.inf]),
    ...                           np.array([0, 0]), np.array([2]), 3)
    >>> B.toarray().tolist(), lb.tolist()
    ([[1.0, 1.0, -2.0], [1.0, -1.0, -1.0]], [0.0, -1.0])
    """
    A = sp.csr_array(A)
    m = A.shape[0]
    A = sp.csr_array((A.data, A.indices, A.indptr), shape=(m, n_vars))
    row_lb, row_ub = np.array(row_lb, float), np.array(row_ub, float)
    on = np.asarray(row_station) >= 0
    lower, upper = on & np.isfinite(row_lb), on & np.isfinite(row_ub)
    if np.any(lower & upper):
        raise ConfigError("a station's row bounded on both sides cannot be switched")
    rows = np.repeat(np.arange(m), np.diff(A.indptr))
    negative = np.bincount(rows, np.minimum(A.data, 0.0), minlength=m)  # <= 0
    positive = np.bincount(rows, np.maximum(A.data, 0.0), minlength=m)
    coef = np.zeros(m)
    coef[lower] = -(row_lb[lower] - negative[lower])
    row_lb[lower] = negative[lower]
    coef[upper] = positive[upper] - row_ub[upper]
    row_ub[upper] = positive[upper]
    at = np.flatnonzero(on & (coef != 0))
    switch = sp.csr_array((coef[at], (at, station_var[np.asarray(row_station)[at]])),
                          shape=(m, n_vars))
    return sp.csr_array(A + switch), row_lb, row_ub


def eligible_stations(problem: PlanProblem, config, infos) -> tuple[np.ndarray, dict]:
    """The candidate stations some layout could satisfy (:func:`planner.accuracy.checks.
    diagnose`; its accuracy check in known-control mode only), and the others by id with the
    reason.

    Returns
    -------
    eligible : (s,) bool
    excluded : dict
    """
    excluded = diagnose(problem, config, infos, accuracy_check=not config.network)
    eligible = np.ones(problem.n_stations, bool)
    eligible[[problem.station_ids.index(sid) for sid in excluded]] = False
    return eligible, excluded


def joint_model(problem: PlanProblem, config, cover: StationCover, costs: JointCosts,
                infos=None, clashes: tuple[np.ndarray, np.ndarray] | None = None,
                drive_m: np.ndarray | None = None, max_stations: int | None = None,
                tour_edges=()) -> JointModel:
    """Build the joint program (see the module docstring).

    Parameters
    ----------
    problem : PlanProblem
        Every candidate station and every candidate site.
    config : PlanConfig
        The marker program's settings; in network mode no information or accuracy rows.
    cover : StationCover
        Over ``problem``'s stations.
    costs : JointCosts
    infos : list of StationInfo, optional
        The stations' accuracy (default computed).
    clashes : ((q,) int, (q,) int), optional
        Candidate station and site index of every pair too near to hold both.
    drive_m : (s + 1, s + 1) float, optional
        Ground-path drive lengths between the route start (0) and the candidate stations, m;
        with ``costs.drive_per_m > 0`` the program chooses the tour too.
    max_stations : int, optional
        The tour's ``M`` (:func:`~planner.program.joint_tour.tour_block`); default every
        eligible station.
    tour_edges : iterable of (int, int)
        Node pairs the tour graph keeps whatever its size (a baseline's tour).

    Raises
    ------
    InfeasiblePlanError
        Some cell is covered by fewer than ``min_stations`` candidate stations that can
        satisfy the marker rules.
    """
    known = not config.network
    base = build_model(problem, config, information=known)
    if known:
        base = with_tightening_rows(problem, base, config)
    infos = infos if infos is not None else station_infos(problem, config)
    eligible, excluded = eligible_stations(problem, config, infos)
    ns, v0 = problem.n_stations, base.n_vars
    station_var = v0 + np.arange(ns)
    tour = None
    if drive_m is not None and costs.drive_per_m > 0:
        graph = tour_graph(drive_m, eligible, tour_edges)
        m = int(eligible.sum()) if max_stations is None else max_stations
        tour = tour_block(graph, station_var, v0 + ns, costs.drive_per_m, costs.unit, m)
    n_vars = v0 + ns + (0 if tour is None else tour.c.size)
    kinds = base.row_kind
    row_station = np.array([-1 if k.family in _OWN_VARIABLE_FAMILIES else k.station
                            for k in kinds], dtype=np.int64)
    A, lb, ub = switched_rows(base.A, base.row_lb, base.row_ub, row_station, station_var,
                              n_vars)
    cover_rows, n_cover = _cover_rows(cover, eligible, station_var, n_vars)
    clash_rows, clash_station = _clash_rows(base, clashes, station_var, n_vars)
    n_clash = clash_station.size
    x_cost = np.zeros(v0)
    x_cost[:base.var_site.size] = costs.marker / costs.unit * problem.site_cost[base.var_site]
    if tour is None:
        tour_cols = [np.zeros(0)] * 4
        tour_rows = (sp.csr_array((0, n_vars)), np.zeros(0), np.zeros(0), ())
    else:
        tour_cols = [tour.c, tour.lb, tour.ub, tour.integrality]
        tour_rows = (tour.A, tour.row_lb, tour.row_ub, tour.kinds)
    model = Model(
        c=np.r_[x_cost, np.full(ns, costs.station / costs.unit), tour_cols[0]],
        A=sp.csr_array(sp.vstack([A, cover_rows, clash_rows, tour_rows[0]])),
        row_lb=np.r_[lb, np.full(n_cover, float(cover.min_stations)), np.full(n_clash, -np.inf),
                     tour_rows[1]],
        row_ub=np.r_[ub, np.full(n_cover, np.inf), np.ones(n_clash), tour_rows[2]],
        lb=np.r_[base.lb, np.zeros(ns), tour_cols[1]],
        ub=np.r_[base.ub, eligible.astype(float), tour_cols[2]],
        integrality=np.r_[base.integrality, np.ones(ns), tour_cols[3]].astype(
            base.integrality.dtype),
        var_site=base.var_site, site_var=base.site_var,
        row_kind=kinds + (RowKind("cover"),) * n_cover
        + tuple(RowKind("clash", int(st)) for st in clash_station) + tour_rows[3])
    return JointModel(model=model, station_var=station_var, excluded=excluded, tour=tour)


def _clash_rows(base: Model, clashes, station_var: np.ndarray, n_vars: int
                ) -> tuple[sp.csr_array, np.ndarray]:
    """``x_j + w_s <= 1`` for every clashing pair whose site is a variable; the rows and
    their stations."""
    if clashes is None:
        return sp.csr_array((0, n_vars)), np.zeros(0, np.int64)
    st, site = (np.asarray(a, np.int64) for a in clashes)
    keep = base.site_var[site] >= 0
    st, site = st[keep], site[keep]
    q = np.arange(st.size)
    return sp.csr_array((np.ones(2 * st.size), (np.r_[q, q], np.r_[base.site_var[site],
                                                                   station_var[st]])),
                        shape=(st.size, n_vars)), st


def _cover_rows(cover: StationCover, eligible: np.ndarray, station_var: np.ndarray,
                n_vars: int) -> tuple[sp.csr_array, int]:
    """One coverage row per distinct set of eligible covering stations; refuses a cell with
    too few."""
    keep = eligible[cover.pair_station]
    cells, stations = cover.pair_cell[keep], cover.pair_station[keep]
    incidence = sp.csr_array((np.ones(cells.size), (cells, stations)),
                             shape=(cover.n_cells, station_var.size))
    incidence.sum_duplicates()
    short = np.flatnonzero(np.diff(incidence.indptr) < cover.min_stations)
    if short.size:
        raise InfeasiblePlanError(
            f"{short.size} of {cover.n_cells} cells are covered by fewer than "
            f"{cover.min_stations} candidate station(s) that can meet the marker rules "
            f"(first: cell {short[0]}); add candidate stations or relax the coverage "
            "requirement")
    first = _undominated(incidence)
    rows = incidence[first]
    rows = sp.csr_array((rows.data, station_var[rows.indices], rows.indptr),
                        shape=(first.size, n_vars))
    return rows, int(first.size)


#: Coverage rows are reduced to the undominated ones when there are at most this many cells.
_DOMINANCE_MAX_CELLS = 20_000


def _undominated(incidence: sp.csr_array) -> np.ndarray:
    """Indices of the cells whose coverage row is implied by no other: one of each set of
    cells with the same covering stations, and none whose set contains another cell's (that
    cell's row asks for the same stations from fewer). Above :data:`_DOMINANCE_MAX_CELLS`
    cells only duplicates are removed.

    Examples
    --------
    >>> inc = sp.csr_array(np.array([[1, 1, 0], [1, 0, 0], [1, 0, 0], [0, 1, 1]]))
    >>> _undominated(inc).tolist()
    [1, 3]
    """
    inc = sp.csr_array(incidence, dtype=np.float64)
    size = np.diff(inc.indptr)
    if inc.shape[0] > _DOMINANCE_MAX_CELLS:
        first: dict[bytes, int] = {}
        for c in range(inc.shape[0]):
            first.setdefault(np.sort(inc.indices[inc.indptr[c]:inc.indptr[c + 1]]).tobytes(), c)
        return np.sort(np.fromiter(first.values(), np.int64))
    shared = sp.csr_array(inc @ inc.T).tocoo()
    a, b, n = shared.row, shared.col, shared.data
    # row b is implied by row a when a's stations are all b's: strictly fewer, or the same set
    # and a comes first
    contains = (a != b) & (n == size[a]) & ((size[a] < size[b]) | (a < b))
    keep = np.ones(inc.shape[0], bool)
    keep[b[contains]] = False
    return np.flatnonzero(keep)


def plan_stations_and_sites(problem: PlanProblem, config, cover: StationCover,
                            costs: JointCosts, incumbent: tuple | None = None,
                            clashes: tuple[np.ndarray, np.ndarray] | None = None,
                            infos=None, drive_m: np.ndarray | None = None) -> JointResult:
    """The joint cut loop: solve, check the chosen stations, cut, re-solve until all pass.

    Parameters
    ----------
    problem : PlanProblem
        Every candidate station and every candidate site.
    config : PlanConfig
        Uses ``time_limit_s`` (for the whole loop), ``mip_gap``, ``requirement_m`` and the
        marker program's rules.
    cover : StationCover
    costs : JointCosts
    incumbent : tuple of ((s,) bool, (n,) bool), optional
        Stations and sites known to pass (a baseline's): the answer when the time limit stops
        the loop first, with the best bound proved. With the drive priced, its tour is
        PyVRP's over ``drive_m`` (:func:`planner.traverse.route.solve_tour`).
    clashes : ((q,) int, (q,) int), optional
        Candidate station and site index of every pair too near to hold both.
    infos : list of StationInfo, optional
        The stations' accuracy, when the caller has it (default computed).
    drive_m : (s + 1, s + 1) float, optional
        Drive lengths between the route start (0) and the candidate stations, m: with
        ``costs.drive_per_m > 0`` the program chooses the tour too
        (:mod:`planner.program.joint_tour`). The result's bound is then at least the bound of
        the stops and the drive (the root cuts' relaxation,
        :func:`~planner.program.joint_tour_cuts.tighten_tour`) plus the
        bound of the markers
        (:func:`~planner.program.joint_tour_cuts.fewest_markers_bound`): two parts of one cost, each
        bounded on its own.

    Returns
    -------
    result : JointResult

    Raises
    ------
    InfeasiblePlanError
        No layout covers the area and meets the rules; :class:`PlanTimeLimitError` when the
        time limit ended the search before any layout passed and no incumbent was given.
    """
    t0 = time.perf_counter()
    infos = station_infos(problem, config) if infos is None else infos
    priced = drive_m is not None and costs.drive_per_m > 0
    incumbent_cost, incumbent_tour = None, None
    if incumbent is not None:
        if priced:
            incumbent_tour, _ = shortest_tour(drive_m, incumbent[0])
        incumbent_cost = costs.of(int(incumbent[0].sum()),
                                  int(problem.site_cost[incumbent[1]].sum()),
                                  tour_units(drive_m, incumbent_tour, costs) if priced else 0.0)
    joint = joint_model(problem, config, cover, costs, infos, clashes,
                        drive_m=drive_m if priced else None,
                        max_stations=max_stations(incumbent_cost, costs.station,
                                                  problem.n_stations),
                        tour_edges=() if incumbent_tour is None else tour_legs(incumbent_tour))
    model, station_var = joint.model, joint.station_var
    bound, solve_time, n_cuts, history = -np.inf, 0.0, 0, []
    start = None if incumbent is None else _start(model, station_var, *incumbent, joint.tour,
                                                  incumbent_tour)
    complete = None if joint.tour is None else joint.tour.graph.complete
    if joint.tour is not None:
        model, n_cuts, tour_bound, relaxed_w = tighten_tour(
            model, station_var, joint.tour, costs.unit, config.time_limit_s * ROOT_TIME_SHARE,
            history)
        if relaxed_w is not None and cover.covered(relaxed_w > 0.5) and np.all(
                np.abs(relaxed_w - np.round(relaxed_w)) < 1e-6):
            # the relaxation's stops are whole: HiGHS completes them (markers, tour) first
            start = np.full(model.n_vars, np.nan)
            start[station_var] = np.round(relaxed_w)
        if np.isfinite(tour_bound):
            # stops and drive at least the tour's bound, markers at least the fewest any
            # station needs; a whole number of units when every cost is
            bound = tour_bound + costs.unit * fewest_markers_bound(model, station_var)
            if costs.integral:
                bound = math.ceil(bound / costs.unit - 1e-6) * costs.unit
            # the bound as a row (valid: no layout costs less), so HiGHS stops once it
            # holds a layout that meets it
            nz = np.flatnonzero(model.c)
            model = model.with_rows(
                sp.csr_array((model.c[nz], (np.zeros(nz.size, np.int64), nz)),
                             shape=(1, model.n_vars)),
                [bound / costs.unit], [np.inf], [RowKind("objective-bound")])

    def result(stations, selected, sol, iteration, tour) -> JointResult:
        return JointResult(stations=stations, selected=selected, solution=sol,
                           iterations=iteration, n_cuts=n_cuts, solve_time_s=solve_time,
                           excluded=joint.excluded, history=history, tour=tour,
                           tour_complete=complete)

    def incumbent_result(iteration: int) -> JointResult:
        stations, selected = incumbent
        obj = incumbent_cost
        gap = max(obj - bound, 0.0) / obj if np.isfinite(bound) else float("nan")
        proven = np.isfinite(bound) and bound >= obj - 1e-9
        sol = Solution(status="optimal" if proven else "time_limit", selected=selected,
                       objective=obj, dual_bound=obj if proven else float(bound),
                       gap=0.0 if proven else gap, solve_time_s=0.0,
                       message="time limit: the baseline's layout, with the best proven bound")
        return result(stations, selected, sol, iteration, incumbent_tour)

    iteration = 0
    while True:
        iteration += 1
        remaining = config.time_limit_s - (time.perf_counter() - t0)
        if remaining <= 0:
            if incumbent is not None:
                return incumbent_result(iteration - 1)
            raise PlanTimeLimitError(
                f"time limit {config.time_limit_s:g} s reached after {iteration - 1} "
                "iteration(s) before every chosen station met the requirement; raise "
                "`time_limit_s`")
        sol = logged_solve(model, remaining, config.mip_gap, history, iteration, start=start,
                           unit=costs.unit)
        solve_time += sol.solve_time_s
        if np.isfinite(sol.dual_bound):
            bound = max(bound, sol.dual_bound)
        if sol.x is not None and bound > sol.dual_bound:
            sol = _with_bound(sol, bound, costs.unit if costs.integral else 0.0)
        if sol.x is None:
            if sol.status == "infeasible":
                raise InfeasiblePlanError(
                    "no choice of stations and markers covers the area and meets every "
                    "chosen station's requirement; add candidate stations or relax the "
                    "coverage or accuracy requirement")
            if incumbent is not None:
                return incumbent_result(iteration)
            raise PlanTimeLimitError(f"solver found no layout ({sol.status}: {sol.message}); "
                                     "raise `time_limit_s`")
        stations = sol.x[station_var] > 0.5
        rows = None
        if not config.network:
            rows, lower, kinds = accuracy_cuts(problem, model, sol.selected, config, infos,
                                               outer_approximation=True,
                                               stations=np.flatnonzero(stations))
        if rows is None:
            if incumbent is not None and incumbent_cost < sol.objective - 1e-9:
                return incumbent_result(iteration)
            tour = None if joint.tour is None else tour_order(joint.tour, sol.x)
            return result(stations, sol.selected, sol, iteration, tour)
        row_station = np.array([k.station for k in kinds], dtype=np.int64)
        A, lb, ub = switched_rows(rows, lower, np.full(len(lower), np.inf), row_station,
                                  station_var, model.n_vars)
        n_cuts += A.shape[0]
        model = model.with_rows(A, lb, ub, kinds)


#: Share of the time limit the tour's root cuts may take.
ROOT_TIME_SHARE = 0.5


def _with_bound(sol: Solution, bound: float, step: float) -> Solution:
    """``sol`` with a better dual bound proved elsewhere: its gap, and "optimal" once the
    bound is within less than ``step`` of the objective (the objective's granularity: one
    unit when it is a whole number of units, else 0)."""
    gap = max(sol.objective - bound, 0.0) / max(abs(sol.objective), 1e-9)
    proven = sol.objective - bound < max(step, 0.0) - 1e-6 or sol.objective - bound <= 1e-9
    return replace(sol, dual_bound=float(bound), gap=0.0 if proven else gap,
                   status="optimal" if proven else sol.status)


def shortest_tour(drive_m: np.ndarray, stations: np.ndarray) -> tuple[np.ndarray, dict]:
    """The stations ``stations`` ((s,) bool) in the order of PyVRP's closed tour from the
    route start over ``drive_m`` ((s + 1, s + 1), route start 0), (k,) int candidate indices,
    and the solver's record (:func:`planner.traverse.route.solve_tour`)."""
    from planner.traverse.route import solve_tour

    idx = np.flatnonzero(stations)
    nodes = np.r_[0, idx + 1]
    order, record = solve_tour(np.asarray(drive_m, float)[np.ix_(nodes, nodes)])
    return idx[np.asarray(order, np.int64) - 1], record


def tour_units(drive_m: np.ndarray, order: np.ndarray, costs: JointCosts) -> float:
    """The program's cost of the closed tour through ``order`` (candidate indices) from the
    route start, in units of ``costs.unit`` (each leg rounded as the program rounds it)."""
    return float(leg_cost_units(leg_lengths_m(drive_m, order), costs.drive_per_m,
                                costs.unit).sum())


def _start(model: Model, station_var: np.ndarray, stations: np.ndarray, selected: np.ndarray,
           tour: TourBlock | None = None, order: np.ndarray | None = None) -> np.ndarray:
    """A partial start for HiGHS: the stations and sites of a known layout and, with a tour
    block, its tour through ``order``; NaN for the sector variables (HiGHS completes them)."""
    start = np.full(model.n_vars, np.nan)
    start[:model.var_site.size] = selected[model.var_site]
    start[station_var] = stations
    if tour is not None and order is not None:
        values = tour_start(tour, order)
        if values is not None:
            start[np.r_[tour.edge_var, tour.flow_var.ravel()]] = values
    return start
