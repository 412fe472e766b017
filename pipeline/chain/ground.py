"""Ground removal on a horizontal grid (station frame).

Two tests, both needed for a point to stand "above the ground":

height
    The local ground under a point is the lowest return in its grid cell (``cell_m``, 0.5 m);
    the point must stand ``min_height_m`` above it. On the VLP-16 rig the vertical component of
    range noise on the ground is small (the beams meet the ground at grazing angles), so the
    minimum is biased low by only millimetres. A cell lying wholly in a marker's shadow holds
    only marker points and loses them, but a 0.20 m marker always spreads over cells that also
    hold ground in front of it.
steepness
    On a slope the lowest return of a 0.5 m cell lies up to ``slope * 0.7 m`` below the cell's
    other ground points: 0.1 m on the 8 deg ejecta outside a fresh crater's rim, 0.4 m on its
    38 deg inner wall (Pike's bowl, 0.196 D deep, is that steep at the rim for every D). Such
    points chain a marker near the rim into a rim cluster of metres. A point therefore must
    also rise more than :data:`STEEPNESS_TOLERANCE_M` above the cone of slope
    :data:`GROUND_MAX_SLOPE` (50 deg) standing on some return within
    :data:`SUPPORT_RADIUS_M` of it (the lowest return of each :data:`SUPPORT_CELL_M` cell
    stands for the returns of its cell): terrain up to 50 deg never does, the upper half of a
    sphere always does (its top stands ``2 R`` above the ground at its foot, ``R`` away, and the
    sphere's own lower returns support the rest), and so do the walls of a rock.
"""

from __future__ import annotations

import numpy as np

from markerplan.errors import ConfigError
from pipeline.kernels import lowest_in_cells, rise_over_cone

#: Steepest terrain the ground stage takes for ground: tan 50 deg (fresh crater walls reach
#: 38 deg, and the range noise on a wall facing the sensor steepens it between neighbouring
#: returns; a marker's upper half, seen from its foot, is steeper).
GROUND_MAX_SLOPE = 1.2

#: How far above the slope cone a point must rise to stand above the ground, metres: the
#: vertical scatter of ground returns (range noise along beams at grazing angles), well below a
#: marker's rise over its foot (``2 R - R * GROUND_MAX_SLOPE`` = 0.08 m for R = 0.1 m).
STEEPNESS_TOLERANCE_M = 0.03

#: How far from a point the steepness test looks for the ground under the cone, metres: a
#: marker's top lies ``R`` from its foot, with the range noise's spread around it.
SUPPORT_RADIUS_M = 0.3

#: Cell of the steepness test's support grid, metres: its lowest return stands for the cell.
SUPPORT_CELL_M = 0.05


def local_ground_height(xyz_m: np.ndarray, cell_m: float = 0.5) -> np.ndarray:
    """Local ground height under every point (one compiled pass per step:
    :func:`pipeline.kernels.lowest_in_cells`).

    Parameters
    ----------
    xyz_m : (N, 3) float
        Points, station (or site) frame with z up, metres.
    cell_m : float
        Grid cell size, metres.

    Returns
    -------
    ground_z_m : (N,) float
        Lowest z in each point's cell, metres.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0.1, 0.1, -1.0], [0.2, 0.2, -0.8], [5.0, 5.0, 0.0]])
    >>> local_ground_height(pts, 0.5).tolist()
    [-1.0, -1.0, 0.0]
    """
    _ground_iv(xyz_m, cell_m, 0.0)
    n = xyz_m.shape[0]
    if n == 0:
        return np.zeros(0)
    return lowest_in_cells(np.ascontiguousarray(xyz_m, dtype=float), float(cell_m))


def rise_over_slope(xyz_m: np.ndarray, queries: np.ndarray, max_slope: float = GROUND_MAX_SLOPE,
                    support_radius_m: float = SUPPORT_RADIUS_M,
                    support_cell_m: float = SUPPORT_CELL_M) -> np.ndarray:
    """How far each queried point rises above the steepest-ground cone under it.

    The rise of point ``p`` is ``max_q (z_p - z_q - max_slope * d_xy(p, q))`` over the lowest
    return ``q`` of every ``support_cell_m`` cell within ``support_radius_m`` of ``p``
    (horizontal distance): positive when ``p`` stands on something steeper than
    ``max_slope`` (:func:`pipeline.kernels.rise_over_cone`: one compiled pass over the cloud,
    one over the queries; the grid covers only the ``support_radius_m`` tiles around the
    queries).

    Parameters
    ----------
    xyz_m : (N, 3) float
        The cloud, z up, metres.
    queries : (n,) int
        Indices of the points to rate.
    max_slope : float
        Steepest ground, rise over run.
    support_radius_m, support_cell_m : float
        Search radius and support-grid cell, metres.

    Returns
    -------
    rise_m : (n,) float
        Metres (``-inf`` for a point with no finite position).

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0.0, 0, 0], [0.1, 0, 0.05], [0.1, 0.02, 0.3]])
    >>> np.round(rise_over_slope(pts, np.array([1, 2])), 3).tolist()
    [0.0, 0.226]
    """
    if not (max_slope >= 0 and support_radius_m > 0 and support_cell_m > 0):
        raise ConfigError(f"the steepness test needs max_slope >= 0, support_radius_m > 0 and "
                          f"support_cell_m > 0, got {max_slope}, {support_radius_m}, "
                          f"{support_cell_m}")
    queries = np.asarray(queries, dtype=np.int64)
    if not queries.size:
        return np.zeros(0)
    return rise_over_cone(np.ascontiguousarray(xyz_m, dtype=float), queries,
                          float(max_slope), float(support_radius_m), float(support_cell_m))


def remove_ground(xyz_m: np.ndarray, cell_m: float = 0.5, min_height_m: float = 0.1,
                  max_slope: float = GROUND_MAX_SLOPE,
                  steepness_tolerance_m: float = STEEPNESS_TOLERANCE_M,
                  support_radius_m: float = SUPPORT_RADIUS_M) -> np.ndarray:
    """Mask of points standing above the ground (module docstring: both tests).

    Parameters
    ----------
    xyz_m : (N, 3) float
        Points, z up, metres.
    cell_m : float
        See :func:`local_ground_height`.
    min_height_m : float
        Keep points at least this high above the local ground, metres.
    max_slope, steepness_tolerance_m, support_radius_m : float
        The steepness test: keep points rising more than ``steepness_tolerance_m`` (metres)
        above the cone of ``max_slope`` (rise over run) on some return within
        ``support_radius_m`` (metres; :func:`rise_over_slope`).

    Returns
    -------
    above : (N,) bool

    Examples
    --------
    A 38 deg crater wall is ground; a post on flat ground is not.

    >>> import numpy as np
    >>> x = np.arange(0, 1, 0.02)
    >>> wall = np.column_stack([x, np.zeros_like(x), 0.78 * x])
    >>> post = np.array([[2.0, 0, 0], [2.02, 0, 0], [2.01, 0, 0.2]])
    >>> np.flatnonzero(remove_ground(np.vstack([wall, post]))).tolist()
    [52]
    """
    _ground_iv(xyz_m, cell_m, min_height_m)
    if not steepness_tolerance_m >= 0:
        raise ConfigError(f"ground `steepness_tolerance_m` must be >= 0 metres, got "
                          f"{steepness_tolerance_m}")
    above = xyz_m[:, 2] - local_ground_height(xyz_m, cell_m) >= min_height_m
    high = np.flatnonzero(above)
    rise = rise_over_slope(xyz_m, high, max_slope, support_radius_m)
    above[high] = rise > steepness_tolerance_m
    return above


def _ground_iv(xyz_m, cell_m, min_height_m) -> None:
    if xyz_m.ndim != 2 or xyz_m.shape[1] != 3:
        raise ConfigError(f"`xyz_m` must have shape (N, 3), got {xyz_m.shape}")
    if not cell_m > 0:
        raise ConfigError(f"ground `cell_m` must be > 0 metres, got {cell_m}")
    if not min_height_m >= 0:
        raise ConfigError(f"ground `min_height_m` must be >= 0, got {min_height_m}")
