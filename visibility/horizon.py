"""Conservative sky culling: which rays of a scan provably hit nothing.

:class:`HorizonBound` bounds, per azimuth bin, the elevation of anything visible from near a
station; :class:`PatternBound` applies it to a fixed beam pattern (one LiDAR revolution) under
any rotation.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage

from visibility.dem import DEM


class HorizonBound:
    """Conservative upper bound on the elevation of anything visible from near a point.

    For every azimuth bin (site frame) it stores the sine of the largest elevation at which
    terrain (or a sphere) can be seen from any origin within ``origin_radius_m`` of
    ``centre_m`` at the same height. A ray steeper than the bound in its bin cannot hit
    anything, so the simulator may skip it without changing the result.

    Parameters
    ----------
    dem : DEM
    centre_m : (3,) float
        Site-frame point (the station's LiDAR centre), metres.
    origin_radius_m : float
        Horizontal radius within which ray origins lie (mounting offset), metres.
    sphere_centres_m : (m, 3) float, optional
    sphere_radius_m : float
    reach_m : float
        Terrain farther than this (horizontally) is ignored (max range).
    n_bins : int
        Azimuth bins.
    """

    def __init__(self, dem: DEM, centre_m: np.ndarray, origin_radius_m: float = 0.0,
                 sphere_centres_m: np.ndarray | None = None, sphere_radius_m: float = 0.1,
                 reach_m: float = np.inf, n_bins: int = 1440) -> None:
        self.n_bins = n_bins
        c = np.asarray(centre_m, dtype=float)
        x, y = dem.grid_xy()
        zmax = ndimage.maximum_filter(dem.heights_m, size=3, mode="nearest")
        gx = np.broadcast_to(x[None, :], dem.shape).ravel() - c[0]
        gy = np.broadcast_to(y[:, None], dem.shape).ravel() - c[1]
        gz = zmax.ravel() - c[2]
        spread = np.full(gx.shape, dem.cell_size_m * np.sqrt(2) + origin_radius_m)
        if sphere_centres_m is not None and len(sphere_centres_m):
            s = np.asarray(sphere_centres_m, dtype=float) - c
            gx = np.concatenate([gx, s[:, 0]])
            gy = np.concatenate([gy, s[:, 1]])
            gz = np.concatenate([gz, s[:, 2] + sphere_radius_m])
            spread = np.concatenate([spread, np.full(len(s), sphere_radius_m + origin_radius_m)])
        rho = np.hypot(gx, gy)
        keep = rho - spread <= reach_m
        gx, gy, gz, rho, spread = gx[keep], gy[keep], gz[keep], rho[keep], spread[keep]
        near = np.maximum(rho - spread, 0.0)
        far = rho + spread
        # largest elevation of a point within `spread` of the vertex with height <= gz
        sin_up = gz / np.hypot(gz, near)
        sin_down = gz / np.hypot(gz, far)
        sin_e = np.where(gz >= 0, np.where(near > 0, sin_up, 1.0), sin_down)
        width = 2 * np.pi / n_bins
        half = np.arcsin(np.clip(spread / np.maximum(rho, 1e-12), 0.0, 1.0))
        half[rho <= spread] = np.pi
        k = np.ceil(half / width).astype(np.int64) + 1  # +1 bin for float32 directions
        group = np.minimum(np.ceil(np.log2(np.maximum(k, 1))).astype(np.int64), 30)
        bins = (np.floor(np.arctan2(gy, gx) / width).astype(np.int64)) % n_bins
        profile = np.full(n_bins, -1.0)
        for g in np.unique(group):
            sel = group == g
            p = np.full(n_bins, -1.0)
            np.maximum.at(p, bins[sel], sin_e[sel])
            size = 2 * (1 << int(g)) + 1
            if size >= n_bins:
                p[:] = p.max()
            else:
                p = ndimage.maximum_filter1d(p, size, mode="wrap")
            profile = np.maximum(profile, p)
        self.sin_elevation = np.minimum(profile + 1e-6, 1.0)
        self._sin_min = float(self.sin_elevation.min())
        self._sin_max = float(self.sin_elevation.max())

    def may_hit(self, directions: np.ndarray) -> np.ndarray:
        """(n,) bool: the unit site-frame ``directions`` (n, 3) are not provably empty."""
        d = np.asarray(directions)
        return self.may_hit_z(d[:, 2], lambda idx: d[idx])

    def may_hit_z(self, dz: np.ndarray, rows: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """Like :meth:`may_hit` but from the z components ``dz`` (n,) alone.

        ``rows(idx)`` must return the full directions (k, 3) of the rays ``idx``; it is only
        called for rays whose elevation lies between the lowest and highest bin bound, so most
        rays never need their azimuth.
        """
        ok = dz <= self._sin_min
        unsure = np.flatnonzero(~ok & (dz <= self._sin_max))
        if len(unsure):
            d = rows(unsure)
            width = 2 * np.pi / self.n_bins
            bins = np.floor(np.arctan2(d[:, 1], d[:, 0]) / width).astype(np.int64) % self.n_bins
            ok[unsure] = d[:, 2] <= self.sin_elevation[bins]
        return ok


class PatternBound:
    """A :class:`HorizonBound` applied to a fixed beam pattern turned by any rotation.

    A LiDAR revolution fires the same directions every frame; only the frame's rotation
    changes. The pattern is kept column by column, so a frame's z components take one
    vector-matrix product (no (n, 3) directions are built), and the full directions of the
    few beams whose elevation lies between the bound's lowest and highest value are gathered
    row by row. The decisions are those of :meth:`HorizonBound.may_hit` on the rotated
    directions.

    Parameters
    ----------
    bound : HorizonBound
    pattern : (n, 3) float
        Unit beam directions of the pattern (sensor frame).

    Examples
    --------
    >>> from visibility.dem import DEM
    >>> bound = HorizonBound(DEM(np.zeros((5, 5)), (-2.0, -2.0), 1.0), [0.0, 0.0, 1.0])
    >>> beams = PatternBound(bound, np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]))
    >>> beams.may_hit(np.eye(3)).tolist(), beams.may_hit(-np.eye(3)).tolist()
    ([False, True], [True, False])
    """

    def __init__(self, bound: HorizonBound, pattern: np.ndarray) -> None:
        self.bound = bound
        self.pattern = np.ascontiguousarray(pattern, dtype=float)
        self._columns = np.ascontiguousarray(self.pattern.T)

    def may_hit(self, rotation: np.ndarray) -> np.ndarray:
        """(n,) bool: the beams ``rotation @ pattern[k]`` that are not provably empty.

        Parameters
        ----------
        rotation : (3, 3) float
            Pattern (sensor) frame to the bound's (site) frame.
        """
        pattern = self.pattern
        return self.bound.may_hit_z(rotation[2] @ self._columns,
                                    lambda rows: np.take(pattern, rows, axis=0) @ rotation.T)
