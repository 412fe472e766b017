"""Chance-constrained planning: valid rows for stations whose chance of failing is too high.

A station's chance of passing only grows with the sites a layout adds
(:mod:`planner.accuracy.chance`), so when a layout's station ``s`` provably fails its target
with the site set ``C``, every layout whose usable sites at ``s`` lie inside ``C`` fails too:
``sum_{j in U_s \\ C} x_j >= 1``. :func:`chance_cuts` first grows ``C`` by the least useful
sites while the failure stays proven (a stronger row), as the accuracy cuts do. A layout the
bounds cannot decide (enumeration budget spent) gets the plain row on ``C`` as an
``"chance-undecided"`` row, counted in the plan, since it is not proven valid.

In network mode the stations' rule judges count and directions; a layout that meets it is then
judged as a whole, with the network's accuracy and local requirement
(:mod:`planner.accuracy.network_chance`), and a layout that fails gets a no-good row
(:meth:`ChanceRule.whole_cuts`), which with ``local_markers`` keeps the markers of the
layout's judged marker pairs in (marker pairs are not monotone in the selection).

:func:`chance_count_rows` are valid from the start: a station needs at least ``k`` markers
when even its ``k - 1`` likeliest usable markers detect ``min_markers`` too rarely.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from markerplan.errors import InfeasiblePlanError
from planner.accuracy.chance import StationOdds, more_losses_than, station_odds, station_target
from planner.accuracy.checks import StationInfo
from planner.accuracy.network_chance import NetworkChance, NetworkOdds
from planner.problem.usability import PlanProblem
from planner.program.model import Model, RowKind

#: Most enumerations one failing station's set growth may run, and most loss sets each judges
#: (a set fails provably once its enumerated failures pass the target: a few suffice).
MAX_GROWTH_EVALUATIONS = 12
GROWTH_LOSS_SETS = 600


@dataclass(frozen=True)
class ChanceRule:
    """The chance constraint of a plan: every station's odds and its allowed chance of failing.

    Attributes
    ----------
    odds : list of StationOdds, (s,)
    target : float
        Each station's allowed chance of failing (:func:`~planner.accuracy.chance.station_target`).
    whole : callable or None
        Network mode: ``whole(selected) -> NetworkChance``, the whole network's certified
        chance of failing with its accuracy (:mod:`planner.accuracy.network_chance`), decided
        against ``epsilon``; ``None`` in known control, where the stations' targets are the
        whole rule.
    epsilon : float or None
        The plan's allowed chance of failing (with ``whole``).
    paired : callable or None
        With ``whole`` and ``local_markers``: ``paired(selected) -> (m,) int``, the layout's
        sites some judged marker pair holds (:meth:`~planner.accuracy.network_chance.
        NetworkOdds.paired_sites`).
    """

    odds: list[StationOdds]
    target: float
    whole: Callable[[np.ndarray], NetworkChance] | None = None
    epsilon: float | None = None
    paired: Callable[[np.ndarray], np.ndarray] | None = None

    def cuts(self, problem: PlanProblem, model: Model, selected: np.ndarray):
        """:func:`chance_cuts` of a layout."""
        return chance_cuts(problem, model, selected, self.odds, self.target)

    def count_rows(self, problem: PlanProblem, model: Model):
        """:func:`chance_count_rows`."""
        return chance_count_rows(problem, model, self.odds, self.target)

    def layout_ok(self, selected: np.ndarray) -> bool:
        """Whether every station meets its target with ``selected`` ((n,) bool), and the
        whole network its ``epsilon``."""
        return all(o.chance(o.info.sites[selected[o.info.sites]], self.target).fail_high
                   <= self.target for o in self.odds) and self.whole_ok(selected)

    def whole_ok(self, selected: np.ndarray) -> bool:
        """Whether the whole network fails with chance at most ``epsilon``, by its bounds or
        its sampled outcomes (:meth:`~planner.accuracy.network_chance.NetworkChance.meets`;
        always true without ``whole``)."""
        return self.whole is None or self.whole(selected).meets(self.epsilon)

    def whole_cuts(self, problem: PlanProblem, model: Model, selected: np.ndarray
                   ) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
        """A no-good row for a layout ``C`` whose whole network fails ``epsilon``: some site
        outside it, ``sum_{j not in C} x_j >= 1`` (valid: a subset of a failing layout fails
        too), or with ``local_markers`` some site outside it or one of the sites ``P`` of its
        judged marker pairs left out, ``sum_{j not in C} x_j - sum_{j in P} x_j >= 1 - |P|``
        (valid: a subset of ``C`` holding ``P`` fails in every outcome ``C`` fails in; fixed
        sites of ``P`` drop out); ``"chance-network"`` when proven, ``"chance-undecided"``
        when only sampled outcomes decided it; ``(None, [], [])`` when it passes or without
        ``whole``."""
        if self.whole_ok(selected):
            return None, [], []
        proven = self.whole(selected).fail_low > self.epsilon
        rest = np.flatnonzero(~np.asarray(selected, bool) & (model.site_var >= 0))
        paired = np.zeros(0, np.int64) if self.paired is None else self.paired(selected)
        paired = paired[model.site_var[paired] >= 0]
        row = model.site_row(np.r_[rest, paired], np.r_[np.ones(rest.size),
                                                        -np.ones(paired.size)])
        return (sp.csr_array(row), [1.0 - paired.size],
                [RowKind("chance-network" if proven else "chance-undecided")])


def chance_rule(problem: PlanProblem, config, infos: list[StationInfo]) -> ChanceRule | None:
    """The plan's :class:`ChanceRule`, or ``None`` when it has none: ``chance_epsilon`` is
    ``None`` (the naive plan) or the problem knows no detection chances. In network mode it
    also judges the whole network (each layout once)."""
    if config.chance_epsilon is None or problem.pair_detection_p is None:
        return None
    target = station_target(config.chance_epsilon, problem.n_stations)
    if not config.network:
        return ChanceRule(station_odds(problem, infos, config), target)
    judged: dict[bytes, tuple[NetworkChance, np.ndarray]] = {}

    def judge(selected: np.ndarray) -> tuple[NetworkChance, np.ndarray]:
        key = np.packbits(np.asarray(selected, bool)).tobytes()
        if key not in judged:
            odds = NetworkOdds(problem, selected, config)
            judged[key] = odds.decide(config.chance_epsilon), odds.paired_sites()
        return judged[key]

    return ChanceRule(station_odds(problem, infos, config), target,
                      lambda selected: judge(selected)[0], config.chance_epsilon,
                      lambda selected: judge(selected)[1])


def chance_preflight(problem: PlanProblem, config, rule: ChanceRule) -> dict[str, str]:
    """Stations that provably miss their target whatever the layout, and why.

    With every allowed usable site selected: too few likely markers
    (:func:`min_markers_for_chance` above the usable sites) or a proven chance of failing
    above the target.
    """
    allowed = ~problem.site_mask(config.forbidden, "forbidden")
    out = {}
    for s, o in enumerate(rule.odds):
        sites = o.info.sites[allowed[o.info.sites]]
        if not sites.size:
            continue  # no usable site at all: :func:`~planner.accuracy.checks.diagnose` says so
        c = o.chance(sites, rule.target)
        if c.fail_low > rule.target:
            out[problem.station_ids[s]] = (
                f"even all {sites.size} usable sites give a chance of passing of at most "
                f"{1 - c.fail_low:.4f}, below the {1 - rule.target:.4f} each station needs "
                f"for chance_epsilon {config.chance_epsilon:g}")
    return out


def chance_cuts(problem: PlanProblem, model: Model, selected: np.ndarray,
                odds: list[StationOdds], target: float
                ) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """Rows for every station whose chance of failing with ``selected`` exceeds ``target``.

    Parameters
    ----------
    problem : PlanProblem
    model : Model
    selected : (n,) bool
    odds : list of StationOdds, (s,)
    target : float
        Each station's allowed chance of failing.

    Returns
    -------
    rows : (c, v) sparse or None
        ``None`` when every station meets its target.
    lower : list of float
    kinds : list of RowKind
        ``"chance"`` (proven) or ``"chance-undecided"``.
    """
    rows, lower, kinds = [], [], []
    for s, o in enumerate(odds):
        chosen = o.info.sites[selected[o.info.sites]]
        c = o.chance(chosen, target)
        if c.fail_high <= target:
            continue
        if c.fail_low > target:
            grown, kind = grow_failing_chance(o, chosen, target), "chance"
        else:
            grown, kind = chosen, "chance-undecided"
        rest = np.setdiff1d(o.info.sites, grown)
        if rest.size == 0:  # every usable site fails: the preflight names such stations
            raise InfeasiblePlanError(
                f"station {problem.station_ids[s]}: even all {o.info.sites.size} usable "
                f"sites fail with chance {c.fail_low:.4f}, above the {target:.4g} it may; "
                "raise chance_epsilon or add candidate sites")
        rows.append(model.site_row(rest))
        lower.append(1.0)
        kinds.append(RowKind(kind, s))
    return (sp.csr_array(sp.vstack(rows)) if rows else None), lower, kinds


def grow_failing_chance(odds: StationOdds, failing: np.ndarray, target: float) -> np.ndarray:
    """Grow a provably failing site set, least useful sites first, while failure stays proven.

    A site's use is its detection chance times its information weight ``q / sigma^2``. "The
    set plus the next ``m`` sites in that order still provably fails" is monotone in ``m``
    only up to what the bounds can prove, so the additions are found by bisection within
    ``MAX_GROWTH_EVALUATIONS`` enumerations; a site that would let the station pass is
    skipped. Returns candidate-site indices of the grown set (a superset of ``failing``).
    """
    info = odds.info
    in_set = np.zeros(info.sites.size, bool)
    in_set[info.rows(failing)] = True
    order = np.argsort(odds.q / info.sigma_m**2, kind="stable")
    order = order[~in_set[order]]
    evaluations = 0

    def fails(extra: np.ndarray) -> bool:
        nonlocal evaluations
        evaluations += 1
        sites = np.sort(np.r_[info.sites[in_set], info.sites[extra]])
        return odds.chance(sites, target, GROWTH_LOSS_SETS, stop_above=target).fail_low > target

    pos = 0
    while pos < order.size and evaluations < MAX_GROWTH_EVALUATIONS:
        lo, hi = 0, order.size - pos  # largest m with fails(order[pos:pos + m])
        while lo < hi and evaluations < MAX_GROWTH_EVALUATIONS:
            mid = (lo + hi + 1) // 2
            if fails(order[pos:pos + mid]):
                lo = mid
            else:
                hi = mid - 1
        in_set[order[pos:pos + lo]] = True
        pos += lo + 1
    return info.sites[in_set]


def min_markers_for_chance(odds: StationOdds, target: float) -> int:
    """Fewest usable markers station ``odds`` needs so that ``min_markers`` of them can be
    detected with chance at least ``1 - target``: with its ``k`` likeliest markers (the best
    any ``k`` can do); its usable site count + 1 when even all of them fall short."""
    q = np.sort(odds.q)[::-1]
    need = odds.min_markers
    for k in range(need, q.size + 1):
        # P(fewer than `need` of the k detected) = P(more than k - need lost)
        if more_losses_than(q[:k])[k - need] <= target:
            return k
    return q.size + 1


def chance_count_rows(problem: PlanProblem, model: Model, odds: list[StationOdds],
                      target: float) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """Rows valid for every layout that meets the chance targets, two per station at most.

    - ``"chance-count"``: ``sum_{j in U_s} x_j >= k_s`` where :func:`min_markers_for_chance`
      exceeds ``min_markers`` (and does not exceed the usable sites);
    - ``"chance-critical"``: a station with exactly ``min_markers`` markers loses its count
      with any one of them, so it passes only when all are detected: ``sum_j w_j x_j <= W``
      with ``w_j = -log q_j`` and ``W = -log(1 - target)``. As one row valid for every
      count: ``sum_j w'_j x_j - M sum_j x_j <= W - M min_markers`` with ``w'_j = min(w_j,
      2 W)`` (capping only weakens it) and ``M = (min_markers + 1) 2 W - W``, which no
      layout with more markers can reach.
    """
    rows, lower, upper, kinds = [], [], [], []
    cap = -2.0 * np.log1p(-target)
    big = (odds[0].min_markers + 1) * cap + np.log1p(-target) if odds else 0.0
    for s, o in enumerate(odds):
        k = min_markers_for_chance(o, target)
        if o.min_markers < k <= o.info.sites.size:
            rows.append(model.site_row(o.info.sites))
            lower.append(float(k))
            upper.append(np.inf)
            kinds.append(RowKind("chance-count", s))
        w = np.minimum(-np.log(np.maximum(o.q, 1e-300)), cap)
        if o.info.sites.size and np.any(w > -np.log1p(-target)):
            rows.append(model.site_row(o.info.sites, w - big))
            lower.append(-np.inf)
            upper.append(-np.log1p(-target) - big * o.min_markers)
            kinds.append(RowKind("chance-critical", s))
    return (sp.csr_array(sp.vstack(rows)) if rows else None), lower, upper, kinds
