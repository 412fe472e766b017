"""Ground removal on a horizontal grid (station frame).

The local ground under a point is the lowest return in its grid cell. On the VLP-16 rig the
vertical component of range noise on the ground is small (the beams meet the ground at grazing
angles), so the minimum is biased low by only millimetres; steep crater walls do leave
"above-ground" points, which the two-box gate rejects as too large. A cell lying wholly in a
marker's shadow holds only marker points and loses them, but a 0.20 m marker always spreads
over cells that also hold ground in front of it.
"""

from __future__ import annotations

import numpy as np

from markerplan.errors import ConfigError
from pipeline.kernels import lowest_in_cells


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


def remove_ground(xyz_m: np.ndarray, cell_m: float = 0.5, min_height_m: float = 0.1
                  ) -> np.ndarray:
    """Mask of points at least ``min_height_m`` above the local ground.

    Parameters
    ----------
    xyz_m : (N, 3) float
        Points, z up, metres.
    cell_m : float
        See :func:`local_ground_height`.
    min_height_m : float
        Keep points at least this high above the local ground, metres.

    Returns
    -------
    above : (N,) bool
    """
    _ground_iv(xyz_m, cell_m, min_height_m)
    return xyz_m[:, 2] - local_ground_height(xyz_m, cell_m) >= min_height_m


def _ground_iv(xyz_m, cell_m, min_height_m) -> None:
    if xyz_m.ndim != 2 or xyz_m.shape[1] != 3:
        raise ConfigError(f"`xyz_m` must have shape (N, 3), got {xyz_m.shape}")
    if not cell_m > 0:
        raise ConfigError(f"ground `cell_m` must be > 0 metres, got {cell_m}")
    if not min_height_m >= 0:
        raise ConfigError(f"ground `min_height_m` must be >= 0, got {min_height_m}")
