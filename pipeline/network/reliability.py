"""Reliability of a network adjustment in Baarda's sense, and data snooping.

For an adjustment with design ``A`` (rows: observation components), weights ``P`` (diagonal)
and parameter covariance ``Q`` (a-priori, i.e. sigma0 = 1), the residuals have covariance
``Q_vv = P^-1 - A Q A^T``. A point observation ``i`` (a marker centre, 3 components) has the
3 x 3 block ``Q_vv,i = P_i^-1 - A_i Q A_i^T``.

test of the point observation (the decision statistic)
    The alternative hypothesis is an outlier of any direction in the whole point:
    ``y_i + c_i`` with ``C_i = [I3 at observation i]`` (Teunissen, *Testing theory*, 2000,
    section 4; the ``q``-dimensional test of Baarda's B-method). Its statistic
    ``T_i = v^T P C_i (C_i^T P Q_vv P C_i)^-1 C_i^T P v = v_i^T Q_vv,i^-1 v_i`` follows
    chi2(q_i) when the model holds, with ``q_i = rank(Q_vv,i)`` (3 unless part of the point is
    uncontrolled; the pseudo-inverse then). ``T_i`` is also the decrease of ``v^T P v`` when
    the observation is left out. An observation is suspect when ``T_i`` exceeds the
    ``1 - alpha0`` quantile of chi2(q_i); so that statistics of different ``q`` compare, each
    is reported also as the standard-normal deviate of its p-value, ``w_i =
    Phi^-1(1 - p_i / 2)`` (for ``q = 1`` Baarda's ``|w|``), and the test is ``w_i > k =
    Phi^-1(1 - alpha0 / 2)`` (3.29 for ``alpha0 = 0.001``).
redundancy number
    ``r_i = (Q_vv P)_ii`` in [0, 1] per component: the share of an error in it that shows in
    its own residual. Over all observations (pseudo-observations included) they sum to the
    degrees of freedom.
w-test per component (Baarda)
    ``w_i = v_i / sqrt(Q_vv,ii)``, standard normal when the model holds; kept beside the
    point test as a diagnostic (which axis the error is along).
minimal detectable bias
    Per component ``MDB_i = delta0 sigma_i / sqrt(r_i)`` with ``delta0 = Phi^-1(1 - alpha0 / 2)
    + Phi^-1(beta0)`` (4.13 for 0.001 / 0.80): the one-dimensional test's, which the planner
    predicts (:mod:`planner.accuracy.reliability`). For the point test, a bias ``b`` has the
    non-centrality ``b^T P_i Q_vv,i P_i b``; its MDB in the worst direction is
    ``sqrt(lambda0 / min eig(P_i^1/2 Q_vv,i P_i^1/2)) / sqrt(p_i)`` with ``lambda0(alpha0,
    beta0, q)`` the non-centrality at which the test rejects with probability ``beta0``
    (21.5 for q = 3 at 0.001 / 0.80; 17.1 = 4.13^2 for q = 1).
effect of the MDB
    ``dx = Q A_i^T p_i MDB_i``, the shift of the parameters an undetected bias of that size
    causes (external reliability); reported as the largest shift of any station or marker
    position.

Data snooping tests every point observation, removes the one with the largest ``w_i`` (the
smallest p-value) when it exceeds ``k``, re-adjusts, and repeats. The adjustment itself lives
in :mod:`pipeline.network.adjustment`; this module only sees its linearised system.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.optimize import brentq
from scipy.special import erfcx, ndtri_exp
from scipy.stats import chi2, ncx2, norm

from pipeline.network.marginals import design_times

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


def chi2_logsf(statistic: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """``log P(chi2(dof) > statistic)`` for ``dof`` in 0..3, finite for any statistic.

    ``scipy.stats.chi2.logsf`` underflows to ``-inf`` above about 1,500 (a blunder of
    decimetres at centimetre noise gives millions); the closed forms with the scaled
    complementary error function ``erfcx(x) = exp(x^2) erfc(x)`` do not. ``dof = 0``
    (nothing tested) gives 0.

    Parameters
    ----------
    statistic : (n,) float
        Chi-square values, >= 0.
    dof : (n,) int
        Degrees of freedom, 0 to 3.

    Returns
    -------
    log_p : (n,) float

    Examples
    --------
    >>> chi2_logsf(np.array([10.0, 100.0, 4e6]), np.array([3, 1, 3])).round(4).tolist()
    [-3.9864, -52.5381, -1999992.6249]
    """
    t = np.asarray(statistic, dtype=float)
    x = np.sqrt(t / 2.0)
    with np.errstate(divide="ignore"):
        return np.select([dof == 1, dof == 2, dof == 3],
                         [np.log(erfcx(x)) - t / 2.0, -t / 2.0,
                          np.log(erfcx(x) + np.sqrt(2.0 * t / np.pi)) - t / 2.0], 0.0)


def normalised_statistic(statistic: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """The standard-normal deviate ``Phi^-1(1 - p / 2)`` of a chi-square statistic's p-value:
    a test statistic of any ``dof`` on the scale of Baarda's ``|w|`` (equal to it for ``dof =
    1``), so that ``normalised > critical_value(alpha0)`` exactly when the chi-square test
    rejects at ``alpha0``.

    Parameters
    ----------
    statistic : (n,) float
    dof : (n,) int
        0 to 3 (0 gives 0).

    Returns
    -------
    w : (n,) float, >= 0

    Examples
    --------
    >>> normalised_statistic(np.array([3.29**2, 0.0, 16.266]), np.array([1, 3, 3])).round(2)
    array([3.29, 0.  , 3.29])
    """
    log_half_p = chi2_logsf(statistic, dof) - math.log(2.0)
    return np.maximum(-ndtri_exp(np.minimum(log_half_p, math.log(0.5))), 0.0)


def point_non_centrality(alpha0: float, beta0: float, dof: int = 3) -> float:
    """``lambda0``: the non-centrality at which the chi-square test of ``dof`` dimensions at
    level ``alpha0`` rejects with probability ``beta0`` (Baarda's B-method).

    Examples
    --------
    >>> round(point_non_centrality(0.001, 0.80), 2), round(point_non_centrality(0.001, 0.8, 1), 2)
    (21.55, 17.07)
    """
    critical = float(chi2.isf(alpha0, dof))
    return float(brentq(lambda lam: ncx2.sf(critical, dof, lam) - beta0, 1e-9,
                        10.0 * critical + 100.0, xtol=1e-12))


@dataclass(frozen=True)
class Rejection:
    """One observation removed by data snooping.

    Attributes
    ----------
    station_id, marker_id : str
        The point observation (all three components) removed.
    w : float
        Its normalised point-test statistic (:func:`normalised_statistic`) when it was removed.
    round : int
        Snooping round, 1 for the first removal.
    statistic : float
        Its point-test statistic ``T`` (chi-square, ``dof`` degrees of freedom).
    dof : int
    """

    station_id: str
    marker_id: str
    w: float
    round: int
    statistic: float = float("nan")
    dof: int = 3


@dataclass(frozen=True)
class PointTests:
    """The test of each point observation as one 3-dimensional group (see the module doc).

    Attributes
    ----------
    statistic : (n,) float
        ``T = v_i^T Q_vv,i^+ v_i``, chi2(``dof``) under the model.
    dof : (n,) int
        ``rank(Q_vv,i)``: 3, fewer where part of the point is uncontrolled, 0 for a marker seen
        once.
    w : (n,) float
        :func:`normalised_statistic` of ``statistic``: the decision statistic, compared with
        ``critical_value(alpha0)``.
    smallest_redundancy : (n,) float
        Smallest eigenvalue of ``P_i^1/2 Q_vv,i P_i^1/2`` (0 where ``dof < 3``): the
        redundancy of the point's worst-controlled direction (of least squares; with robust
        weights, of ``I - rho_i P_i^1/2 G_i P_i^1/2``).
    """

    statistic: np.ndarray
    dof: np.ndarray
    w: np.ndarray
    smallest_redundancy: np.ndarray


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
        Minimal detectable bias of the one-dimensional test per component, m (``inf`` where
        uncontrolled).
    mdb_effect_m : (n,) float
        Largest shift of any station or marker position caused by any one of the three MDBs of
        the observation, m.
    point : PointTests
        The test of each point observation (the decision statistic).
    mdb_point_m : (n,) float
        Minimal detectable bias of the point test in the point's worst direction, m (``inf``
        where some direction is uncontrolled).
    """

    redundancy: np.ndarray
    w_test: np.ndarray
    mdb_m: np.ndarray
    mdb_effect_m: np.ndarray
    point: PointTests
    mdb_point_m: np.ndarray


#: Observation components per chunk of the MDB effect (a chunk holds (rows, 3 (s + k)) floats).
_SHIFT_ROWS = 1536


def residual_blocks(blocks: np.ndarray, columns: np.ndarray, covariance: np.ndarray
                    ) -> np.ndarray:
    """``A_i Q A_i^T`` (n, 3, 3) of each observation from the covariance's blocks, m^2.

    Parameters as in :func:`observation_reliability`.
    """
    q = covariance[columns[:, :, None], columns[:, None, :]]
    return blocks @ q @ np.swapaxes(blocks, 1, 2)


def point_tests(aqa: np.ndarray, weight: np.ndarray, residual: np.ndarray,
                rho: np.ndarray | None = None) -> PointTests:
    """The test of each point observation (see the module doc).

    With robust weight factors ``rho`` (the adjustment's weights are ``rho_i P_i``) the test
    is that of the observation against the solution of all the others: its leave-one-out
    residual ``e_i = (I - rho_i P_i G_i)^-1 v_i`` (``G_i = A_i Q A_i^T`` with that adjustment's
    ``Q``) has the covariance ``P_i^-1 + G_i (I - rho_i P_i G_i)^-1`` under the observation's
    own noise, and ``T_i = e_i^T Cov(e_i)^-1 e_i``. In the eigenbasis of ``H = P^1/2 G P^1/2``
    (eigenvalues ``h``, ``z = P^1/2 v`` in it) this is ``sum z^2 / ((1 - rho h) (1 - rho h +
    h))``: for ``rho = 1`` the least-squares test ``sum z^2 / (1 - h)``, for ``rho = 0`` the
    observation's misfit against the rest ``sum z^2 / (1 + h)``, which a down-weighted blunder
    keeps. Directions with ``1 - rho h`` ~0 (determined by this observation alone) are
    uncontrolled and not tested.

    Parameters
    ----------
    aqa : (n, 3, 3) float
        ``A_i Q A_i^T`` (:func:`residual_blocks`) with the adjustment's weights, m^2.
    weight : (n, 3) float
        The observations' own weights ``1 / sigma_component**2``, 1/m^2 (> 0).
    residual : (n, 3) float
        Residuals ``v``, m.
    rho : (n,) float or None
        Robust weight factors the adjustment used (None: all 1, least squares).

    Returns
    -------
    PointTests

    Examples
    --------
    A point observed twice with unit weight: each residual block is ``I3 / 2`` and
    ``T = 2 |v|^2``.

    >>> aqa, v = np.stack([np.eye(3) / 2] * 2), np.array([[1.0, 0, 0], [-1.0, 0, 0]])
    >>> t = point_tests(aqa, np.ones((2, 3)), v)
    >>> t.statistic.tolist(), t.dof.tolist(), t.w.round(2).tolist()
    ([2.0, 2.0], [3, 3], [0.56, 0.56])

    The same misfit, the second observation down-weighted to 0 (the mean is the first: ``G =
    I3``, residuals 0 and 2): its test is ``|2|^2 / 2``, the least squares one again.

    >>> point_tests(np.stack([np.eye(3)] * 2), np.ones((2, 3)),
    ...             np.array([[0.0, 0, 0], [-2.0, 0, 0]]), np.array([1.0, 0.0])).statistic
    array([0., 2.])
    """
    root = np.sqrt(weight)
    h = root[:, :, None] * aqa * root[:, None, :]
    eig, vec = np.linalg.eigh(0.5 * (h + np.swapaxes(h, 1, 2)))
    rho = np.ones((aqa.shape[0], 1)) if rho is None else np.asarray(rho, float)[:, None]
    lam = 1.0 - rho * eig
    controlled = lam > _MIN_REDUNDANCY
    z = np.einsum("nji,nj->ni", vec, root * residual)
    scale = np.where(controlled, lam * (lam + eig), 1.0)
    statistic = np.sum(np.where(controlled, z**2 / scale, 0.0), axis=1)
    dof = controlled.sum(axis=1)
    return PointTests(statistic, dof, normalised_statistic(statistic, dof),
                      np.where(dof == 3, lam.min(axis=1), 0.0))


def _redundancy(aqa: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Redundancy numbers (n, 3) from ``A_i Q A_i^T`` and the weights."""
    return np.clip(1.0 - weight * np.diagonal(aqa, axis1=1, axis2=2), 0.0, 1.0)


def _w(r: np.ndarray, weight: np.ndarray, residual: np.ndarray) -> np.ndarray:
    controlled = r > _MIN_REDUNDANCY
    return np.where(controlled, residual * np.sqrt(weight / np.where(controlled, r, 1.0)), 0.0)


def observation_reliability(blocks: np.ndarray, columns: np.ndarray, weight: np.ndarray,
                            covariance: np.ndarray, residual: np.ndarray,
                            position_columns: np.ndarray, delta0: float, lambda0: float,
                            point: PointTests | None = None) -> ObservationReliability:
    """Redundancy, tests, MDBs and MDB effect of point observations.

    Parameters
    ----------
    blocks : (n, 3, c) float
        Design block of each observation: the derivatives of its 3 components with respect to
        the ``c`` parameters it involves (m per m, m per rad).
    columns : (n, c) int
        Those parameters' indices.
    weight : (n, 3) float
        Weights ``1 / sigma_component**2``, 1/m^2.
    covariance : (u, u) float or MarginalCovariance
        A-priori covariance ``Q`` of the parameters (zero rows for parameters the datum fixes),
        dense or :class:`pipeline.network.marginals.MarginalCovariance`.
    residual : (n, 3) float
        Residuals ``v``, m.
    position_columns : (p, 3) int
        Parameter columns of the station and marker positions whose shift is the MDB effect.
    delta0 : float
        Non-centrality of the component test (:func:`non_centrality`).
    lambda0 : float
        Non-centrality of the point test (:func:`point_non_centrality`, 3 dimensions).
    point : PointTests or None
        The point tests to report (those of a robust adjustment); None: least squares' with
        ``covariance``. The MDBs are least squares' either way.

    Returns
    -------
    ObservationReliability

    Examples
    --------
    One unknown point observed twice with unit weight: each component has redundancy 1/2.

    >>> blocks, columns = np.stack([np.eye(3)] * 2), np.array([[0, 1, 2]] * 2)
    >>> rel = observation_reliability(blocks, columns, np.ones((2, 3)), np.eye(3) / 2,
    ...                               np.zeros((2, 3)), np.array([[0, 1, 2]]), 4.13, 21.55)
    >>> rel.redundancy.tolist()
    [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]]
    >>> round(float(rel.mdb_effect_m[0]), 3)  # half of MDB = 4.13 / sqrt(0.5)
    2.92
    >>> round(float(rel.mdb_point_m[0]), 3)  # sqrt(21.55 / 0.5)
    6.565
    """
    aqa = residual_blocks(blocks, columns, covariance)
    r = _redundancy(aqa, weight)
    controlled = r > _MIN_REDUNDANCY
    mdb = np.where(controlled, delta0 / np.sqrt(weight * np.where(controlled, r, 1.0)), np.inf)
    n, c = columns.shape
    design = sp.csr_matrix((blocks.ravel(), np.repeat(columns, 3, axis=0).ravel(),
                            np.arange(0, 3 * n * c + 1, c)), shape=(3 * n, covariance.shape[0]))
    per_unit = np.empty(3 * n)
    for first in range(0, 3 * n, _SHIFT_ROWS):  # Q A_i^T per unit, in chunks of rows
        rows = slice(first, min(first + _SHIFT_ROWS, 3 * n))
        shift = design_times(covariance, design[rows], position_columns.ravel())
        per_unit[rows] = np.sqrt(np.max(np.sum(shift.reshape(shift.shape[0], -1, 3) ** 2,
                                               axis=2), axis=1))
    per_unit = per_unit.reshape(n, 3)
    effect = np.where(controlled, per_unit * weight * np.where(controlled, mdb, 0.0), np.inf)
    tests = point_tests(aqa, weight, residual)
    full = tests.dof == 3
    mdb_point = np.where(full, np.sqrt(lambda0 / (weight.min(axis=1) * np.where(
        full, tests.smallest_redundancy, 1.0))), np.inf)
    return ObservationReliability(r, _w(r, weight, residual), mdb, effect.max(axis=1),
                                  tests if point is None else point, mdb_point)


def data_snooping(solve: Callable[[np.ndarray, Any], tuple[Any, PointTests]], n: int,
                  alpha0: float, max_rejections: int,
                  removable: Callable[[np.ndarray, int], bool]
                  ) -> tuple[Any, np.ndarray, list[tuple[int, float, float, int, int]]]:
    """Baarda's data snooping on point observations: remove the one with the largest
    normalised point-test statistic (the smallest p-value) while it exceeds
    ``k = critical_value(alpha0)``.

    Parameters
    ----------
    solve : callable
        ``solve(keep, previous) -> (solution, tests)``: adjusts the observations ``keep``
        ((n,) bool) starting from ``previous`` (None the first time, else the last solution)
        and returns the solution and the :class:`PointTests` of the kept observations in order.
    n : int
        Number of point observations.
    alpha0 : float
        Significance level of each point test.
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
    rejected : list of (int, float, float, int, int)
        ``(observation index, w, T, dof, round)`` for every removal, in order.

    Examples
    --------
    >>> t_all = np.array([0.5, 200.0, 30.0, 1.0])
    >>> def solve(keep, previous):
    ...     t = t_all[keep]
    ...     return "fit", PointTests(t, np.full(t.size, 3), normalised_statistic(t, 3), t)
    >>> _, keep, rejected = data_snooping(solve, 4, 0.001, 10, lambda keep, i: True)
    >>> keep.tolist(), [(i, round(w, 2), dof, r) for i, w, _, dof, r in rejected]
    ([True, False, False, True], [(1, 13.76, 3, 1), (2, 4.83, 3, 2)])
    """
    keep = np.ones(n, dtype=bool)
    solution, tests = solve(keep, None)
    k = critical_value(alpha0)
    rejected: list[tuple[int, float, float, int, int]] = []
    while len(rejected) < max_rejections and tests.w.size:
        worst = int(np.argmax(tests.w))
        index = int(np.flatnonzero(keep)[worst])
        if tests.w[worst] <= k or not removable(keep, index):
            break
        keep[index] = False
        rejected.append((index, float(tests.w[worst]), float(tests.statistic[worst]),
                         int(tests.dof[worst]), len(rejected) + 1))
        solution, tests = solve(keep, solution)
    return solution, keep, rejected
