"""A planning run's inputs: the site preset (:mod:`visibility.sites`) or DEM, the stations,
existing and as-built markers, the boundary and exclusion zones, read strictly into
:class:`PlanInputs` by :func:`load_inputs`.

Station and marker files are CSV or GeoJSON points (site frame, m; a missing height is the
ground's plus the default); every refusal is one :class:`~markerplan.errors.InputFileError` line
naming the file and the fix.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import shapely

from markerplan.errors import ConfigError, DataError, InputFileError
from markerplan.reading import (
    MAX_ABS_COORDINATE_M,
    finite_number,
    json_kind,
    load_json,
    read_csv,
    require_type,
    unique_ids,
)
from planner.config import MAX_MARKERS, MAX_STATIONS
from planner.problem.candidates import (
    edge_margin_m,
    load_polygons,
    valid_area,
)
from visibility.dem import read_dem_by_window, to_dem_xy
from visibility.orbital import HeightError, orbital_dem
from visibility.sites import (
    PRESETS,
    TERRAIN_KINDS,
    load_site,
    orbital_grade,
    site_with_dem,
    site_with_marker_radius,
)


@dataclass
class PlanInputs:
    """Everything a plan is made for, site frame (metres).

    Attributes
    ----------
    site_name : str
        The site preset's name, or the DEM file's stem (``mydem`` for ``mydem.tif``).
    site_seed : int or None
        Terrain seed of the site preset (None on a DEM file).
    dem : visibility.dem.DEM
    station_ids : list of str
    station_xyz : (s, 3) float
        LiDAR centres, m.
    station_heading_rad : (s,) float
    boundary_xy : (k, 2) float or None
        Where markers may go (None: the whole DEM; on a DEM with nodata and no
        ``--boundary``, :func:`default_boundary`).
    exclusions : list of shapely Polygon
    craters : list
        Objects with ``centre_xy_m`` and ``diameter_m`` (for the map and crater exclusion).
    as_built_ids : list of str
    as_built_xyz : (m, 3) float
        The site's as-built marker layout (empty when not known), m.
    existing_ids : list of str
    existing_xyz : (e, 3) float
        Markers already in the field, fixed in the plan, m.
    control : tuple of pipeline.network.observations.ControlPoint
        Network mode's datum: control points with known coordinates and sigmas (a lander's
        fiducials), in the plan like existing markers; empty: none.
    marker_radius_m : float
    sources : dict
        Where each input came from (for provenance): the preset, and input files as absolute
        paths; ``"terrain"`` (when the plan is made on an orbital DEM or one with a declared
        height error, :func:`terrain_record`) its kind, cell, error and seed.
    height_error : visibility.orbital.HeightError or None
        The planning DEM's declared height error (the orbital preset's, or a ``--dem``'s
        ``dem_height_error``); ``None``: the terrain is taken as exact.
    """

    site_name: str
    site_seed: int | None
    dem: object
    station_ids: list[str]
    station_xyz: np.ndarray
    station_heading_rad: np.ndarray
    boundary_xy: np.ndarray | None
    exclusions: list
    craters: list
    as_built_ids: list[str]
    as_built_xyz: np.ndarray
    existing_ids: list[str] = field(default_factory=list)
    existing_xyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    control: tuple = ()
    marker_radius_m: float = 0.10
    lidar_height_m: float = 1.0
    sources: dict = field(default_factory=dict)
    height_error: HeightError | None = None

    def with_stations(self, ids: list[str]) -> PlanInputs:
        """These inputs for the stations ``ids`` only (ids of :attr:`station_ids`, as
        :func:`select_stations` checks them), in that order; ``sources`` records them."""
        k = [self.station_ids.index(i) for i in ids]
        return replace(self, station_ids=list(ids), station_xyz=self.station_xyz[k],
                       station_heading_rad=self.station_heading_rad[k],
                       sources={**self.sources, "station_ids": list(ids)})


def select_stations(available: list[str], wanted: tuple[str, ...] | None) -> list[str]:
    """The ``--station-ids`` among ``available`` (all of them when ``wanted`` is ``None``).

    Raises
    ------
    ConfigError
        An id that is not among ``available``; the message lists the valid ones.

    Examples
    --------
    >>> select_stations(["S1", "S2", "S3"], ("S3", "S1"))
    ['S3', 'S1']
    >>> select_stations(["S1"], None)
    ['S1']
    """
    if wanted is None:
        return list(available)
    return list(known_ids(wanted, available, "`station_ids`", "station"))


def known_ids(wanted, available, option: str, what: str) -> tuple[str, ...]:
    """``wanted`` as a tuple, when every id is among ``available``.

    Parameters
    ----------
    wanted, available : iterable of str
    option : str
        The option that gave ``wanted`` (for the message).
    what : str
        What the ids name (``"station"``, ``"marker"``).

    Raises
    ------
    ConfigError
        Names the unknown ids and lists the valid ones (the first 20).
    """
    wanted, available = tuple(wanted), list(available)
    unknown = [i for i in wanted if i not in available]
    if unknown:
        shown = ", ".join(available[:20]) + (", ..." if len(available) > 20 else "")
        raise ConfigError(f"{option}: unknown {what} id(s) {', '.join(unknown)}; valid ids are "
                          f"{shown}")
    return wanted


def load_inputs(site: str = "default", site_seed: int | None = None, dem_path=None,
                stations_path=None, boundary_path=None, exclude_paths=(),
                existing: str | None = None, marker_radius_m: float | None = None,
                station_ids=None, reproject: bool = False,
                sight_radius_m: float | None = None, terrain: str = "truth",
                dem_height_error: HeightError | None = None, control=None,
                stations_chosen: bool = False) -> PlanInputs:
    """Assemble the inputs of a plan from a site preset and optional files.

    Parameters
    ----------
    site : str
        Preset name (``visibility.sites``); supplies what no file replaces.
    site_seed : int, optional
        Terrain seed of the preset (default 0).
    dem_path : path, optional
        GeoTIFF / npz DEM in the site frame (replaces the preset terrain; the preset's craters
        and as-built layout are then dropped, the site is named after the file). Needs
        ``stations_path``: the preset's stations belong to the preset's terrain. Stations and
        existing markers must stand on its measured terrain; where it has nodata, markers may
        go only inside :func:`default_boundary` (or ``boundary_path``, kept
        :func:`~planner.problem.candidates.edge_margin_m` off nodata).
    stations_path : path, optional
        Stations CSV (``id, x_m, y_m[, z_m][, heading_deg]``; ``z_m`` is the LiDAR centre, default
        ground + rig height) or GeoJSON Points with an ``id`` property.
    boundary_path : path, optional
        GeoJSON with one polygon (no holes): where markers may go.
    exclude_paths : sequence of path
        GeoJSON polygons where no marker may go.
    existing : str, optional
        ``"as-built"`` (the preset's layout) or a markers CSV (``id, x_m, y_m[, z_m]``): markers
        already in the field, fixed in the plan.
    marker_radius_m : float, optional
        Marker radius, m (default: the preset's); markers rest on the ground, so their centres
        stand this far above it.
    station_ids : sequence of str, optional
        Only these of the stations (:func:`select_stations`); default all.
    reproject : bool
        Resample a DEM that is not metric and square (``read_dem(..., reproject=True)``); the
        station, boundary, exclusion and existing-marker files are then in the DEM file's CRS
        and mapped into the DEM's (:func:`visibility.dem.to_dem_xy`).
    sight_radius_m : float, optional
        Read only the part of the DEM within this distance of the stations
        (:func:`sight_window`; e.g. ``config.max_range_m``, beyond which no pair counts);
        default, and with ``reproject``, the whole DEM.
    terrain : {"truth", "orbital"}
        The preset's terrain to plan on: its fine truth, or its orbital-grade planning DEM
        (:func:`visibility.sites.planning_dem`; preset craters smaller than two orbital cells
        are not known from orbit and dropped; the as-built layout is re-seated on it).
    dem_height_error : HeightError, optional
        The planning DEM's height error: a ``dem_path``'s, or, with ``terrain="orbital"``, one
        replacing the preset's grade (the orbital DEM is then drawn with it).
    control : path, optional
        Control points CSV (``id,x_m,y_m,z_m,sigma_m``, :func:`read_control_points`).
    stations_chosen : bool
        The plan chooses its stations (over an area of interest, :mod:`planner.design`): a
        ``dem_path`` needs no ``stations_path`` (then no stations, and the whole DEM is read);
        a preset keeps its own stations as the layout to compare with.

    Raises
    ------
    ConfigError
        ``dem_path`` without ``stations_path``, an unknown preset, ``terrain="orbital"`` with
        ``dem_path`` or on a preset without an orbital DEM, or ``dem_height_error`` on the
        preset's truth terrain.
    InputFileError, DataError
        A malformed input file (see :func:`read_stations`, :func:`read_markers`,
        :func:`planner.problem.candidates.load_polygons`), a point outside the DEM or on nodata
        (off a preset's terrain, the message says so), or a given ``z_m`` below the ground.
    """
    if dem_path is not None and stations_path is None and not stations_chosen:
        raise ConfigError(f"`dem_path` {dem_path} needs `stations_path`: the preset's stations "
                          "belong to its own terrain, not to this DEM; give `stations_path` with "
                          "the stations on this DEM")
    _terrain_iv(terrain, dem_path, dem_height_error)
    if terrain == "orbital":
        orbital_grade(site)  # refused before the preset's terrain is made
    preset = load_site(site, site_seed)
    if terrain == "orbital":
        preset = _on_orbital_dem(preset, dem_height_error)
        dem_height_error = dem_height_error or orbital_grade(site).height_error
    if marker_radius_m is not None:
        preset = site_with_marker_radius(preset, marker_radius_m)
    sources = {"site": site, "seed": preset.seed}
    dem = preset.dem
    craters = list(preset.craters)
    as_built_ids, as_built_xyz = list(preset.marker_ids), np.asarray(preset.marker_centres_m)
    boundary = np.asarray(preset.boundary_xy_m, float) if len(preset.boundary_xy_m) else None
    site_name, site_seed = site, preset.seed
    station_points = (None if stations_path is None
                      else read_points(stations_path, "`stations_path`", MAX_STATIONS))
    if dem_path is not None:
        window = None
        if sight_radius_m is not None and not reproject and station_points is not None:
            window = sight_window([[p["x_m"], p["y_m"]] for p in station_points], sight_radius_m)
        dem, window = read_dem_by_window(dem_path, window, what=f"`dem_path` {dem_path}",
                                             reproject=reproject)
        sources.update(dem=_absolute(dem_path), reproject=bool(reproject))
        if window is not None:
            sources["dem_window"] = list(window)
        site_name, site_seed = Path(dem_path).stem, None
        craters = []
        boundary = None if boundary_path is not None else default_boundary(
            dem, float(preset.marker_radius_m))
        as_built_ids, as_built_xyz = [], np.zeros((0, 3))
    if terrain == "orbital" or dem_height_error is not None:
        on_file = dem_path is not None
        sources["terrain"] = terrain_record("file" if on_file else terrain, dem,
                                            dem_height_error, None if on_file else preset.seed)
    lidar_h = float(preset.lidar_height_m)
    off_site = OFF_DEM_FIX if dem_path is not None else (
        f"the points are not on site preset {site!r}'s terrain (this DEM): choose the preset "
        f"whose terrain holds them ({', '.join(PRESETS)}) or give the DEM they stand on with "
        "`dem_path`")
    if station_points is None and dem_path is not None:  # stations chosen later
        ids, xyz, heading = [], np.zeros((0, 3)), np.zeros(0)
    elif station_points is not None:
        ids, xyz, heading = place_stations(station_points, dem, lidar_h, off_site)
        sources["stations"] = _absolute(stations_path)
        as_built_ids, as_built_xyz = [], np.zeros((0, 3))
    else:
        ids = list(preset.station_ids)
        _check_inside(dem, np.asarray(preset.station_xy_m), ids, "station")
        xyz = np.column_stack([preset.station_xy_m,
                               dem.height_at(preset.station_xy_m) + lidar_h])
        heading = np.asarray(preset.station_heading_rad, float)
    if boundary_path is not None:
        boundary = _boundary_iv(polygons_on_dem(load_polygons(boundary_path, "`boundary_path`"),
                                                 dem), boundary_path)
        sources["boundary"] = _absolute(boundary_path)
    exclusions = []
    for p in exclude_paths:
        exclusions += polygons_on_dem(load_polygons(p, "`exclude_paths`"), dem)
    if exclude_paths:
        sources["exclude"] = [_absolute(p) for p in exclude_paths]
    ex_ids, ex_xyz = [], np.zeros((0, 3))
    if existing == "as-built":
        if not as_built_ids:
            raise InputFileError("`existing` as-built: this input has no as-built layout (it is "
                                 "dropped with `dem_path`/`stations_path`); give a markers CSV "
                                 "instead")
        ex_ids, ex_xyz = list(as_built_ids), as_built_xyz.copy()
    elif existing is not None:
        ex_ids, ex_xyz = read_markers(existing, dem, float(preset.marker_radius_m),
                                      off_dem_fix=off_site)
    if existing is not None:
        sources["existing"] = existing if existing == "as-built" else _absolute(existing)
    control_points = () if control is None else read_control_points(control, dem, off_site)
    if control is not None:
        sources["control"] = _absolute(control)
    inputs = PlanInputs(site_name=site_name, site_seed=site_seed, dem=dem, station_ids=ids,
                        station_xyz=xyz, station_heading_rad=heading, boundary_xy=boundary,
                        exclusions=exclusions, craters=craters, as_built_ids=as_built_ids,
                        as_built_xyz=as_built_xyz, existing_ids=ex_ids, existing_xyz=ex_xyz,
                        control=control_points,
                        marker_radius_m=float(preset.marker_radius_m), lidar_height_m=lidar_h,
                        sources=sources, height_error=dem_height_error)
    if station_ids is None:
        return inputs
    return inputs.with_stations(select_stations(inputs.station_ids, station_ids))


def _terrain_iv(terrain: str, dem_path, dem_height_error) -> None:
    """Refuse a terrain choice that names no planning DEM (one-line :class:`ConfigError`)."""
    if terrain not in TERRAIN_KINDS:
        raise ConfigError(f"`terrain` {terrain!r}: choose one of {', '.join(TERRAIN_KINDS)}")
    if terrain == "orbital" and dem_path is not None:
        raise ConfigError(f"`terrain` orbital is a site preset's orbital DEM and `dem_path` "
                          f"{dem_path} replaces the preset's terrain; drop `terrain` and declare "
                          "the file's error with `dem_height_error`")
    if dem_height_error is not None and not isinstance(dem_height_error, HeightError):
        raise ConfigError(f"`dem_height_error` must be a HeightError, got "
                          f"{type(dem_height_error).__name__}")
    if dem_height_error is not None and terrain == "truth" and dem_path is None:
        raise ConfigError("`dem_height_error` declares the error of a `dem_path` FILE or of "
                          "`terrain` orbital, and the preset's truth terrain is exact; add "
                          "`dem_path` or `terrain` orbital, or drop `dem_height_error`")


def _on_orbital_dem(preset, height_error: HeightError | None):
    """The preset on its orbital planning DEM (:func:`visibility.sites.planning_dem`, drawn
    with ``height_error`` when given): the as-built markers re-seated on it, craters smaller
    than two orbital cells (unresolved from orbit) and all rocks dropped."""
    grade = orbital_grade(preset.name)
    dem = orbital_dem(preset.dem, grade.cell_m, height_error or grade.height_error,
                      seed=preset.seed)
    resolved = [c for c in preset.craters if c.diameter_m >= 2.0 * grade.cell_m]
    return replace(site_with_dem(preset, dem), craters=resolved)


def terrain_record(kind: str, dem, height_error: HeightError | None, seed) -> dict:
    """Provenance of the planning terrain: ``{"kind", "cell_m", "height_error", "seed"}``.

    Parameters
    ----------
    kind : {"truth", "orbital", "file"}
    dem : visibility.dem.DEM
        The planning DEM.
    height_error : HeightError or None
        Its declared error (``rms_m``, ``correlation_m``).
    seed : int or None
        Seed of an orbital DEM's error field.
    """
    return {"kind": kind, "cell_m": float(dem.cell_size_m),
            "height_error": None if height_error is None else height_error.record(),
            "seed": seed}


#: Room kept beyond the stations' sight radius when a DEM is read by window, m: the edge
#: margin markers keep from the window's edge (:func:`~planner.problem.candidates.edge_margin_m`,
#: two cells) for cells up to 2.5 m.
WINDOW_MARGIN_M = 5.0


def sight_window(station_xy, sight_radius_m: float) -> tuple[float, float, float, float]:
    """The part of a DEM stations can see: their bounding box grown by ``sight_radius_m`` and
    :data:`WINDOW_MARGIN_M`.

    Parameters
    ----------
    station_xy : (s, 2) float
        Stations in the DEM file's coordinates, m.
    sight_radius_m : float
        How far a station sees, m.

    Returns
    -------
    window : (xmin, xmax, ymin, ymax) float
        As :func:`visibility.dem.read_dem` takes it, m.

    Examples
    --------
    >>> sight_window([[0.0, 0.0], [10.0, 4.0]], 30.0)
    (-35.0, 45.0, -35.0, 39.0)
    """
    xy = np.asarray(station_xy, dtype=float).reshape(-1, 2)
    r = sight_radius_m + WINDOW_MARGIN_M
    return (float(xy[:, 0].min() - r), float(xy[:, 0].max() + r),
            float(xy[:, 1].min() - r), float(xy[:, 1].max() + r))


def polygons_on_dem(polygons: list, dem) -> list:
    """Polygons read in the DEM file's CRS, in the DEM's (:func:`visibility.dem.to_dem_xy`,
    corner by corner)."""
    if dem.source_crs is None:
        return polygons
    return [shapely.transform(p, lambda xy: to_dem_xy(dem, xy)) for p in polygons]


def _absolute(path) -> str:
    """``path`` made absolute (symbolic links resolved), as provenance records an input file,
    so that ``verify`` and ``reduce`` find it from any folder."""
    return str(Path(path).resolve())


def default_boundary(dem, marker_radius_m: float) -> np.ndarray | None:
    """Where markers may go on a DEM when no ``--boundary`` is given: the outline of its
    largest piece of measured terrain, :func:`~planner.problem.candidates.edge_margin_m` inside it
    (:func:`~planner.problem.candidates.valid_area`); ``None`` (the whole DEM) when it has no
    nodata.

    Returns
    -------
    corners : (k, 2) float or None
        Site frame, m. Holes in that piece and other pieces of measured terrain are not part
        of it; :func:`~planner.problem.candidates.candidate_sites` keeps markers off nodata anyway.
    """
    if dem.valid is None:
        return None
    area = valid_area(dem, edge_margin_m(dem, marker_radius_m))
    largest = max(getattr(area, "geoms", [area]), key=lambda g: g.area)
    return np.asarray(largest.exterior.coords, float)


def _boundary_iv(polygons: list, path) -> np.ndarray:
    """The corners (k, 2) of the one hole-free polygon a ``--boundary`` file must hold."""
    if len(polygons) != 1:
        raise InputFileError(f"`boundary_path` {path}: holds {len(polygons)} polygons, the site "
                             "boundary is one; give a single Polygon (exclude areas with "
                             "`exclude_paths`)")
    if len(polygons[0].interiors):
        raise InputFileError(f"`boundary_path` {path}: the polygon has holes; give its outline "
                             "only and the holes with `exclude_paths`")
    return np.asarray(polygons[0].exterior.coords, float)


#: The advice of a point off the DEM given with it (:meth:`visibility.dem.DEM.require_inside`).
OFF_DEM_FIX = "move it inside or use a DEM covering it"


def _check_inside(dem, xy: np.ndarray, ids, label: str, fix: str = OFF_DEM_FIX) -> None:
    dem.require_inside(xy, ids, label, fix)


#: Largest magnitude of a ``heading_deg``, degrees.
MAX_ABS_HEADING_DEG = 360.0
_POINT_COLUMNS = "id, x_m, y_m[, z_m][, heading_deg]"


def read_points(path, option: str, max_points: int = MAX_MARKERS) -> list[dict]:
    """Points of a CSV (``id, x_m, y_m[, z_m][, heading_deg]``) or a GeoJSON FeatureCollection
    of Points (``id`` and ``heading_deg`` properties, optional ``z`` coordinate).

    Parameters
    ----------
    path : str or Path
        ``.geojson`` / ``.json``: GeoJSON; anything else: CSV with a header row.
    option : str
        How messages name the input: the argument (``"`stations_path`"``, ``"`existing`"``,
        which the CLI spells as its flags) or ``"INPUT"``.
    max_points : int
        Most points accepted.

    Returns
    -------
    points : list of dict
        ``id`` (str, unique, non-empty), ``x_m``, ``y_m`` (finite floats), ``z_m`` and
        ``heading_deg`` (finite float or None when not given).

    Raises
    ------
    InputFileError
        Missing, unreadable or non-UTF-8 file; ragged CSV rows or missing columns; GeoJSON of
        the wrong shape; no points or more than ``max_points``; a number that is not finite or
        beyond :data:`~markerplan.reading.MAX_ABS_COORDINATE_M` (headings beyond
        :data:`MAX_ABS_HEADING_DEG`); empty or repeated ids.
    """
    what = f"{option} {path}"
    if Path(path).suffix.lower() in (".geojson", ".json"):
        rows = _geojson_points(load_json(path, what), what)
    else:
        header, cells = read_csv(path, what, required=("id", "x_m", "y_m"),
                                 fix=f"give a CSV with columns {_POINT_COLUMNS}")
        rows = [dict(zip(header, (c.strip() for c in r), strict=True)) for r in cells]
    if not rows:
        raise InputFileError(f"{what}: no points found; give at least one row "
                             f"({_POINT_COLUMNS})")
    if len(rows) > max_points:
        raise InputFileError(f"{what}: {len(rows)} points, more than the {max_points} accepted; "
                             "give only the real points")
    ids = unique_ids([r["id"] for r in rows], what)
    points = []
    for pid, r in zip(ids, rows, strict=True):
        p = {"id": pid}
        for key in ("x_m", "y_m", "z_m", "heading_deg"):
            v = r.get(key)
            if key in ("z_m", "heading_deg") and (v is None or v == ""):
                p[key] = None
                continue
            p[key] = finite_number(v, f"{what}: {key} of {pid!r}",
                                   MAX_ABS_HEADING_DEG if key == "heading_deg"
                                   else MAX_ABS_COORDINATE_M)
        points.append(p)
    return points


def _geojson_points(doc: dict, what: str) -> list[dict]:
    """Rows (``id``, ``x_m``, ``y_m``, optional ``z_m``, ``heading_deg``) of a FeatureCollection
    of Points; refuses any other shape, naming the feature."""
    fix = "give a GeoJSON FeatureCollection of Points with an 'id' property"
    if doc.get("type") != "FeatureCollection":
        raise InputFileError(f"{what}: expected a GeoJSON FeatureCollection, got type "
                             f"{doc.get('type')!r:.40}; {fix}")
    feats = doc.get("features")
    if not isinstance(feats, list):
        raise InputFileError(f"{what}: 'features' must be a list, got {json_kind(feats)}; {fix}")
    rows = []
    for k, f in enumerate(feats):
        where = f"{what}: feature {k}"
        require_type(f, dict, where)
        g = f.get("geometry")
        if not isinstance(g, dict) or g.get("type") != "Point":
            got = repr(g.get("type")) if isinstance(g, dict) else json_kind(g)
            raise InputFileError(f"{where}: geometry must be a Point, got {got:.40}; {fix}")
        c = g.get("coordinates")
        if not isinstance(c, list) or len(c) not in (2, 3):
            raise InputFileError(f"{where}: Point coordinates must be [x, y] or [x, y, z], got "
                                 f"{c!r:.40}; give site-frame metres")
        props = f.get("properties")
        props = {} if props is None else require_type(props, dict, f"{where}: properties")
        pid = props.get("id", f"P{k + 1}")
        require_type(pid, (str, int), f"{where}: property 'id'")
        row = {"id": str(pid).strip(), "x_m": c[0], "y_m": c[1]}
        if len(c) > 2:
            row["z_m"] = c[2]
        if props.get("heading_deg") is not None:
            row["heading_deg"] = props["heading_deg"]
        rows.append(row)
    return rows


def read_stations(path, dem, lidar_height_m: float) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Stations from CSV/GeoJSON -> ids, LiDAR centres (s, 3) m, headings (s,) rad.

    Parameters
    ----------
    path : str or Path
        CSV ``id, x_m, y_m[, z_m][, heading_deg]`` or GeoJSON Points (see :func:`read_points`);
        at most :data:`planner.config.MAX_STATIONS` stations.
    dem : visibility.dem.DEM
        Terrain; every station must stand on its measured terrain.
    lidar_height_m : float
        LiDAR centre above the ground where ``z_m`` is not given, m.

    Raises
    ------
    InputFileError, DataError
        Unreadable or malformed file (see :func:`read_points`), a station outside the DEM or
        on nodata, or a ``z_m`` below the ground.
    """
    return place_stations(read_points(path, "`stations_path`", MAX_STATIONS), dem, lidar_height_m)


def place_stations(points: list[dict], dem, lidar_height_m: float, off_dem_fix: str = OFF_DEM_FIX
                   ) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Stations read by :func:`read_points` -> ids, LiDAR centres (s, 3) m, headings (s,) rad
    on ``dem`` (see :func:`read_stations`; a ``z_m`` below the ground is refused);
    ``off_dem_fix`` is the advice when one lies off the DEM."""
    ids, xyz = _points_on_dem(points, dem, lidar_height_m, "station", off_dem_fix)
    heading = np.radians([p["heading_deg"] or 0.0 for p in points])
    return ids, xyz, heading


def read_markers(path, dem, marker_radius_m: float, option: str = "`existing`",
                 off_dem_fix: str = OFF_DEM_FIX) -> tuple[list[str], np.ndarray]:
    """Markers CSV/GeoJSON (``id, x_m, y_m[, z_m]``) -> ids and centres (m, 3) m.

    Parameters
    ----------
    path : str or Path
        See :func:`read_points`; at most :data:`planner.config.MAX_MARKERS` markers.
    dem : visibility.dem.DEM
        Terrain; every marker must stand on its measured terrain.
    marker_radius_m : float
        Default ``z``: ground + this radius, m.
    option : str
        Names the argument in error messages.
    off_dem_fix : str
        The advice when a marker lies off the DEM.

    Raises
    ------
    InputFileError, DataError
        Unreadable or malformed file (see :func:`read_points`), a marker outside the DEM or on
        nodata, or buried (``z_m`` more than ``marker_radius_m`` below the ground).
    """
    return _points_on_dem(read_points(path, option, MAX_MARKERS), dem, marker_radius_m,
                          "marker", off_dem_fix, sink_m=marker_radius_m)


def read_control_points(path, dem, off_dem_fix: str = OFF_DEM_FIX) -> tuple:
    """Control points (a lander's fiducials) from a CSV ``id,x_m,y_m,z_m,sigma_m``
    (:func:`pipeline.network.detections.read_control`, the adjustment's ``--control`` file),
    each over the DEM's measured terrain.

    Parameters
    ----------
    path : str or Path
    dem : visibility.dem.DEM
    off_dem_fix : str
        The advice when a point lies off the DEM.

    Returns
    -------
    control : tuple of pipeline.network.observations.ControlPoint
        Site frame (a reprojected DEM's file CRS mapped like the other inputs), m.

    Raises
    ------
    InputFileError, DataError
        A malformed file, a point off the DEM or on nodata, or below the ground (``z_m`` is
        the point's centre, on the lander above the ground).
    """
    from pipeline.network.detections import read_control
    from pipeline.network.observations import ControlPoint

    points = read_control(Path(path))
    ids = [c.marker_id for c in points]
    xy = to_dem_xy(dem, np.array([c.xyz_m[:2] for c in points]))
    _check_inside(dem, xy, ids, "control point", off_dem_fix)
    below = dem.height_at(xy) - np.array([c.xyz_m[2] for c in points])
    if np.any(below > 0):
        k = int(np.argmax(below > 0))
        raise DataError(f"control point {ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m lies "
                        f"{below[k]:.2f} m below the ground: z_m is the point's centre in the "
                        "site frame, above the ground; fix z_m in the control file")
    return tuple(ControlPoint(c.marker_id, np.r_[q, c.xyz_m[2]], c.sigma_m)
                 for c, q in zip(points, xy, strict=True))


def _points_on_dem(points: list[dict], dem, height_m: float, label: str,
                   off_dem_fix: str = OFF_DEM_FIX, sink_m: float = 0.0
                   ) -> tuple[list[str], np.ndarray]:
    """Ids and (k, 3) positions of :func:`read_points` rows that must stand on the DEM's
    measured terrain (:meth:`~visibility.dem.DEM.valid_at`; ``off_dem_fix`` advises one that
    does not), m; they are given in the DEM file's CRS (:func:`visibility.dem.to_dem_xy`); a
    missing ``z_m`` is the ground plus ``height_m``, a given one may lie at most ``sink_m``
    below the ground (:func:`_above_ground_iv`)."""
    ids = [p["id"] for p in points]
    xy = to_dem_xy(dem, np.array([[p["x_m"], p["y_m"]] for p in points], float))
    _check_inside(dem, xy, ids, label, off_dem_fix)
    ground = dem.height_at(xy)
    given = np.array([np.nan if p["z_m"] is None else p["z_m"] for p in points], float)
    _above_ground_iv(ids, xy, given, ground, label, height_m, sink_m)
    return ids, np.column_stack([xy, np.where(np.isnan(given), ground + height_m, given)])


def _above_ground_iv(ids, xy: np.ndarray, z_m: np.ndarray, ground_m: np.ndarray, label: str,
                     height_m: float, sink_m: float) -> None:
    """Refuse a given height more than ``sink_m`` below the ground: a LiDAR centre underground
    (``sink_m`` 0) or a marker buried whole (``sink_m`` its radius) sees or shows nothing.

    Parameters
    ----------
    ids : sequence of str, (k,)
    xy : (k, 2) float
        Positions, site frame, m.
    z_m, ground_m : (k,) float
        Given heights (nan: not given) and the ground under them, m.
    label : str
        ``"station"`` or ``"marker"``.
    height_m : float
        The default height above the ground, m (for the advice).
    sink_m : float
        How far below the ground a given height may lie, m.

    Raises
    ------
    DataError
        Names the first such point, its height, the ground's and the fix.
    """
    below = ground_m - z_m
    bad = np.flatnonzero(below > sink_m)
    if bad.size:
        k = int(bad[0])
        centre = "the LiDAR centre" if label == "station" else "the marker's centre"
        raise DataError(f"{label} {ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m: z_m "
                        f"{z_m[k]:.2f} m lies {below[k]:.2f} m below the ground there "
                        f"({ground_m[k]:.2f} m); z_m is {centre}, above the ground: fix it, or "
                        f"leave it empty for the ground + {height_m:g} m")
