"""Which stations cover which AOI cells: the predicted coverage matrix.

A station covers an AOI cell (:class:`~planner.coverage.grid.AoiGrid`) when, from its LiDAR
centre to the cell's ground point,

- the range is at most ``max_range_m``,
- the incidence (between the ray and the cell's ground normal) is at most
  ``max_incidence_deg``,
- the predicted point density of one full scan (:mod:`planner.coverage.density`) is at least
  ``min_density_per_m2``, and
- the line of sight to a point :data:`HAIR_M` above the terrain mesh at the cell centre
  (:func:`mesh_ground_m`) is clear of terrain (Embree,
  :meth:`visibility.scene.RayScene.line_of_sight`) and, on a DEM with nodata, its
  ground track crosses no nodata (:func:`planner.problem.sight.crosses_nodata`: unknown terrain
  could hide the cell).

The rays are cast like the marker visibility
(:func:`visibility.visibility_matrix.tiled_visibility`): stations in square blocks
(:func:`~visibility.visibility_matrix.station_groups`), each block through a terrain-only scene
of the DEM tile within its reach (:func:`~visibility.visibility_matrix.reach_tiles`), so no
step holds a mesh of the whole site, and the blocks are mapped by ``map_groups`` (the built-in
``map`` or a cluster's, :mod:`planner.distributed`).
"""

from __future__ import annotations

import numbers
import sys
import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from markerplan.errors import ConfigError
from planner.coverage.density import ground_density_per_m2
from planner.problem.sight import angular_sampling, crosses_nodata
from visibility.visibility_matrix import AngularSampling, reach_tiles, station_groups

#: The line of sight ends this far above the terrain mesh at the cell centre, m, so that a ray
#: grazing the ground is not stopped by the cell's own surface (Embree's float32 rounding).
HAIR_M = 0.02

#: Most station x cell pairs one coverage matrix (or one station block of it) keeps (about
#: 50 bytes each).
MAX_PAIRS = 20_000_000
#: Station x cell pairs in range handled at once (about 150 bytes each while in hand).
PAIRS_PER_CHUNK = 1_000_000


@dataclass(frozen=True)
class CoverageSettings:
    """What counts as an AOI cell measured (:mod:`planner.coverage.sight`).

    Attributes
    ----------
    cell_m : float
        Side of an AOI cell, m (rounded to whole DEM cells). 1 m: the cell of a construction
        terrain model on a 40 m site, fine enough to show a crater rim, coarse enough that a
        cell holds a hundred points.
    max_range_m : float
        Largest LiDAR centre to ground distance, m. 30 m, the plan's marker range: beyond it a
        VLP-16's returns off dark regolith at grazing angles thin out and the ±3 cm range
        error is no longer the datasheet's.
    max_incidence_deg : float
        Largest angle between the ray and the ground normal, degrees. 85: the LiDAR stands 1 m
        above the ground, so on flat ground a cell at horizontal distance ``d`` is seen at
        ``atan(d / 1 m)``; 85 degrees reaches 11.4 m (80 only 5.7 m, 70 only 2.7 m). The beam's
        3 mrad footprint is then stretched 11 times, to about 0.4 m at 11 m: still inside a
        1 m cell.
    min_density_per_m2 : float
        Smallest predicted point density of one full scan, points per m^2. 100: a point
        every 10 cm, a hundred per 1 m cell, enough to fit the cell's surface to a
        centimetre. On flat ground it binds at 22.7 m (after the incidence limit); on a slope
        facing the station it bounds the range.
    min_stations : int
        Stations that must cover every AOI cell (2: each cell seen from two sides).
    """

    cell_m: float = 1.0
    max_range_m: float = 30.0
    max_incidence_deg: float = 85.0
    min_density_per_m2: float = 100.0
    min_stations: int = 1

    def __post_init__(self) -> None:
        for name, hi in (("cell_m", 1000.0), ("max_range_m", 100.0)):
            v = getattr(self, name)
            if not (_is_number(v) and 0 < v <= hi):
                raise ConfigError(f"`{name}` must be a number in (0, {hi:g}] m, got {v!r}")
        v = self.max_incidence_deg
        if not (_is_number(v) and 0 < v <= 90):
            raise ConfigError(f"`max_incidence_deg` must be in (0, 90] degrees, got {v!r}")
        v = self.min_density_per_m2
        if not (_is_number(v) and 0 <= v < np.inf):
            raise ConfigError(f"`min_density_per_m2` must be a finite number >= 0 points per "
                              f"m^2, got {v!r}")
        v = self.min_stations
        if not (isinstance(v, int | np.integer) and not isinstance(v, bool) and 1 <= v <= 10):
            raise ConfigError(f"`min_stations` must be an integer from 1 to 10, got {v!r}")

    @property
    def max_incidence_rad(self) -> float:
        return float(np.radians(self.max_incidence_deg))


def _is_number(v) -> bool:
    """A real number (numpy's included), not a bool."""
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


@dataclass(frozen=True)
class CoverageMatrix:
    """Sparse station x AOI cell pairs where the station covers the cell.

    Attributes
    ----------
    station : (p,) int
        Station index (into the stations given).
    cell : (p,) int
        AOI cell index (into :attr:`~planner.coverage.grid.AoiGrid.cell_index`).
    distance_m : (p,) float
        LiDAR centre to the cell's ground point, m.
    incidence_rad : (p,) float
        Angle between the ray and the cell's ground normal, rad.
    density_per_m2 : (p,) float
        Predicted points per m^2 of one full scan.
    n_stations, n_cells : int
        Matrix size.
    n_rays : int
        Rays cast: the lines of sight and one vertical ray per cell to find the mesh under it.
    elapsed_s : float
        Ray casting, summed over groups, s.
    """

    station: np.ndarray
    cell: np.ndarray
    distance_m: np.ndarray
    incidence_rad: np.ndarray
    density_per_m2: np.ndarray
    n_stations: int
    n_cells: int
    n_rays: int = 0
    elapsed_s: float = 0.0

    def __len__(self) -> int:
        return int(self.station.size)

    @property
    def rays_per_s(self) -> float:
        return self.n_rays / self.elapsed_s if self.elapsed_s > 0 else float("nan")

    def count(self, chosen=None) -> np.ndarray:
        """(n_cells,) how many of the ``chosen`` stations ((k,) int; default all) cover each
        cell."""
        keep = self._chosen(chosen)
        return np.bincount(self.cell[keep], minlength=self.n_cells)

    def best_density(self, chosen=None) -> np.ndarray:
        """(n_cells,) the largest predicted density of the ``chosen`` stations at each cell,
        points per m^2 (0 where none covers it)."""
        keep = self._chosen(chosen)
        out = np.zeros(self.n_cells)
        np.maximum.at(out, self.cell[keep], self.density_per_m2[keep])
        return out

    def _chosen(self, chosen) -> np.ndarray:
        if chosen is None:
            return np.ones(len(self), bool)
        k = np.asarray(chosen, dtype=np.int64).reshape(-1)
        if k.size and (k.min() < 0 or k.max() >= self.n_stations):
            raise ConfigError(f"`chosen` stations must be indices in 0..{self.n_stations - 1}, "
                              f"got {k.min()}..{k.max()}")
        return np.isin(self.station, k)


@dataclass(frozen=True)
class Geometry:
    """Station x cell pairs within range, with their figures and which limits they pass.

    Attributes
    ----------
    station, cell : (p,) int
    distance_m, incidence_rad, density_per_m2 : (p,) float
    within_incidence, dense : (p,) bool
        Passes the incidence limit; passes the incidence and density limits.
    """

    station: np.ndarray
    cell: np.ndarray
    distance_m: np.ndarray
    incidence_rad: np.ndarray
    density_per_m2: np.ndarray
    within_incidence: np.ndarray
    dense: np.ndarray


def pair_geometry(station_position_m: np.ndarray, ground_m: np.ndarray, normal: np.ndarray,
                  settings: CoverageSettings, sampling: AngularSampling,
                  dense_only: bool = False) -> Geometry:
    """Range, incidence and density of the station x cell pairs within ``max_range_m``.

    Stations are taken in chunks of about :data:`PAIRS_PER_CHUNK` pairs in range, so memory
    holds one chunk's pairs and the pairs kept.

    Parameters
    ----------
    station_position_m : (s, 3) float
        LiDAR centres, site frame, m.
    ground_m : (c, 3) float
        Cells' ground points, m.
    normal : (c, 3) float
        Cells' unit ground normals.
    settings : CoverageSettings
    sampling : AngularSampling
    dense_only : bool
        Keep only the pairs passing the incidence and density limits.

    Returns
    -------
    geometry : Geometry
        Pairs ordered by station, then cell (indices into the arrays given).

    Raises
    ------
    ConfigError
        More than :data:`MAX_PAIRS` pairs kept.
    """
    st = np.asarray(station_position_m, dtype=float).reshape(-1, 3)
    parts = []
    if len(st) and len(ground_m):
        cells = cKDTree(ground_m)
        n = cells.query_ball_point(st, r=settings.max_range_m, return_length=True)
        targets = PAIRS_PER_CHUNK * np.arange(1, n.sum() // PAIRS_PER_CHUNK + 1)
        cut = np.searchsorted(np.cumsum(n), targets)
        kept = 0
        for a, b in zip(np.r_[0, cut], np.r_[cut, len(st)], strict=True):
            if b > a:
                part = _chunk_geometry(st, a, b, cells, ground_m, normal, settings, sampling)
                if dense_only:
                    part = Geometry(*(np.asarray(v)[part.dense] for v in vars(part).values()))
                kept += part.station.size
                if kept > MAX_PAIRS:
                    raise ConfigError(f"more than {MAX_PAIRS} station x AOI cell pairs within "
                                      f"`cover_max_range_m` {settings.max_range_m:g} m; "
                                      "raise `aoi_cell_m`, lower `cover_max_range_m` or give "
                                      "fewer stations")
                parts.append(part)
    if not parts:
        e, z = np.zeros(0, np.int64), np.zeros(0)
        return Geometry(e, e, z, z, z, z.astype(bool), z.astype(bool))
    return Geometry(*(np.concatenate([vars(p)[k] for p in parts]) for k in vars(parts[0])))


def _chunk_geometry(st: np.ndarray, a: int, b: int, cells, ground_m: np.ndarray,
                    normal: np.ndarray, settings: CoverageSettings, sampling) -> Geometry:
    """:func:`pair_geometry` of stations ``a..b-1`` (station indices into ``st``)."""
    pairs = cKDTree(st[a:b]).sparse_distance_matrix(cells, settings.max_range_m,
                                                    output_type="ndarray")
    order = np.lexsort((pairs["j"], pairs["i"]))
    sta, ce = pairs["i"][order].astype(np.int64) + a, pairs["j"][order].astype(np.int64)
    ray = ground_m[ce] - st[sta]
    dist = np.linalg.norm(ray, axis=1)
    ok = dist > 0
    sta, ce, ray, dist = sta[ok], ce[ok], ray[ok], dist[ok]
    cos_i = -np.einsum("ij,ij->i", ray, normal[ce]) / dist
    incidence = np.arccos(np.clip(cos_i, -1.0, 1.0))
    elevation = np.arctan2(ray[:, 2], np.hypot(ray[:, 0], ray[:, 1]))
    density = ground_density_per_m2(dist, elevation, cos_i, sampling)
    within = incidence <= settings.max_incidence_rad
    return Geometry(sta, ce, dist, incidence, density, within,
                    within & (density >= settings.min_density_per_m2))


@dataclass(frozen=True)
class CoverageGroup:
    """One station block's share of the coverage matrix: everything a worker needs.

    Attributes
    ----------
    tile : visibility.dem.DEM
        The terrain within reach of the block's stations.
    station_index : (g,) int
        The block's stations (indices into all stations).
    station_position_m : (g, 3) float
        Their LiDAR centres, m.
    cell_index : (k,) int
        The AOI cells within reach (indices into all AOI cells).
    ground_m : (k, 3) float
        Their ground points, m.
    normal : (k, 3) float
        Their unit ground normals.
    settings : CoverageSettings
    sampling : AngularSampling
    """

    tile: object
    station_index: np.ndarray
    station_position_m: np.ndarray
    cell_index: np.ndarray
    ground_m: np.ndarray
    normal: np.ndarray
    settings: CoverageSettings
    sampling: AngularSampling


def group_coverage(group: CoverageGroup) -> CoverageMatrix:
    """The coverage pairs of one station block, cast through its own tile (pure: the scene
    is built here, only when some pair passes the range, incidence and density limits).

    Returns
    -------
    part : CoverageMatrix
        Whole-list station and cell indices, in no particular order; ``n_stations`` and
        ``n_cells`` 0.
    """
    geo = pair_geometry(group.station_position_m, group.ground_m, group.normal,
                        group.settings, group.sampling, dense_only=True)
    k = np.arange(geo.station.size)
    st, ce = geo.station, geo.cell
    elapsed, n_rays = 0.0, 0
    if k.size:
        from visibility.scene import RayScene

        scene = RayScene(group.tile)
        t0 = time.perf_counter()
        used, at = np.unique(ce, return_inverse=True)
        ground = mesh_ground_m(scene, group.ground_m[used])
        origin = group.station_position_m[st]
        target = ground[at] + [0.0, 0.0, HAIR_M]
        clear = scene.line_of_sight(origin, target)
        elapsed, n_rays = time.perf_counter() - t0, int(k.size + used.size)
        if group.tile.valid is not None:
            clear &= ~crosses_nodata(group.tile, origin[:, :2], target[:, :2])
        k, st, ce = k[clear], st[clear], ce[clear]
    return CoverageMatrix(station=group.station_index[st], cell=group.cell_index[ce],
                          distance_m=geo.distance_m[k], incidence_rad=geo.incidence_rad[k],
                          density_per_m2=geo.density_per_m2[k], n_stations=0, n_cells=0,
                          n_rays=n_rays, elapsed_s=elapsed)


def mesh_ground_m(scene, ground_m: np.ndarray) -> np.ndarray:
    """The points of the scene's terrain mesh under the given ground points (a vertical ray
    each): the mesh's triangles and the DEM's bilinear height differ by centimetres on rough
    ground, enough to bury a sight line's end :data:`HAIR_M` above the bilinear height.

    Parameters
    ----------
    scene : visibility.scene.RayScene
    ground_m : (c, 3) float
        Ground points, site frame, m.

    Returns
    -------
    on_mesh : (c, 3) float
        The same x, y; z on the mesh (the given z where the vertical ray misses it), m.
    """
    top = float(scene.dem.heights_m.max()) + 1.0
    origin = np.column_stack([ground_m[:, :2], np.full(len(ground_m), top)])
    down = np.broadcast_to(np.array([0.0, 0.0, -1.0]), origin.shape)
    hits = scene.intersect(origin, np.ascontiguousarray(down))
    z = np.where(np.isfinite(hits.distance_m), top - hits.distance_m, ground_m[:, 2])
    return np.column_stack([ground_m[:, :2], z])


def coverage_matrix(dem, station_position_m, grid, settings: CoverageSettings | None = None,
                    map_groups=map, progress: bool = False, block_m: float | None = None,
                    sampling: AngularSampling | None = None) -> CoverageMatrix:
    """Which stations cover which AOI cells (see the module docstring).

    Parameters
    ----------
    dem : visibility.dem.DEM
        Terrain, site frame.
    station_position_m : (s, 3) float
        LiDAR centres of the candidate stations, site frame, m.
    grid : planner.coverage.grid.AoiGrid
        The AOI cells (made from ``dem`` with ``settings.cell_m``).
    settings : CoverageSettings, optional
    map_groups : callable
        ``map_groups(group_coverage, groups)`` -> iterable of answers in the groups' order
        (built-in ``map``, or a cluster's, see :func:`planner.problem.sight.sight_problem`).
    progress : bool
        Progress bar (station blocks) on stderr.
    block_m : float, optional
        Side of a station block, m (default ``4 * max_range_m``, as
        :func:`~visibility.visibility_matrix.tiled_visibility`).
    sampling : AngularSampling, optional
        The rig's angular sampling (default :func:`planner.problem.sight.angular_sampling`).

    Returns
    -------
    matrix : CoverageMatrix
        Pairs ordered by station, then cell; the same for any ``map_groups`` and block size
        (up to Embree's float32 rounding of a ray grazing an edge).

    Raises
    ------
    ConfigError
        Stations not a finite (s, 3) array, or too many pairs (:data:`MAX_PAIRS`).
    """
    settings = settings or CoverageSettings()
    sampling = sampling or angular_sampling()
    st = np.asarray(station_position_m, dtype=float)
    if st.ndim != 2 or st.shape[1] != 3 or not np.all(np.isfinite(st)):
        raise ConfigError(f"`station_position_m` must be a finite (s, 3) array, got shape "
                          f"{st.shape}")
    from tqdm import tqdm

    ground = grid.ground_m()
    groups = station_groups(st[:, :2], block_m or 4.0 * settings.max_range_m) if len(st) else []

    def tasks():
        for g, cells, tile in reach_tiles(dem, groups, st[:, :2], grid.centre_xy_m,
                                          settings.max_range_m, dem.cell_size_m):
            yield CoverageGroup(tile, g, st[g], cells, ground[cells], grid.normal[cells],
                                settings, sampling)

    parts = list(tqdm(map_groups(group_coverage, tasks()), total=len(groups),
                      desc="coverage", unit="group", file=sys.stderr,
                      disable=None if progress else True))
    station = np.concatenate([p.station for p in parts] + [np.zeros(0, np.int64)])
    cell = np.concatenate([p.cell for p in parts] + [np.zeros(0, np.int64)])
    order = np.lexsort((cell, station))

    def joined(name):
        return np.concatenate([getattr(p, name) for p in parts] + [np.zeros(0)])[order]

    return CoverageMatrix(station=station[order], cell=cell[order],
                          distance_m=joined("distance_m"), incidence_rad=joined("incidence_rad"),
                          density_per_m2=joined("density_per_m2"), n_stations=len(st),
                          n_cells=len(grid), n_rays=sum(p.n_rays for p in parts),
                          elapsed_s=sum(p.elapsed_s for p in parts))
