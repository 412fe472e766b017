"""Seeded bootstrap intervals for the fitted coefficients.

Each replicate refits on ``m = min(n, max_rows)`` rows drawn with replacement (whole station
scans at a time when the table names them). When ``m < n``
this is the m-out-of-n bootstrap (Bickel, Goetze & van Zwet 1997):
deviations of a replicate from the full-data estimate are shrunk by ``sqrt(m / n)``, which also
keeps it valid for coefficients held at their ``>= 0`` bound. With ``m = n`` it is the
ordinary percentile bootstrap.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BootstrapResult:
    """Replicates of a parameter vector.

    Attributes
    ----------
    samples : (B, q) float
        Refitted parameters, one row per replicate.
    shrink : float
        ``sqrt(m / n)``, the factor applied to deviations from the full-data estimate.
    rows_per_replicate : int
    """

    samples: np.ndarray
    shrink: float
    rows_per_replicate: int

    def interval(self, estimate: np.ndarray, samples: np.ndarray | None = None,
                 level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """Percentile interval around ``estimate``.

        Parameters
        ----------
        estimate : (q,) float
            Full-data value.
        samples : (B, q) float, optional
            Replicates of a derived quantity (default: :attr:`samples`).
        level : float

        Returns
        -------
        lo, hi : (q,) float
        """
        s = self.samples if samples is None else samples
        a = (1 - level) / 2
        q_lo, q_hi = np.quantile(s, [a, 1 - a], axis=0)
        return (estimate + self.shrink * (q_lo - estimate),
                estimate + self.shrink * (q_hi - estimate))


def bootstrap(refit: Callable[[np.ndarray], np.ndarray], groups: np.ndarray,
              n_replicates: int, max_rows: int, rng: np.random.Generator) -> BootstrapResult:
    """Refit on resampled rows.

    When rows come in groups (one station scan: its markers share the scan's calibration
    error), whole groups are drawn with replacement until ``m`` rows are collected (the last
    group cut to fit), so within-scan correlation widens the intervals as it should.
    Otherwise single rows are drawn.

    Parameters
    ----------
    refit : callable
        ``refit(rows) -> (q,) parameters`` with ``rows`` an (m,) int array of row indices
        (repeats allowed).
    groups : (n,) int
        Group of each row (all distinct: plain row bootstrap).
    n_replicates : int
    max_rows : int
        Rows per replicate, ``m = min(n, max_rows)``.
    rng : numpy.random.Generator

    Returns
    -------
    result : BootstrapResult
    """
    n_rows = groups.size
    m = min(n_rows, max_rows)
    _, inverse, counts = np.unique(groups, return_inverse=True, return_counts=True)
    members = np.split(np.argsort(inverse, kind="stable"), np.cumsum(counts)[:-1])
    samples = []
    for _ in range(n_replicates):
        if counts.size == n_rows:
            rows = rng.integers(0, n_rows, m)
        else:
            picked, total = [], 0
            while total < m:
                picked.append(members[rng.integers(counts.size)])
                total += picked[-1].size
            rows = np.concatenate(picked)[:m]
        samples.append(refit(rows))
    return BootstrapResult(samples=np.asarray(samples), shrink=float(np.sqrt(m / n_rows)),
                           rows_per_replicate=m)
