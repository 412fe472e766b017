"""Compiled inner loops of the station chain (numba, compiled on first use and cached on disk).

Once their numpy forms were exhausted, two kinds of loop dominated the processing of a station:
passes over its ~11 million points, each making temporaries (the turntable synthesis,
:func:`transform_frames`; the detection's thinning, :func:`range_thinned`; its ground grid,
:func:`lowest_in_cells`; the re-search's range bands, :func:`in_wanted_bins`), and the ~900
small Gauss-Newton sphere fits whose per-call overheads far exceed their arithmetic
(:func:`los_gauss_newton_fixed`, :func:`gauss_newton_fixed_radius`). Compiled, each is one
pass with no temporaries. The formulas are those of the numpy forms they replace; sums are
taken in point order, so results agree with those forms to round-off (the thinning, the grid
and the bands exactly). The ground stage's steepness test, :func:`rise_over_cone`, was written
compiled from the start (tested against a brute-force numpy search).

The kernels are compiled once per installation (a few seconds; cached beside this file, or in
``NUMBA_CACHE_DIR``) and loaded once per process (under a second).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def transform_frames(xyz_sensor_m: np.ndarray, frame_index: np.ndarray, rotation: np.ndarray,
                     translation: np.ndarray, out: np.ndarray, range_out: np.ndarray
                     ) -> None:
    """``out[i] = rotation[f] @ xyz_sensor_m[i] + translation[f]`` with ``f = frame_index[i]``,
    and optionally ``range_out[i] = |out[i]|``.

    Parameters
    ----------
    xyz_sensor_m : (N, 3) float32 or float64
        Points in the sensor frame, metres.
    frame_index : (N,) int
        Frame of each point, indexing ``rotation`` (any order; the caller checks the range).
    rotation : (F, 3, 3) float64
        Sensor -> station rotation of each frame.
    translation : (F, 3) float64
        Sensor origin of each frame in the station frame, metres.
    out : (N, 3) float64
        Written in place: the points in the station frame, metres.
    range_out : (N,) or (0,) float64
        Written in place when of length N: each point's distance from the station origin,
        metres (in the same pass, instead of a second one over ``out``).
    """
    with_range = range_out.shape[0] > 0
    for i in range(xyz_sensor_m.shape[0]):
        f = frame_index[i]
        x, y, z = xyz_sensor_m[i, 0], xyz_sensor_m[i, 1], xyz_sensor_m[i, 2]
        for k in range(3):
            out[i, k] = (rotation[f, k, 0] * x + rotation[f, k, 1] * y + rotation[f, k, 2] * z
                         + translation[f, k])
        if with_range:
            range_out[i] = math.sqrt(out[i, 0] * out[i, 0] + out[i, 1] * out[i, 1]
                                     + out[i, 2] * out[i, 2])


@njit(cache=True, nogil=True)
def los_gauss_newton_fixed(range_m: np.ndarray, beam: np.ndarray, centre_m: np.ndarray,
                           radius_m: float, var0_m2: np.ndarray, incidence_var_m2: float,
                           min_cos_incidence: float, max_iter: int, tol_m: float
                           ) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-radius line-of-sight sphere fit by damped Gauss-Newton, sensor at the origin.

    Minimises ``sum (rho_i - t_i(c))^2 / var_i``: ``t_i`` is the range at which beam ``i`` meets
    the sphere of radius ``radius_m`` about ``c`` (incidence capped at
    ``acos(min_cos_incidence)``), ``var_i = var0_i + incidence_var * tan^2 i``. Each step is
    capped at half the radius; the iterations stop when a step is shorter than ``tol_m``, after
    ``max_iter`` steps, or when the normal matrix is exactly singular.

    Parameters
    ----------
    range_m : (n,) float64
        Measured range of each beam, metres.
    beam : (n, 3) float64
        Unit direction of each beam.
    centre_m : (3,) float64
        Start centre, metres.
    radius_m : float
        Sphere radius, metres.
    var0_m2 : (n,) float64
        Range variance of each beam at normal incidence, m^2.
    incidence_var_m2 : float
        Variance per unit ``tan^2`` of the incidence angle, m^2 (0: none).
    min_cos_incidence : float
        Cosine of the largest incidence a beam is treated as meeting the sphere at.
    max_iter : int
        Largest number of steps.
    tol_m : float
        Step length that ends the iterations, metres.

    Returns
    -------
    centre_m : (3,) float64
        The estimate, metres.
    covariance : (3, 3) float64
        ``(J^T W J)^-1`` at the last step, m^2 (NaN if no step was taken).
    """
    c = centre_m.copy()
    cov = np.full((3, 3), np.nan)
    r2 = radius_m * radius_m
    h2_min = r2 * min_cos_incidence * min_cos_incidence
    m = np.empty((3, 4))  # [J^T W J, J^T W r]
    v = np.empty(4)  # a row of the Jacobian times h, and h times the residual
    for _ in range(max_iter):
        cc = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
        m[:] = 0.0
        for i in range(range_m.shape[0]):
            bx, by, bz = beam[i, 0], beam[i, 1], beam[i, 2]
            along = bx * c[0] + by * c[1] + bz * c[2]
            h2 = max(along * along + (r2 - cc), h2_min)
            h = math.sqrt(h2)
            t = along - h
            var = var0_m2[i]
            if incidence_var_m2 != 0.0:
                var += incidence_var_m2 * max(r2 - h2, 0.0) / h2
            w = 1.0 / (var * h2)
            v[0], v[1], v[2] = t * bx - c[0], t * by - c[1], t * bz - c[2]
            v[3] = (range_m[i] - t) * h
            for row in range(3):
                wv = w * v[row]
                for col in range(4):
                    m[row, col] += wv * v[col]
        inv, singular = inverse3(m)
        if singular:
            break
        cov = inv
        step = np.empty(3)
        for k in range(3):
            step[k] = -(cov[k, 0] * m[0, 3] + cov[k, 1] * m[1, 3] + cov[k, 2] * m[2, 3])
        length = math.sqrt(step[0] * step[0] + step[1] * step[1] + step[2] * step[2])
        damp = min(1.0, 0.5 * radius_m / max(length, 1e-300))
        for k in range(3):
            c[k] += step[k] * damp
        if (length if damp == 1.0 else length * damp) < tol_m:
            break
    return c, cov


@njit(cache=True, nogil=True)
def inverse3(m: np.ndarray) -> tuple[np.ndarray, bool]:
    """Inverse of the leading 3 x 3 block of ``m`` by cofactors.

    Parameters
    ----------
    m : (3, >= 3) float64
        Rows of the matrix (columns past the third are ignored).

    Returns
    -------
    inverse : (3, 3) float64
        NaN when the matrix is singular.
    singular : bool
        True when the determinant is exactly zero.
    """
    inv = np.full((3, 3), np.nan)
    c00 = m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1]
    c01 = m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2]
    c02 = m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0]
    det = m[0, 0] * c00 + m[0, 1] * c01 + m[0, 2] * c02
    if det == 0.0:
        return inv, True
    inv[0, 0], inv[1, 0], inv[2, 0] = c00 / det, c01 / det, c02 / det
    inv[0, 1] = (m[0, 2] * m[2, 1] - m[0, 1] * m[2, 2]) / det
    inv[1, 1] = (m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0]) / det
    inv[2, 1] = (m[0, 1] * m[2, 0] - m[0, 0] * m[2, 1]) / det
    inv[0, 2] = (m[0, 1] * m[1, 2] - m[0, 2] * m[1, 1]) / det
    inv[1, 2] = (m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2]) / det
    inv[2, 2] = (m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0]) / det
    return inv, False


@njit(cache=True, nogil=True)
def gauss_newton_fixed_radius(points_m: np.ndarray, radius_m: float, centre_m: np.ndarray,
                              max_iter: int, tol_m: float) -> np.ndarray:
    """Geometric least-squares sphere centre with the radius fixed, by Gauss-Newton.

    Minimises ``sum (|p_i - c| - R)^2``; each step solves ``U^T U s = U^T r`` (``U``: unit
    vectors from the centre to the points, ``r = |p_i - c| - R``). The iterations stop when a
    step is shorter than ``tol_m``, after ``max_iter`` steps, or when ``U^T U`` is exactly
    singular.

    Parameters
    ----------
    points_m : (n, 3) float
        Points, metres.
    radius_m : float
        Sphere radius, metres.
    centre_m : (3,) float64
        Start centre, metres.
    max_iter : int
        Largest number of steps.
    tol_m : float
        Step length that ends the iterations, metres.

    Returns
    -------
    centre_m : (3,) float64
        The estimate, metres.
    """
    c = centre_m.copy()
    m = np.empty((3, 4))  # [U^T U, U^T r]
    u = np.empty(3)
    for _ in range(max_iter):
        m[:] = 0.0
        for i in range(points_m.shape[0]):
            for k in range(3):
                u[k] = points_m[i, k] - c[k]
            n = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
            scale = 1.0 / max(n, 1e-12)
            for k in range(3):
                u[k] *= scale
            r = n - radius_m
            for row in range(3):
                for col in range(3):
                    m[row, col] += u[row] * u[col]
                m[row, 3] += u[row] * r
        inv, singular = inverse3(m)
        if singular:
            break
        length2 = 0.0
        for k in range(3):
            s = inv[k, 0] * m[0, 3] + inv[k, 1] * m[1, 3] + inv[k, 2] * m[2, 3]
            c[k] += s
            length2 += s * s
        if math.sqrt(length2) < tol_m:
            break
    return c


@njit(cache=True, nogil=True)
def range_thinned(range_m: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """Indices ``i`` (ascending) with ``i % int(clip((full / max(r_i, floor))^2, 1, max_stride))
    == 0``, the arithmetic in the ranges' float type.

    Parameters
    ----------
    range_m : (N,) float32 or float64
        Range of each point, metres.
    limits : (4,) array of ``range_m``'s type
        ``full`` (range within which points are thinned, metres), ``max_stride`` (the largest
        stride), ``floor`` (smallest range used, metres) and 1.

    Returns
    -------
    subset : (n,) int64
    """
    full, max_stride, floor, one = limits[0], limits[1], limits[2], limits[3]
    out = np.empty(range_m.shape[0], dtype=np.int64)
    n = 0
    for i in range(range_m.shape[0]):
        q = full / max(range_m[i], floor)
        stride = int(min(max(q * q, one), max_stride))
        if i % stride == 0:
            out[n] = i
            n += 1
    return out[:n].copy()


@njit(cache=True, nogil=True)
def lowest_in_cells(xyz_m: np.ndarray, cell_m: float) -> np.ndarray:
    """Lowest z of the points in each point's horizontal grid cell.

    Parameters
    ----------
    xyz_m : (N, 3) float
        Points, z up, metres.
    cell_m : float
        Cell size, metres; cell ``(floor(x / cell_m), floor(y / cell_m))``.

    Returns
    -------
    ground_z_m : (N,) float64
        Lowest z in each point's cell, metres; NaN for a point whose x or y is not finite.
    """
    n = xyz_m.shape[0]
    out = np.full(n, np.nan)
    flat = np.full(n, -1, dtype=np.int64)
    ix0 = iy0 = ix1 = iy1 = 0
    seen = False
    for i in range(n):
        x, y = xyz_m[i, 0] / cell_m, xyz_m[i, 1] / cell_m
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        ix, iy = int(math.floor(x)), int(math.floor(y))
        if seen:
            ix0, ix1, iy0, iy1 = min(ix0, ix), max(ix1, ix), min(iy0, iy), max(iy1, iy)
        else:
            ix0, ix1, iy0, iy1, seen = ix, ix, iy, iy, True
    if not seen:
        return out
    ny = iy1 - iy0 + 1
    grid = np.full((ix1 - ix0 + 1) * ny, np.inf)
    for i in range(n):
        x, y = xyz_m[i, 0] / cell_m, xyz_m[i, 1] / cell_m
        if math.isfinite(x) and math.isfinite(y):
            flat[i] = (int(math.floor(x)) - ix0) * ny + int(math.floor(y)) - iy0
            grid[flat[i]] = min(grid[flat[i]], xyz_m[i, 2])
    for i in range(n):
        if flat[i] >= 0:
            out[i] = grid[flat[i]]
    return out


@njit(cache=True, nogil=True)
def in_wanted_bins(range_m: np.ndarray, bin_m: float, wanted: np.ndarray
                   ) -> np.ndarray:
    """Indices (ascending) of the points whose range bin ``min(int(r / bin_m), len - 1)`` is
    ``wanted``.

    Parameters
    ----------
    range_m : (N,) float
        Ranges, metres.
    bin_m : float
        Bin width, metres.
    wanted : (B,) bool
        Bins to keep; the last bin also holds every range beyond it.

    Returns
    -------
    indices : (n,) int64
        Never a point whose range is negative or NaN.
    """
    out = np.empty(range_m.shape[0], dtype=np.int64)
    last = wanted.shape[0] - 1
    n = 0
    for i in range(range_m.shape[0]):
        if range_m[i] >= 0.0 and wanted[int(min(range_m[i] / bin_m, last))]:
            out[n] = i
            n += 1
    return out[:n].copy()


@njit(cache=True, nogil=True)
def rise_over_cone(xyz_m: np.ndarray, queries: np.ndarray, max_slope: float, reach_m: float,
                   cell_m: float) -> np.ndarray:
    """Rise of each queried point over the steepest-ground cone under it
    (:func:`pipeline.chain.ground.rise_over_slope`, which checks the arguments).

    The lowest return of each ``cell_m`` cell is kept on a grid built only on the tiles of
    ``reach_m`` around the queries; each query takes the largest
    ``z - z_low - max_slope * d_xy`` over the cells' lowest returns within ``reach_m``.

    Parameters
    ----------
    xyz_m : (N, 3) float64, C-contiguous
    queries : (n,) int64
        Indices of the points rated.
    max_slope, reach_m, cell_m : float

    Returns
    -------
    rise_m : (n,) float64
        ``-inf`` for a query with no finite position.
    """
    n_q = queries.size
    out = np.full(n_q, -np.inf)
    per_tile = max(1, int(math.ceil(reach_m / cell_m)))  # support cells per tile edge
    tile_m = per_tile * cell_m
    ti0 = tj0 = ti1 = tj1 = 0
    seen = False
    for k in range(n_q):
        x, y = xyz_m[queries[k], 0], xyz_m[queries[k], 1]
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        ti, tj = int(math.floor(x / tile_m)), int(math.floor(y / tile_m))
        if seen:
            ti0, ti1, tj0, tj1 = min(ti0, ti), max(ti1, ti), min(tj0, tj), max(tj1, tj)
        else:
            ti0, ti1, tj0, tj1, seen = ti, ti, tj, tj, True
    if not seen:
        return out
    ti0, tj0, ti1, tj1 = ti0 - 1, tj0 - 1, ti1 + 1, tj1 + 1  # the tiles a query can reach
    nti, ntj = ti1 - ti0 + 1, tj1 - tj0 + 1
    slot = np.full(nti * ntj, -1, dtype=np.int64)
    n_slots = 0
    for k in range(n_q):
        x, y = xyz_m[queries[k], 0], xyz_m[queries[k], 1]
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        ti, tj = int(math.floor(x / tile_m)), int(math.floor(y / tile_m))
        for a in range(ti - 1, ti + 2):
            for b in range(tj - 1, tj + 2):
                t = (a - ti0) * ntj + b - tj0
                if slot[t] < 0:
                    slot[t] = n_slots
                    n_slots += 1
    cells = per_tile * per_tile
    low = np.full((n_slots * cells, 3), np.inf)  # lowest return of each support cell
    for i in range(xyz_m.shape[0]):
        x, y = xyz_m[i, 0], xyz_m[i, 1]
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        ci, cj = int(math.floor(x / cell_m)), int(math.floor(y / cell_m))
        ti, tj = ci // per_tile, cj // per_tile
        if ti < ti0 or ti > ti1 or tj < tj0 or tj > tj1:
            continue
        s = slot[(ti - ti0) * ntj + tj - tj0]
        if s < 0:
            continue
        c = s * cells + (ci - ti * per_tile) * per_tile + cj - tj * per_tile
        if xyz_m[i, 2] < low[c, 2]:
            low[c, 0], low[c, 1], low[c, 2] = x, y, xyz_m[i, 2]
    for k in range(n_q):
        p = queries[k]
        x, y, z = xyz_m[p, 0], xyz_m[p, 1], xyz_m[p, 2]
        if not (math.isfinite(x) and math.isfinite(y)):
            continue
        ci, cj = int(math.floor(x / cell_m)), int(math.floor(y / cell_m))
        best = -np.inf
        for a in range(ci - per_tile, ci + per_tile + 1):  # per_tile cells >= the reach
            for b in range(cj - per_tile, cj + per_tile + 1):
                ta, tb = a // per_tile, b // per_tile
                c = slot[(ta - ti0) * ntj + tb - tj0] * cells + (a - ta * per_tile) * per_tile \
                    + b - tb * per_tile
                d = math.hypot(low[c, 0] - x, low[c, 1] - y)  # inf for an empty cell
                if d <= reach_m:
                    best = max(best, z - low[c, 2] - max_slope * d)
        out[k] = best
    return out
