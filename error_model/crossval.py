"""k-fold cross-validation: basis-size choice, optional-predictor choice and the envelope's
held-out coverage.

Folds are drawn over groups (station x replicate when the table names them) so that rows of
one scan, which share its calibration error, are never split between training and test.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from error_model.basis import Basis
from error_model.solve import (
    Constraints,
    MeanFitter,
    QuantileFitter,
    Scaling,
    pinball,
)


@dataclass(frozen=True)
class CvScore:
    """Held-out loss of one candidate: mean over folds and its standard error."""

    mean: float
    se: float
    folds: tuple[float, ...]

    def to_dict(self) -> dict:
        return {"mean": self.mean, "se": self.se, "folds": list(self.folds)}


def fold_labels(groups: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """Fold index of every row, assigning whole groups round-robin in a seeded order.

    Parameters
    ----------
    groups : (n,) int
        Group id per row; rows are their own group when there are fewer than ``k`` groups.
    k : int
    rng : numpy.random.Generator

    Returns
    -------
    labels : (n,) int in ``[0, k)``
    """
    uniq, inverse = np.unique(groups, return_inverse=True)
    if uniq.size < k:
        inverse, uniq = np.arange(groups.size), np.arange(groups.size)
    order = rng.permutation(uniq.size)
    group_fold = np.empty(uniq.size, int)
    group_fold[order] = np.arange(uniq.size) % k
    return group_fold[inverse]


def _score(losses: list[float]) -> CvScore:
    arr = np.asarray(losses)
    se = float(arr.std(ddof=1) / np.sqrt(arr.size)) if arr.size > 1 else 0.0
    return CvScore(float(arr.mean()), se, tuple(float(v) for v in arr))


def cv_mean_model(basis: Basis, phi: np.ndarray, y: np.ndarray, labels: np.ndarray,
                  solver: str) -> CvScore:
    """Held-out mean squared error of the mean-error fit (metres^2).

    Parameters
    ----------
    basis : Basis
    phi : (n, p) float
        Features of all rows under ``basis``.
    y : (n,) float
        3D errors, metres.
    labels : (n,) int
        Fold of each row.
    solver : str
    """
    fitter = MeanFitter(Constraints(basis.nonneg, basis.nonneg_rows()),
                        Scaling.from_data(phi, y), solver)
    losses = []
    for f in np.unique(labels):
        test = labels == f
        b = fitter.fit(phi[~test], y[~test])
        losses.append(float(np.mean((y[test] - phi[test] @ b) ** 2)))
    return _score(losses)


def cv_quantile_model(basis: Basis, phi: np.ndarray, y: np.ndarray, labels: np.ndarray,
                      tau: float, solver: str) -> dict:
    """Held-out pinball loss and coverage of the envelope.

    Returns
    -------
    scores : dict
        ``pinball`` (CvScore as dict, metres), ``coverage`` (fraction of held-out errors at
        or below the envelope, pooled over folds) and ``coverage_folds``.
    """
    fitter = QuantileFitter(Constraints(basis.nonneg, basis.nonneg_rows()),
                            Scaling.from_data(phi, y), tau, solver)
    losses, covered, cov_folds = [], np.zeros(y.size, bool), []
    for f in np.unique(labels):
        test = labels == f
        b = fitter.fit(phi[~test], y[~test])
        pred = phi[test] @ b
        losses.append(float(np.mean(pinball(y[test] - pred, tau))))
        covered[test] = y[test] <= pred
        cov_folds.append(float(np.mean(y[test] <= pred)))
    return {"pinball": _score(losses).to_dict(), "coverage": float(covered.mean()),
            "coverage_folds": cov_folds}


def one_se_choice(candidates: list[tuple[Basis, CvScore]]) -> tuple[Basis, CvScore]:
    """The smallest basis whose CV loss is within one standard error of the best (1-SE rule)."""
    best = min(candidates, key=lambda c: c[1].mean)[1]
    ok = [c for c in candidates if c[1].mean <= best.mean + best.se]
    return min(ok, key=lambda c: (c[0].n_features, c[1].mean))
