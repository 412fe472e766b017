"""The chance that a whole network plan passes when planned markers may be lost, certified.

In network mode one lost pair weakens every station its marker ties, so the stations'
outcomes are not independent and a station's accuracy is the network's: the per-station
figures of :mod:`planner.accuracy.chance` judge only each station's count and directions there.
This module judges the plan as ``markerplan verify --network`` does: every station's count,
directions and network accuracy (:mod:`planner.accuracy.network`) with the pairs that were
detected.

Passing is monotone in the detected pairs (a kept observation only adds information, and
counts and sectors only grow), so :func:`~planner.accuracy.chance.enumerate_losses` over the
layout's usable pairs gives certified bounds on the plan's chance of failing: loss sets by size,
a set judged only when none of its subsets already fails, the Poisson-binomial tail beyond the
sizes enumerated added to the upper bound. Adding a site to a layout never lowers the chance
either (its pairs are extra, independent observations), so a layout proven to fail proves every
layout with a subset of its sites fails: the chance-constrained planner's no-good rows
(:mod:`planner.program.cuts_chance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.accuracy.chance import MAX_LOSS_SETS, TAIL_FRACTION, enumerate_losses
from planner.accuracy.network import network_model
from planner.problem.usability import PlanProblem, sector_index


@dataclass(frozen=True)
class NetworkChance:
    """Certified bounds on a network layout's chance of failing.

    Attributes
    ----------
    fail_low, fail_high : float
        ``fail_low <= P(some station fails) <= fail_high``.
    n_pairs : int
        The layout's usable pairs (each detected with its own chance).
    max_losses : int
        Loss sets of up to this many pairs were judged (``n_pairs``: all, exact).
    """

    fail_low: float
    fail_high: float
    n_pairs: int
    max_losses: int

    @property
    def exact(self) -> bool:
        return self.max_losses >= self.n_pairs

    @property
    def pass_low(self) -> float:
        """Certified lower bound on the plan's ``P(pass)``."""
        return 1.0 - self.fail_high

    def to_json(self) -> dict:
        return {"fail_low": self.fail_low, "fail_high": self.fail_high,
                "pass_low": self.pass_low, "n_pairs": self.n_pairs,
                "max_losses": self.max_losses, "exact": self.exact}


class NetworkOdds:
    """A network layout's usable pairs with their detection chances, judged as a whole.

    Parameters
    ----------
    problem : PlanProblem
        With ``pair_detection_p`` (else every pair is detected).
    selected : (n,) bool
        The layout.
    config : PlanConfig
        The network's datum and priors (:func:`~planner.accuracy.network.network_model`),
        ``min_markers``, ``min_sectors``, ``n_sectors``, ``requirement_m``.
    """

    def __init__(self, problem: PlanProblem, selected: np.ndarray, config) -> None:
        sub = problem.restrict(np.asarray(selected, bool))
        self.net = network_model(sub, config)
        pairs = self.net.pair_index
        self.q = sub.detection_p[pairs]
        s = sub.n_stations
        sector = sector_index(sub.pair_bearing_rad[pairs], config.n_sectors)
        #: (p, s) and (p, s * n_sectors) float: each pair's station and station-sector
        self._station = np.zeros((pairs.size, s))
        self._station[np.arange(pairs.size), self.net.pair_station] = 1.0
        self._sector = np.zeros((pairs.size, s * config.n_sectors))
        self._sector[np.arange(pairs.size), self.net.pair_station * config.n_sectors + sector] = 1
        self.n_sectors = config.n_sectors
        self.min_markers = config.min_markers
        self.min_sectors = config.min_sectors
        self.requirement_m = config.requirement_m
        self._all_sites = np.ones(sub.n_sites)

    def passes(self, kept: np.ndarray) -> np.ndarray:
        """(k,) bool: whether every station passes with each row of ``kept`` ((k, p) bool over
        the network's pairs: detected or lost)."""
        k = kept.astype(float)
        count = k @ self._station
        sectors = ((k @ self._sector) > 0).reshape(len(k), -1, self.n_sectors).sum(axis=2)
        ok = np.all((count >= self.min_markers) & (sectors >= self.min_sectors), axis=1)
        with np.errstate(over="ignore", invalid="ignore"):  # untied stations: inf
            for row in np.flatnonzero(ok):
                j = self.net.information(self._all_sites, kept[row])
                err = self.net.station_errors_from(self.net.covariance(j))
                ok[row] = bool(np.all(err <= self.requirement_m))
        return ok

    def chance(self, epsilon: float, budget: int = MAX_LOSS_SETS,
               decide: bool = False) -> NetworkChance:
        """:class:`NetworkChance` of the layout; the enumeration stops once the tail left is
        below ``TAIL_FRACTION * epsilon`` (``epsilon``: the plan's allowed chance of failing)
        or after ``budget`` loss sets; with ``decide``, as soon as the bounds put the chance
        of failing above or below ``epsilon`` (the planner's question)."""
        stop = epsilon if decide else None
        c = enumerate_losses(self.q, self.passes, TAIL_FRACTION * epsilon, budget, stop, stop)
        return NetworkChance(c.fail_low, c.fail_high, c.n_markers, c.max_losses)


def network_chance(problem: PlanProblem, selected: np.ndarray, config,
                   epsilon: float | None = None, budget: int = MAX_LOSS_SETS) -> NetworkChance:
    """:class:`NetworkChance` of the layout ``selected`` ((n,) bool); ``epsilon`` (default
    ``config.chance_epsilon``, or 0.05 for a plan not made for one) sets where the enumeration
    may stop."""
    eps = epsilon if epsilon is not None else (config.chance_epsilon or 0.05)
    return NetworkOdds(problem, selected, config).chance(eps, budget)
