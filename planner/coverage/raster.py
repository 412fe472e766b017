"""The predicted coverage of chosen stations over the AOI grid, its GeoTIFF, and where no
candidate station covers the AOI and why.

- :func:`coverage_raster`: per cell, how many chosen stations cover it and the best (largest)
  predicted point density, (ny, nx) float32, NaN outside the AOI;
- :func:`write_coverage_raster`: ``coverage.tif``, band 1 the count and band 2 the density, in
  the DEM's CRS (:func:`planner.outputs.gis.write_float_geotiff`: made in memory, written into
  the output folder's staging folder, :func:`markerplan.output_folder.output_folder`);
- :func:`uncovered_summary`: the cells the candidate stations leave short of
  ``min_stations``, where they are and which limit stops them.
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
    area_m2 : float
    text : str
        One line: how many cells, their area, where (bounding box and centroid) and why (count
        per reason with the setting that binds); empty when every cell is covered.
    """

    cell: np.ndarray
    reason: np.ndarray
    nearest_m: np.ndarray
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
        return Uncovered(short, short, np.zeros(0), 0.0, "")
    geo = pair_geometry(st, grid.ground_m()[short], grid.normal[short], settings,
                        sampling or angular_sampling())
    passing = np.stack([np.bincount(geo.cell[m], minlength=short.size) for m in
                        (np.ones(len(geo.cell), bool), geo.within_incidence, geo.dense)])
    # the first limit that leaves fewer than `need`; all three passed: the line of sight
    reason = np.argmax(np.vstack([passing < need, np.ones((1, short.size), bool)]), axis=0)
    nearest = _nearest_m(st, grid.centre_xy_m[short])
    xy = grid.centre_xy_m[short]
    area = short.size * grid.cell_area_m2
    x0, y0 = xy.min(axis=0) - 0.5 * grid.cell_m
    x1, y1 = xy.max(axis=0) + 0.5 * grid.cell_m
    cx, cy = xy.mean(axis=0)
    far = nearest[reason == 0]
    limits = (f"at least {far.min() if far.size else np.inf:.1f} m across from every "
              f"candidate station, beyond `cover_max_range_m` {settings.max_range_m:g} m",
              f"`cover_max_incidence_deg` {settings.max_incidence_deg:g}",
              f"`cover_min_density_per_m2` {settings.min_density_per_m2:g}",
              "the terrain, or nodata on the way, hides it from every station in reach")
    why = "; ".join(f"{n} {REASONS[r]} ({limits[r]})"
                    for r, n in enumerate(np.bincount(reason, minlength=len(REASONS))) if n)
    by = "any candidate station" if need == 1 else f"{need} candidate stations"
    text = (f"{short.size} AOI cells ({area:g} m^2) in [{x0:.1f}, {x1:.1f}] x [{y0:.1f}, "
            f"{y1:.1f}] m (centroid ({cx:.1f}, {cy:.1f}) m) cannot be covered by {by}: {why}")
    return Uncovered(cell=short, reason=reason, nearest_m=nearest, area_m2=float(area),
                     text=text)


def _nearest_m(station_position_m: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(u,) horizontal distance from each point to its nearest station, m (inf: none)."""
    if not len(station_position_m):
        return np.full(len(xy), np.inf)
    from scipy.spatial import cKDTree

    return cKDTree(station_position_m[:, :2]).query(xy)[0]
