"""Reliability of a network adjustment in Baarda's sense, and data snooping.

For an adjustment with design ``A`` (rows: observation components), weights ``P`` (diagonal)
and parameter covariance ``Q`` (a-priori, i.e. sigma0 = 1), the residuals have covariance
``Q_vv = P^-1 - A Q A^T``. Per component ``i``:

redundancy number
    ``r_i = (Q_vv P)_ii`` in [0, 1]: the share of an error in observation ``i`` that shows in
    its own residual. Over all observations (pseudo-observations included) they sum to the
    degrees of freedom.
w-test (Baarda)
    ``w_i = v_i / sqrt(Q_vv,ii)``, standard normal when the model holds; an observation is
    suspect when ``|w_i| > k = Phi^-1(1 - alpha0 / 2)`` (3.29 for ``alpha0 = 0.001``).
minimal detectable bias
    ``MDB_i = delta0 sigma_i / sqrt(r_i)``, the bias the w-test finds with power ``beta0``;
    ``delta0 = Phi^-1(1 - alpha0 / 2) + Phi^-1(beta0)`` (4.13 for 0.001 / 0.80).
effect of the MDB
    ``dx = Q A_i^T p_i MDB_i``, the shift of the parameters an undetected bias of that size
    causes (external reliability); reported as the largest shift of any station or marker
    position.

Data snooping tests all components, removes the observation holding the largest ``|w|``
(all three components of that marker centre) when it exceeds ``k``, re-adjusts, and repeats.
The adjustment itself lives in :mod:`pipeline.network.adjustment`; this module only sees
its linearised system.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.special import ndtri_exp
from scipy.stats import norm

#: Redundancy below which a component is uncontrolled (its own error never shows): w = 0 there.
_MIN_REDUNDANCY = 1e-10


def critical_value(alpha0: float) -> float:
    """Two-sided critical value of the w-test for significance level ``alpha0`` in (0, 1):
    ``Phi^-1(1 - alpha0 / 2)``, computed from ``log(alpha0 / 2)`` so that it stays finite and
    exact for any ``alpha0`` down to the smallest float (``1 - alpha0 / 2`` rounds to 1, and
    ``Phi^-1`` to inf, below about 1e-16).

    Examples
    --------
    >>> round(critical_value(0.001), 2)
    3.29
    >>> round(critical_value(1e-300), 2), round(critical_value(5e-324), 2)
    (37.07, 38.49)
    """
    return float(-ndtri_exp(math.log(alpha0) - math.log(2.0)))


def non_centrality(alpha0: float, beta0: float) -> float:
    """Baarda's ``delta0``: the bias, in sigmas of its residual, the w-test detects with power
    ``beta0`` at level ``alpha0`` (the far tail of the two-sided test is neglected, < 1e-20).

    Examples
    --------
    >>> round(non_centrality(0.001, 0.80), 2)
    4.13
    """
    return critical_value(alpha0) + float(norm.ppf(beta0))


@dataclass(frozen=True)
class Rejection:
    """One observation removed by data snooping.

    Attributes
    ----------
    station_id, marker_id : str
        The point observation (all three components) removed.
    w : float
        Its largest w-test statistic (signed) when it was removed.
    round : int
        Snooping round, 1 for the first removal.
    """

    station_id: str
    marker_id: str
    w: float
    round: int


@dataclass(frozen=True)
class ObservationReliability:
    """Internal and external reliability of ``n`` point observations (3 components each).

    Attributes
    ----------
    redundancy : (n, 3) float
        Redundancy numbers ``r``, dimensionless.
    w_test : (n, 3) float
        Baarda's w statistic per component (0 where ``r`` is ~0: uncontrolled).
    mdb_m : (n, 3) float
        Minimal detectable bias per component, m (``inf`` where uncontrolled).
    mdb_effect_m : (n,) float
        Largest shift of any station or marker position caused by any one of the three MDBs of
        the observation, m.
    """

    redundancy: np.ndarray
    w_test: np.ndarray
    mdb_m: np.ndarray
    mdb_effect_m: np.ndarray


def _redundancy(blocks: np.ndarray, columns: np.ndarray, weight: np.ndarray,
                covariance: np.ndarray) -> np.ndarray:
    """Redundancy numbers (n, 3) from the (c, c) covariance blocks of each observation."""
    q = covariance[columns[:, :, None], columns[:, None, :]]
    aqa = np.sum((blocks @ q) * blocks, axis=2)
    return np.clip(1.0 - weight * aqa, 0.0, 1.0)


def _w(r: np.ndarray, weight: np.ndarray, residual: np.ndarray) -> np.ndarray:
    controlled = r > _MIN_REDUNDANCY
    return np.where(controlled, residual * np.sqrt(weight / np.where(controlled, r, 1.0)), 0.0)


def w_tests(blocks: np.ndarray, columns: np.ndarray, weight: np.ndarray,
            covariance: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """Baarda's w statistics ``v_i / sqrt(Q_vv,ii)`` of point observations, (n, 3).

    Parameters as in :func:`observation_reliability`; 0 where a component is uncontrolled.
    """
    return _w(_redundancy(blocks, columns, weight, covariance), weight, residual)


def observation_reliability(blocks: np.ndarray, columns: np.ndarray, weight: np.ndarray,
                            covariance: np.ndarray, residual: np.ndarray,
                            position_columns: np.ndarray, delta0: float
                            ) -> ObservationReliability:
    """Redundancy, w-test, MDB and MDB effect of point observations.

    Parameters
    ----------
    blocks : (n, 3, c) float
        Design block of each observation: the derivatives of its 3 components with respect to
        the ``c`` parameters it involves (m per m, m per rad).
    columns : (n, c) int
        Those parameters' indices.
    weight : (n, 3) float
        Weights ``1 / sigma_component**2``, 1/m^2.
    covariance : (u, u) float
        A-priori covariance ``Q`` of the parameters (zero rows for parameters the datum fixes).
    residual : (n, 3) float
        Residuals ``v``, m.
    position_columns : (p, 3) int
        Parameter columns of the station and marker positions whose shift is the MDB effect.
    delta0 : float
        Non-centrality from :func:`non_centrality`.

    Returns
    -------
    ObservationReliability

    Examples
    --------
    One unknown point observed twice with unit weight: each component has redundancy 1/2.

    >>> blocks, columns = np.stack([np.eye(3)] * 2), np.array([[0, 1, 2]] * 2)
    >>> rel = observation_reliability(blocks, columns, np.ones((2, 3)), np.eye(3) / 2,
    ...                               np.zeros((2, 3)), np.array([[0, 1, 2]]), 4.13)
    >>> rel.redundancy.tolist()
    [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]]
    >>> round(float(rel.mdb_effect_m[0]), 3)  # half of MDB = 4.13 / sqrt(0.5)
    2.92
    """
    r = _redundancy(blocks, columns, weight, covariance)
    controlled = r > _MIN_REDUNDANCY
    mdb = np.where(controlled, delta0 / np.sqrt(weight * np.where(controlled, r, 1.0)), np.inf)
    n, c = columns.shape
    design = sp.csr_matrix((blocks.ravel(), np.repeat(columns, 3, axis=0).ravel(),
                            np.arange(0, 3 * n * c + 1, c)), shape=(3 * n, covariance.shape[0]))
    shift = np.asarray(design @ covariance[:, position_columns.ravel()])  # Q A_i^T per unit
    per_unit = np.sqrt(np.max(np.sum(shift.reshape(3 * n, -1, 3) ** 2, axis=2), axis=1)
                       ).reshape(n, 3)
    effect = np.where(controlled, per_unit * weight * np.where(controlled, mdb, 0.0), np.inf)
    return ObservationReliability(r, _w(r, weight, residual), mdb, effect.max(axis=1))


def data_snooping(solve: Callable[[np.ndarray, Any], tuple[Any, np.ndarray]], n: int,
                  alpha0: float, max_rejections: int,
                  removable: Callable[[np.ndarray, int], bool]
                  ) -> tuple[Any, np.ndarray, list[tuple[int, float, int]]]:
    """Baarda's data snooping: remove the worst point observation while ``max |w| > k``.

    Parameters
    ----------
    solve : callable
        ``solve(keep, previous) -> (solution, w)``: adjusts the observations ``keep`` ((n,)
        bool) starting from ``previous`` (None the first time, else the last solution) and
        returns the solution and its w-tests (m, 3) for the kept observations in order.
    n : int
        Number of point observations.
    alpha0 : float
        Significance level of each w-test.
    max_rejections : int
        Most observations removed; snooping stops there.
    removable : callable
        ``removable(keep, i) -> bool``: whether observation ``i`` may be removed from ``keep``
        (False when removing it would leave a station untied); snooping stops at the first
        worst observation that may not be removed.

    Returns
    -------
    solution
        The last solution.
    keep : (n,) bool
        Observations kept.
    rejected : list of (int, float, int)
        ``(observation index, w, round)`` for every removal, in order.

    Examples
    --------
    >>> w_all = np.array([[0.5, 0, 0], [9.0, 0, 0], [-4.0, 0, 0], [1.0, 0, 0]])
    >>> solve = lambda keep, previous: ("fit", w_all[keep])
    >>> _, keep, rejected = data_snooping(solve, 4, 0.001, 10, lambda keep, i: True)
    >>> keep.tolist(), rejected
    ([True, False, False, True], [(1, 9.0, 1), (2, -4.0, 2)])
    """
    keep = np.ones(n, dtype=bool)
    solution, w = solve(keep, None)
    k = critical_value(alpha0)
    rejected: list[tuple[int, float, int]] = []
    while len(rejected) < max_rejections and w.size:
        worst = int(np.argmax(np.abs(w).max(axis=1)))
        component = int(np.argmax(np.abs(w[worst])))
        index = int(np.flatnonzero(keep)[worst])
        if abs(w[worst, component]) <= k or not removable(keep, index):
            break
        keep[index] = False
        rejected.append((index, float(w[worst, component]), len(rejected) + 1))
        solution, w = solve(keep, solution)
    return solution, keep, rejected
