"""What-if marker reduction: the trade-off curve, how few of a layout's markers still meet the
requirement.

For a :class:`~planner.problem.usability.PlanProblem` whose candidate sites are the markers that may
be kept (a layout, or with ``--free`` every candidate site), :func:`tradeoff_curve` finds for
every count ``k`` the ``k`` markers that minimise the **worst station's** predicted error
(:mod:`planner.accuracy.checks`), proven by integer programming. The drop order and per-marker
losses are :mod:`planner.reduction.losses`.

Exact minimax by bisection on one model
---------------------------------------
A station's predicted error never grows when a marker is added, so the worst-station error is
monotone in the subset and "some ``k``-subset has worst error <= eps" is monotone in ``eps``.
One integer program answers exactly that question (:mod:`planner.reduction.minimax`). The least
feasible ``eps`` is found by bisection, ending with a test just below the best subset found
(``rel_tol``), which proves it optimal.

Each count starts from an incumbent (the best one-marker drop of the previous count's subset,
or a subset the caller knows) and from the lower bound "no subset beats keeping every site"
and, once proven, "no smaller set beats the next larger count's optimum". The time limit is
shared equally by the counts still to do. A solve that stops at its time limit without an
answer cannot prove a bound infeasible; the point is then marked ``proven=False`` (never called
optimal) and keeps its best subset found — or, if a smaller count's subset is better, that
subset plus its best additions, so the curve stays monotone.

Network mode
------------
With ``config.network`` the errors are the network's relative to the datum
(:mod:`planner.accuracy.network`) and a count's worst error is the worst of its stations and its
kept markers, as ``plan --network`` judges a layout. Each question "is there a ``k``-subset with
everything <= ``eps``?" is then the planner's own network program
(:func:`planner.program.loop.plan_sites`, requirement ``eps``, budget row ``= k``): see
:class:`~planner.reduction.minimax.NetworkMinimax`. A kept marker's own error counts, so the
curve need not be monotone.

Every requirement kind of the configuration is judged as ``plan`` judges it
(:func:`planner.accuracy.checks.evaluate_layout`'s ``all_ok``): the allowance relative to the
datum (``requirement_m`` plus ``requirement_ppm``, none with ``datum_requirement`` false), the
pose aids (``heading_aid``, ``odometry_percent``), a control-point datum, and the local
requirement on station pairs and (``local_markers``) on pairs of kept markers within
``local_within_m``. The local requirement is a constraint: each count's subset minimises the
worst error relative to the datum among the subsets meeting it (the program holds it as rows),
and the curve stops at the first count where none does.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from markerplan.errors import ConfigError, InfeasiblePlanError
from planner.accuracy.checks import diagnose
from planner.problem.usability import PlanProblem, directions_ok
from planner.reduction.losses import check_worst, local_ok, reduction_iv, worst_marker
from planner.reduction.minimax import MinimaxModel, NetworkMinimax

#: Final bisection step: a subset is proven optimal when nothing is feasible this far below it.
REL_TOL = 1e-9


@dataclass(frozen=True)
class CurvePoint:
    """The best ``k``-marker subset (site frame, metres).

    Attributes
    ----------
    k : int
        Number of markers kept.
    selected : (n,) bool
        Candidate sites kept.
    error_m : (s,) float
        Predicted error of every station with this subset, m.
    count, sectors : (s,) int
        Usable kept markers and occupied bearing sectors per station.
    ok : (s,) bool
        Station meets count, directions and the requirement.
    lower_bound_m : float
        Proven: no ``k``-subset has a worst-station error <= this, m (``-inf`` if nothing proven;
        network mode with ``requirement_ppm``: of the error scaled to the allowance's constant
        part, :meth:`planner.reduction.minimax.NetworkMinimax.worst`).
    proven : bool
        False when a solve hit its time limit, so the subset is not proven optimal.
    n_solves : int
        MILP solves spent on this point.
    statuses : tuple of str
        Status of each solve (``optimal``, ``infeasible``, ``time_limit``, ``no_solution``).
    marker_error_m : (n,) float or None
        Network mode: predicted error of each kept marker relative to the datum (nan for the
        others), m.
    markers_ok : bool
        Network mode: every kept marker meets the requirement (always True otherwise).
    pairs_ok : bool
        Network mode with a local requirement: every judged station pair meets it (always
        True otherwise).
    marker_pairs_ok : bool
        Network mode with ``local_markers``: every judged pair of kept markers meets the local
        requirement (always True otherwise). The curve minimises the worst error relative to
        the datum among the subsets meeting the local requirement.
    """

    k: int
    selected: np.ndarray
    error_m: np.ndarray
    count: np.ndarray
    sectors: np.ndarray
    ok: np.ndarray
    lower_bound_m: float
    proven: bool
    n_solves: int
    statuses: tuple[str, ...]
    marker_error_m: np.ndarray | None = None
    markers_ok: bool = True
    pairs_ok: bool = True
    marker_pairs_ok: bool = True

    @property
    def worst_error_m(self) -> float:
        """Worst station error, m; in network mode the worst of the stations and the kept
        markers (what the requirement applies to)."""
        markers = self.worst_marker_error_m
        return self.worst_station_error_m if markers is None \
            else max(self.worst_station_error_m, markers)

    @property
    def worst_station_error_m(self) -> float:
        return float(self.error_m.max())

    @property
    def worst_marker_error_m(self) -> float | None:
        """Network mode: worst kept marker's error, m (``None`` otherwise)."""
        return worst_marker(self.marker_error_m)

    @property
    def mean_error_m(self) -> float:
        return float(self.error_m.mean())

    @property
    def meets_requirement(self) -> bool:
        return bool(self.ok.all()) and self.markers_ok and self.pairs_ok \
            and self.marker_pairs_ok


@dataclass(frozen=True)
class Curve:
    """The trade-off curve, ``points`` ordered from the most markers to the fewest.

    Attributes
    ----------
    points : list of CurvePoint
    k_directions : int
        Fewest markers meeting count and direction rows at every station (accuracy ignored);
        in network mode, if the curve found that fewer cannot tie every station to the datum
        (and meet the local requirement), the fewest that do.
    k_feasible : int or None
        Fewest markers on the curve meeting the requirement at every station (``None``: no
        point does).
    k_feasible_minimal : bool
        Proven that no smaller count meets it (False when a smaller count hit the time limit
        or lies below ``k_min``).
    n_cuts : int
        Accuracy cuts generated over the whole study.
    solve_time_s : float
        Total time in the solver, s.
    complete : bool
        False when the time limit stopped the curve before ``k_min``.
    """

    points: list[CurvePoint]
    k_directions: int
    k_feasible: int | None
    k_feasible_minimal: bool
    n_cuts: int
    solve_time_s: float
    complete: bool = True

    @property
    def proven(self) -> bool:
        return self.complete and all(p.proven for p in self.points)

    def at(self, k: int) -> CurvePoint:
        """The point with ``k`` markers."""
        for p in self.points:
            if p.k == k:
                return p
        ks = [p.k for p in self.points] or [0]
        raise ConfigError(f"k must be one of the curve's counts {min(ks)}..{max(ks)}, got {k}")


def tradeoff_curve(problem: PlanProblem, config, k_max: int | None = None,
                   k_min: int | None = None, time_limit_s: float | None = None,
                   tol_m: float = 1e-4, exact: bool = True,
                   start: np.ndarray | None = None,
                   incumbents: dict[int, np.ndarray] | None = None) -> Curve:
    """Minimal worst-station predicted error for every marker count, by integer programming.

    Parameters
    ----------
    problem : PlanProblem
        Candidate sites are the markers that may be kept (a layout, or all candidate sites);
        none may be ``site_existing``.
    config : PlanConfig
        Uses ``requirement_m`` (pass/fail and the information rows' scale), ``min_markers``,
        ``n_sectors``, ``min_sectors``, ``working_radius_m``, ``inclinometer_sigma_deg``,
        ``existing`` (markers always kept), ``forbidden`` (markers never kept) and
        ``time_limit_s`` (the whole study, unless ``time_limit_s`` is given).
    k_max : int, optional
        Largest count (default: every candidate site not forbidden).
    k_min : int, optional
        Smallest count (default: the fewest markers that meet the count and direction rows).
    time_limit_s : float, optional
        Wall-clock limit of the whole curve, s, shared equally by the counts still to do.
    tol_m : float
        Bisection stops at this width (worst error minus proven lower bound), m.
    exact : bool
        Then test just below the best subset until it is proven optimal (to ``REL_TOL``);
        without it a point is optimal within ``tol_m``.
    start : (n,) bool, optional
        A ``k_max``-subset meeting the count and direction rows (e.g. the layout) to start from;
        each count's search also starts from the best one-marker drop of the previous point.
    incumbents : dict of int -> (n,) bool, optional
        Known ``k``-subsets meeting the count and direction rows (e.g. the layout-only optimum
        in free mode); the search starts from the best of these and the one-marker drop.

    Returns
    -------
    curve : Curve
        Points from ``k_max`` down to ``k_min``; ``worst_error_m`` never decreases as k falls
        (known control; in network mode a kept marker's own error may break that).

    Raises
    ------
    ConfigError
        ``k_min`` / ``k_max`` out of range, redundant mode, a budget or existing sites.
    InfeasiblePlanError
        No subset meets the count and direction rows, naming the stations and why.
    """
    reduction_iv(problem, config, np.ones(problem.n_sites, bool))
    limit = config.time_limit_s if time_limit_s is None else float(time_limit_s)
    deadline = time.perf_counter() + limit
    mm = (NetworkMinimax if config.network else MinimaxModel)(problem, config, deadline)
    if not mm.bisect:  # descent: a point is proven optimal (to REL_TOL) or not at all
        tol_m, exact = np.inf, True
    k_dir = mm.min_count_directions()
    if k_dir is None:
        why = diagnose(problem, config.replace(requirement_m=1e9), mm.infos)
        raise InfeasiblePlanError(
            "no subset gives every station >= "
            f"{config.min_markers} usable markers in >= {config.min_sectors} sectors"
            + (": " + "; ".join(f"{k}: {v}" for k, v in why.items()) if why else "")
            + "; add markers or relax min_markers / min_sectors")
    n = problem.n_sites
    pool = ~problem.site_mask(config.forbidden, "forbidden")
    k_max = int(pool.sum()) if k_max is None else k_max
    k_min = k_dir if k_min is None else k_min
    _k_range_iv(k_min, k_max, k_dir, int(pool.sum()))
    start = _start_iv(start, n, k_max)
    if start is not None and not directions_ok(problem, start, config).all():
        start = None  # not a valid incumbent: some station lacks its count or directions
    allowed = np.isin(np.arange(n), mm.model.var_site) & pool
    floor = mm.floor(allowed) * (1 - REL_TOL)  # no subset beats keeping every site
    kept = problem.site_mask(config.existing, "existing")
    points: list[CurvePoint] = []
    complete = True
    best_above = None  # proven optimum of the next larger k (a lower bound for this k)
    previous = start
    for k in range(k_max, k_min - 1, -1):
        statuses: list[str] = []
        proven = True
        # share the time left equally among the counts still to do
        mm.deadline = time.perf_counter() + (deadline - time.perf_counter()) / (k - k_min + 1)
        if k >= mm.nx:  # every usable marker fits: keeping all is optimal (monotone)
            best, lo = mm.pad(allowed, k, pool), floor
        else:
            incumbent = _best_of(mm, [previous if previous is not None
                                      and previous.sum() == k else _drop_one(mm, previous, kept),
                                      (incumbents or {}).get(k)])
            lo = max(floor, -np.inf if best_above is None else best_above * (1 - REL_TOL))
            best, lo, proven = _minimax(mm, k, incumbent, lo, best_above, tol_m, exact,
                                        statuses)
            if best is None:
                # no k-subset meets the directions and (network mode) ties every station to
                # the datum and meets the local requirement; fewer markers cannot either
                # (``local_markers``: fewer markers have fewer pairs, taken as no easier)
                if proven:
                    k_dir = k + 1
                else:  # the time limit ran out before any k-subset was found
                    complete = False
                break
        best = mm.pad(best, k, pool)
        check = mm.check(best)
        points.append(CurvePoint(k=k, selected=best, error_m=check.error_m, count=check.count,
                                 sectors=check.sectors, ok=check.ok, lower_bound_m=float(lo),
                                 proven=bool(proven), n_solves=len(statuses),
                                 statuses=tuple(statuses), marker_error_m=check.marker_error_m,
                                 markers_ok=check.markers_ok, pairs_ok=check.pairs_ok,
                                 marker_pairs_ok=check.marker_pairs_ok))
        best_above = check_worst(check) if proven and exact and mm.monotone else None
        previous = best
    points = _monotone(mm, points, allowed)
    feasible = [p.k for p in points if p.meets_requirement]
    k_feasible = min(feasible) if feasible else None
    return Curve(points=points, k_directions=k_dir, k_feasible=k_feasible,
                 k_feasible_minimal=_minimal(points, k_feasible, k_dir, config.requirement_m,
                                             mm.monotone),
                 n_cuts=mm.n_cuts, solve_time_s=mm.solve_time_s, complete=complete)


def _monotone(mm: MinimaxModel, points: list[CurvePoint], allowed: np.ndarray
              ) -> list[CurvePoint]:
    """Adding markers never hurts a station: where a smaller count's subset beats a larger
    count's (only possible when the larger one is not proven optimal, or in network mode, where
    a kept marker's own error counts), replace the larger one by the smaller plus its best
    additions, from the fewest markers up, if that is better."""
    out = list(points)
    for i in range(len(out) - 2, -1, -1):  # out[i + 1] has one marker fewer than out[i]
        small, big = out[i + 1], out[i]
        if not small.worst_error_m < big.worst_error_m * (1 - REL_TOL):
            continue
        sel = small.selected.copy()
        while sel.sum() < big.k:
            free = np.flatnonzero(allowed & ~sel)
            if free.size == 0:
                break
            errs = [mm.worst(np.where(np.arange(sel.size) == j, True, sel)) for j in free]
            sel[free[int(np.argmin(errs))]] = True
        chk = mm.check(sel)
        if not (check_worst(chk) < big.worst_error_m and local_ok(chk)):
            continue
        out[i] = replace(big, selected=sel, error_m=chk.error_m, count=chk.count,
                         sectors=chk.sectors, ok=chk.ok, marker_error_m=chk.marker_error_m,
                         markers_ok=chk.markers_ok, pairs_ok=chk.pairs_ok,
                         marker_pairs_ok=chk.marker_pairs_ok)
    return out


def _start_iv(start, n: int, k_max: int) -> np.ndarray | None:
    if start is None:
        return None
    start = np.asarray(start, dtype=bool)
    if start.shape != (n,) or int(start.sum()) != k_max:
        raise ConfigError(f"`start` must be (n,) bool with k_max = {k_max} sites selected, got "
                          f"shape {start.shape} with {int(start.sum())} selected")
    return start


def _minimal(points: list[CurvePoint], k_feasible: int | None, k_dir: int,
             requirement_m: float, monotone: bool = True) -> bool:
    """Whether no count below ``k_feasible`` can pass (proven): the count just below on a
    monotone curve, else every count down to ``k_dir``."""
    if k_feasible is None:
        return False
    if k_feasible == k_dir:
        return True
    lowest = k_feasible - 1 if monotone else k_dir
    below = [p for p in points if lowest <= p.k < k_feasible]
    return len(below) == k_feasible - lowest and all(
        p.proven or p.lower_bound_m >= requirement_m for p in below)


def _best_of(mm: MinimaxModel, subsets) -> np.ndarray | None:
    """The subset with the lowest worst-station error among those meeting the direction rows."""
    ok = [np.asarray(x, bool) for x in subsets
          if x is not None and directions_ok(mm.problem, np.asarray(x, bool), mm.config).all()]
    return min(ok, key=lambda x: mm.worst(x)) if ok else None


def _drop_one(mm: MinimaxModel, selected: np.ndarray | None, kept: np.ndarray
              ) -> np.ndarray | None:
    """The best subset one marker smaller that keeps every count and direction row, or None."""
    if selected is None:
        return None
    best, best_key = None, None
    for m in np.flatnonzero(selected & ~kept):
        trial = selected.copy()
        trial[m] = False
        if directions_ok(mm.problem, trial, mm.config).all():
            key = mm.worst(trial)
            if best_key is None or key < best_key:
                best, best_key = trial, key
    return best


def _minimax(mm: MinimaxModel, k: int, incumbent: np.ndarray | None, lo: float,
             best_above: float | None, tol_m: float, exact: bool, statuses: list[str]
             ) -> tuple[np.ndarray | None, float, bool]:
    """Bisection for one k: (best subset, proven lower bound, proven optimal).

    ``lo`` is a proven lower bound (W*(k) > lo); ``incumbent`` a feasible k-subset or None.
    The subset is ``None`` when no k-subset was found: proven (no k-subset exists) or not
    (the time limit).
    """
    proven = True
    best = incumbent
    mm.solve_cap_s = np.inf
    if best is not None and not np.isfinite(mm.worst(best)):
        best = None  # network mode: the incumbent leaves a station untied to the datum or
        # fails the local requirement
    if best is None:
        best, proven = mm.query(k, np.inf, statuses)
        if best is None:  # proven: no k-subset at all (network: none ties every station)
            return None, lo, proven
    hi = mm.worst(best)
    if best_above is not None and hi > best_above:  # W*(k) >= W*(k+1): try that first
        sel, ok = mm.query(k, best_above, statuses)
        if sel is not None:
            best, hi = sel, mm.worst(sel)
        elif ok:
            lo = best_above
        else:
            return best, lo, False
    width = tol_m
    while True:
        if hi - lo > width:
            eps = 0.5 * (lo + hi)
        elif exact:  # final test just below the best: infeasible proves it optimal
            eps = hi * (1 - REL_TOL)
        else:
            return best, lo, proven
        if eps <= lo:
            return best, lo, proven
        if time.perf_counter() >= mm.deadline:
            statuses.append("time_limit")
            return best, lo, False
        final = hi - lo <= width
        # one solve may take a third of the time left for this count, so that a bound too
        # hard to prove leaves time to try a less ambitious one
        mm.solve_cap_s = (mm.deadline - time.perf_counter()) / 3.0
        sel, ok = mm.query(k, eps, statuses)
        if sel is not None:
            best, hi = sel, mm.worst(sel)
            if final:
                width /= 16.0
        elif ok:
            lo = eps
        else:  # no answer in time: eps is not proven infeasible; try closer to the best
            hard = eps
            while time.perf_counter() < mm.deadline:
                eps = 0.5 * (hard + hi)
                if hi - eps <= width:
                    break
                mm.solve_cap_s = (mm.deadline - time.perf_counter()) / 3.0
                sel, ok = mm.query(k, eps, statuses)
                if sel is not None:
                    best, hi = sel, mm.worst(sel)
                elif not ok:
                    hard = eps
                else:
                    lo = eps
                    break
            return best, lo, False


def _k_range_iv(k_min: int, k_max: int, k_dir: int, n: int) -> None:
    for name, v in (("k_min", k_min), ("k_max", k_max)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool):
            raise ConfigError(f"`{name}` must be an integer, got {v!r}")
    if not 1 <= k_max <= n:
        raise ConfigError(f"`k_max` must be in 1..{n} (the markers that may be kept), "
                          f"got {k_max}")
    if not k_dir <= k_min <= k_max:
        raise ConfigError(f"`k_min` must be in {k_dir}..{k_max} (below {k_dir} markers no subset "
                          f"meets the direction rows), got {k_min}")
