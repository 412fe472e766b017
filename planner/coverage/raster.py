"""The predicted coverage of chosen stations over the AOI grid, its GeoTIFF, and where no
candidate station covers the AOI and why.

- :func:`coverage_raster`: per cell, how many chosen stations cover it and the best (largest)
  predicted point density, (ny, nx) float32, NaN outside the AOI;
- :func:`write_coverage_raster`: ``coverage.tif``, band 1 the count and band 2 the density, in
  the DEM's CRS (:func:`planner.outputs.gis.write_float_geotiff`: made in memory, written into
  the output folder's staging folder, :func:`markerplan.output_folder.output_folder`);
- :func:`uncovered_summary`: the cells the candidate stations leave short of
  ``min_stations``, in connected patches: where they are and which limit stops them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from planner.coverage.sight import pair_geometry
from planner.outputs.gis import write_float_geotiff
from planner.problem.sight import angular_sampling

#: The coverage raster's file name in an output folder.
COVERAGE_FILE = "coverage.tif"
#: Its bands' descriptions.
COVERAGE_BANDS = ("stations covering the cell", "best predicted point density (points/m^2)")


@dataclass(frozen=True)
class CoverageRaster:
    """The predicted coverage of chosen stations on the AOI grid.

    Attributes
    ----------
    count : (ny, nx) float32
        Chosen stations covering each cell; NaN outside the AOI.
    density_per_m2 : (ny, nx) float32
        The largest predicted point density of those stations, points per m^2 (0 where none
        covers the cell); NaN outside the AOI.
    transform : tuple of 6 float
        GDAL-order affine of the grid, m.
    crs : str or None
        The DEM's CRS (WKT).
    """

    count: np.ndarray
    density_per_m2: np.ndarray
    transform: tuple
    crs: str | None


def coverage_raster(matrix, grid, chosen=None) -> CoverageRaster:
    """Per-cell count and best density of the chosen stations.

    Parameters
    ----------
    matrix : planner.coverage.sight.CoverageMatrix
    grid : planner.coverage.grid.AoiGrid
        The grid the matrix was computed on.
    chosen : (k,) int, optional
        Indices of the chosen stations into the matrix's stations (default all).

    Returns
    -------
    raster : CoverageRaster
    """
    count = np.full(grid.shape, np.nan, np.float32)
    density = np.full(grid.shape, np.nan, np.float32)
    count.flat[grid.cell_index] = matrix.count(chosen)
    density.flat[grid.cell_index] = matrix.best_density(chosen)
    return CoverageRaster(count=count, density_per_m2=density, transform=grid.transform,
                          crs=grid.crs)


def write_coverage_raster(raster: CoverageRaster, folder: Path) -> Path:
    """Write ``folder/coverage.tif``: a 2-band float32 GeoTIFF (count, density; nodata NaN;
    the DEM's CRS).

    Parameters
    ----------
    raster : CoverageRaster
    folder : Path
        The output folder's staging folder.

    Returns
    -------
    path : Path
    """
    return write_float_geotiff(Path(folder) / COVERAGE_FILE,
                               [raster.count, raster.density_per_m2], COVERAGE_BANDS,
                               raster.transform, raster.crs)


#: Why a cell is short of coverage, in the order the limits are tested.
REASONS = ("out of range", "beyond the incidence limit", "below the density limit",
           "occluded")


#: The uncovered summary's text names this many patches, largest first, and sums the rest.
MAX_NAMED_PATCHES = 3


@dataclass(frozen=True)
class UncoveredPatch:
    """One connected patch of uncovered cells (8-connected on the AOI grid).

    Attributes
    ----------
    n_cells : int
    area_m2 : float
    bounds_m : tuple of 4 float
        ``(x0, y0, x1, y1)``: the edges of its cells' bounding box, m.
    reason_count : (len(REASONS),) int
        How many of its cells each limit stops (index into :data:`REASONS`).
    """

    n_cells: int
    area_m2: float
    bounds_m: tuple
    reason_count: np.ndarray


@dataclass(frozen=True)
class Uncovered:
    """The AOI cells the candidate stations cover fewer than ``min_stations`` times.

    Attributes
    ----------
    cell : (u,) int
        Their indices into the AOI cells.
    reason : (u,) int
        Why each is short: the first limit (index into :data:`REASONS`) that leaves it fewer
        than ``min_stations`` stations.
    nearest_m : (u,) float
        Horizontal distance to its nearest candidate station, m.
    patch : (u,) int
        The connected patch (8-neighbours on the AOI grid) each belongs to, an index into
        ``patches``: 0 the largest (ties: the first in row order, north first).
    patches : tuple of UncoveredPatch, (p,)
        The patches, largest first.
    area_m2 : float
    text : str
        One line: how many cells and their area, then where (bounding box and centroid) and
        why (count per reason with the setting that binds); with several patches, where and
        why per patch for the :data:`MAX_NAMED_PATCHES` largest, the number and area of the
        rest, and the count per reason over all. Empty when every cell is covered.
    """

    cell: np.ndarray
    reason: np.ndarray
    nearest_m: np.ndarray
    patch: np.ndarray
    patches: tuple
    area_m2: float
    text: str

    def __len__(self) -> int:
        return int(self.cell.size)


def uncovered_summary(matrix, grid, station_position_m, settings, sampling=None) -> Uncovered:
    """Where the candidate stations leave the AOI short of ``min_stations`` and why.

    Parameters
    ----------
    matrix : planner.coverage.sight.CoverageMatrix
        Coverage of the candidate stations.
    grid : planner.coverage.grid.AoiGrid
    station_position_m : (s, 3) float
        The candidate stations' LiDAR centres (those of ``matrix``), m.
    settings : planner.coverage.sight.CoverageSettings
    sampling : AngularSampling, optional
        As the matrix was computed with.

    Returns
    -------
    uncovered : Uncovered
    """
    need = settings.min_stations
    short = np.flatnonzero(matrix.count() < need)
    st = np.asarray(station_position_m, float).reshape(-1, 3)
    if not short.size:
        return Uncovered(cell=short, reason=short, nearest_m=np.zeros(0), patch=short,
                         patches=(), area_m2=0.0, text="")
    geo = pair_geometry(st, grid.ground_m()[short], grid.normal[short], settings,
                        sampling or angular_sampling())
    passing = np.stack([np.bincount(geo.cell[m], minlength=short.size) for m in
                        (np.ones(len(geo.cell), bool), geo.within_incidence, geo.dense)])
    # the first limit that leaves fewer than `need`; all three passed: the line of sight
    reason = np.argmax(np.vstack([passing < need, np.ones((1, short.size), bool)]), axis=0)
    nearest = _nearest_m(st, grid.centre_xy_m[short])
    xy = grid.centre_xy_m[short]
    patch = _patch_labels(grid, short)
    patches = _patches(patch, reason, xy, grid.cell_m)
    area = short.size * grid.cell_area_m2
    far = nearest[reason == 0]
    limits = (f"at least {far.min() if far.size else np.inf:.1f} m across from every "
              f"candidate station, beyond `cover_max_range_m` {settings.max_range_m:g} m",
              f"`cover_max_incidence_deg` {settings.max_incidence_deg:g}",
              f"`cover_min_density_per_m2` {settings.min_density_per_m2:g}",
              "the terrain, or nodata on the way, hides it from every station in reach")
    why = "; ".join(f"{n} {REASONS[r]} ({limits[r]})"
                    for r, n in enumerate(np.bincount(reason, minlength=len(REASONS))) if n)
    by = "any candidate station" if need == 1 else f"{need} candidate stations"
    head = f"{short.size} AOI cells ({area:g} m^2)"
    if len(patches) == 1:
        cx, cy = xy.mean(axis=0)
        text = (f"{head} {_where(patches[0])} (centroid ({cx:.1f}, {cy:.1f}) m) cannot be "
                f"covered by {by}: {why}")
    else:
        named = "; ".join(
            f"patch {k + 1}: {p.n_cells} cells ({p.area_m2:g} m^2) {_where(p)}, "
            + ", ".join(f"{n} {REASONS[r]}" for r, n in enumerate(p.reason_count) if n)
            for k, p in enumerate(patches[:MAX_NAMED_PATCHES]))
        rest = patches[MAX_NAMED_PATCHES:]
        more = (f"; and {len(rest)} more patch{'es' if len(rest) > 1 else ''} "
                f"({sum(p.area_m2 for p in rest):g} m^2)" if rest else "")
        text = (f"{head} in {len(patches)} separate patches cannot be covered by {by}: "
                f"{named}{more}; over all patches: {why}")
    return Uncovered(cell=short, reason=reason, nearest_m=nearest, patch=patch,
                     patches=patches, area_m2=float(area), text=text)


def _patch_labels(grid, short: np.ndarray) -> np.ndarray:
    """(u,) the 8-connected patch of each of the AOI cells ``short`` on the grid's (ny, nx)
    layout, numbered from 0 by size, largest first (ties: the first in row order)."""
    from scipy import ndimage

    flat = grid.cell_index[short]
    mask = np.zeros(grid.shape, bool)
    mask.flat[flat] = True
    labels, n = ndimage.label(mask, structure=np.ones((3, 3), bool))
    label = labels.flat[flat] - 1
    rank = np.empty(n, int)
    rank[np.argsort(-np.bincount(label, minlength=n), kind="stable")] = np.arange(n)
    return rank[label]


def _patches(patch: np.ndarray, reason: np.ndarray, xy: np.ndarray,
             cell_m: float) -> tuple[UncoveredPatch, ...]:
    """The patches of cells labelled ``patch`` (0..p-1) with centres ``xy`` (u, 2) m."""
    n = int(patch.max()) + 1
    lo = np.full((n, 2), np.inf)
    hi = np.full((n, 2), -np.inf)
    np.minimum.at(lo, patch, xy)
    np.maximum.at(hi, patch, xy)
    lo -= 0.5 * cell_m
    hi += 0.5 * cell_m
    size = np.bincount(patch, minlength=n)
    counts = np.bincount(patch * len(REASONS) + reason,
                         minlength=n * len(REASONS)).reshape(n, len(REASONS))
    return tuple(UncoveredPatch(n_cells=int(size[k]), area_m2=float(size[k] * cell_m ** 2),
                                bounds_m=(*map(float, lo[k]), *map(float, hi[k])),
                                reason_count=counts[k])
                 for k in range(n))


def _where(p: UncoveredPatch) -> str:
    """``in [x0, x1] x [y0, y1] m``: a patch's bounding box."""
    x0, y0, x1, y1 = p.bounds_m
    return f"in [{x0:.1f}, {x1:.1f}] x [{y0:.1f}, {y1:.1f}] m"


def _nearest_m(station_position_m: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(u,) horizontal distance from each point to its nearest station, m (inf: none)."""
    if not len(station_position_m):
        return np.full(len(xy), np.inf)
    from scipy.spatial import cKDTree

    return cKDTree(station_position_m[:, :2]).query(xy)[0]
