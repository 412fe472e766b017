"""The station x candidate-site visibility matrix (sparse), ray-cast through the terrain.

For every station-site pair within range it gives the distance, elevation angle and bearing of
the marker centre from the LiDAR centre, the **visible fraction** of the marker sphere and the
**expected number of points** the rig's angular sampling puts on it. Site frame, metres,
radians; bearings counter-clockwise from +x, elevation positive upwards.

Visible fraction
----------------
A bundle of ``rays_per_marker`` rays goes from the LiDAR centre to sample points on the marker's
sensor-facing hemisphere. The sample points are a sunflower (Vogel) pattern, uniform over the
sphere's projected disc as the sensor sees it, lifted onto the front surface — so each ray
stands for an equal share of the returns the LiDAR would get. They are cast through a
terrain-only scene; a sample point counts as visible when the first terrain hit is not nearer
than the point itself (less ``HIT_TOLERANCE_M``). Parts of the sphere buried in the ground are
behind the terrain surface, so they count as occluded automatically.

Expected points
---------------
The tilted VLP-16 on a turntable draws, per frame, each laser's cone around the horizontal
spin axis; near the horizon every laser crosses the horizontal on both sides of the rig, so a
full turn of ``frames_per_turn`` frames lays ``2 * n_lasers * frames_per_turn`` lines over
``2 pi`` of azimuth, each sampled every ``azimuth_step_rad`` along the spin. The density of
returns per steradian at elevation ``e`` is therefore
``L / (azimuth_step_rad * cos e)`` with ``L = 2 n_lasers frames_per_turn / (2 pi)``, and
``expected_points = visible_fraction * solid_angle * density`` with the marker's solid angle
``2 pi (1 - sqrt(1 - r^2 / d^2))``.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from markerplan.constants import GOLDEN_ANGLE_RAD
from markerplan.errors import ConfigError

#: A terrain hit this much before a sample point still counts the point as visible, m.
HIT_TOLERANCE_M = 0.01


@dataclass(frozen=True)
class AngularSampling:
    """The rig's angular sampling (VLP-16 tilted 90 deg on a turntable), for point counts.

    Attributes
    ----------
    azimuth_step_rad : float
        Spin-azimuth step between firings (0.2 deg at 10 Hz), rad.
    frames_per_turn : int
        Frames (LiDAR revolutions) in one full turntable turn.
    n_lasers : int
    """

    azimuth_step_rad: float = float(np.radians(0.2))
    frames_per_turn: int = 800
    n_lasers: int = 16

    def density_per_sr(self, elevation_rad) -> np.ndarray:
        """Returns per steradian at the given elevations (see module docstring)."""
        lines_per_rad = 2.0 * self.n_lasers * self.frames_per_turn / (2.0 * np.pi)
        cos_e = np.maximum(np.cos(np.asarray(elevation_rad, float)), 0.05)
        return lines_per_rad / (self.azimuth_step_rad * cos_e)


@dataclass(frozen=True)
class VisibilityMatrix:
    """Sparse station x site pairs (site frame).

    Attributes
    ----------
    station, site : (p,) int
        Station and site index of each pair.
    distance_m : (p,) float
        LiDAR centre to marker centre, m.
    elevation_rad : (p,) float
        Elevation of the marker centre seen from the LiDAR centre, rad (positive up).
    bearing_rad : (p,) float
        Bearing of the marker from the station, counter-clockwise from +x, rad in (-pi, pi].
    visible_fraction : (p,) float
        Unoccluded fraction of the sensor-facing hemisphere, 0..1.
    expected_points : (p,) float
        Expected returns on the marker from one full station scan.
    n_rays : int
        Rays cast.
    elapsed_s : float
        Wall-clock time of the ray casting, s.
    """

    station: np.ndarray
    site: np.ndarray
    distance_m: np.ndarray
    elevation_rad: np.ndarray
    bearing_rad: np.ndarray
    visible_fraction: np.ndarray
    expected_points: np.ndarray
    n_rays: int = 0
    elapsed_s: float = 0.0

    def __len__(self) -> int:
        return int(self.station.shape[0])

    @property
    def rays_per_s(self) -> float:
        return self.n_rays / self.elapsed_s if self.elapsed_s > 0 else float("nan")


def disc_pattern(n: int) -> np.ndarray:
    """(n, 2) sunflower points uniform over the unit disc (equal-area cells).

    Examples
    --------
    >>> p = disc_pattern(24)
    >>> p.shape, bool(np.all(np.hypot(p[:, 0], p[:, 1]) < 1))
    ((24, 2), True)
    """
    k = np.arange(n) + 0.5
    r = np.sqrt(k / n)
    a = k * GOLDEN_ANGLE_RAD
    return np.column_stack([r * np.cos(a), r * np.sin(a)])


def _pairs_in_range(station_xyz, site_xyz, max_range_m):
    tree = cKDTree(site_xyz)
    lists = tree.query_ball_point(station_xyz, r=max_range_m)
    st = np.concatenate([np.full(len(li), s, dtype=np.int64) for s, li in enumerate(lists)])
    si = np.concatenate([np.sort(np.asarray(li, dtype=np.int64)) for li in lists])
    return st, si


def _vm_iv(station_xyz, site_xyz, marker_radius_m, max_range_m, rays_per_marker):
    st = np.asarray(station_xyz, dtype=float)
    si = np.asarray(site_xyz, dtype=float)
    if st.ndim != 2 or st.shape[1] != 3:
        raise ConfigError(f"`station_position_m` must have shape (s, 3), got {st.shape}")
    if si.ndim != 2 or si.shape[1] != 3:
        raise ConfigError(f"`site_centre_m` must have shape (n, 3), got {si.shape}")
    if not np.all(np.isfinite(st)) or not np.all(np.isfinite(si)):
        raise ConfigError("station and site coordinates must be finite")
    if not marker_radius_m > 0 or not max_range_m > 0:
        raise ConfigError(f"`marker_radius_m` and `max_range_m` must be > 0, got "
                          f"{marker_radius_m!r}, {max_range_m!r}")
    if not isinstance(rays_per_marker, (int, np.integer)) or rays_per_marker < 1:
        raise ConfigError(f"`rays_per_marker` must be an integer >= 1, got {rays_per_marker!r}")
    return st, si


def visibility_matrix(scene, station_position_m, site_centre_m, marker_radius_m: float = 0.10,
                      max_range_m: float = 30.0, rays_per_marker: int = 24,
                      sampling: AngularSampling | None = None, batch_rays: int = 1 << 20,
                      progress: bool = True) -> VisibilityMatrix:
    """Visibility of every candidate site from every station within range.

    Parameters
    ----------
    scene : visibility.scene.RayScene
        Terrain-only scene (no marker spheres), site frame.
    station_position_m : (s, 3) float
        LiDAR centres, site frame, m.
    site_centre_m : (n, 3) float
        Marker centres at the candidate sites, site frame, m.
    marker_radius_m : float
        Marker radius, m.
    max_range_m : float
        Pairs farther apart (3D) are left out, m.
    rays_per_marker : int
        Rays in each marker's bundle.
    sampling : AngularSampling, optional
        The rig's angular sampling, for ``expected_points``.
    batch_rays : int
        Rays per ``scene.intersect`` call (many pairs per call keep all cores busy).
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    vis : VisibilityMatrix
        Pairs ordered by station, then site; a pair whose marker would contain the LiDAR centre
        is dropped.
    """
    st, si = _vm_iv(station_position_m, site_centre_m, marker_radius_m, max_range_m,
                    rays_per_marker)
    sampling = sampling or AngularSampling()
    from tqdm import tqdm

    ps, pj = _pairs_in_range(st, si, max_range_m) if len(st) and len(si) else (
        np.zeros(0, np.int64), np.zeros(0, np.int64))
    diff = si[pj] - st[ps]
    dist = np.linalg.norm(diff, axis=1)
    keep = dist > 2.0 * marker_radius_m
    ps, pj, diff, dist = ps[keep], pj[keep], diff[keep], dist[keep]
    horiz = np.hypot(diff[:, 0], diff[:, 1])
    elevation = np.arctan2(diff[:, 2], horiz)
    bearing = np.arctan2(diff[:, 1], diff[:, 0])

    disc = disc_pattern(rays_per_marker)
    frac = np.zeros(ps.size)
    per_batch = max(1, batch_rays // rays_per_marker)
    t0 = time.perf_counter()
    n_rays = 0
    with tqdm(total=ps.size, desc="visibility", unit="pair", file=sys.stderr,
              disable=None if progress else True) as bar:
        for a in range(0, ps.size, per_batch):
            b = min(ps.size, a + per_batch)
            frac[a:b] = _visible_fraction(scene, st[ps[a:b]], si[pj[a:b]], marker_radius_m, disc)
            n_rays += (b - a) * rays_per_marker
            bar.update(b - a)
    elapsed = time.perf_counter() - t0
    r2 = (marker_radius_m / dist) ** 2
    solid = 2.0 * np.pi * (1.0 - np.sqrt(1.0 - r2))
    expected = frac * solid * sampling.density_per_sr(elevation)
    return VisibilityMatrix(station=ps, site=pj, distance_m=dist, elevation_rad=elevation,
                            bearing_rad=bearing, visible_fraction=frac,
                            expected_points=expected, n_rays=n_rays, elapsed_s=elapsed)


def _visible_fraction(scene, origin: np.ndarray, centre: np.ndarray, radius: float,
                      disc: np.ndarray) -> np.ndarray:
    """Visible fraction for a batch of pairs: origins (b, 3), centres (b, 3) -> (b,)."""
    view = centre - origin
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    # orthonormal basis (e1, e2) perpendicular to the line of sight
    helper = np.where(np.abs(view[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(view, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(view, e1)
    u, w = disc[:, 0], disc[:, 1]
    depth = np.sqrt(np.clip(1.0 - u**2 - w**2, 0.0, None))
    pts = centre[:, None, :] + radius * (u[None, :, None] * e1[:, None, :]
                                         + w[None, :, None] * e2[:, None, :]
                                         - depth[None, :, None] * view[:, None, :])
    rays = pts - origin[:, None, :]
    length = np.linalg.norm(rays, axis=2)
    dirs = rays / length[..., None]
    k = disc.shape[0]
    orig = np.repeat(origin, k, axis=0)
    hits = scene.intersect(orig, dirs.reshape(-1, 3), float(length.max()) + 1.0)
    hit_d = np.asarray(hits.distance_m, dtype=float).reshape(-1, k)
    visible = ~(hit_d < length - HIT_TOLERANCE_M)  # a miss is inf (or nan): visible
    return visible.mean(axis=1)


@dataclass(frozen=True)
class VisibilityGroup:
    """One group's share of a tiled visibility matrix: everything a worker needs.

    Attributes
    ----------
    tile : visibility.dem.DEM
        The terrain within reach of the group's stations (:func:`tile_rectangle`).
    station_index : (g,) int
        The group's stations, as indices into the whole station list.
    station_position_m : (g, 3) float
        Their LiDAR centres, site frame, m.
    site_index : (k,) int
        The sites within range of some station of the group, indices into the whole site list.
    site_centre_m : (k, 3) float
        Their marker centres, site frame, m.
    marker_radius_m, max_range_m : float
        m.
    rays_per_marker : int
    sampling : AngularSampling
    """

    tile: object
    station_index: np.ndarray
    station_position_m: np.ndarray
    site_index: np.ndarray
    site_centre_m: np.ndarray
    marker_radius_m: float
    max_range_m: float
    rays_per_marker: int
    sampling: AngularSampling


@dataclass(frozen=True)
class GroupVisibility:
    """:func:`group_visibility`'s answer: one group's pairs, whole-list indices.

    Attributes
    ----------
    vis : VisibilityMatrix
        Station and site indices refer to the whole station and site lists.
    scene_s : float
        Time spent building the tile's scene, s.
    n_triangles : int
        Terrain triangles in the tile's scene.
    """

    vis: VisibilityMatrix
    scene_s: float
    n_triangles: int


def tile_rectangle(xy_m: np.ndarray, margin_m: float) -> tuple[float, float, float, float]:
    """The rectangle a group's tile must cover: the points' bounding box plus a margin
    (:meth:`~visibility.dem.DEM.crop` starts the tile on an even row and column, so its
    triangles match the whole mesh's).

    Parameters
    ----------
    xy_m : (p, 2) float
        The group's stations and the sites they see, site frame, m: every ray runs between
        a station and a point on a marker.
    margin_m : float
        Marker radius plus one cell, m.

    Returns
    -------
    xmin, xmax, ymin, ymax : float
        Site frame, m (for :meth:`~visibility.dem.DEM.crop`).
    """
    lo = xy_m.min(axis=0) - margin_m
    hi = xy_m.max(axis=0) + margin_m
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def group_visibility(group: VisibilityGroup) -> GroupVisibility:
    """Ray-cast one group of stations against its sites through its own tile (pure: the
    scene is built here, only when some site is in reach, and dropped on return).

    Parameters
    ----------
    group : VisibilityGroup

    Returns
    -------
    answer : GroupVisibility
    """
    from visibility.scene import RayScene

    if not len(group.site_index):  # nothing in reach: no scene to build
        empty = visibility_matrix(None, group.station_position_m, np.zeros((0, 3)),
                                  group.marker_radius_m, group.max_range_m,
                                  group.rays_per_marker, group.sampling, progress=False)
        return GroupVisibility(vis=empty, scene_s=0.0, n_triangles=0)
    t = time.perf_counter()
    scene = RayScene(group.tile)
    scene_s = time.perf_counter() - t
    vis = visibility_matrix(scene, group.station_position_m, group.site_centre_m,
                            group.marker_radius_m, group.max_range_m, group.rays_per_marker,
                            group.sampling, progress=False)
    vis = replace(vis, station=group.station_index[vis.station], site=group.site_index[vis.site])
    return GroupVisibility(vis=vis, scene_s=scene_s, n_triangles=scene.n_triangles)


def station_groups(station_xy_m: np.ndarray, block_m: float) -> list[np.ndarray]:
    """Stations grouped by square blocks of side ``block_m`` (m), blocks in row-major order.

    Returns
    -------
    groups : list of (g,) int
        Station indices of each non-empty block, ascending.

    Examples
    --------
    >>> [g.tolist() for g in station_groups(np.array([[0.0, 0], [25, 0], [1, 1]]), 20.0)]
    [[0, 2], [1]]
    """
    xy = np.asarray(station_xy_m, dtype=float)
    block = np.floor((xy - xy.min(axis=0)) / block_m).astype(np.int64)
    key = block[:, 1] * (block[:, 0].max() + 1) + block[:, 0]
    order = np.argsort(key, kind="stable")
    cuts = np.flatnonzero(np.diff(key[order])) + 1
    return np.split(order, cuts)


def reach_tiles(dem, groups: list[np.ndarray], station_xy_m: np.ndarray,
                target_xy_m: np.ndarray, reach_m: float, margin_m: float):
    """For each station group, the targets within its reach and the DEM tile its rays cross
    (made lazily, one group at a time).

    Parameters
    ----------
    dem : visibility.dem.DEM
        Terrain, site frame.
    groups : list of (g,) int
        Station indices of each group (:func:`station_groups`).
    station_xy_m : (s, 2) float
        Stations, site frame, m.
    target_xy_m : (n, 2) float
        What the rays go to (marker sites, AOI cells), site frame, m.
    reach_m : float
        Targets within this horizontal distance of some station of a group are its targets, m.
    margin_m : float
        How far beyond the stations and targets a ray may pass, m (:func:`tile_rectangle`).

    Yields
    ------
    group : (g,) int
        The group's stations.
    targets : (k,) int
        Its targets within reach, ascending.
    tile : visibility.dem.DEM
        The terrain around the group's stations that reach a target and those targets (all
        its stations when none does).
    """
    tree = cKDTree(target_xy_m) if len(target_xy_m) else None
    # nearest-neighbour queries up to just past the reach (their bound is strict), no lists
    bound = reach_m * (1.0 + 1e-9) + 1e-12
    for g in groups:
        sxy = station_xy_m[g]
        targets, seeing = np.zeros(0, np.int64), g
        if tree is not None:
            lo, hi = sxy.min(axis=0), sxy.max(axis=0)
            box = tree.query_ball_point(0.5 * (lo + hi), 0.5 * float(np.hypot(*(hi - lo)))
                                        + reach_m)
            box = np.sort(np.asarray(box, np.int64))
            if box.size:
                near = cKDTree(sxy).query(target_xy_m[box], distance_upper_bound=bound)[0]
                targets = box[near <= reach_m]
            if targets.size:
                nearest = cKDTree(target_xy_m[targets]).query(sxy, distance_upper_bound=bound)[0]
                seeing = g[nearest <= reach_m]
        xy = np.vstack([station_xy_m[seeing], target_xy_m[targets]])
        yield g, targets, dem.crop(*tile_rectangle(xy, margin_m))


def tiled_visibility(dem, station_position_m, site_centre_m, marker_radius_m: float = 0.10,
                     max_range_m: float = 30.0, rays_per_marker: int = 24,
                     sampling: AngularSampling | None = None, block_m: float | None = None,
                     map_groups=map, progress: bool = True, desc: str = "visibility"
                     ) -> tuple[VisibilityMatrix, dict]:
    """:func:`visibility_matrix` without a mesh of the whole DEM: stations in square blocks,
    each block cast through a tile of the DEM that reaches as far as its rays
    (:func:`group_visibility`).

    A ray runs from a station to a point on a marker within ``max_range_m``, so the bounding
    box of the group's stations and the sites they see, widened by the marker radius and one
    cell (:func:`tile_rectangle`, on the whole DEM's triangles), holds every triangle a ray
    could hit: at most ``block_m + 2 max_range_m`` across. The tile's mesh is recentred
    on the tile, so Embree's float32 coordinates differ from the whole mesh's by rounding: a
    ray grazing an edge can rarely flip (see ``benchmarks/km_plan.py``).

    Parameters
    ----------
    dem : visibility.dem.DEM
        Terrain, site frame.
    station_position_m, site_centre_m, marker_radius_m, max_range_m, rays_per_marker, sampling
        As :func:`visibility_matrix`.
    block_m : float, optional
        Side of a station block, m (default ``4 * max_range_m``: a dense grid of stations
        then builds 2.25 times the DEM's triangles in all, each tile at most 9 ``max_range_m``
        squared).
    map_groups : callable
        ``map_groups(group_visibility, groups)`` -> iterable of answers in the groups' order;
        default the built-in ``map`` (one group at a time in this process). The groups are
        made lazily, so at most the tiles the map holds at once are in memory.
    progress : bool
        Progress bar (groups) on stderr.
    desc : str
        Its label (what the rays are cast for: each bar of a run has its own).

    Returns
    -------
    vis : VisibilityMatrix
        The same pairs in the same order as :func:`visibility_matrix`; ``elapsed_s`` is the
        ray-casting time summed over groups.
    stats : dict
        ``"groups"``, ``"scene_s"`` (summed scene builds, s) and ``"max_tile_triangles"``.
    """
    st, si = _vm_iv(station_position_m, site_centre_m, marker_radius_m, max_range_m,
                    rays_per_marker)
    sampling = sampling or AngularSampling()
    from tqdm import tqdm

    groups = station_groups(st[:, :2], block_m or 4.0 * max_range_m) if len(st) else []

    def tasks():
        for g, sites, tile in reach_tiles(dem, groups, st[:, :2], si[:, :2], max_range_m,
                                          marker_radius_m + dem.cell_size_m):
            yield VisibilityGroup(tile, g, st[g], sites, si[sites], marker_radius_m,
                                  max_range_m, rays_per_marker, sampling)

    answers = list(tqdm(map_groups(group_visibility, tasks()), total=len(groups),
                        desc=desc, unit="group", file=sys.stderr,
                        disable=None if progress else True))
    parts = [a.vis for a in answers]
    station = np.concatenate([p.station for p in parts] + [np.zeros(0, np.int64)])
    site = np.concatenate([p.site for p in parts] + [np.zeros(0, np.int64)])
    order = np.lexsort((site, station))

    def joined(name):
        return np.concatenate([getattr(p, name) for p in parts] + [np.zeros(0)])[order]

    vis = VisibilityMatrix(station=station[order], site=site[order],
                           distance_m=joined("distance_m"), elevation_rad=joined("elevation_rad"),
                           bearing_rad=joined("bearing_rad"),
                           visible_fraction=joined("visible_fraction"),
                           expected_points=joined("expected_points"),
                           n_rays=sum(p.n_rays for p in parts),
                           elapsed_s=sum(p.elapsed_s for p in parts))
    stats = {"groups": len(groups), "scene_s": sum(a.scene_s for a in answers),
             "max_tile_triangles": max((a.n_triangles for a in answers), default=0)}
    return vis, stats
