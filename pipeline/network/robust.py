"""Robust estimation of the network: iteratively reweighted least squares (IRLS).

Beside data snooping (:mod:`pipeline.network.reliability`), which removes one suspect
observation at a time, a robust M-estimator keeps every observation and lowers the weight of
those that disagree with the rest, all at once; several blunders cannot then hide each other.
Each point observation (a marker centre, 3 components) gets one factor ``rho`` on its weight,
a function of its *standardised residual*: the normalised statistic ``w`` of the test of the
point as one 3-dimensional group (:class:`pipeline.network.reliability.PointTests`: the
standard-normal deviate of the p-value of ``T = v^T Q_vv^-1 v``, chi2(3)). ``w`` is computed
with the observations' own (a-priori) weights and the residual covariance of plain least
squares at the current solution, so that a down-weighted observation is still judged by its
own noise, and it is on the scale of a standard normal: the tuning constants keep their usual
meaning.

Huber (1964; Huber, *Robust statistics*, 1981, section 7.8)
    ``rho = 1`` for ``w <= k``, ``k / w`` above. ``k = 1.5`` (:data:`HUBER_K`), Huber's
    "Proposal 2" value; 1.345 gives 95 % efficiency under normal errors. Convex: the solution
    is unique, but a blunder keeps a bounded influence (``k`` sigmas' worth).
IGG-III (Yang 1994; Yang, Song & Xu, *J. Geodesy* 76, 2002, 353-359)
    ``rho = 1`` for ``w <= k0``; ``(k0 / w) ((k1 - w) / (k1 - k0))^2`` for ``k0 < w <= k1``;
    0 above ``k1``. ``k0 = 1.5``, ``k1 = 3.0`` (:data:`IGG3_K0`, :data:`IGG3_K1`; Yang
    recommends k0 in 1.0-1.5 and k1 in 2.5-8.0). Redescending: a gross error gets weight 0 and
    no influence, but the estimate depends on the start: it starts from Huber's solution, not
    from plain least squares, whose smeared residuals would reject good observations too.

Each round takes the weights of the new residuals; after :data:`UNDAMPED_ROUNDS` rounds it
moves the weights only halfway to them (a damped fixed-point iteration: the same fixed point,
but IGG-III's redescending weights cannot cycle between two sets). It stops when no weight
would change by more than :data:`WEIGHT_TOLERANCE`. A weight of
0 is solved with :data:`WEIGHT_FLOOR` instead, so that an unknown whose only observations are
rejected stays determined (with a huge variance) rather than making the normal equations
singular; it counts as rejected in the degrees of freedom.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from markerplan.errors import DataError

#: The robust estimators :func:`robust_weights` knows.
ESTIMATORS = ("huber", "igg3")

#: Huber's tuning constant, in units of the standardised residual.
HUBER_K = 1.5
#: IGG-III's tuning constants, in units of the standardised residual.
IGG3_K0, IGG3_K1 = 1.5, 3.0

#: The reweighting has converged when no weight factor changes by more than this (an
#: observation's influence then changes by less than 1e-4 of its own).
WEIGHT_TOLERANCE = 1e-4
#: Rounds before the weights are damped.
UNDAMPED_ROUNDS = 10
#: Most reweighting rounds.
MAX_ROUNDS = 100
#: The weight factor a rejected observation (weight 0) is solved with.
WEIGHT_FLOOR = 1e-10


def robust_weights(w: np.ndarray, estimator: str, k0: float, k1: float) -> np.ndarray:
    """Weight factors of point observations from their standardised residuals.

    Parameters
    ----------
    w : (n,) float
        Normalised point-test statistics (>= 0), standard-normal scale.
    estimator : {"huber", "igg3"}
    k0 : float
        Huber's ``k`` or IGG-III's ``k0`` (> 0).
    k1 : float
        IGG-III's ``k1`` (> ``k0``); unused by Huber.

    Returns
    -------
    rho : (n,) float
        In [0, 1].

    Examples
    --------
    >>> w = np.array([0.5, 1.5, 2.0, 3.0, 40.0])
    >>> robust_weights(w, "huber", 1.5, 3.0).round(4).tolist()
    [1.0, 1.0, 0.75, 0.5, 0.0375]
    >>> robust_weights(w, "igg3", 1.5, 3.0).round(4).tolist()
    [1.0, 1.0, 0.3333, 0.0, 0.0]
    """
    w = np.asarray(w, dtype=float)
    ratio = k0 / np.maximum(w, k0)
    if estimator == "huber":
        return ratio
    return np.where(w <= k1, ratio * ((k1 - np.minimum(np.maximum(w, k0), k1)) / (k1 - k0))**2,
                    0.0)


def reweighted(solve: Callable[[np.ndarray, Any], tuple[Any, np.ndarray]],
               weights: Callable[[np.ndarray], np.ndarray], start: tuple[Any, np.ndarray]
               ) -> tuple[Any, np.ndarray, np.ndarray, int]:
    """Iteratively reweighted least squares.

    Parameters
    ----------
    solve : callable
        ``solve(rho, previous) -> (solution, w)``: adjusts with each observation's weight
        multiplied by ``rho`` ((n,) float), starting from ``previous`` (a solution), and
        returns the solution and the (n,) standardised residuals at it.
    weights : callable
        ``weights(w) -> rho`` (:func:`robust_weights` with its constants bound).
    start : (solution, (n,) float)
        A solution and its standardised residuals to start from (e.g. plain least squares).

    Returns
    -------
    solution
        The solution with the final weights.
    rho : (n,) float
        The weight factors it was computed with.
    w : (n,) float
        Its standardised residuals (``weights(w)`` equals ``rho`` to the tolerance).
    rounds : int
        Reweighting rounds (1: the start needed no change of weights).

    Raises
    ------
    DataError
        The weights still change after :data:`MAX_ROUNDS` rounds.

    Examples
    --------
    The weighted mean of 1-D values, with ``w`` the distance from it in unit sigmas:

    >>> y = np.array([0.1, -0.2, 0.0, 0.1, 8.0])
    >>> def solve(rho, previous):
    ...     mean = float(np.sum(rho * y) / np.sum(rho))
    ...     return mean, np.abs(y - mean)
    >>> mean, rho, w, rounds = reweighted(solve, lambda w: robust_weights(w, "igg3", 1.5, 3),
    ...                                   solve(np.ones(5), None))
    >>> round(mean, 6), rho.tolist(), rounds
    (0.0, [1.0, 1.0, 1.0, 1.0, 0.0], 3)
    """
    solution, w = start
    rho = np.ones(w.size)
    for rounds in range(1, MAX_ROUNDS + 1):
        new = weights(w)
        change = float(np.abs(new - rho).max(initial=0.0))
        if change <= WEIGHT_TOLERANCE:
            return solution, rho, w, rounds
        rho = new if rounds <= UNDAMPED_ROUNDS else 0.5 * (rho + new)
        solution, w = solve(rho, solution)
    raise DataError(f"the robust reweighting did not converge in {MAX_ROUNDS} rounds (weights "
                    f"still change by {change:.2g}); Huber's estimator always converges")
