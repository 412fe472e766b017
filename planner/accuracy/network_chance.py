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

With ``local_markers`` each outcome also judges the pairs of selected markers
(:mod:`planner.accuracy.local_markers`) among those it still estimates: a marker is the mean of
its detected measurements, and a marker none of whose measurements was detected is not
estimated, so its pairs no longer exist and are not judged. Passing is then not monotone in
the detected pairs (losing a marker's last measurement drops its failing pairs), so every loss
set is judged (``monotone=False``: no pruning, the bounds stay certified within the same
budget). Across layouts only this holds: a layout ``S`` inside a failing ``C`` that keeps every
marker of ``C``'s judged pairs (:meth:`NetworkOdds.paired_sites`) fails in every outcome in
which ``C`` fails (the same pairs, each estimated from the same detected measurements, with
less pose information), so the planner's no-good rows keep those markers in
(:meth:`planner.program.cuts_chance.ChanceRule.whole_cuts`).

A large network has thousands of pairs and expects many losses: no enumeration within its
budget can bound the tail below the plan's epsilon. :meth:`NetworkOdds.decide` then judges
``SAMPLES_TO_DECIDE`` sampled outcomes with the same judge, and a layout meets the rule when
the Wilson 95 % lower bound of its pass rate does (a statistical decision, recorded as such, not
a certificate).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.sparse import csr_array

from error_model.detection import wilson_interval
from planner.accuracy.chance import (
    MAX_LOSS_SETS,
    TAIL_FRACTION,
    enumerate_losses,
    more_losses_than,
    sizes_within,
)
from planner.accuracy.local import local_accuracy
from planner.accuracy.local_markers import LocalMarkerAccuracy, local_marker_accuracy
from planner.accuracy.network import SINGULAR_PIVOT, NetworkCovariance, network_model
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
        Loss sets of up to this many pairs were judged (``n_pairs``: all, exact; 0: the
        enumeration could not help and was skipped).
    n_samples, n_passed : int
        Sampled outcomes judged, and passed, when the bounds could not decide (else 0).
    """

    fail_low: float
    fail_high: float
    n_pairs: int
    max_losses: int
    n_samples: int = 0
    n_passed: int = 0

    @property
    def exact(self) -> bool:
        return self.max_losses >= self.n_pairs

    @property
    def pass_low(self) -> float:
        """Certified lower bound on the plan's ``P(pass)``."""
        return 1.0 - self.fail_high

    def meets(self, epsilon: float) -> bool:
        """Whether the layout fails with chance at most ``epsilon``: proven by the bounds, or
        (when sampled) by the Wilson 95 % lower bound of the sampled pass rate."""
        if self.fail_high <= epsilon:
            return True
        return bool(self.n_samples) and self.fail_low <= epsilon \
            and wilson_interval(self.n_passed, self.n_samples)[0] >= 1.0 - epsilon

    def to_json(self) -> dict:
        out = {"fail_low": self.fail_low, "fail_high": self.fail_high,
               "pass_low": self.pass_low, "n_pairs": self.n_pairs,
               "max_losses": self.max_losses, "exact": self.exact}
        if self.n_samples:
            out["decided_by_samples"] = {"n_samples": self.n_samples, "n_passed": self.n_passed}
        return out


#: Most matrix entries one batch of :meth:`NetworkOdds.station_errors` holds (8 bytes each).
_BATCH_VALUES = 4_000_000

#: Sampled outcomes that decide a layout the bounds cannot.
SAMPLES_TO_DECIDE = 400


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
        ``min_markers``, ``min_sectors``, ``n_sectors``, ``requirement_m``,
        ``requirement_ppm``, the local requirement (``local_markers``).
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
        self.local = local_accuracy(self.net, config)
        self.local_markers = local_marker_accuracy(self.net, config)
        self.selected = np.flatnonzero(np.asarray(selected, bool))
        # each tie's block H_a^T H_b scattered into the flattened (6 s)^2 pose matrix
        blocks, flat = self.net.tie_blocks(np.arange(self.net.tie_a.size))
        self._scatter = csr_array((blocks.ravel(), (np.repeat(np.arange(len(blocks)), 36),
                                                    flat.ravel())),
                                  shape=(len(blocks), (6 * s) ** 2))

    def passes(self, kept: np.ndarray) -> np.ndarray:
        """(k,) bool: whether every station passes with each row of ``kept`` ((k, p) bool over
        the network's pairs: detected or lost), and, with a local requirement, every station
        pair it judges and (``local_markers``) every pair of markers still estimated (each row
        that passes the rest inverted on its own)."""
        k = kept.astype(float)
        count = k @ self._station
        sectors = ((k @ self._sector) > 0).reshape(len(k), -1, self.n_sectors).sum(axis=2)
        ok = np.all((count >= self.min_markers) & (sectors >= self.min_sectors), axis=1)
        n6 = 6 * self.net.problem.n_stations
        rows = np.flatnonzero(ok)
        step = max(1, _BATCH_VALUES // (n6 * n6))
        for lo in range(0, rows.size, step):
            at = rows[lo:lo + step]
            covariances = self.covariances(kept[at])
            blocks = self._station_blocks(covariances)
            ok[at] = self.net.figure.station_within(
                blocks.reshape(-1, 6, 6), self.net.radius,
                np.tile(self.net.allowed_station_m, at.size)).reshape(at.size, -1).all(axis=1)
            if self.local is not None:
                ok[at] &= self.local.all_within(covariances)
            if self.local_markers is not None:
                ok[at] &= self._marker_pairs_pass(kept[at], covariances)
        return ok

    @property
    def monotone(self) -> bool:
        """Whether passing is monotone in the detected pairs (not with ``local_markers``)."""
        return self.local_markers is None

    def _marker_pairs_pass(self, kept: np.ndarray, covariances: list[NetworkCovariance]
                           ) -> np.ndarray:
        """(k,) bool: whether every judged pair of the markers each row of ``kept`` ((k, p)
        bool) still estimates passes, with that row's covariance."""
        every = np.ones(self.net.problem.n_sites, bool)
        req = self.local_markers.requirement
        return np.array([LocalMarkerAccuracy(self.net, req, np.where(row, self.net.weight, 0.0))
                         .failing(cov, every)[1].size == 0
                         for row, cov in zip(kept, covariances, strict=True)], bool)

    def paired_sites(self) -> np.ndarray:
        """(m,) int: the layout's sites (indices into the whole problem) that some judged
        marker pair holds with every pair detected (empty without ``local_markers``)."""
        if self.local_markers is None:
            return np.zeros(0, np.int64)
        pairs = self.local_markers.pairs(np.ones(self.net.problem.n_sites, bool))
        return self.selected[np.unique(np.r_[pairs.first, pairs.second])]

    def station_errors(self, kept: np.ndarray) -> np.ndarray:
        """(k, s) 95 % network error of every station with each row of ``kept`` ((k, p) bool),
        m (``inf`` where a station is left undetermined; :meth:`station_covariances`)."""
        blocks = self.station_covariances(kept)
        return self.net.figure.station_errors(blocks.reshape(-1, 6, 6),
                                              self.net.radius).reshape(len(kept), -1)

    def station_covariances(self, kept: np.ndarray) -> np.ndarray:
        """(k, s, 6, 6) pose covariance of every station with each row of ``kept`` ((k, p)
        bool), ``inf`` where a station is left undetermined (:meth:`covariances`)."""
        return self._station_blocks(self.covariances(kept))

    def _station_blocks(self, covariances: list[NetworkCovariance]) -> np.ndarray:
        """(k, s, 6, 6) every station's block of each covariance, ``inf`` where undetermined."""
        s = self.net.problem.n_stations
        out = np.empty((len(covariances), s, 6, 6))
        for row, cov in enumerate(covariances):
            out[row] = cov.station(np.arange(s))
            out[row, ~cov.determined] = np.inf
        return out

    def covariances(self, kept: np.ndarray) -> list[NetworkCovariance]:
        """The pose covariance with each row of ``kept`` ((k, p) bool): the information of
        the kept pairs (:meth:`~planner.accuracy.network.NetworkModel.information` with
        ``kept``) for all rows at once, inverted in one batch; a row whose information is
        (nearly) singular goes through :meth:`~planner.accuracy.network.NetworkModel.
        covariance` (which flags its undetermined stations)."""
        net = self.net
        s, n6 = net.problem.n_stations, 6 * net.problem.n_stations
        coef = net.tie_coefficients(np.where(kept, net.weight, 0.0))  # (k, t)
        full = (self._scatter.T @ coef.T).T.reshape(-1, n6, n6)
        j = full[:, net.free[:, None], net.free[None, :]]
        j = 0.5 * (j + np.swapaxes(j, 1, 2))
        j += net.prior_information
        out: list[NetworkCovariance | None] = [None] * len(kept)
        diag = np.diagonal(j, axis1=1, axis2=2)
        good = np.zeros(len(kept), bool)
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            try:
                chol = np.linalg.cholesky(j)
                good = np.min(np.diagonal(chol, axis1=1, axis2=2) ** 2 / diag, axis=1) \
                    > SINGULAR_PIVOT
            except np.linalg.LinAlgError:  # some row not positive definite: one by one
                pass
            if good.any():
                inverse = np.linalg.inv(j[good])
                for row, c in zip(np.flatnonzero(good), inverse, strict=True):
                    cov = np.zeros((n6, n6))
                    cov[net.free[:, None], net.free[None, :]] = c
                    out[row] = NetworkCovariance(full=cov, determined=np.ones(s, bool))
            for row in np.flatnonzero(~good):
                out[row] = net.covariance(j[row])
        return out

    def chance(self, epsilon: float, budget: int = MAX_LOSS_SETS,
               decide: bool = False) -> NetworkChance:
        """:class:`NetworkChance` of the layout; the enumeration stops once the tail left is
        below ``TAIL_FRACTION * epsilon`` (``epsilon``: the plan's allowed chance of failing)
        or after ``budget`` loss sets; with ``decide``, as soon as the bounds put the chance
        of failing above or below ``epsilon`` (the planner's question)."""
        stop = epsilon if decide else None
        c = enumerate_losses(self.q, self.passes, TAIL_FRACTION * epsilon, budget, stop, stop,
                             self.monotone)
        return NetworkChance(c.fail_low, c.fail_high, c.n_markers, c.max_losses)

    def can_bound(self, epsilon: float, budget: int = MAX_LOSS_SETS) -> bool:
        """Whether the loss sets ``budget`` allows can leave a tail (the chance of losing more
        pairs) at most ``epsilon``: else no enumeration can prove the layout meets it."""
        return bool(more_losses_than(self.q)[sizes_within(self.q.size, budget)] <= epsilon)

    def decide(self, epsilon: float, seed: int = 0, budget: int = MAX_LOSS_SETS
               ) -> NetworkChance:
        """Whether the layout fails with chance at most ``epsilon``, as a
        :class:`NetworkChance` whose :meth:`~NetworkChance.meets` answers: by the bounds
        (stopping once they decide) when the enumeration can reach a tail below ``epsilon``
        within ``budget`` loss sets, else (or when they still cannot decide) by
        ``SAMPLES_TO_DECIDE`` sampled outcomes (seeded by ``seed``)."""
        m = self.q.size
        if self.can_bound(epsilon, budget):
            c = self.chance(epsilon, budget, decide=True)
            if c.fail_high <= epsilon or c.fail_low > epsilon:
                return c
        else:
            c = NetworkChance(0.0, 1.0, m, 0)
        kept = np.random.default_rng(seed).random((SAMPLES_TO_DECIDE, m)) < self.q
        return replace(c, n_samples=SAMPLES_TO_DECIDE, n_passed=int(self.passes(kept).sum()))


def network_chance(problem: PlanProblem, selected: np.ndarray, config,
                   epsilon: float | None = None, budget: int = MAX_LOSS_SETS) -> NetworkChance:
    """:class:`NetworkChance` of the layout ``selected`` ((n,) bool); ``epsilon`` (default
    ``config.chance_epsilon``, or 0.05 for a plan not made for one) sets where the enumeration
    may stop. A layout with too many pairs for the budget to bound its tail below ``epsilon``
    gets the empty bounds [0, 1] with ``max_losses`` 0 (its sampled pass rate is the figure)."""
    eps = epsilon if epsilon is not None else (config.chance_epsilon or 0.05)
    odds = NetworkOdds(problem, selected, config)
    if not odds.can_bound(eps, budget):  # the bounds could not say more than [0, 1]
        return NetworkChance(0.0, 1.0, odds.q.size, 0)
    return odds.chance(eps, budget)
