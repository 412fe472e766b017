"""Candidate marker sites: a grid inside the site boundary, minus what a marker cannot use.

All coordinates are in the site frame (local metres). A candidate's marker centre is the ground
height under it plus the marker radius (the sphere rests on the ground).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry import Polygon

from markerplan.errors import ConfigError, DataError, InputFileError
from markerplan.reading import finite_number, json_kind, load_json

#: Baseline for the slope under a marker, m (a 0.20 m sphere's footprint, not DEM micro-relief).
SLOPE_BASELINE_M = 0.25
#: Most candidate sites one plan may ray cast (the large preset at 0.5 m has ~460 000 grid
#: points), counted after the boundary, nodata and range drops.
MAX_GRID_POINTS = 500_000
#: Most grid points laid out before any drop (16 bytes each: the ``km`` preset at 0.5 m).
MAX_RAW_GRID_POINTS = 8 * MAX_GRID_POINTS


@dataclass(frozen=True)
class Candidates:
    """Candidate marker sites, site frame.

    Attributes
    ----------
    ids : tuple of str, (n,)
    centre_m : (n, 3) float
        Marker centre at each site (ground + radius), m.
    dropped : dict
        Number of grid points dropped per reason (outside boundary, on nodata, near nodata,
        excluded, near station, out of range, crater, slope; the nodata reasons only for a DEM
        with nodata, the station reasons only with stations).
    """

    ids: tuple[str, ...]
    centre_m: np.ndarray
    dropped: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.ids)


def load_polygons(path: str | Path, option: str = "`exclude_paths`") -> list[Polygon]:
    """Read polygons (site frame, metres) from a GeoJSON file.

    Accepts a FeatureCollection, a Feature or a bare geometry of type Polygon or MultiPolygon.

    Parameters
    ----------
    path : str or Path
        UTF-8 GeoJSON file.
    option : str
        How messages name the input (the argument, ``"`boundary_path`"`` or
        ``"`exclude_paths`"``, which the CLI spells as its flags).

    Returns
    -------
    polygons : list of shapely Polygon
        At least one; each valid with positive area.

    Raises
    ------
    InputFileError
        Missing, unreadable or non-UTF-8 file, not JSON, not a GeoJSON object, no polygons,
        malformed coordinates (not ``[x, y]`` pairs, not finite, beyond
        :data:`~markerplan.reading.MAX_ABS_COORDINATE_M`), more than :data:`MAX_POLYGON_VERTICES`
        corners, or an invalid polygon (self-intersecting, too few points), naming the file and
        the feature.
    """
    what = f"{option} {path}"
    data = load_json(path, what)
    kind = data.get("type")
    if kind == "FeatureCollection":
        features = data.get("features")
        if not isinstance(features, list):
            raise InputFileError(f"{what}: 'features' must be a list, got "
                                 f"{json_kind(features)}; give a GeoJSON FeatureCollection")
        geoms = [f.get("geometry") if isinstance(f, dict) else f for f in features]
    elif kind == "Feature":
        geoms = [data.get("geometry")]
    else:
        geoms = [data]
    polys: list[Polygon] = []
    n_vertices = 0
    for k, g in enumerate(geoms):
        where = f"{what}: feature {k}"
        if not isinstance(g, dict) or g.get("type") not in ("Polygon", "MultiPolygon"):
            got = repr(g.get("type")) if isinstance(g, dict) else json_kind(g)
            raise InputFileError(f"{where}: geometry must be a Polygon or MultiPolygon, got "
                                 f"{got:.40}; give GeoJSON polygons")
        coords = g.get("coordinates")
        rings_of = [coords] if g["type"] == "Polygon" else coords
        if not isinstance(rings_of, list):
            raise InputFileError(f"{where}: malformed MultiPolygon: coordinates must be a "
                                 f"list of polygons, got {json_kind(rings_of)}")
        for rings in rings_of:
            rings = _rings_iv(rings, where)
            n_vertices += sum(len(r) for r in rings)
            if n_vertices > MAX_POLYGON_VERTICES:
                raise InputFileError(f"{what}: more than {MAX_POLYGON_VERTICES} polygon corners; "
                                     "simplify the polygons")
            polys.append(_valid_polygon(Polygon(rings[0], rings[1:]), where))
    if not polys:
        raise InputFileError(f"{what}: no polygons found; give a GeoJSON Polygon")
    return polys


#: Most polygon corners accepted in one GeoJSON file (a site outline needs tens).
MAX_POLYGON_VERTICES = 100_000


def _rings_iv(rings, where: str) -> list[list[tuple[float, float]]]:
    """Polygon coordinates -> rings of finite ``(x, y)`` corners, or an InputFileError."""
    if not isinstance(rings, list) or not rings:
        raise InputFileError(f"{where}: malformed polygon: coordinates must be a non-empty "
                             f"list of rings, got {json_kind(rings)}; give closed rings of "
                             "[x, y] pairs in metres")
    out = []
    for ring in rings:
        if not isinstance(ring, list) or len(ring) < 4:
            got = f"{len(ring)} corner(s)" if isinstance(ring, list) else json_kind(ring)
            raise InputFileError(f"{where}: malformed ring: needs at least 4 [x, y] pairs "
                                 f"(closed), got {got}; give closed rings in metres")
        pts = []
        for i, pt in enumerate(ring):
            if not isinstance(pt, list) or len(pt) not in (2, 3):
                raise InputFileError(f"{where}: malformed corner: must be [x, y] (or "
                                     f"[x, y, z]), got {pt!r:.40}; give coordinates in metres")
            pts.append((finite_number(pt[0], f"{where}: corner {i} x"),
                        finite_number(pt[1], f"{where}: corner {i} y")))
        out.append(pts)
    return out


def _valid_polygon(p: Polygon, where: str) -> Polygon:
    if p.is_empty or p.convex_hull.area <= 0:
        raise InputFileError(f"{where}: polygon is empty or has zero area; give at least "
                             "three distinct, non-collinear corners")
    if not p.is_valid:
        raise InputFileError(f"{where}: invalid polygon ({shapely.is_valid_reason(p)}); fix the "
                             "ring so it does not cross itself")
    return p


def as_polygon(boundary, name: str = "boundary") -> Polygon:
    """A valid shapely Polygon from a Polygon or an (k, 2) array of corners (site frame, m)."""
    if isinstance(boundary, Polygon):
        return _valid_polygon(boundary, name)
    arr = np.asarray(boundary, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
        raise ConfigError(f"`{name}` must be a polygon or (k >= 3, 2) corners, got {arr.shape}")
    return _valid_polygon(Polygon(arr), name)


def _candidates_iv(dem, boundary, exclusions, station_xy, config):
    xmin, xmax, ymin, ymax = dem.extent()
    dem_box = shapely.box(xmin, ymin, xmax, ymax)
    region = dem_box if boundary is None else as_polygon(boundary).intersection(dem_box)
    if region.is_empty:
        raise DataError("the site boundary does not overlap the DEM "
                        f"[{xmin:.1f}, {xmax:.1f}] x [{ymin:.1f}, {ymax:.1f}] m; "
                        "give a boundary in the DEM's site frame")
    excl = [as_polygon(e, "exclusion") for e in exclusions]
    st = np.zeros((0, 2)) if station_xy is None else np.asarray(station_xy, float)
    if st.ndim != 2 or st.shape[1] < 2:
        raise ConfigError(f"`station_xy` must have shape (s, 2) or (s, 3), got {st.shape}")
    return region, excl, st[:, :2]


def candidate_sites(dem, config, boundary=None, exclusions=(), station_xy=None, craters=(),
                    marker_radius_m: float = 0.10) -> Candidates:
    """Grid of candidate marker sites.

    Parameters
    ----------
    dem : visibility.dem.DEM
        Terrain, site frame. Where it has nodata (:attr:`~visibility.dem.DEM.valid`), a
        site must stand on measured terrain, its slope stencil too (:func:`on_terrain`,
        dropped as "on nodata"), and at least :func:`edge_margin_m` inside the measured area
        (:func:`valid_area`, dropped as "near nodata").
    config : PlanConfig
        Uses ``grid_spacing_m``, ``max_slope_deg``, ``exclude_crater_interiors``,
        ``min_station_distance_m``, ``max_range_m``.
    boundary : Polygon or (k, 2) float, optional
        Site boundary; default the DEM's rectangle.
    exclusions : sequence of Polygon or (k, 2) float
        Areas where no marker may go (work zones, rover paths).
    station_xy : (s, 2) or (s, 3) float, optional
        Stations; sites closer than ``min_station_distance_m`` to one are dropped ("near
        station"), and so are sites farther than ``max_range_m`` plus the marker radius
        (horizontally) from every one ("out of range": no station can use them).
    craters : sequence
        Objects with ``centre_xy_m`` and ``diameter_m``; their interiors (within the rim crest)
        are dropped when ``config.exclude_crater_interiors``.
    marker_radius_m : float
        Marker radius, m (centre = ground + radius).

    Returns
    -------
    candidates : Candidates

    Raises
    ------
    ConfigError
        When ``grid_spacing_m`` would lay out more than :data:`MAX_RAW_GRID_POINTS` grid points,
        or leave more than :data:`MAX_GRID_POINTS` sites after the boundary, nodata, exclusion
        and station drops.
    DataError
        When no site survives, with the count dropped for each reason.
    """
    region, excl, st = _candidates_iv(dem, boundary, exclusions, station_xy, config)
    s = config.grid_spacing_m
    x0, y0, x1, y1 = region.bounds
    n_grid = np.ceil((x1 - x0) / s) * np.ceil((y1 - y0) / s)
    if n_grid > MAX_RAW_GRID_POINTS:
        raise ConfigError(_too_many(s, n_grid, "candidate grid points", MAX_RAW_GRID_POINTS,
                                    x1 - x0, y1 - y0))
    gx = np.arange(x0 + s / 2, x1, s)
    gy = np.arange(y0 + s / 2, y1, s)
    points = GridPoints(gx, gy)
    drop = points.drop

    # keep a slope baseline's margin inside the DEM so height_at never leaves it
    h = max(SLOPE_BASELINE_M, dem.cell_size_m)
    inner = shapely.box(dem.extent()[0] + h, dem.extent()[2] + h, dem.extent()[1] - h,
                        dem.extent()[3] - h)
    drop(~shapely.contains_xy(region.intersection(inner), points.xy[:, 0], points.xy[:, 1]),
         "outside boundary")
    if dem.valid is not None:
        drop(~on_terrain(dem, points.xy, h), "on nodata")
        area = valid_area(dem, edge_margin_m(dem, marker_radius_m))
        drop(~shapely.contains_xy(area, points.xy[:, 0], points.xy[:, 1]), "near nodata")
    if excl:
        union = shapely.union_all(excl)
        drop(shapely.intersects_xy(union, points.xy[:, 0], points.xy[:, 1]), "excluded zone")
    if len(st) and len(points.xy):
        d = cKDTree(st).query(points.xy)[0]
        far = d > config.max_range_m + marker_radius_m
        drop(d < config.min_station_distance_m, "near station")
        drop(far[d >= config.min_station_distance_m], "out of range")
    if len(points.xy) > MAX_GRID_POINTS:
        raise ConfigError(_too_many(s, len(points.xy), "candidate sites in range of a station",
                                    MAX_GRID_POINTS, x1 - x0, y1 - y0))
    if config.exclude_crater_interiors and len(craters) and len(points.xy):
        inside = np.zeros(len(points.xy), bool)
        for c in craters:
            cx, cy = c.centre_xy_m
            inside |= np.hypot(points.xy[:, 0] - cx, points.xy[:, 1] - cy) < 0.5 * c.diameter_m
        drop(inside, "crater interior")
    if len(points.xy):
        drop(ground_slope_rad(dem, points.xy, h) > config.max_slope_rad, "too steep")
    if len(points.xy) == 0:
        raise DataError("no candidate marker site is left (dropped: "
                        + points.dropped_text()
                        + "); enlarge the boundary, shrink exclusions or relax max_slope_deg")
    z = dem.height_at(points.xy) + marker_radius_m
    ids = tuple(f"C{k:05d}" for k in range(len(points.xy)))
    return Candidates(ids=ids, centre_m=np.column_stack([points.xy, z]), dropped=points.dropped)


class GridPoints:
    """Points of a grid filtered step by step, each step's count of dropped points kept by
    its reason (for the message when none is left).

    Examples
    --------
    >>> p = GridPoints(np.arange(3.0), np.arange(2.0))
    >>> p.drop(p.xy[:, 0] > 1.5, "east")
    >>> len(p.xy), p.dropped_text()
    (4, '2 east')
    """

    def __init__(self, gx: np.ndarray, gy: np.ndarray) -> None:
        xx, yy = np.meshgrid(gx, gy)
        self.xy = np.column_stack([xx.ravel(), yy.ravel()])
        self.dropped: dict[str, int] = {}

    def drop(self, mask: np.ndarray, reason: str) -> None:
        """Drop the points where ``mask`` ((n,) bool) holds, counting them under ``reason``."""
        self.dropped[reason] = int(np.sum(mask))
        self.xy = self.xy[~np.asarray(mask, bool)]

    def dropped_text(self) -> str:
        """``"3 outside boundary, 0 on nodata, ..."``."""
        return ", ".join(f"{v} {k}" for k, v in self.dropped.items())


def _too_many(spacing_m: float, n: float, what: str, limit: int, width_m: float,
              height_m: float) -> str:
    """The one-line message for a candidate grid larger than ``limit``."""
    return (f"`grid_spacing_m` {spacing_m:g} m gives {n:.3g} {what} on this {width_m:.0f} x "
            f"{height_m:.0f} m site, more than the {limit} accepted; raise grid_spacing_m or "
            "shrink the boundary")


def ground_slope_rad(dem, xy: np.ndarray, baseline_m: float = SLOPE_BASELINE_M) -> np.ndarray:
    """Ground slope at points from central differences of the DEM over ``baseline_m``, rad.

    Parameters
    ----------
    dem : visibility.dem.DEM
    xy : (n, 2) float
        Site-frame points at least ``baseline_m`` inside the DEM, m.
    """
    e = np.array([[baseline_m, 0.0]])
    n = np.array([[0.0, baseline_m]])
    gx = (dem.height_at(xy + e) - dem.height_at(xy - e)) / (2 * baseline_m)
    gy = (dem.height_at(xy + n) - dem.height_at(xy - n)) / (2 * baseline_m)
    return np.arctan(np.hypot(gx, gy))


def on_terrain(dem, xy: np.ndarray, baseline_m: float = SLOPE_BASELINE_M) -> np.ndarray:
    """Whether each point and the four points of its slope stencil (:func:`ground_slope_rad`)
    lie on measured terrain (:meth:`visibility.dem.DEM.valid_at`).

    Parameters
    ----------
    dem : visibility.dem.DEM
    xy : (n, 2) float
        Site-frame points, m.
    baseline_m : float
        The slope stencil's half-width, m.

    Returns
    -------
    on_data : (n,) bool
    """
    xy = np.atleast_2d(np.asarray(xy, dtype=float))
    ok = dem.valid_at(xy)
    for d in ([baseline_m, 0.0], [-baseline_m, 0.0], [0.0, baseline_m], [0.0, -baseline_m]):
        ok &= dem.valid_at(xy + np.array([d]))
    return ok


def edge_margin_m(dem, marker_radius_m: float) -> float:
    """How far inside the measured terrain's outline a marker must stand, m: two cells, or
    the slope stencil's half-width plus the marker radius when that is more (the sphere and
    the ground it is judged on stay on measured terrain).

    Examples
    --------
    >>> from visibility.dem import DEM
    >>> edge_margin_m(DEM(np.zeros((3, 3)), (0.0, 0.0), 0.5), 0.1)
    1.0
    >>> edge_margin_m(DEM(np.zeros((3, 3)), (0.0, 0.0), 0.1), 0.1)
    0.35
    """
    return max(2.0 * dem.cell_size_m, max(SLOPE_BASELINE_M, dem.cell_size_m) + marker_radius_m)


def valid_area(dem, margin_m: float = 0.0):
    """The DEM's measured terrain as polygons, shrunk by ``margin_m``.

    The outline follows the edges of the valid cells' footprints (cell ``[j, i]`` covers
    ``x0 + (i -+ 0.5) * cell``, ``y0 + (j -+ 0.5) * cell``), including the DEM's own edge;
    nodata inside the area makes holes. It is shrunk by ``margin_m`` plus half a cell and then
    simplified within half a cell, so every point of it lies at least ``margin_m`` inside the
    footprints.

    Parameters
    ----------
    dem : visibility.dem.DEM
        Terrain, site frame.
    margin_m : float
        Distance kept from nodata and from the DEM's edge, m.

    Returns
    -------
    area : shapely Polygon or MultiPolygon
        Site frame, m.

    Raises
    ------
    DataError
        Nothing of the measured terrain is wider than twice ``margin_m``.

    Examples
    --------
    >>> from visibility.dem import DEM
    >>> valid = np.zeros((20, 20), bool); valid[2:18, 2:18] = True
    >>> area = valid_area(DEM(np.zeros((20, 20)), (0.0, 0.0), 1.0, valid=valid), 1.0)
    >>> [round(b, 6) for b in area.bounds]
    [3.0, 3.0, 16.0, 16.0]
    """
    from rasterio import features
    from rasterio.transform import Affine

    c = dem.cell_size_m
    x0, y0 = dem.origin_m
    mask = dem.valid_mask()
    transform = Affine(c, 0.0, x0 - 0.5 * c, 0.0, c, y0 - 0.5 * c)  # rows run along +y
    cells = [shapely.geometry.shape(g) for g, _ in
             features.shapes(mask.astype(np.uint8), mask=mask, transform=transform)]
    area = shapely.union_all(cells).buffer(-(margin_m + 0.5 * c)).simplify(0.5 * c)
    if area.is_empty:
        raise DataError(f"the DEM's measured terrain is nowhere wider than "
                        f"{2 * margin_m:.2f} m (twice the {margin_m:.2f} m kept from nodata and "
                        "the DEM's edge); give a DEM with more measured terrain around the site")
    return area
