"""The chance that a station passes when planned markers may be lost, with certified bounds.

Each usable station-site pair of a layout is detected and accepted with its probability
(:attr:`planner.problem.usability.PlanProblem.detection_p`), independently of every other pair.
A station passes when the markers it detects meet the count, the directions and (in known
control) the predicted accuracy, which is what ``markerplan verify`` checks. Passing is
*monotone*: detecting more markers never makes a station fail (more information, more
sectors). So

- ``P(fail) = sum over loss sets L of P(L) [the markers left fail]``, and the failing loss sets
  are closed upwards: a loss set holding a failing one fails. :func:`station_chance` enumerates
  loss sets by size, smallest first, and evaluates only those none of whose subsets already
  fails; it stops when the chance of losing more markers than enumerated (the Poisson-binomial
  tail, exact) is negligible or the enumeration's budget is spent. The sum over the enumerated
  failing sets bounds ``P(fail)`` from below, adding the tail bounds it from above; with every
  size enumerated both are exact.
- a station's ``P(pass)`` only grows when sites are added to a layout, so a layout whose
  station fails its target proves every layout with a subset of its sites at that station fails
  too (the chance-constrained planner's no-good cuts, :mod:`planner.program.cuts_chance`).

:func:`station_target` splits the plan's ``chance_epsilon`` over the stations (a union bound:
the plan fails with probability at most the sum of its stations'); :func:`plan_chance` gives a
layout's figures per station and for the plan.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from planner.accuracy.checks import StationInfo
from planner.problem.usability import PlanProblem, sector_index

#: Most loss sets one station's enumeration evaluates.
MAX_LOSS_SETS = 20_000
#: The enumeration stops once the chance of losing more markers than enumerated is below this
#: fraction of the station's target.
TAIL_FRACTION = 1e-3


@dataclass(frozen=True)
class StationChance:
    """Certified bounds on one station's chance of failing with a layout.

    Attributes
    ----------
    fail_low, fail_high : float
        ``fail_low <= P(fail) <= fail_high``; equal when every loss set was judged.
    n_markers : int
        The station's usable markers in the layout.
    max_losses : int
        Loss sets of up to this many markers were enumerated (``n_markers``: all).
    """

    fail_low: float
    fail_high: float
    n_markers: int
    max_losses: int

    @property
    def exact(self) -> bool:
        return self.max_losses >= self.n_markers

    @property
    def pass_low(self) -> float:
        """Certified lower bound on ``P(pass)``."""
        return 1.0 - self.fail_high


def station_target(epsilon: float, n_stations: int) -> float:
    """Each station's allowed chance of failing: ``epsilon / n_stations`` (union bound).

    Examples
    --------
    >>> station_target(0.05, 5)
    0.01
    """
    return float(epsilon) / max(int(n_stations), 1)


class StationOdds:
    """One station's usable sites with their detection chance and sector, for enumeration.

    Parameters
    ----------
    problem : PlanProblem
    info : StationInfo
        The station's usable sites and their information (known-control accuracy).
    config : PlanConfig
        Uses ``min_markers``, ``min_sectors``, ``n_sectors``, ``requirement_m``.
    accuracy : bool
        Judge the predicted accuracy of the markers left (known control); ``False`` judges
        count and directions only (network mode, whose accuracy is the network's).
    """

    def __init__(self, problem: PlanProblem, info: StationInfo, config,
                 accuracy: bool = True) -> None:
        self.info = info
        self.q = problem.detection_p[info.pairs]
        self.sector = sector_index(problem.pair_bearing_rad[info.pairs], config.n_sectors)
        self.min_markers = config.min_markers
        self.min_sectors = config.min_sectors
        self.requirement_m = config.requirement_m
        self.accuracy = accuracy

    def chance(self, sites, target: float, budget: int = MAX_LOSS_SETS,
               stop_above: float | None = None) -> StationChance:
        """:class:`StationChance` of the usable ones among ``sites`` (candidate-site indices).

        ``target`` (the allowed chance of failing) sets where the enumeration may stop: once
        the tail left is below ``TAIL_FRACTION * target``; it judges at most ``budget`` loss
        sets, and stops as soon as the chance of failing is proven above ``stop_above``
        (then ``fail_high`` is only what the enumeration so far bounds).
        """
        rows = self.info.rows(sites)
        return _enumerate(self, rows, TAIL_FRACTION * target, budget, stop_above)

    def passes(self, rows: np.ndarray, kept: np.ndarray) -> np.ndarray:
        """(k,) bool: whether each set of markers left passes; ``kept`` is (k, m) bool over
        ``rows``."""
        count = kept.sum(axis=1)
        occupied = np.zeros((kept.shape[0], int(self.sector.max(initial=0)) + 1), bool)
        for c, s in enumerate(self.sector[rows]):
            occupied[:, s] |= kept[:, c]
        ok = (count >= self.min_markers) & (occupied.sum(axis=1) >= self.min_sectors)
        if self.accuracy and ok.any():
            parts = self.info.info[rows].reshape(rows.size, 16)
            j = (kept[ok].astype(float) @ parts).reshape(-1, 4, 4)
            ok[np.flatnonzero(ok)] = self.info.within(j, self.requirement_m)
        return ok


def _enumerate(odds: StationOdds, rows: np.ndarray, tail_tolerance: float,
               budget: int = MAX_LOSS_SETS, stop_above: float | None = None
               ) -> StationChance:
    """:func:`enumerate_losses` of one station's markers ``rows``."""
    return enumerate_losses(odds.q[rows], lambda kept: odds.passes(rows, kept),
                            tail_tolerance, budget, stop_above)


def enumerate_losses(q: np.ndarray, passes, tail_tolerance: float,
                     budget: int = MAX_LOSS_SETS, stop_above: float | None = None,
                     stop_below: float | None = None, monotone: bool = True) -> StationChance:
    """Certified bounds on ``P(fail)`` when each of ``m`` items is kept with its chance ``q``.

    Loss sets are enumerated by size, smallest first; a set is judged only when none of its
    subsets already fails (failing is closed upwards; with ``monotone`` false every set is
    judged), until the chance of losing more items
    than enumerated is at most ``tail_tolerance``, the next size would pass ``budget`` sets,
    failure is proven above ``stop_above`` or below ``stop_below`` (a decision, not figures).

    Parameters
    ----------
    q : (m,) float
        Each item's chance of being kept (detected and accepted).
    passes : callable
        ``passes(kept) -> (k,) bool`` for ``kept``, (k, m) bool: whether each outcome passes;
        with ``monotone``, keeping more must never fail.
    tail_tolerance, budget, stop_above, stop_below, monotone
        As above.

    Returns
    -------
    StationChance
        ``n_markers`` is ``m``.
    """
    m = q.size
    whole_fails = not passes(np.ones((1, m), bool))[0]
    if whole_fails and monotone:
        return StationChance(1.0, 1.0, m, m)
    tail = more_losses_than(q)  # tail[k] = P(more than k items lost)
    low = float(np.prod(q)) if whole_fails else 0.0
    failed = np.zeros(0, np.int64)  # colex ranks of the failing loss sets of the last size
    sizes = sizes_within(m, budget)
    k = 0
    while k < sizes:
        if tail[k] <= tail_tolerance:
            break
        k += 1
        lost = np.array(list(itertools.combinations(range(m), k)), np.int64)  # (c, k)
        fails = np.zeros(len(lost), bool)
        if failed.size and monotone:
            for drop in range(k):  # a subset one smaller failed
                fails |= np.isin(_colex_rank(np.delete(lost, drop, axis=1)), failed)
        judge = np.flatnonzero(~fails)
        if judge.size:
            kept = np.ones((judge.size, m), bool)
            kept[np.arange(judge.size)[:, None], lost[judge]] = False
            fails[judge] = ~passes(kept)
        if fails.all() and monotone:  # every larger loss set holds one of these: all fail
            low += float(_exactly_lost(q, lost[fails]).sum()) + float(tail[k])
            return StationChance(min(low, 1.0), min(low, 1.0), m, m)
        low += float(_exactly_lost(q, lost[fails]).sum())
        failed = _colex_rank(lost[fails])
        if (stop_above is not None and low > stop_above) \
                or (stop_below is not None and low + float(tail[k]) <= stop_below):
            return StationChance(min(low, 1.0), min(low + float(tail[k]), 1.0), m, k)
    high = low + (float(tail[k]) if k < m else 0.0)
    return StationChance(min(low, 1.0), min(high, 1.0), m, k if k < m else m)


def sizes_within(m: int, budget: int) -> int:
    """The largest ``k`` such that every loss set of up to ``k`` of ``m`` items fits in
    ``budget`` judged sets (``sum_{i <= k} C(m, i) <= budget``).

    Examples
    --------
    >>> sizes_within(5, 15), sizes_within(5, 14)
    (2, 1)
    """
    k, used = 0, 0
    while k < m and used + math.comb(m, k + 1) <= budget:
        k += 1
        used += math.comb(m, k)
    return k


def _colex_rank(sets: np.ndarray) -> np.ndarray:
    """(c,) int: the colex rank ``sum_i C(s_i, i + 1)`` of each row of ``sets`` ((c, k) int,
    ascending), distinct for distinct sets of one size; below ``C(m, k)`` for items < m."""
    if sets.shape[1] == 0:
        return np.zeros(len(sets), np.int64)
    top = int(sets.max(initial=0)) + 1
    table = np.array([[math.comb(n, i + 1) for i in range(sets.shape[1])] for n in range(top)],
                     np.int64)
    return table[sets, np.arange(sets.shape[1])].sum(axis=1)


def _exactly_lost(q: np.ndarray, lost: np.ndarray) -> np.ndarray:
    """(c,) probability that exactly the markers in each row of ``lost`` ((c, k) int) are lost
    and all the others detected."""
    keep = np.ones((len(lost), q.size), bool)
    keep[np.arange(len(lost))[:, None], lost] = False
    return np.prod(np.where(keep, q, 1.0 - q), axis=1)


def more_losses_than(q: np.ndarray) -> np.ndarray:
    """(m + 1,) ``P(more than k of the markers lost)`` for k = 0..m (Poisson binomial), each
    marker detected with its chance ``q`` ((m,) float) independently.

    Examples
    --------
    >>> more_losses_than(np.array([0.5, 0.5])).tolist()
    [0.75, 0.25, 0.0]
    """
    dist = np.zeros(q.size + 1)
    dist[0] = 1.0
    for p in q:
        dist[1:] = dist[1:] * p + dist[:-1] * (1.0 - p)
        dist[0] *= p
    return np.maximum(1.0 - np.cumsum(dist), 0.0)


@dataclass(frozen=True)
class PlanChance:
    """A layout's chance of passing, per station and for the plan.

    Attributes
    ----------
    epsilon : float or None
        The plan's allowed chance of failing (``None``: not constrained, figures reported).
    station_target : float or None
        Each station's allowed chance of failing (:func:`station_target`).
    stations : list of StationChance, (s,)
    """

    epsilon: float | None
    station_target: float | None
    stations: list[StationChance]

    @property
    def pass_low(self) -> float:
        """Certified lower bound on the plan's ``P(pass)``: stations' outcomes are independent
        in known control (each uses its own pairs), so the product of their bounds."""
        return float(np.prod([c.pass_low for c in self.stations]))

    @property
    def union_pass_low(self) -> float:
        """``1 - sum of the stations' P(fail)`` bounds: valid without independence."""
        return max(0.0, 1.0 - float(sum(c.fail_high for c in self.stations)))


def plan_chance(problem: PlanProblem, selected: np.ndarray, config, odds: list[StationOdds]
                ) -> PlanChance:
    """Every station's :class:`StationChance` with the layout ``selected`` ((n,) bool).

    ``config.chance_epsilon`` sets the targets (``None``: the figures of a plan not made for
    them, judged against the default 0.05 for the enumeration's stopping rule only).
    """
    eps = config.chance_epsilon
    target = None if eps is None else station_target(eps, problem.n_stations)
    judge = target if target is not None else station_target(0.05, problem.n_stations)
    stations = [o.chance(o.info.sites[selected[o.info.sites]], judge) for o in odds]
    return PlanChance(epsilon=eps, station_target=target, stations=stations)


def station_odds(problem: PlanProblem, infos: list[StationInfo], config) -> list[StationOdds]:
    """:class:`StationOdds` of every station (network mode: count and directions only)."""
    return [StationOdds(problem, info, config, accuracy=not config.network) for info in infos]
