"""Site presets: synthetic lunar terrain plus rover stations and an as-built marker layout.

``default``
    A 40 m x 40 m crater test field modelled on the published field experiment (11 markers of
    0.20 m diameter, 7 stations, every station seeing markers in three or more directions).
    DEM: 60 m x 60 m (10 m of terrain beyond the working area on every side) at 0.1 m cells
    (601 x 601 cells, 720 k triangles: Embree scene built in ~2 s; rocks from 0.15 m). Five
    craters 3-8 m across placed between the stations (one fresh, the others degraded), random
    craters 0.5-2.5 m from a power-law SFD, three boulders of 0.6-0.8 m, random rocks
    0.15-0.5 m (Golombek & Rapp, k = 1 %), 2 cm RMS micro-relief at 1 m (H = 0.85) and a 1.5 deg
    regional slope. Stations: the centre and a hexagon of radius 12 m. Markers: an inner
    hexagon of radius 6 m (between the stations) and an outer pentagon of radius 18 m.
``large``
    About 300 m x 300 m for scale: DEM 340 m x 340 m at 0.5 m cells, craters 2-30 m, boulders
    0.5-2 m, 100 stations on a jittered 30 m grid, 121 markers on the offset 30 m grid.
``km``
    A kilometre-scale crater field: DEM 1 km x 1 km at 0.25 m cells (4001 x 4001 cells,
    32 M triangles: too big for one ray scene, so plans tile it, :mod:`planner.problem.sight`).
    Random craters 1-40 m from the equilibrium SFD (``b = 2``) at 5 % of the mare density, rocks
    0.3-1.5 m (Golombek & Rapp, k = 1 %). About 300 stations every 20 m along a serpentine
    rover traverse (six 900 m east-west legs 160 m apart, jittered 2 m), markers every 60 m
    along the legs, 10 m to the side.

The layouts are fixed; only the terrain randomness depends on ``seed`` (default 0), and random
craters and rocks keep out of stations and markers.

Orbital planning DEM
--------------------
Beside its fine truth terrain (what ``verify`` simulates), ``default`` and ``large`` have an
orbital-grade planning DEM, :func:`planning_dem` (``kind="orbital"``,
:func:`visibility.orbital.orbital_dem`): the truth block-averaged onto the 2 m posts of an LROC
NAC stereo DTM (the finest orbital product of the Moon; a LOLA site product is 5 m) plus a
Gaussian height error of 0.3 m RMS correlated over 10 m (:data:`ORBITAL_GRADES`). 0.3 m is the
low end of LOLA's 0.3-0.5 m median error and about NAC DTMs' expected vertical precision; 10 m
is five NAC posts, the scale of the stereo matching window. Rocks (0.15-2 m) and the small
craters vanish into the 2 m means. The error field's seed is the site's seed, so
``--site-seed`` gives another terrain and another orbital product of it.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field, replace

import numpy as np

from markerplan.errors import ConfigError
from visibility.dem import DEM
from visibility.orbital import HeightError, orbital_dem
from visibility.terrain import Crater, CraterSpec, RockSpec, TerrainSpec, generate_terrain

MARKER_RADIUS_M = 0.10
LIDAR_HEIGHT_M = 1.0


@dataclass
class Site:
    """A survey site, site frame (W), metres.

    Attributes
    ----------
    name : str
    dem : DEM
        Terrain with rocks baked in.
    station_ids : list of str
    station_xy_m : (s, 2) float
        Rover station positions.
    station_heading_rad : (s,) float
        Station headings (rotation of the station frame about z), radians.
    marker_ids : list of str
    marker_centres_m : (m, 3) float
        As-built marker centres (ground + radius).
    marker_radius_m : float
    craters : list of Crater
    rock_centres_m : (k, 3) float
    rock_radii_m : (k,) float
    boundary_xy_m : (p, 2) float
        Working-area polygon (where markers may go).
    seed : int
    lidar_height_m : float
        Nominal LiDAR centre height above the ground at a station.
    """

    name: str
    dem: DEM
    station_ids: list[str]
    station_xy_m: np.ndarray
    station_heading_rad: np.ndarray
    marker_ids: list[str]
    marker_centres_m: np.ndarray
    marker_radius_m: float = MARKER_RADIUS_M
    craters: list[Crater] = field(default_factory=list)
    rock_centres_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    rock_radii_m: np.ndarray = field(default_factory=lambda: np.zeros(0))
    boundary_xy_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    seed: int = 0
    lidar_height_m: float = LIDAR_HEIGHT_M

    @property
    def station_position_m(self) -> np.ndarray:
        """(s, 3) station-frame origins (LiDAR centres) in the site frame: ground + height."""
        z = self.dem.height_at(self.station_xy_m) + self.lidar_height_m
        return np.column_stack([self.station_xy_m, z])

    @property
    def rocks(self) -> list[dict]:
        """Rocks as ``{"centre_m": [x, y, z], "radius_m": r}`` dicts."""
        return [{"centre_m": c.tolist(), "radius_m": float(r)}
                for c, r in zip(self.rock_centres_m, self.rock_radii_m, strict=True)]


def _default_layout() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    hexa = np.radians(np.arange(0, 360, 60))
    stations = np.vstack([[0.0, 0.0], 12.0 * np.column_stack([np.cos(hexa), np.sin(hexa)])])
    headings = np.radians([0.0, 90.0, 150.0, 210.0, 270.0, 330.0, 30.0])
    inner = hexa + np.radians(30)
    outer = np.radians(np.arange(0, 360, 72))
    markers = np.vstack([6.0 * np.column_stack([np.cos(inner), np.sin(inner)]),
                         18.0 * np.column_stack([np.cos(outer), np.sin(outer)])])
    return stations, headings, markers


def _default_site(seed: int) -> Site:
    stations, headings, markers_xy = _default_layout()
    keep = _keepout(stations, 1.5, markers_xy, 1.0)
    spec = TerrainSpec(
        extent_m=(-30.0, 30.0, -30.0, 30.0), cell_size_m=0.1,
        hurst=0.85, roughness_1m_m=0.02, rolloff_m=10.0,
        slope_deg=1.5, slope_azimuth_deg=30.0,
        crater_density=0.004, crater_sfd_exponent=2.0, crater_diameter_range_m=(0.5, 2.5),
        fresh_fraction=0.2,
        rock_abundance=0.01, rock_diameter_range_m=(0.15, 0.5),
        craters=(CraterSpec((13.75, 10.0), 8.0, 0.0),
                 CraterSpec((-5.25, 16.2), 6.0, 0.01),
                 CraterSpec((-17.0, 0.0), 5.0, 0.02),
                 CraterSpec((-5.25, -16.2), 4.0, 0.005),
                 CraterSpec((13.75, -10.0), 3.0, 0.01)),
        rocks=(RockSpec((8.5, 5.0), 0.8, 0.3), RockSpec((-9.0, -5.0), 0.6, 0.3),
               RockSpec((2.0, -13.0), 0.7, 0.3)),
        keepout_xyr_m=keep,
    )
    return _assemble("default", spec, seed, stations, headings, markers_xy,
                     boundary=_square(20.0))


def _large_site(seed: int) -> Site:
    g = np.arange(-135.0, 136.0, 30.0)
    sx, sy = np.meshgrid(g, g)
    jitter = np.random.default_rng([seed, 1]).uniform(-3.0, 3.0, (sx.size, 2))
    stations = np.column_stack([sx.ravel(), sy.ravel()]) + jitter
    headings = np.random.default_rng([seed, 2]).uniform(0, 2 * np.pi, len(stations))
    m = np.arange(-150.0, 151.0, 30.0)
    mx, my = np.meshgrid(m, m)
    markers_xy = np.column_stack([mx.ravel(), my.ravel()])
    keep = _keepout(stations, 3.0, markers_xy, 2.0)
    spec = TerrainSpec(
        extent_m=(-170.0, 170.0, -170.0, 170.0), cell_size_m=0.5,
        hurst=0.85, roughness_1m_m=0.02, rolloff_m=30.0,
        slope_deg=1.0, slope_azimuth_deg=120.0,
        crater_density=0.003, crater_sfd_exponent=2.0, crater_diameter_range_m=(2.0, 30.0),
        fresh_fraction=0.2,
        rock_abundance=0.02, rock_diameter_range_m=(0.5, 2.0),
        keepout_xyr_m=keep,
    )
    return _assemble("large", spec, seed, stations, headings, markers_xy,
                     boundary=_square(150.0))


#: Serpentine traverse of the ``km`` preset: leg ends (x, m), leg rows (y, m), station step (m).
KM_LEG_X_M = (-450.0, 450.0)
KM_LEG_Y_M = tuple(-400.0 + 160.0 * k for k in range(6))
KM_STATION_STEP_M = 20.0


def km_traverse() -> np.ndarray:
    """(p, 2) vertices of the ``km`` preset's serpentine traverse, site frame, m."""
    x0, x1 = KM_LEG_X_M
    ends = [((x0, y), (x1, y)) if k % 2 == 0 else ((x1, y), (x0, y))
            for k, y in enumerate(KM_LEG_Y_M)]
    return np.array([p for leg in ends for p in leg])


def points_along(path: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Points every ``step_m`` along a polyline (its start included) and the path's heading
    there: ((p, 2) m, (p,) rad)."""
    seg = np.diff(path, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    start = np.r_[0.0, np.cumsum(length)]
    s = np.arange(0.0, start[-1] + 1e-9, step_m)
    k = np.clip(np.searchsorted(start, s, side="right") - 1, 0, len(seg) - 1)
    xy = path[k] + ((s - start[k]) / length[k])[:, None] * seg[k]
    return xy, np.arctan2(seg[k, 1], seg[k, 0])


def _km_site(seed: int) -> Site:
    path = km_traverse()
    stations, headings = points_along(path, KM_STATION_STEP_M)
    stations = stations + np.random.default_rng([seed, 1]).uniform(-2.0, 2.0, stations.shape)
    x0, x1 = KM_LEG_X_M
    mx = np.arange(x0, x1 + 1e-9, 60.0)
    markers_xy = np.vstack([np.column_stack([mx, np.full(mx.size, y + 10.0)])
                            for y in KM_LEG_Y_M])
    keep = _keepout(stations, 3.0, markers_xy, 2.0)
    spec = TerrainSpec(
        extent_m=(-500.0, 500.0, -500.0, 500.0), cell_size_m=0.25,
        hurst=0.85, roughness_1m_m=0.02, rolloff_m=30.0,
        slope_deg=1.0, slope_azimuth_deg=60.0,
        crater_density=0.004, crater_sfd_exponent=2.0, crater_diameter_range_m=(1.0, 40.0),
        fresh_fraction=0.2,
        rock_abundance=0.01, rock_diameter_range_m=(0.3, 1.5),
        keepout_xyr_m=keep,
    )
    return _assemble("km", spec, seed, stations, headings, markers_xy,
                     boundary=_square(480.0))


def _keepout(stations: np.ndarray, station_radius_m: float, markers_xy: np.ndarray,
             marker_radius_m: float) -> tuple:
    """Keep-out discs ``(x, y, r)`` (m) around the stations and the marker layout: no crater or
    rock is placed there (:attr:`visibility.terrain.TerrainSpec.keepout_xyr_m`)."""
    return tuple((float(x), float(y), station_radius_m) for x, y in stations) + tuple(
        (float(x), float(y), marker_radius_m) for x, y in markers_xy)


def _square(half_m: float) -> np.ndarray:
    """(4, 2) corners of the square boundary ``[-half_m, half_m]²``, site frame, m."""
    return np.array([[-half_m, -half_m], [half_m, -half_m], [half_m, half_m],
                     [-half_m, half_m]])


def _assemble(name: str, spec: TerrainSpec, seed: int, stations: np.ndarray,
              headings: np.ndarray, markers_xy: np.ndarray, boundary: np.ndarray) -> Site:
    terrain = generate_terrain(spec, np.random.default_rng([seed, zlib.crc32(name.encode())]))
    dem = terrain.dem
    centres = np.column_stack([markers_xy, dem.height_at(markers_xy) + MARKER_RADIUS_M])
    return Site(
        name=name, dem=dem,
        station_ids=[f"S{k + 1}" for k in range(len(stations))],
        station_xy_m=stations, station_heading_rad=np.asarray(headings, dtype=float),
        marker_ids=[f"M{k + 1:02d}" for k in range(len(markers_xy))],
        marker_centres_m=centres, craters=terrain.craters,
        rock_centres_m=terrain.rock_centres_m, rock_radii_m=terrain.rock_radii_m,
        boundary_xy_m=boundary, seed=seed)


def site_with_dem(site: Site, dem: DEM) -> Site:
    """The preset's stations and marker layout on another DEM (e.g. a real GeoTIFF).

    Marker centres are re-seated on the new ground (ground + radius); the preset's craters
    and rocks belong to its own terrain and are dropped.

    Raises
    ------
    DataError
        A station or marker lies outside ``dem``.
    """
    for label, ids, xy in (("station", site.station_ids, site.station_xy_m),
                           ("marker", site.marker_ids, site.marker_centres_m[:, :2])):
        dem.require_inside(xy, ids, label,
                           "use a DEM covering the site (same site-frame coordinates)")
    return replace(site, dem=dem, marker_centres_m=_seated(site.marker_centres_m, dem,
                                                          site.marker_radius_m),
                   craters=[], rock_centres_m=np.zeros((0, 3)), rock_radii_m=np.zeros(0))


def site_with_marker_radius(site: Site, radius_m: float) -> Site:
    """The site with markers of another radius, re-seated on the ground (centre = ground +
    ``radius_m``), metres."""
    return replace(site, marker_radius_m=float(radius_m),
                   marker_centres_m=_seated(site.marker_centres_m, site.dem, radius_m))


def site_with_stations(site: Site, ids: list[str], xy_m: np.ndarray,
                       heading_rad: np.ndarray) -> Site:
    """The site with other stations: ids, (s, 2) positions (m) and (s,) headings (rad)."""
    return replace(site, station_ids=list(ids), station_xy_m=np.asarray(xy_m, float)[:, :2],
                   station_heading_rad=np.asarray(heading_rad, float))


def _seated(centres_m: np.ndarray, dem: DEM, radius_m: float) -> np.ndarray:
    """(m, 3) marker centres at the same x, y resting on ``dem``: z = ground + radius (m)."""
    xy = centres_m[:, :2]
    return np.column_stack([xy, dem.height_at(xy) + radius_m])


@dataclass(frozen=True)
class OrbitalGrade:
    """How a preset's orbital planning DEM is made (:func:`planning_dem`).

    Attributes
    ----------
    cell_m : float
        Orbital post spacing, m.
    height_error : HeightError
    """

    cell_m: float
    height_error: HeightError


#: The orbital planning DEM of each preset that has one (module docstring): NAC-grade 2 m posts,
#: 0.3 m RMS height error correlated over 10 m. ``km`` (32 M cells of truth) has none.
ORBITAL_GRADES = {"default": OrbitalGrade(2.0, HeightError(0.3, 10.0)),
                  "large": OrbitalGrade(2.0, HeightError(0.3, 10.0))}

#: The terrains a plan can be made on: the preset's fine truth, or its orbital planning DEM.
TERRAIN_KINDS = ("truth", "orbital")


def planning_dem(site: Site, kind: str = "truth") -> DEM:
    """The terrain a plan of ``site`` is made on.

    Parameters
    ----------
    site : Site
        A preset (:func:`load_site`).
    kind : {"truth", "orbital"}
        ``"truth"``: the site's own fine terrain; ``"orbital"``: its orbital-grade DEM
        (:data:`ORBITAL_GRADES`, error field seeded by ``site.seed``).

    Raises
    ------
    ConfigError
        An unknown kind, or a preset without an orbital DEM.
    """
    if kind not in TERRAIN_KINDS:
        raise ConfigError(f"unknown terrain {kind!r}; choose one of {', '.join(TERRAIN_KINDS)}")
    if kind == "truth":
        return site.dem
    grade = orbital_grade(site.name)
    return orbital_dem(site.dem, grade.cell_m, grade.height_error, seed=site.seed)


def orbital_grade(name: str) -> OrbitalGrade:
    """The orbital grade of preset ``name`` (:data:`ORBITAL_GRADES`); ConfigError when it has
    none."""
    if name not in ORBITAL_GRADES:
        raise ConfigError(f"site preset {name!r} has no orbital planning DEM; use terrain "
                          f"'truth' or one of the presets {', '.join(ORBITAL_GRADES)}")
    return ORBITAL_GRADES[name]


PRESETS = {"default": _default_site, "large": _large_site, "km": _km_site}


def load_site(name: str, seed: int | None = None) -> Site:
    """Build a site preset.

    Parameters
    ----------
    name : {"default", "large", "km"}
    seed : int, optional
        Terrain seed (default 0).

    Returns
    -------
    site : Site

    Raises
    ------
    ConfigError
        Unknown preset name.
    """
    if name not in PRESETS:
        raise ConfigError(f"unknown site preset {name!r}; choose one of {', '.join(PRESETS)}")
    seed = 0 if seed is None else int(seed)
    return PRESETS[name](seed)
