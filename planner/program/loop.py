"""The accuracy-cut loop: solve, check every station exactly, cut the failing layout, re-solve.

:func:`plan_sites` solves (:func:`planner.program.solving.solve`), checks every station's
predicted accuracy exactly (:class:`planner.accuracy.checks.StationInfo`), adds valid cuts for
stations that fail (:mod:`planner.program.cuts_known`, :mod:`planner.program.cuts_network`) and
re-solves until all pass. In known-control mode the first solve is the directions-only
relaxation (:func:`_combinatorial_first`); the full model is built only when its layout fails a
station. Large network problems start from the greedy layout, improved by a local search
(:func:`planner.program.local_search.local_search`) and repaired until it meets the chance
targets in a chance-constrained plan, and a root relaxation (:func:`_root_relaxation`).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from markerplan.errors import ConfigError, InfeasiblePlanError, PlanTimeLimitError
from planner.accuracy.checks import StationInfo, diagnose, evaluate_layout, station_infos
from planner.accuracy.network import NetworkModel, network_model
from planner.problem.usability import PlanProblem
from planner.program.background import in_background
from planner.program.cuts_chance import ChanceRule, chance_preflight, chance_rule
from planner.program.cuts_count import station_count_rows
from planner.program.cuts_known import accuracy_cuts
from planner.program.cuts_network import MAX_TERMS, network_cuts, network_preflight, sparse_tangent
from planner.program.highs import WarmLP, reset_after_fork
from planner.program.local_search import local_search
from planner.program.model import (
    Model,
    PlanResult,
    RowKind,
    Solution,
    build_model,
    with_tightening_rows,
)
from planner.program.solving import logged_solve, solve

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
#: ... and its local search (:func:`~planner.program.local_search.local_search`) tries no move
#: after this fraction of the time limit.
_PRUNE_TIME_FRACTION = 0.65
#: Network mode, large problems: the root relaxation (:func:`_root_relaxation`) runs in a forked
#: process (:func:`~planner.program.background.in_background`) while the greedy incumbent and
#: its local search run (on two cores the bound costs the incumbent little time), and
#: stops at this fraction of the time limit, after at most this many LP solves, or when its bound
#: rose less than this (relative) over 5 solves; its rows in the integer program give up at most
#: this fraction of their right-hand side.
_ROOT_TIME_FRACTION = 0.75
_ROOT_MAX_ROUNDS = 100
_ROOT_STALL = 2e-3
_ROOT_SPARSE_SLACK = 0.05
#: Network mode, root relaxation: most moves of the in-point towards one LP solution.
_ROOT_MAX_STEPS = 8


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
    chance = chance_rule(problem, config, infos)
    if config.network:
        return _plan_network(problem, config, model, infos, chance)
    t0 = time.perf_counter()
    first = None
    if chance is not None:  # before the first solve: its cuts assume some site can help
        _refuse_hopeless(problem, config, diagnose(problem, config, infos), chance)
    if model is None:
        first, rows = _combinatorial_first(problem, config, infos, chance)
        if rows is None:
            return first
        model = _with_chance_counts(
            with_tightening_rows(problem, build_model(problem, config), config), problem, chance)
        if rows[0] is not None:
            model = model.with_rows(rows[0], rows[1], np.full(len(rows[1]), np.inf), rows[2])
    _refuse_hopeless(problem, config, diagnose(problem, config, infos), None)

    def cuts(selected):
        return _stacked(accuracy_cuts(problem, model, selected, config, infos,
                                      outer_approximation=True),
                        chance.cuts(problem, model, selected) if chance else (None, [], []))

    def check(selected):
        return evaluate_layout(problem, selected, config, infos)

    repair = _repair(problem, config, chance, check)
    result = _cut_loop(problem, config, model, cuts, check, t0=t0, repair=repair,
                       incumbent=_redundant_start(problem, config, chance, repair, t0))
    if first is None:
        return result
    return replace(result, iterations=result.iterations + first.iterations,
                   n_cuts=result.n_cuts + first.n_cuts,
                   solve_time_s=result.solve_time_s + first.solve_time_s,
                   history=first.history + result.history)


def _refuse_hopeless(problem: PlanProblem, config, failing: dict[str, str],
                     chance: ChanceRule | None) -> None:
    """Raise :class:`InfeasiblePlanError` naming every station no layout can satisfy
    (``failing``, and those that provably miss the chance target) and why."""
    by_chance = chance is not None and not failing
    if by_chance:
        failing = chance_preflight(problem, config, chance)
    if failing:
        raise InfeasiblePlanError(
            f"no layout meets the requirement ({config.requirement_m:g} m, "
            f">= {config.min_markers} markers in >= {config.min_sectors} of {config.n_sectors} "
            "sectors"
            + (f", failing with chance <= {config.chance_epsilon:g}" if by_chance else "")
            + ") at station(s): "
            + "; ".join(f"{k}: {v}" for k, v in failing.items())
            + "; fix the causes named, relax the configuration"
            + (", raise chance_epsilon (or set it to none: the naive plan)"
               if by_chance else "") + " or add candidate sites")


#: Chance-constrained planning, known control: most of the time limit the redundant plan (a
#: starting layout) may take.
_REDUNDANT_START_FRACTION = 0.3


def _redundant_start(problem: PlanProblem, config, chance: ChanceRule | None, repair,
                     t0: float) -> np.ndarray | None:
    """Known control: the redundant plan (every station survives any one loss), repaired
    until it meets the chance targets, as the chance-constrained search's first incumbent;
    ``None`` without a chance rule, in redundant mode, or when it fails or runs out of its
    share of the time limit. A redundant layout fails a station only when two or more of its
    markers are lost, so it is often near the chance-constrained optimum."""
    if chance is None or config.redundant:
        return None
    budget = min(_REDUNDANT_START_FRACTION * config.time_limit_s,
                 config.time_limit_s - (time.perf_counter() - t0))
    if budget <= 0:
        return None
    try:
        layout = plan_sites(problem, config.replace(redundant=True, chance_epsilon=None,
                                                    time_limit_s=budget)).selected
    except InfeasiblePlanError:  # also its time limit
        return None
    return layout if chance.layout_ok(layout) else repair(layout)


def _repair(problem: PlanProblem, config, chance: ChanceRule | None, check):
    """The cut loop's ``repair``: a failing layout grown until it meets every chance target
    (:func:`~planner.program.chance_start.repair_layout`), or ``None`` without a chance rule."""
    if chance is None:
        return None
    from planner.program.chance_start import repair_layout

    allowed = ~problem.site_mask(config.forbidden, "forbidden")
    return lambda selected: repair_layout(selected, chance, allowed,
                                          lambda sel: check(sel).all_ok
                                          and chance.whole_ok(sel))


def _stacked(*blocks) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """Several ``(rows, lower, kinds)`` blocks of cuts as one (``rows`` None: no cut)."""
    rows = [b[0] for b in blocks if b[0] is not None]
    lower = [v for b in blocks if b[0] is not None for v in b[1]]
    kinds = [k for b in blocks if b[0] is not None for k in b[2]]
    return (sp.csr_array(sp.vstack(rows)) if rows else None), lower, kinds


def _with_chance_counts(model: Model, problem: PlanProblem, chance: ChanceRule | None) -> Model:
    """``model`` with the chance rule's count rows (valid from the start), if any."""
    if chance is None:
        return model
    rows, lower, upper, kinds = chance.count_rows(problem, model)
    if rows is None:
        return model
    return model.with_rows(rows, lower, upper, kinds)


def _combinatorial_first(problem: PlanProblem, config, infos: list[StationInfo],
                         chance: ChanceRule | None = None
                         ) -> tuple[PlanResult | None, tuple | None]:
    """Known control: solve the directions rows alone first; done if that passes.

    :func:`~planner.program.model.build_model` without its information rows is the plain
    cover-plus-sector model. It is a relaxation of the full program (every row left out —
    information, tightening, accuracy cuts — holds for every passing layout), so its optimum
    bounds the full one from below: a layout that is optimal here and passes every station's
    exact check is optimal for the plan. In it many candidate sites have identical columns (same
    stations, same sectors): the markers of such a group go to its members with the most
    information (``sum 3 / sigma^2`` over their usable pairs).

    Returns
    -------
    result : PlanResult or None
        The plan when the layout passes (then ``rows`` is None), else the first solve's
        record (iterations, cuts, solver time, history) for the loop that follows.
    rows : tuple or None
        ``(rows, lower, kinds)`` of :func:`~planner.program.cuts_known.accuracy_cuts` for the
        failing layout (``rows`` None when there was no layout), to add to the full model.
    """
    relaxed = _with_chance_counts(build_model(problem, config, information=False), problem,
                                  chance)
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
        if chance is not None:
            rows = _stacked(rows, chance.cuts(problem, relaxed, sol.selected))
    result = PlanResult(selected=sol.selected, check=check, solution=sol, iterations=1,
                        n_cuts=0 if rows[0] is None else rows[0].shape[0],
                        solve_time_s=sol.solve_time_s, model=relaxed, history=history)
    if sol.selected is not None and rows[0] is None:
        return result, None
    return result, rows


def _plan_network(problem: PlanProblem, config, model: Model | None,
                  infos: list[StationInfo], chance: ChanceRule | None = None) -> PlanResult:
    """:func:`plan_sites` in network mode: the same build/solve/cut loop with the network's
    accuracy checks and cuts (:func:`~planner.program.cuts_network.network_cuts`); the chance
    rule judges each station's count and directions (its odds ignore accuracy: a network
    station's accuracy depends on every station's detections), then a layout that meets
    every other rule as a whole network (:meth:`ChanceRule.whole_cuts`)."""
    t0 = time.perf_counter()
    net = network_model(problem, config)
    n_tying = int(net.tying.sum())
    if n_tying > MAX_NETWORK_TYING_SITES:
        raise ConfigError(
            f"network mode takes at most {MAX_NETWORK_TYING_SITES:,} candidate sites seen by two "
            f"or more stations; this site has {n_tying:,}: coarsen the candidate grid "
            f"(grid_spacing_m in `config_path`; {config.grid_spacing_m:g} m now, try "
            f"{config.grid_spacing_m * math.sqrt(n_tying / MAX_NETWORK_TYING_SITES) * 1.2:.1f} m)")
    hopeless = network_preflight(problem, config, net, infos)
    if chance is not None:
        _refuse_hopeless(problem, config, {}, chance)
    if model is None:
        model = _with_chance_counts(
            with_tightening_rows(problem, build_model(problem, config), config), problem, chance)
    ub = model.ub.copy()
    var = model.site_var[np.flatnonzero(hopeless)]
    ub[var[var >= 0]] = 0.0
    model = replace(model, ub=ub)
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    j_all = net.information(~forbidden & ~hopeless & (net.n_stations_seeing > 0))
    upper_bound = greedy = None
    root_bound, root = -np.inf, None
    existing = problem.site_mask(config.existing, "existing") | problem.site_existing
    root_job = None
    if int(net.tying.sum()) > _SPARSE_ABOVE_SITES and not config.redundant \
            and np.all(problem.site_cost[~existing] == 1):
        # every layout at least as good as the greedy one has at most its number of sites
        from planner.program.baselines import network_baseline

        root_job = in_background(_root_relaxation, problem, model, net,
                                 t0 + _ROOT_TIME_FRACTION * config.time_limit_s,
                                 after_fork=reset_after_fork)
        # a stuck greedy gives no starting layout: the search goes on without one
        greedy = network_baseline(problem, config.replace(
            forbidden=config.forbidden + tuple(
                problem.site_ids[j] for j in np.flatnonzero(hopeless & ~forbidden))), net,
            deadline=t0 + _GREEDY_TIME_FRACTION * config.time_limit_s)

    def check(selected):
        return evaluate_layout(problem, selected, config, infos, net=net)

    repair = _repair(problem, config, chance, check)
    start = pruning = None
    if greedy is not None and greedy.meets_requirement \
            and (config.max_bias_effect_m is None  # the greedy ignores the bias bound
                 or check(greedy.selected).all_ok):
        start = greedy.selected
        pruning = local_search(problem, config, net, start,
                               deadline=t0 + _PRUNE_TIME_FRACTION * config.time_limit_s)
        changed = bool(pruning.removed) or pruning.swaps > 0
        if changed and not check(pruning.selected).all_ok:
            pruning = None  # it fails a rule the search does not judge (the bias bound)
        elif changed:
            start = pruning.selected
        if chance is not None and not chance.layout_ok(start):
            start = repair(start)  # None: it cannot
    root_cuts, counts = [], (None, [], [])
    if root_job is not None:  # valid with or without a starting layout
        root_cuts, counts, root_bound, root = root_job()
    if start is not None:
        in_model = model.site_var >= 0
        upper_bound = int((start & in_model).sum())
        nx = model.var_site.size
        row = sp.csr_array((np.ones(nx), (np.zeros(nx, np.int64), np.arange(nx))),
                           shape=(1, model.n_vars))
        model = model.with_rows(row, [-np.inf], [float(upper_bound)],
                                [RowKind("upper-bound")])
        model = _root_rows(model, root_cuts, upper_bound)
        if counts[0] is not None:
            model = model.with_rows(counts[0], counts[1], np.full(len(counts[1]), np.inf),
                                    counts[2])

    def cuts(selected):
        rows = _stacked(network_cuts(problem, model, selected, config, net, j_all, upper_bound),
                        chance.cuts(problem, model, selected) if chance else (None, [], []))
        if rows[0] is None and chance is not None:  # then the whole network, the costly part
            rows = chance.whole_cuts(problem, model, selected)
        return rows

    result = _cut_loop(problem, config, model, cuts, check, incumbent=start, t0=t0,
                       bound=root_bound, repair=repair)
    return replace(result, greedy=greedy, pruning=pruning, root=root)


def _root_relaxation(problem: PlanProblem, model: Model, net: NetworkModel, deadline: float
                     ) -> tuple[list[tuple[int, np.ndarray, float]], tuple, float, dict]:
    """Tangent rows that tighten a large network model at its LP relaxation; a lower bound.

    With ``x`` relaxed to ``[0, 1]``: first one tangent per station at the every-site
    information scaled onto the requirement's boundary, ``J_t = J_prior + t (J_all - J_prior)``
    with ``t = (e_all / allowance)^2`` (the station's); then an in-out cutting-plane loop:
    linearise at ``x_lin = (x_LP + x_in) / 2`` (``x_in`` the last point where every station
    passes, at first every open site); where ``x_lin`` passes it becomes ``x_in``, otherwise
    its failing stations' tangents
    (:meth:`~planner.accuracy.network.NetworkModel.station_tangents`, worst rim point) are
    added and the LP is solved again. Linearising between the two points keeps the tangents
    informative where the LP solution alone leaves stations untied. Every
    tangent is valid for every layout (the error is convex in the information), so each LP
    optimum bounds the fewest markers from below. Stops after ``budget_s``, ``_ROOT_MAX_ROUNDS``
    solves, when the bound rose less than ``_ROOT_STALL`` (relative) over 5 solves, or when
    the LP solution passes every station (to ``_ROOT_MAX_STEPS`` halvings). Then, before
    ``deadline``, the per-station count rows (each station's count of its own tying sites,
    rounded up: :func:`~planner.program.cuts_count.station_count_rows`) join the LP, which is
    solved once more. The LP is ``model`` relaxed, kept in HiGHS between rounds
    (:class:`~planner.program.highs.WarmLP`: each round starts from the last basis); it reads
    ``model`` and ``net`` only (it runs beside the greedy).

    Parameters
    ----------
    deadline : float
        :func:`time.perf_counter` value after which no LP is started (one running is stopped).

    Returns
    -------
    cuts : list of (station, coef (n,), rhs)
        The tangents, ``sum_j coef_j x_j >= rhs`` over every site (:func:`_root_rows` adds them
        to the integer program).
    counts : (rows, lower, kinds)
        The count rows (``rows`` None: none), for the integer program as they are.
    bound : float
        Proven lower bound on the objective (``-inf`` when no LP solved), rounded up when every
        feasible objective is a whole number.
    record : dict
        ``bound``, ``lp_solves``, ``rows`` (tangents), ``time_s`` and ``stopped``: why the loop
        ended (``"budget"``, ``"rounds"``, ``"stall"``, ``"solved"``: the LP solution passes,
        or the LP's status).
    """
    t0 = time.perf_counter()
    allowed = net.allowed_station_m
    nx = model.var_site.size
    in_model = model.site_var >= 0
    x_in = np.zeros(problem.n_sites)
    x_in[model.var_site] = model.ub[:nx]
    x_in *= net.tying
    sites_all = net.site_information(x_in)
    prior = net.prior_information
    e_all = net.station_errors_from(net.covariance(prior + sites_all))
    cuts = []  # (station, coefficients (n,), rhs)
    tied = np.flatnonzero(np.isfinite(e_all) & np.isfinite(allowed)
                          & (np.arange(problem.n_stations) != net.reference))
    try:  # every station determined: one decomposition for all the scaled informations
        scaled = net.scaled_covariances(sites_all, (e_all[tied] / allowed[tied]) ** 2, tied)
    except np.linalg.LinAlgError:
        scaled = ((int(k), net.covariance(prior + (e_all[k] / allowed[k]) ** 2 * sites_all))
                  for k in tied)
    for k, cov_t in scaled:
        cuts += net.station_tangents(cov_t, [k])
    lp = WarmLP(model.c, model.A, model.row_lb, model.row_ub, model.lb, model.ub)
    bound, history = -np.inf, []
    added = 0
    stopped = "rounds"
    for _ in range(_ROOT_MAX_ROUNDS):
        if cuts[added:]:
            rows = sp.vstack([model.site_row(np.flatnonzero(in_model & (c > 0)),
                                             c[in_model & (c > 0)] / rhs)
                              for _, c, rhs in cuts[added:]])
            n = len(cuts) - added
            lp.add_rows(rows, np.ones(n), np.full(n, np.inf))
            added = len(cuts)
        remaining = deadline - time.perf_counter()
        if remaining <= 0:
            stopped = "budget"
            break
        sol = lp.solve(remaining)
        if sol.status != "optimal" or sol.x is None:
            stopped = sol.status
            break
        bound = max(bound, sol.objective)
        history.append(bound)
        x_lp = np.zeros(problem.n_sites)
        x_lp[model.var_site] = sol.x[:nx]
        if len(history) > 5 and history[-1] - history[-6] < _ROOT_STALL * abs(history[-1]):
            stopped = "stall"
            break
        failing = np.zeros(0, np.int64)
        for _ in range(_ROOT_MAX_STEPS):
            x_lin = 0.5 * (x_lp + x_in)
            cov = net.covariance(net.information(x_lin))
            failing = np.flatnonzero(net.stations_failing(net.station_errors_from(cov)))
            if failing.size:
                break
            x_in = x_lin
        if failing.size == 0:  # the LP solution (nearly) passes: the relaxation is solved
            stopped = "solved"
            break
        cuts += net.station_tangents(cov, failing)
    counts = (None, [], [])
    if stopped != "budget" and time.perf_counter() < deadline:
        rows, lower, kinds, extra = station_count_rows(model, net, cuts, deadline)
        cuts += extra
        counts = (rows, lower, kinds)
        new = cuts[added:]
        if rows is not None or new:
            blocks = [rows] if rows is not None else []
            blocks += [model.site_row(np.flatnonzero(in_model & (c > 0)),
                                      c[in_model & (c > 0)] / rhs) for _, c, rhs in new]
            lp.add_rows(sp.vstack(blocks), list(lower) + [1.0] * len(new),
                        np.full(len(lower) + len(new), np.inf))
            remaining = deadline - time.perf_counter()
            sol = lp.solve(remaining) if remaining > 0 else None
            if sol is not None and sol.status == "optimal":
                bound = max(bound, sol.objective)
                history.append(bound)
    if np.isfinite(bound) and np.all(model.integrality == 1) \
            and np.all(model.c == np.round(model.c)):
        bound = float(math.ceil(bound - 1e-6))  # a bound on a whole number: on its ceiling
    record = {"bound": float(bound), "lp_solves": len(history), "rows": len(cuts),
              "count_rows": len(counts[1]),
              "time_s": round(time.perf_counter() - t0, 1), "stopped": stopped,
              "bounds": [round(float(b), 2) for b in history]}
    return cuts, counts, bound, record


def _root_rows(model: Model, cuts, upper_bound: int) -> Model:
    """``model`` with the root relaxation's tangents (:func:`_root_relaxation`) as rows of
    family ``"oa-root"``, sparsified under ``upper_bound``
    (:func:`~planner.program.cuts_network.sparse_tangent`, giving up at most
    ``_ROOT_SPARSE_SLACK`` of each right-hand side: valid for every layout of at most
    ``upper_bound`` sites)."""
    in_model = model.site_var >= 0
    kept = []
    for k, c, rhs in cuts:
        sites, coef, lo = sparse_tangent(np.where(in_model, c, 0.0), rhs, upper_bound,
                                          MAX_TERMS, _ROOT_SPARSE_SLACK)
        kept.append((model.site_row(sites, coef), lo, RowKind("oa-root", int(k))))
    if not kept:
        return model
    rows, lower, kinds = zip(*kept, strict=True)
    return model.with_rows(sp.vstack(rows), lower, np.full(len(lower), np.inf), kinds)


def _cut_loop(problem: PlanProblem, config, model: Model, cuts, check,
              incumbent: np.ndarray | None = None, t0: float | None = None,
              bound: float = -np.inf, repair=None) -> PlanResult:
    """Solve, cut with ``cuts(selected) -> (rows, lower, kinds)`` (``rows`` None: passes),
    re-solve until every check passes; ``check(selected) -> LayoutCheck``.

    ``repair(selected) -> (n,) bool or None``: a passing layout grown from the first failing
    one, which becomes the incumbent (see below) when none was given.

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

    def incumbent_result(proven: bool) -> PlanResult:
        obj = float(problem.site_cost[incumbent].sum())
        gap = max(obj - bound, 0.0) / max(abs(obj), 1e-9) if np.isfinite(bound) \
            else float("nan")
        sol = Solution(status="optimal" if proven else "time_limit", selected=incumbent,
                       objective=obj, dual_bound=obj if proven else float(bound),
                       gap=0.0 if proven else gap, solve_time_s=0.0,
                       message="the passing layout found first: proven optimal by the "
                               "lower bound" if proven else
                               "time limit: the passing layout found first, with the best "
                               "proven bound")
        return PlanResult(selected=incumbent, check=check(incumbent), solution=sol,
                          iterations=iteration - 1, n_cuts=n_cuts,
                          solve_time_s=solve_time, model=model, history=history)

    improving = False  # the model asks for a layout cheaper than the incumbent
    while True:
        iteration += 1
        remaining = config.time_limit_s - (time.perf_counter() - t0)
        proven = incumbent is not None and np.isfinite(bound) \
            and math.ceil(bound - 1e-6) >= problem.site_cost[incumbent].sum() - 1e-9
        if (remaining <= 0 or proven) and incumbent is not None:
            return incumbent_result(proven)
        if remaining <= 0:
            raise PlanTimeLimitError(
                f"time limit {config.time_limit_s:g} s reached after {iteration - 1} "
                "iteration(s) before every station met the accuracy requirement; "
                "raise `time_limit_s`")
        sol = logged_solve(model, remaining, config.mip_gap, history, iteration)
        solve_time += sol.solve_time_s
        if np.isfinite(sol.dual_bound):
            bound = max(bound, sol.dual_bound)
        if sol.selected is None:
            if sol.status == "infeasible" and improving:
                iteration += 1  # no cheaper layout exists: the incumbent is optimal
                return incumbent_result(True)
            if sol.status == "infeasible":
                why = (f"the marker budget ({config.budget}) is too small"
                       if config.budget is not None else
                       "the stations' direction and accuracy requirements conflict"
                       + ("" if config.max_bias_effect_m is None else
                          f" with `max_bias_effect_m` {config.max_bias_effect_m:g} m"))
                raise InfeasiblePlanError(f"no layout is feasible: {why}; "
                                          "raise `budget` or relax the configuration")
            if incumbent is not None:
                continue  # time limit: the incumbent is the answer
            raise PlanTimeLimitError(f"solver found no layout ({sol.status}: {sol.message}); "
                                     "raise `time_limit_s`")
        rows, lower, kinds = cuts(sol.selected)
        if rows is not None and incumbent is None and repair is not None:
            incumbent, repair = repair(sol.selected), None
            model, improving = _improving(problem, model, incumbent)
        if rows is None:
            if incumbent is not None and problem.site_cost[incumbent].sum() \
                    < problem.site_cost[sol.selected].sum() - 1e-9:
                iteration += 1  # a time-limited solve's layout, dearer than the incumbent
                return incumbent_result(False)
            return PlanResult(selected=sol.selected, check=check(sol.selected), solution=sol,
                              iterations=iteration, n_cuts=n_cuts, solve_time_s=solve_time,
                              model=model, history=history)
        n_cuts += rows.shape[0]
        model = model.with_rows(rows, lower, np.full(len(lower), np.inf), kinds)


def _improving(problem: PlanProblem, model: Model, incumbent: np.ndarray | None
               ) -> tuple[Model, bool]:
    """``model`` asking for a layout cheaper than ``incumbent`` by at least one (a row
    ``"improve"``, when every site's cost is a whole number), and whether it does: then an
    infeasible model proves the incumbent optimal."""
    costs = problem.site_cost[model.var_site]
    if incumbent is None or not np.all(costs == np.round(costs)):
        return model, False
    row = model.site_row(model.var_site, costs)
    cap = float(problem.site_cost[incumbent].sum()) - 1.0
    return model.with_rows(row, [-np.inf], [cap], [RowKind("improve")]), True
