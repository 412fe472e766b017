"""The plan's GIS files, in the DEM's CRS: ``plan.gpkg``, the stand-map GeoTIFFs, and the
coordinates of the GeoJSON files.

- ``plan.gpkg`` (GDAL's GPKG driver through pyogrio): layers ``markers`` (Point Z),
  ``stations`` (Point Z), ``sight_lines`` (LineString Z, station -> each marker it uses) and,
  when the site has one, ``boundary`` (Polygon: where markers may go). Written in the DEM's CRS;
  without one (a synthetic site's local frame) the layers have no CRS.
- ``usable_markers.tif`` and ``station_error.tif``: :class:`planner.outputs.stand_map.StandMap` as
  float32 GeoTIFFs, nodata NaN.
- GeoJSON (RFC 7946) is WGS84 longitude/latitude: :func:`geojson_position` transforms to it when
  the DEM's CRS is an Earth CRS; otherwise (no CRS, or a Moon or other body's CRS that has no
  transformation to WGS84) coordinates stay in the site frame / DEM CRS and
  :func:`geojson_crs_members` names the frame in the file.

The same inputs give byte-identical files: GPKG's timestamps are fixed by GDAL's
``OGR_CURRENT_DATE``.

A failed write raises the disk's own :class:`OSError` (its errno), which the output folder
turns into its one line: the GeoTIFFs are made in memory and written by Python; GDAL writes the
GeoPackage itself (a multi-layer GPKG cannot be made in memory through pyogrio) inside
:func:`markerplan.output_folder.library_write`, which asks the disk why GDAL failed.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from planner.accuracy.requirement import datum_text

#: Timestamp GDAL writes into every GPKG (instead of the time of writing).
GPKG_DATE = "2000-01-01T00:00:00Z"

#: Semi-major axes of Earth's ellipsoids lie in this range, m (GRS80/WGS84: 6378137).
EARTH_AXIS_M = (6.37e6, 6.39e6)
#: The Moon's radii in CRS ellipsoids lie in this range, m (IAU 2015 sphere: 1737400).
MOON_AXIS_M = (1.7370e6, 1.7385e6)

#: Decimals of longitude/latitude in GeoJSON (1e-9 degree is about 0.1 mm).
LONLAT_DECIMALS = 9

STAND_MAP_FILES = ("usable_markers.tif", "station_error.tif")


def crs_name(crs: str | None) -> str | None:
    """Short human name of a WKT CRS, with its authority code when it has one.

    >>> from rasterio.crs import CRS
    >>> crs_name(CRS.from_epsg(32633).to_wkt()), crs_name(None)
    ('WGS 84 / UTM zone 33N (EPSG:32633)', None)
    """
    if crs is None:
        return None
    from rasterio.crs import CRS

    c = CRS.from_user_input(crs)
    m = re.match(r'\s*\w+\["([^"]*)"', c.to_wkt())
    name = m.group(1) if m else "unnamed CRS"
    auth = c.to_authority()
    return f"{name} ({auth[0]}:{auth[1]})" if auth else name


def is_earth_crs(crs: str | None) -> bool:
    """Whether a WKT CRS is on Earth (its ellipsoid's semi-major axis is Earth's), i.e. whether
    its coordinates have a WGS84 longitude/latitude.

    >>> from rasterio.crs import CRS
    >>> is_earth_crs(CRS.from_epsg(32633).to_wkt()), is_earth_crs(None)
    (True, False)
    >>> is_earth_crs(CRS.from_user_input("IAU_2015:30100").to_wkt())
    False
    """
    axis = _semi_major_m(crs)
    return axis is not None and EARTH_AXIS_M[0] <= axis <= EARTH_AXIS_M[1]


def _semi_major_m(crs: str | None) -> float | None:
    """Semi-major axis of a WKT CRS's ellipsoid, m (``None``: no CRS or no ellipsoid)."""
    if crs is None:
        return None
    from rasterio.crs import CRS

    m = re.search(r'(?:SPHEROID|ELLIPSOID)\["[^"]*",\s*([0-9.eE+]+)',
                  CRS.from_user_input(crs).to_wkt())
    return None if m is None else float(m.group(1))


def crs_body(crs: str | None):
    """The body of a WKT CRS's ellipsoid, for the local vertical's curvature
    (:class:`pipeline.network.body.Body`): Earth's or the Moon's ellipsoid give the named body
    (its mean radius), any other a sphere of its semi-major axis; ``None`` without a CRS or an
    ellipsoid.

    >>> from rasterio.crs import CRS
    >>> crs_body(CRS.from_user_input("IAU_2015:30100").to_wkt())
    Body(name='moon', radius_m=1737400.0)
    >>> crs_body(CRS.from_epsg(32633).to_wkt()).name, crs_body(None)
    ('earth', None)
    """
    from pipeline.network.body import Body

    axis = _semi_major_m(crs)
    if axis is None:
        return None
    for name, (low, high) in (("earth", EARTH_AXIS_M), ("moon", MOON_AXIS_M)):
        if low <= axis <= high:
            return Body.named(name)
    return Body("sphere", axis)


def to_lonlat(crs: str, xy: np.ndarray) -> np.ndarray:
    """WGS84 longitude, latitude (degrees) of points in an Earth CRS.

    Parameters
    ----------
    crs : str
        WKT of an Earth CRS (:func:`is_earth_crs`).
    xy : (n, 2) float
        Points in that CRS, m.

    Returns
    -------
    lonlat : (n, 2) float
    """
    from rasterio.warp import transform

    xy = np.asarray(xy, float).reshape(-1, 2)
    if not xy.size:
        return xy.copy()
    lon, lat = transform(crs, "EPSG:4326", xy[:, 0].tolist(), xy[:, 1].tolist())
    return np.column_stack([lon, lat])


def geojson_positions(crs: str | None, xyz: np.ndarray) -> list[list[float]]:
    """GeoJSON positions of points: ``[lon, lat, z]`` (WGS84, z in m as given) when ``crs`` is
    an Earth CRS, else ``[x, y, z]`` unchanged (site frame / DEM CRS, m).

    Parameters
    ----------
    crs : str or None
        WKT of the points' CRS.
    xyz : (n, 3) float

    Returns
    -------
    positions : list of n lists of 3 float
    """
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    if not is_earth_crs(crs):
        return xyz.tolist()
    ll = np.round(to_lonlat(crs, xyz[:, :2]), LONLAT_DECIMALS)
    return np.column_stack([ll, xyz[:, 2]]).tolist()


def geojson_crs_members(crs: str | None, frame_note: str) -> dict:
    """Top-level members saying in which frame a GeoJSON file's coordinates are.

    Earth CRS: RFC 7946 WGS84 longitude/latitude (``coordinate_frame`` says so and names the
    DEM's CRS the properties' ``x_m``/``y_m`` are in). Otherwise the coordinates are the site
    frame's or the DEM CRS's metres: ``coordinate_frame`` says which, and a CRS gets a
    ``crs`` member (the pre-RFC 7946 ``name`` form, which QGIS and GDAL read).
    """
    if is_earth_crs(crs):
        return {"coordinate_frame": "WGS84 longitude, latitude (degrees; RFC 7946), z in m; "
                                    f"x_m, y_m in the DEM's CRS, {crs_name(crs)}",
                "source_crs": crs_name(crs)}
    out = {"coordinate_frame": frame_note, "units": "m"}
    if crs is not None:
        out["crs"] = {"type": "name", "properties": {"name": crs_urn(crs)}}
    return out


def crs_urn(crs: str) -> str:
    """The OGC URN of a WKT CRS (``urn:ogc:def:crs:AUTH::CODE``), which GDAL and QGIS read in
    a GeoJSON ``crs`` member; the CRS's name when GDAL finds no authority code for it (e.g.
    the lunar IAU_2015 CRSs, whose WKT1 carries an ``IAU`` authority GDAL does not resolve).

    >>> from rasterio.crs import CRS
    >>> crs_urn(CRS.from_epsg(32633).to_wkt())
    'urn:ogc:def:crs:EPSG::32633'
    """
    from rasterio.crs import CRS

    auth = CRS.from_user_input(crs).to_authority()
    return f"urn:ogc:def:crs:{auth[0]}::{auth[1]}" if auth else crs_name(crs)


def write_plan_gpkg(outcome, doc: dict, path: Path) -> Path:
    """Write ``plan.gpkg``: layers markers, stations, sight_lines and (when the site has one)
    boundary, in the DEM's CRS (none without one); a plan that chose its stations also the
    layers route, aoi and candidate_stations (:func:`design_layers`).

    Parameters
    ----------
    outcome : planner.run.PlanOutcome
        Gives the DEM's CRS, the pairs' distances and sigmas, the boundary.
    doc : dict
        The ``plan.json`` document (markers, stations, network datum).
    path : Path

    Returns
    -------
    path : Path
    """
    import shapely

    prob, res = outcome.problem, outcome.result
    crs = outcome.inputs.dem.crs
    markers, stations = doc["markers"], doc["stations"]
    relative = datum_text(doc["network"]["datum"]) if "network" in doc else "known control"

    def xyz(rows):
        return np.array([[r["x_m"], r["y_m"], r["z_m"]] for r in rows], float).reshape(-1, 3)

    mxyz, sxyz = xyz(markers), xyz(stations)
    layers = {
        "markers": ("Point Z", shapely.points(mxyz), {
            "id": np.array([m["id"] for m in markers], object),
            "x_m": mxyz[:, 0], "y_m": mxyz[:, 1], "z_m": mxyz[:, 2],
            "n_stations": np.array([len(m["stations"]) for m in markers], np.int32),
            "existing": np.array([m["existing"] for m in markers], bool)}),
        "stations": ("Point Z", shapely.points(sxyz), {
            "id": np.array([s["id"] for s in stations], object),
            "predicted_error_m": np.array([np.nan if s["predicted_error_m"] is None
                                           else s["predicted_error_m"] for s in stations]),
            "error_relative_to": np.array([relative] * len(stations), object),
            "meets_requirement": np.array([s["meets_requirement"] for s in stations], bool),
            "n_markers": np.array([s["n_markers"] for s in stations], np.int32),
            "n_sectors": np.array([s["n_sectors"] for s in stations], np.int32)}),
    }
    pairs = np.concatenate([prob.selected_pairs(s, res.selected)
                            for s in range(prob.n_stations)]).astype(np.int64)
    ends = np.stack([prob.station_xyz[prob.pair_station[pairs]],
                     prob.site_xyz[prob.pair_site[pairs]]], axis=1)
    layers["sight_lines"] = ("LineString Z", shapely.linestrings(ends), {
        "station_id": np.array([prob.station_ids[s] for s in prob.pair_station[pairs]], object),
        "marker_id": np.array([prob.site_ids[j] for j in prob.pair_site[pairs]], object),
        "distance_m": prob.pair_distance_m[pairs], "sigma_m": prob.pair_sigma_m[pairs]})
    if outcome.inputs.boundary_xy is not None:
        layers["boundary"] = ("Polygon", shapely.polygons([np.asarray(outcome.inputs.boundary_xy,
                                                                     float)]),
                              {"site": np.array([doc["site"]["name"]], object)})
    if outcome.design is not None:
        layers.update(design_layers(outcome.design, outcome.inputs.dem))
    return write_gpkg_layers(path, layers, crs)


def design_layers(design, dem) -> dict:
    """The GeoPackage layers of a survey design (:class:`planner.design.run.SurveyDesign`):
    ``route`` (the traverse over the ground, one 3D line from the start and back),
    ``aoi`` (the area of interest) and ``candidate_stations`` (every candidate, whether
    chosen and its place on the route), in :func:`write_gpkg_layers`' form."""
    import shapely

    line = np.column_stack([design.route.polyline, dem.height_at(design.route.polyline)])
    n = len(design.candidate_ids)
    order = np.zeros(n, np.int32)
    order[design.order] = np.arange(1, design.order.size + 1)
    covered = np.bincount(design.coverage.station, minlength=n).astype(np.int32)
    ground = design.candidate_position_m.copy()
    ground[:, 2] = dem.height_at(ground[:, :2])
    return {
        "route": ("LineString Z", shapely.linestrings([line]), {
            "length_m": np.array([design.route.length_m]),
            "n_stations": np.array([design.order.size], np.int32),
            "start": np.array([design.route_start_source], object)}),
        "aoi": ("MultiPolygon", np.array([shapely.multipolygons(
            shapely.get_parts(design.aoi))]), {
            "area_m2": np.array([design.aoi.area]),
            "n_cells": np.array([len(design.grid)], np.int32)}),
        "candidate_stations": ("Point Z", shapely.points(ground), {
            "id": np.array(design.candidate_ids, object),
            "chosen": order > 0, "route_order": order, "cells_covered": covered}),
    }


def write_gpkg_layers(path: Path, layers: dict, crs: str | None) -> Path:
    """Write layers into one GeoPackage (GDAL's GPKG driver), timestamps fixed
    (:data:`GPKG_DATE`) so that the same layers give the same bytes.

    Parameters
    ----------
    path : Path
        A GeoPackage not yet written (each layer is added to it).
    layers : dict
        ``{name: (geometry type, geometries, {field: array})}``: an OGR geometry type name
        (``"Point Z"``, ``"LineString Z"``, ``"Polygon"``), (k,) shapely geometries (site
        frame / CRS metres) and (k,) numpy arrays of the attributes, in column order.
    crs : str or None
        WKT of every layer's CRS; None: layers without a CRS.

    Returns
    -------
    path : Path

    Raises
    ------
    OSError
        The disk's refusal (full, a file-size limit, read-only...) when GDAL fails to write.
    """
    import pyogrio
    import shapely
    from pyogrio.raw import write

    from markerplan.output_folder import library_write

    path = Path(path)
    pyogrio.set_gdal_config_options({"OGR_CURRENT_DATE": GPKG_DATE})
    try:
        with library_write(path), warnings.catch_warnings():
            # no CRS is deliberate (a synthetic site's local frame; docs/planner.md says so)
            warnings.filterwarnings("ignore", "'crs' was not provided", UserWarning)
            for name, (gtype, geoms, fields) in layers.items():
                dim = 3 if gtype.endswith(" Z") else 2
                write(path, shapely.to_wkb(geoms, output_dimension=dim, include_srid=False),
                      field_data=list(fields.values()), fields=list(fields), layer=name,
                      driver="GPKG", geometry_type=gtype, crs=crs)
    finally:
        pyogrio.set_gdal_config_options({"OGR_CURRENT_DATE": None})
    return path


def write_stand_map(stand, folder: Path) -> list[Path]:
    """Write a :class:`planner.outputs.stand_map.StandMap` as ``usable_markers.tif`` and
    ``station_error.tif`` (float32, one band, nodata NaN, DEM's CRS) into ``folder``
    (:func:`write_float_geotiff`)."""
    out = []
    for name, band in zip(STAND_MAP_FILES, (stand.usable, stand.error_m), strict=True):
        description = ("usable markers" if name.startswith("usable")
                       else "predicted 95 % station error (m)")
        out.append(write_float_geotiff(Path(folder) / name, [band], [description],
                                       stand.transform, stand.crs))
    return out


def write_float_geotiff(path: Path, bands, descriptions, transform: tuple,
                        crs: str | None) -> Path:
    """Write float32 bands as one GeoTIFF (nodata NaN).

    The GeoTIFF is made in memory and written by Python, so a failing disk raises its own
    :class:`OSError` (its errno) rather than GDAL's "Write failed" and libtiff's lines on
    stderr.

    Parameters
    ----------
    path : Path
        The file (inside an output folder's staging folder).
    bands : sequence of (ny, nx) float
        The bands, row 0 the northern one.
    descriptions : sequence of str
        One per band.
    transform : tuple of 6 float
        GDAL-order affine of the grid, m.
    crs : str or None
        WKT of the grid's CRS.

    Returns
    -------
    path : Path
    """
    from rasterio.io import MemoryFile
    from rasterio.transform import Affine

    path = Path(path)
    ny, nx = bands[0].shape
    with MemoryFile() as memory:
        with memory.open(driver="GTiff", height=ny, width=nx, count=len(bands),
                         dtype="float32", crs=crs, nodata=np.nan,
                         transform=Affine(*transform)) as dst:
            for k, (band, text) in enumerate(zip(bands, descriptions, strict=True), start=1):
                dst.write(np.asarray(band, np.float32), k)
                dst.set_band_description(k, text)
        path.write_bytes(memory.read())
    return path
