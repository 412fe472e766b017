"""Where can the rover stand: the plan's markers as seen from every cell of a grid over the DEM.

For a station standing at each cell centre (LiDAR at the ground plus the plan's LiDAR height),
the same usability rules as the plan decide which of the plan's markers it could use (range,
line of sight by Embree over the terrain, incidence and error-model sigma:
:func:`planner.problem.sight.sight_problem`), and the known-control accuracy of
:mod:`planner.accuracy.known_control` gives its predicted 95 % registration error with those
markers.

The grid is aligned with the DEM: its upper-left corner is the DEM's and a cell is a whole
number of DEM cells, so a GeoTIFF of it lies exactly over the DEM's. Rows run north first (the
GeoTIFF order).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from planner.accuracy import known_control
from planner.accuracy.figure import MAP_DIRECTIONS, ErrorFigure
from planner.problem.sight import sight_problem
from planner.problem.usability import direction_status

#: The default grid has at most about this many cells.
MAX_DEFAULT_CELLS = 40_000


@dataclass(frozen=True)
class StandMap:
    """The stand map of a plan on a grid aligned with its DEM.

    Attributes
    ----------
    usable : (ny, nx) float32
        Number of the plan's markers a station at each cell centre could use; NaN where no
        station can stand (outside the DEM or on nodata).
    error_m : (ny, nx) float32
        Predicted 95 % registration error of that station, m; NaN where it cannot register
        (fewer than the required markers or sectors, pose not determined) or cannot stand.
    transform : tuple of 6 float
        GDAL-order affine ``(a, b, c, d, e, f)``: x = c + a * (col + 0.5) at cell centres,
        y = f + e * (row + 0.5), DEM CRS (site frame) metres.
    cell_m : float
        Cell size, m (a whole number of DEM cells).
    crs : str or None
        The DEM's CRS (WKT).
    elapsed_s : float
        Wall-clock time to compute it, s.
    """

    usable: np.ndarray
    error_m: np.ndarray
    transform: tuple
    cell_m: float
    crs: str | None
    elapsed_s: float


def cells_per_stand_cell(dem, cell_m: float | None = None,
                         max_cells: int = MAX_DEFAULT_CELLS) -> int:
    """How many DEM cells make one stand-map cell (along x and y).

    Parameters
    ----------
    dem : visibility.dem.DEM
    cell_m : float, optional
        Wanted cell size, m (rounded to a whole number of DEM cells, at least one). Default:
        the finest grid with at most ``max_cells`` cells.
    max_cells : int

    Returns
    -------
    k : int

    Examples
    --------
    >>> from visibility.dem import DEM
    >>> dem = DEM(np.zeros((601, 601)), (0.0, 0.0), 0.1)
    >>> cells_per_stand_cell(dem), cells_per_stand_cell(dem, 0.26), cells_per_stand_cell(dem, 0.01)
    (4, 3, 1)
    """
    if cell_m is not None:
        return max(1, round(cell_m / dem.cell_size_m))
    ny, nx = dem.shape
    k = max(1, math.ceil(math.sqrt(ny * nx / max_cells)))
    while math.ceil(ny / k) * math.ceil(nx / k) > max_cells:
        k += 1
    return k


def stand_grid(dem, k: int) -> tuple[np.ndarray, tuple]:
    """Cell centres of the stand-map grid of ``k`` x ``k`` DEM cells per cell.

    Parameters
    ----------
    dem : visibility.dem.DEM
    k : int

    Returns
    -------
    xy : (ny, nx, 2) float
        Cell centres, DEM CRS (site frame) m; row 0 is the northern one.
    transform : tuple of 6 float
        GDAL-order affine of the grid (see :class:`StandMap`).
    """
    transform, rows, cols = aligned_grid(dem, k)
    size, _, left, _, _, top = transform
    x = left + size * (np.arange(cols) + 0.5)
    y = top - size * (np.arange(rows) + 0.5)
    gx, gy = np.meshgrid(x, y)
    return np.stack([gx, gy], axis=-1), transform


def aligned_grid(dem, k: int) -> tuple[tuple, int, int]:
    """The grid of ``k`` x ``k`` DEM cells per cell that covers the DEM, aligned with it: its
    upper-left corner is the DEM's, so a GeoTIFF of it lies exactly over the DEM's.

    Parameters
    ----------
    dem : visibility.dem.DEM
    k : int

    Returns
    -------
    transform : tuple of 6 float
        GDAL-order affine (see :class:`StandMap`), DEM CRS (site frame) m.
    rows, cols : int
        Its size; the last row and column may reach beyond the DEM.

    Examples
    --------
    >>> from visibility.dem import DEM
    >>> aligned_grid(DEM(np.zeros((5, 4)), (0.0, 0.0), 1.0), 2)
    ((2.0, 0.0, -0.5, 0.0, -2.0, 4.5), 3, 2)
    """
    ny, nx = dem.shape
    c = dem.cell_size_m
    left = dem.origin_m[0] - 0.5 * c
    top = dem.origin_m[1] + (ny - 0.5) * c
    size = k * c
    return (size, 0.0, left, 0.0, -size, top), math.ceil(ny / k), math.ceil(nx / k)


def stand_map(outcome, error_model, cell_m: float | None = None, progress: bool = False,
              map_groups=map) -> StandMap:
    """The stand map of a plan: usable markers and predicted error at every grid cell.

    Parameters
    ----------
    outcome : planner.run.PlanOutcome
        The plan (its inputs' DEM, stations' LiDAR height, marker radius; its configuration's
        usability rules, sectors and working radius; its selected markers).
    error_model : ErrorModel
        The error model the plan was made with.
    cell_m : float, optional
        Cell size, m (see :func:`cells_per_stand_cell`).
    progress : bool
        Progress bar of the ray casting on stderr, labelled ``stand map``.
    map_groups : callable
        How the ray casting's station groups (blocks of grid cells, each with its own DEM
        tile) are mapped over, see :func:`planner.problem.sight.sight_problem`.

    Returns
    -------
    stand : StandMap
    """
    t0 = time.perf_counter()
    inp, cfg, prob = outcome.inputs, outcome.config, outcome.problem
    dem = inp.dem
    xy, transform = stand_grid(dem, cells_per_stand_cell(dem, cell_m))
    shape = xy.shape[:2]
    flat = xy.reshape(-1, 2)
    stand = np.flatnonzero(dem.valid_at(flat))
    sxyz = np.column_stack([flat[stand], dem.height_at(flat[stand]) + inp.lidar_height_m])
    sel = np.flatnonzero(outcome.result.selected)
    grid_inputs = replace(inp, station_ids=[f"G{i}" for i in stand], station_xyz=sxyz,
                          station_heading_rad=np.zeros(stand.size))
    problem = sight_problem(grid_inputs, [prob.site_ids[j] for j in sel], prob.site_xyz[sel],
                            cfg, error_model, progress=progress, map_groups=map_groups,
                            desc="stand map").problem
    count, sectors = direction_status(problem, np.ones(sel.size, bool), cfg.n_sectors)
    err = np.full(problem.n_stations, np.nan)
    ruled = (count >= cfg.min_markers) & (sectors >= cfg.min_sectors)
    err[ruled] = _known_control_errors(problem, cfg, ruled)
    err[~np.isfinite(err)] = np.nan
    usable = np.full(flat.shape[0], np.nan, np.float32)
    error = np.full(flat.shape[0], np.nan, np.float32)
    usable[stand] = count
    error[stand] = err
    return StandMap(usable=usable.reshape(shape), error_m=error.reshape(shape),
                    transform=transform, cell_m=float(transform[0]), crs=dem.crs,
                    elapsed_s=time.perf_counter() - t0)


def _known_control_errors(problem, config, stations: np.ndarray) -> np.ndarray:
    """(k,) predicted 95 % error of the ``stations`` ((s,) bool) with all their usable sites as
    known control
    (:func:`planner.accuracy.known_control.errors_from_information` of the summed
    :func:`planner.accuracy.known_control.pair_information`), m; inf where the pose is not
    determined. The quantile figure is integrated over
    :data:`~planner.accuracy.figure.MAP_DIRECTIONS` directions (within 2 % of the plan's)."""
    use = np.flatnonzero(problem.pair_usable)
    use = use[np.argsort(problem.pair_station[use], kind="stable")]
    st = problem.pair_station[use]
    offset = problem.site_xyz[problem.pair_site[use], :2] - problem.station_xyz[st, :2]
    info = known_control.pair_information(np.zeros(2), offset, problem.pair_sigma_m[use])
    j = np.zeros((problem.n_stations, 4, 4))
    if use.size:
        starts = np.flatnonzero(np.r_[True, st[1:] != st[:-1]])
        j[st[starts]] = np.add.reduceat(info, starts, axis=0)
    figure = ErrorFigure(config.error_figure, n_directions=MAP_DIRECTIONS)
    return known_control.errors_from_information(j[stations], config.working_radius_m,
                                                 config.inclinometer_sigma_rad, figure)
