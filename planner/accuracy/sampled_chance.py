"""A layout's chance of passing by sampling detection outcomes (both modes).

Each sample draws, for every usable pair of the layout, whether its marker is detected and
accepted (with the pair's :attr:`~planner.problem.usability.PlanProblem.detection_p`,
independently), marks the lost pairs unusable and checks the layout exactly as the planner does
(:func:`planner.accuracy.checks.evaluate_layout`: count, directions, accuracy; in network mode
the whole network's, where one lost tying marker weakens several stations). The pass rate has
a Wilson 95 % interval. In known control it re-computes, by another route, the exact
probabilities of :mod:`planner.accuracy.chance`; in network mode it is the plan's figure.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from error_model.detection import wilson_interval
from planner.accuracy.checks import evaluate_layout
from planner.problem.usability import OCCLUDED, PlanProblem


@dataclass(frozen=True)
class SampledChance:
    """Pass rates over sampled detection outcomes.

    Attributes
    ----------
    n_samples : int
    seed : int
    n_passed : int
        Samples in which every station passed.
    station_passed : (s,) int
        Samples in which each station passed.
    """

    n_samples: int
    seed: int
    n_passed: int
    station_passed: np.ndarray

    @property
    def rate(self) -> float:
        return self.n_passed / self.n_samples

    @property
    def wilson_95(self) -> tuple[float, float]:
        return wilson_interval(self.n_passed, self.n_samples)

    def to_json(self) -> dict:
        low, high = self.wilson_95
        return {"n_samples": self.n_samples, "seed": self.seed, "n_passed": self.n_passed,
                "pass_rate": self.rate, "wilson_95": [low, high]}


def sampled_chance(problem: PlanProblem, selected: np.ndarray, config, n_samples: int,
                   seed: int = 0) -> SampledChance:
    """Check the layout ``selected`` ((n,) bool) in ``n_samples`` sampled detection outcomes.

    Parameters
    ----------
    problem : PlanProblem
    selected : (n,) bool
    config : PlanConfig
        As :func:`~planner.accuracy.checks.evaluate_layout` uses it (network mode,
        requirement) with the plain rule, which ``verify`` checks: the redundant rule asks
        what a further loss would do, and existing and forbidden sites do not matter here.
    n_samples : int
        >= 1.
    seed : int
        Seeds the draws (same inputs and seed: the same figures).
    """
    selected = np.asarray(selected, bool)
    sub = problem.restrict(selected)
    config = config.replace(existing=(), forbidden=(), redundant=False)
    all_sites = np.ones(sub.n_sites, bool)
    usable = np.flatnonzero(sub.pair_usable)
    q = sub.detection_p[usable]
    rng = np.random.default_rng(seed)
    n_passed = 0
    station_passed = np.zeros(sub.n_stations, np.int64)
    for _ in range(int(n_samples)):
        lost = rng.random(usable.size) >= q
        reason = sub.pair_reason.copy()
        reason[usable[lost]] = OCCLUDED
        check = evaluate_layout(replace(sub, pair_reason=reason), all_sites, config,
                                verdict_only=True)
        station_passed += check.ok
        n_passed += bool(check.ok.all()) and check.pairs_ok and check.marker_pairs_ok
    return SampledChance(n_samples=int(n_samples), seed=int(seed), n_passed=n_passed,
                         station_passed=station_passed)
