"""Relative accuracy between pairs of adjusted stations (STAR*NET-style relative error ellipses).

The relative position of stations ``i`` and ``j`` is ``t_j - t_i`` (their x, y, z; roll and
pitch, which turn about each station's own axes, are not mixed in); its covariance is

    Sigma_ij = Q_ii + Q_jj - Q_ij - Q_ji        (3 x 3 blocks of the x, y, z parameters)

from the adjustment's covariance (dense or
:class:`~pipeline.network.marginals.MarginalCovariance`: the stations' blocks are held). Its
figures at 95 %, as STAR*NET reports them:

- the horizontal relative ellipse: semi-axes ``2.4477 sqrt(lambda)`` of the 2 x 2 horizontal
  block (``sqrt(chi2_2(0.95))``), and the azimuth of the major axis;
- the vertical: ``1.96 sigma_z``;
- the 3-D: ``sqrt(chi2_3(0.95) lambda_max)`` of the 3 x 3 block;
- along the line (the distance's error): ``1.96 sqrt(u^T Sigma u)``, ``u`` the unit vector from
  ``i`` to ``j``.

Pairs of adjusted markers (:func:`marker_pair_covariances`) get the same figures from their
``x, y, z`` blocks, ``Sigma_jk = Q_jj + Q_kk - Q_jk - Q_kj``: a dense covariance holds the
cross blocks ``Q_jk``; a :class:`~pipeline.network.marginals.MarginalCovariance` holds only each
marker's own block, so its cross blocks are computed exactly as columns ``Q[:, cols]``
(:meth:`~pipeline.network.marginals.MarginalCovariance.columns`, one product per chunk of
markers).

Which pairs, and the allowance they are judged against, are the caller's (the planner's
:class:`planner.accuracy.local.LocalRequirement` in ``markerplan adjust``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2, norm

#: Scale of the 95 % horizontal ellipse: ``sqrt(chi2_2(0.95))`` = 2.4477.
HORIZONTAL_SCALE_95 = math.sqrt(float(chi2.ppf(0.95, 2)))
#: chi-square 95 % quantile, 3 degrees of freedom.
CHI2_3_95 = float(chi2.ppf(0.95, 3))
#: Two-sided 95 % of one dimension: 1.96.
ONE_D_95 = float(norm.ppf(0.975))


@dataclass(frozen=True)
class RelativeFigures:
    """95 % figures of the relative position of pairs of stations.

    Attributes
    ----------
    covariance : (p, 3, 3) float
        Covariance of ``t_j - t_i``, site-frame axes, m^2.
    horizontal_major_m, horizontal_minor_m : (p,) float
        Semi-axes of the 95 % horizontal relative ellipse, m.
    azimuth_deg : (p,) float
        Direction of the major axis, degrees from the site frame's +y towards +x, in [0, 180).
    vertical_m : (p,) float
        95 % of the height difference, m.
    ellipsoid_m : (p,) float
        ``sqrt(chi2_3(0.95) lambda_max)``: the 95 % ellipsoid's largest semi-axis, m.
    along_m : (p,) float
        95 % of the distance between them (along the line), m.
    """

    covariance: np.ndarray
    horizontal_major_m: np.ndarray
    horizontal_minor_m: np.ndarray
    azimuth_deg: np.ndarray
    vertical_m: np.ndarray
    ellipsoid_m: np.ndarray
    along_m: np.ndarray


def pair_covariances(covariance, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Covariance of ``t_second - t_first`` for station pairs, (p, 3, 3), m^2.

    Parameters
    ----------
    covariance : (u, u) float or MarginalCovariance
        The adjustment's covariance (stations first, 6 parameters each, x, y, z leading).
    first, second : (p,) int
        Station indices.

    Examples
    --------
    Two independent stations of 1 cm^2 variance per axis: the difference has twice that.

    >>> q = np.zeros((12, 12)); q[[0, 1, 2, 6, 7, 8], [0, 1, 2, 6, 7, 8]] = 1e-4
    >>> np.diag(pair_covariances(q, np.array([0]), np.array([1]))[0]).tolist()
    [0.0002, 0.0002, 0.0002]
    """
    a = 6 * np.asarray(first, dtype=int)[:, None] + np.arange(3)
    b = 6 * np.asarray(second, dtype=int)[:, None] + np.arange(3)

    def block(r, c):
        return covariance[r[:, :, None], c[:, None, :]]

    cross = block(a, b)
    return block(a, a) + block(b, b) - cross - np.swapaxes(cross, 1, 2)


#: Markers per chunk of :func:`marker_pair_covariances`' columns of a MarginalCovariance.
_MARKER_CHUNK = 128


def marker_pair_covariances(covariance, n_station_params: int, first: np.ndarray,
                            second: np.ndarray) -> np.ndarray:
    """Covariance of ``m_second - m_first`` for marker pairs, (p, 3, 3), m^2.

    Parameters
    ----------
    covariance : (u, u) float or MarginalCovariance
        The adjustment's covariance (stations first, ``n_station_params`` of them, then 3 per
        marker).
    n_station_params : int
        ``6 s``.
    first, second : (p,) int
        Marker indices.

    Examples
    --------
    Two markers of 1 cm^2 per axis with a covariance of 0.5 cm^2 per axis between them:

    >>> q = np.zeros((6, 6)); q[np.arange(6), np.arange(6)] = 1e-4
    >>> q[np.arange(3), np.arange(3, 6)] = q[np.arange(3, 6), np.arange(3)] = 5e-5
    >>> np.round(np.diag(marker_pair_covariances(q, 0, np.array([0]), np.array([1]))[0]),
    ...          12).tolist()
    [0.0001, 0.0001, 0.0001]
    """
    from pipeline.network.marginals import MarginalCovariance

    first = np.asarray(first, dtype=int).reshape(-1)
    second = np.asarray(second, dtype=int).reshape(-1)
    ax = np.arange(3)
    a = n_station_params + 3 * first[:, None] + ax
    b = n_station_params + 3 * second[:, None] + ax
    if not isinstance(covariance, MarginalCovariance):
        cross = covariance[a[:, :, None], b[:, None, :]]
        own_a = covariance[a[:, :, None], a[:, None, :]]
        own_b = covariance[b[:, :, None], b[:, None, :]]
    else:
        own_a, own_b = covariance.marker_blocks[first], covariance.marker_blocks[second]
        cross = np.empty((first.size, 3, 3))
        seconds = np.unique(second)
        for lo in range(0, seconds.size, _MARKER_CHUNK):
            cols = seconds[lo:lo + _MARKER_CHUNK]
            q = covariance.columns(n_station_params + 3 * cols[:, None] + ax)  # (u, 3c)
            sel = np.flatnonzero(np.isin(second, cols))
            at = np.searchsorted(cols, second[sel])
            cross[sel] = q[a[sel][:, :, None], 3 * at[:, None, None] + ax[None, None, :]]
    return own_a + own_b - cross - np.swapaxes(cross, 1, 2)


def relative_figures(cov3: np.ndarray, direction: np.ndarray) -> RelativeFigures:
    """The 95 % figures (see the module doc) of relative positions.

    Parameters
    ----------
    cov3 : (p, 3, 3) float
        Covariances of the relative positions (:func:`pair_covariances`), m^2.
    direction : (p, 3) float
        Unit vectors from the first station to the second (zero: no along-line figure, 0).

    Returns
    -------
    RelativeFigures

    Examples
    --------
    sigma_x = 2 cm, sigma_y = 1 cm, sigma_z = 1 cm: the ellipse's major axis points along x
    (azimuth 90 degrees), 2.4477 * 2 cm long.

    >>> f = relative_figures(np.diag([4e-4, 1e-4, 1e-4])[None], np.array([[0.0, 1.0, 0.0]]))
    >>> round(float(f.horizontal_major_m[0]), 4), round(float(f.azimuth_deg[0]), 1)
    (0.049, 90.0)
    >>> round(float(f.along_m[0]), 4), round(float(f.vertical_m[0]), 4)
    (0.0196, 0.0196)
    """
    cov3 = np.asarray(cov3, dtype=float).reshape(-1, 3, 3)
    cov3 = 0.5 * (cov3 + np.swapaxes(cov3, 1, 2))
    direction = np.asarray(direction, dtype=float).reshape(-1, 3)
    lam2, vec2 = np.linalg.eigh(cov3[:, :2, :2])
    lam2 = np.clip(lam2, 0.0, None)
    major = vec2[:, :, 1]
    azimuth = np.degrees(np.arctan2(major[:, 0], major[:, 1])) % 180.0
    lam3 = np.clip(np.linalg.eigvalsh(cov3)[:, -1], 0.0, None)
    along = np.einsum("pi,pij,pj->p", direction, cov3, direction)
    return RelativeFigures(
        covariance=cov3,
        horizontal_major_m=HORIZONTAL_SCALE_95 * np.sqrt(lam2[:, 1]),
        horizontal_minor_m=HORIZONTAL_SCALE_95 * np.sqrt(lam2[:, 0]),
        azimuth_deg=np.where(np.isclose(azimuth, 180.0), 0.0, azimuth),
        vertical_m=ONE_D_95 * np.sqrt(np.clip(cov3[:, 2, 2], 0.0, None)),
        ellipsoid_m=np.sqrt(CHI2_3_95 * lam3),
        along_m=ONE_D_95 * np.sqrt(np.clip(along, 0.0, None)))
