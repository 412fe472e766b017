"""The AOI grid: cells aligned with the DEM, and the ground of the cells inside the AOI.

A cell is ``k`` x ``k`` DEM cells (``k = round(cell_m / DEM cell)``, at least one) on the grid
of :func:`planner.outputs.stand_map.aligned_grid` (its upper-left corner the DEM's), cut to the
window covering the AOI, rows north first (the GeoTIFF order). A cell belongs to the AOI when
its centre lies inside the AOI polygon. Each AOI cell has its centre, the ground height there
(bilinear, :meth:`visibility.dem.DEM.height_at`) and the unit normal of the DEM's mean slope
over the cell (central differences of the DEM averaged over the cell's DEM cells).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np
import shapely

from markerplan.errors import ConfigError, DataError
from planner.outputs.stand_map import aligned_grid

#: Most cells an AOI grid's window may hold (a 2 km x 2 km AOI at 1 m).
MAX_AOI_CELLS = 4_000_000


@dataclass(frozen=True)
class AoiGrid:
    """The AOI's cells on a grid aligned with the DEM (site frame = the DEM's CRS, m).

    Attributes
    ----------
    inside : (ny, nx) bool
        Which cells' centres lie inside the AOI; row 0 is the northern one.
    cell_index : (c,) int
        The AOI cells' flat indices into ``inside`` (row-major, ascending).
    centre_xy_m : (c, 2) float
        Their centres, m.
    ground_z_m : (c,) float
        The ground height at their centres, m.
    normal : (c, 3) float
        Unit upward normals of the ground over each cell.
    transform : tuple of 6 float
        GDAL-order affine ``(a, b, c, d, e, f)``: x = c + a * (col + 0.5) at cell centres,
        y = f + e * (row + 0.5), m.
    crs : str or None
        The DEM's CRS (WKT).
    cell_m : float
        Cell side, m (a whole number of DEM cells).
    """

    inside: np.ndarray
    cell_index: np.ndarray
    centre_xy_m: np.ndarray
    ground_z_m: np.ndarray
    normal: np.ndarray
    transform: tuple
    crs: str | None
    cell_m: float

    @property
    def cell_area_m2(self) -> float:
        """Area of one cell, m^2."""
        return self.cell_m ** 2

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)`` of the grid's window."""
        return self.inside.shape  # type: ignore[return-value]

    def __len__(self) -> int:
        """Number of AOI cells."""
        return int(self.cell_index.size)

    def ground_m(self) -> np.ndarray:
        """(c, 3) the AOI cells' ground points (centre and ground height), m."""
        return np.column_stack([self.centre_xy_m, self.ground_z_m])


def aoi_grid(dem, aoi, cell_m: float) -> AoiGrid:
    """The AOI's cells on a grid of about ``cell_m`` aligned with the DEM.

    Parameters
    ----------
    dem : visibility.dem.DEM
        Terrain, site frame.
    aoi : shapely Polygon or MultiPolygon
        The AOI inside the DEM's extent (:func:`planner.coverage.aoi.read_aoi`), site frame, m.
    cell_m : float
        Wanted cell side, m (rounded to a whole number of DEM cells, at least one).

    Returns
    -------
    grid : AoiGrid

    Raises
    ------
    ConfigError
        ``cell_m`` not a positive number, or a window of more than :data:`MAX_AOI_CELLS`
        cells.
    DataError
        No cell centre inside the AOI, or one off the DEM or on nodata.

    Examples
    --------
    >>> from visibility.dem import DEM
    >>> g = aoi_grid(DEM(np.zeros((11, 11)), (0.0, 0.0), 1.0), shapely.box(2, 2, 5, 4), 2.0)
    >>> g.cell_m, g.shape, len(g), g.centre_xy_m.tolist()
    (2.0, (2, 2), 2, [[2.5, 3.5], [4.5, 3.5]])
    """
    if not (isinstance(cell_m, numbers.Real) and np.isfinite(cell_m) and cell_m > 0):
        raise ConfigError(f"`cell_m` must be a positive number of metres, got {cell_m!r}")
    k = max(1, round(cell_m / dem.cell_size_m))
    (size, _, left, _, _, top), rows, cols = aligned_grid(dem, k)
    x0, y0, x1, y1 = aoi.bounds
    c0, c1 = _span((x0 - left) / size, (x1 - left) / size, cols)
    r0, r1 = _span((top - y1) / size, (top - y0) / size, rows)
    n = (r1 - r0) * (c1 - c0)
    if n > MAX_AOI_CELLS:
        raise ConfigError(f"`aoi_cell_m` {cell_m:g} m gives {n:.3g} cells over the AOI's "
                          f"{x1 - x0:.0f} x {y1 - y0:.0f} m bounding box, more than the "
                          f"{MAX_AOI_CELLS} accepted; raise `aoi_cell_m` or shrink the AOI")
    transform = (size, 0.0, left + c0 * size, 0.0, -size, top - r0 * size)
    x = transform[2] + size * (np.arange(c1 - c0) + 0.5)
    y = transform[5] - size * (np.arange(r1 - r0) + 0.5)
    gx, gy = np.meshgrid(x, y)
    inside = shapely.contains_xy(aoi, gx, gy)
    index = np.flatnonzero(inside)
    if not index.size:
        raise DataError(f"no {size:g} m cell centre lies inside the AOI "
                        f"[{x0:.1f}, {x1:.1f}] x [{y0:.1f}, {y1:.1f}] m; lower `aoi_cell_m` or "
                        "draw a larger AOI")
    xy = np.column_stack([gx.ravel()[index], gy.ravel()[index]])
    bad = np.flatnonzero(~_on_data(dem, xy))
    if bad.size:
        raise DataError(f"{bad.size} AOI cell centres, the first at ({xy[bad[0], 0]:.2f}, "
                        f"{xy[bad[0], 1]:.2f}) m, lie off the DEM or on nodata; draw the AOI "
                        "on the DEM's measured terrain (planner.coverage.aoi.read_aoi checks "
                        "it)")
    normal = _cell_normals(dem, k, r0, r1, c0, c1).reshape(-1, 3)[index]
    return AoiGrid(inside=inside, cell_index=index, centre_xy_m=xy,
                   ground_z_m=dem.height_at(xy), normal=normal, transform=transform,
                   crs=dem.crs, cell_m=float(size))


def _on_data(dem, xy: np.ndarray) -> np.ndarray:
    """(n,) whether each point lies on the DEM's extent and in a valid cell (the cell whose
    centre is nearest)."""
    ok = dem.contains(xy)
    if dem.valid is None:
        return ok
    ny, nx = dem.shape
    i = np.clip(np.rint((xy[:, 0] - dem.origin_m[0]) / dem.cell_size_m).astype(np.int64), 0,
                nx - 1)
    j = np.clip(np.rint((xy[:, 1] - dem.origin_m[1]) / dem.cell_size_m).astype(np.int64), 0,
                ny - 1)
    return ok & dem.valid[j, i]


def _span(lo: float, hi: float, n: int) -> tuple[int, int]:
    """The cells ``[a, b)`` of ``n`` covering the fractional cell range ``lo..hi``."""
    a = min(max(int(np.floor(lo)), 0), n - 1)
    b = max(min(int(np.ceil(hi)), n), a + 1)
    return a, b


def _cell_normals(dem, k: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """(r1 - r0, c1 - c0, 3) unit normals of the window's cells: the DEM's central-difference
    slope (one-sided at the DEM's edge) averaged over each cell's DEM cells."""
    ny, nx = dem.shape
    # grid row r covers DEM rows ny - 1 - (r k .. r k + k - 1) (rows run along +y)
    j_lo, j_hi = max(ny - r1 * k, 0), ny - r0 * k
    i_lo, i_hi = c0 * k, min(c1 * k, nx)
    a, b = max(j_lo - 1, 0), max(i_lo - 1, 0)
    h = dem.heights_m[a:min(j_hi + 1, ny), b:min(i_hi + 1, nx)]
    gy, gx = np.gradient(h, dem.cell_size_m)
    gx = gx[j_lo - a:j_hi - a, i_lo - b:i_hi - b][::-1]  # north first
    gy = gy[j_lo - a:j_hi - a, i_lo - b:i_hi - b][::-1]
    rows, cols = r1 - r0, c1 - c0
    # the window's southern row and eastern column of cells may reach beyond the DEM
    pad = ((0, rows * k - gx.shape[0]), (0, cols * k - gx.shape[1]))

    def mean(g):
        g = np.pad(g, pad, constant_values=np.nan)
        return np.nanmean(g.reshape(rows, k, cols, k), axis=(1, 3))

    n = np.stack([-mean(gx), -mean(gy), np.ones((rows, cols))], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)
