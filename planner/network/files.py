"""The files of ``markerplan adjust``: tables, covariance, GeoJSON and the JSON summary.

Written by :func:`write_network_files` into the command's output folder (numbers from
:mod:`planner.network.record`, spelled by :mod:`markerplan.writing`):

================== ===========================================================================
file               content
================== ===========================================================================
stations.csv       adjusted poses, sigmas, 95 % ellipsoid semi-axes, 95 % station error
stations.csvt      its column types, for QGIS / GDAL (``"String","Real",...``)
markers.csv        adjusted centres, sigmas, 95 % ellipsoid semi-axes, stations that saw them
markers.csvt       its column types
observations.csv   every identified detection: residuals, redundancy numbers, the test of the
                   point observation and the per-component w-tests, MDBs and their effect,
                   robust weight; ``status`` kept / flagged / removed
parameters.csv     the unknowns in the covariance's order, with values and sigmas (m, rad)
covariance.npy     the full a-priori covariance (sigma0 = 1) of all unknowns, m^2 and rad^2
                   (not with the sparse covariance: only its marginal blocks exist)
network.geojson    stations and markers (Points) and the ties (LineStrings), site frame
adjustment.json    the summary: configuration, version, solver status, datum, sigma0^2, dof,
                   global test, rejected observations, reliability, requirement
report.md          the report a surveyor reads (:mod:`planner.network.report`)
network.png        the network map (:mod:`planner.network.map`)
================== ===========================================================================

With variance components estimated, ``variance_components.csv`` (:data:`VARIANCE_FILES`) holds
them, one row per group and a last row ``all`` for the whole network. With relative accuracy
asked for (:attr:`planner.network.record.AdjustmentRun.relative`), ``relative.csv``
(:data:`RELATIVE_FILES`) holds the relative error ellipses of the neighbouring station pairs
(:mod:`planner.network.relative`) and ``adjustment.json`` its ``relative`` section.

Every CSV opens with its header. With a CRS (:attr:`planner.network.record.AdjustmentRun.crs`)
``stations.prj`` and ``markers.prj`` (:data:`PRJ_FILES`) hold its WKT for GIS readers
(:func:`markerplan.writing.write_gis_sidecars`); ``adjustment.json`` names the frame too.

No file holds a timing or a host name, so the same inputs give byte-identical files.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from markerplan.writing import column_types, json_default, write_csv, write_gis_sidecars
from planner.network import record as nr
from planner.network.relative import RELATIVE_COLUMNS, relative_rows, relative_section
from planner.outputs.gis import geojson_crs_members, geojson_positions

FILES = ("stations.csv", "stations.csvt", "markers.csv", "markers.csvt", "observations.csv",
         "parameters.csv", "covariance.npy", "network.geojson", "adjustment.json", "report.md",
         "network.png")
#: Written besides :data:`FILES` when the coordinates have a CRS.
PRJ_FILES = ("stations.prj", "markers.prj")
#: Written besides :data:`FILES` when variance components are estimated.
VARIANCE_FILES = ("variance_components.csv",)
#: Written besides :data:`FILES` with relative accuracy.
RELATIVE_FILES = ("relative.csv",)


def write_network_files(folder: str | Path, run: nr.AdjustmentRun, draw_map: bool = True
                        ) -> dict:
    """Write every file of :data:`FILES` (and, with a CRS, :data:`PRJ_FILES`; with variance
    components, :data:`VARIANCE_FILES`) into ``folder``.

    Parameters
    ----------
    folder : str or Path
        Existing output folder.
    run : AdjustmentRun
        The adjustment and its context.
    draw_map : bool
        Draw ``network.png`` (matplotlib; about a second).

    Returns
    -------
    doc : dict
        The ``adjustment.json`` document.
    """
    from pipeline.network.reliability import critical_value
    from planner.network.map import draw_network_map
    from planner.network.report import report_markdown

    folder = Path(folder)
    stations = nr.station_rows(run)
    markers = nr.marker_rows(run)
    observations = nr.observation_rows(run, critical_value(run.result.settings.alpha0))
    dense = isinstance(run.result.covariance, np.ndarray)
    files = [f for f in FILES if (draw_map or f != "network.png")
             and (dense or f != "covariance.npy")]
    if run.crs is not None:
        files += PRJ_FILES
    variance = nr.variance_rows(run.result)
    if variance:
        files += VARIANCE_FILES
    relative = [] if run.relative is None else relative_rows(run.result, run.relative)
    if run.relative is not None:
        files += RELATIVE_FILES
    doc = nr.adjustment_record(run, stations, markers, observations, files)
    doc["relative"] = (None if run.relative is None
                       else relative_section(relative, run.relative))
    doc = finite_json(doc)
    for name, columns, rows in (("stations.csv", nr.STATION_COLUMNS, stations),
                                ("markers.csv", nr.MARKER_COLUMNS, markers)):
        write_csv(folder / name, columns, rows)
        write_gis_sidecars(folder / name, column_types(columns, rows), run.crs)
    write_csv(folder / "observations.csv", nr.OBSERVATION_COLUMNS, observations)
    write_csv(folder / "parameters.csv", nr.PARAMETER_COLUMNS, nr.parameter_rows(run.result))
    if variance:
        write_csv(folder / "variance_components.csv", nr.VARIANCE_COLUMNS, variance)
    if run.relative is not None:
        write_csv(folder / "relative.csv", RELATIVE_COLUMNS, relative)
    if dense:
        np.save(folder / "covariance.npy", np.ascontiguousarray(run.result.covariance,
                                                                dtype=np.float64))
    write_json(folder / "network.geojson",
               network_geojson(doc, stations, markers, observations, run.crs))
    write_json(folder / "adjustment.json", doc)
    (folder / "report.md").write_text(report_markdown(doc, stations, markers, observations,
                                                      relative), encoding="utf-8")
    if draw_map:
        draw_network_map(run, stations, markers, observations, folder / "network.png")
    return doc


def write_json(path: Path, doc: Any) -> None:
    """Write ``doc`` as indented JSON with sorted keys (numpy values allowed)."""
    Path(path).write_text(json.dumps(doc, indent=1, sort_keys=True, default=json_default)
                          + "\n", encoding="utf-8")


def finite_json(value: Any) -> Any:
    """``value`` with every non-finite float (nan, inf) replaced by ``None`` at any depth.

    >>> finite_json({"a": [1.0, float("nan")], "b": float("inf"), "c": "x"})
    {'a': [1.0, None], 'b': None, 'c': 'x'}
    """
    if isinstance(value, dict):
        return {k: finite_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite_json(v) for v in value]
    if isinstance(value, float | np.floating) and not math.isfinite(value):
        return None
    return value


def _point(row: dict) -> list[float]:
    return [round(float(row[c]), 4) for c in ("x_m", "y_m", "z_m")]


def network_geojson(doc: dict, stations: list[dict], markers: list[dict],
                    observations: list[dict], crs: str | None = None) -> dict:
    """The network as a GeoJSON FeatureCollection.

    Stations and markers are Points (x, y, z, m) with their 95 % figures; every identified
    observation is a LineString from its station to its marker, with its ``status``. As the
    plan's ``markers.geojson`` (:func:`planner.outputs.gis.geojson_positions`): WGS84
    longitude/latitude when ``crs`` is an Earth CRS, else the site frame's metres, and
    ``coordinate_frame`` says which.

    Parameters
    ----------
    doc : dict
        The ``adjustment.json`` document (frame, datum, provenance).
    stations, markers, observations : list of dict
        Rows of :mod:`planner.network.record`.
    crs : str, optional
        WKT of the coordinates' CRS (:attr:`planner.network.record.AdjustmentRun.crs`).

    Returns
    -------
    geojson : dict
    """
    keys = [s["station_id"] for s in stations] + [("marker", m["marker_id"]) for m in markers]
    where = dict(zip(keys, geojson_positions(crs, [_point(r) for r in stations + markers]),
                     strict=True))
    feats = [{"type": "Feature",
              "geometry": {"type": "Point", "coordinates": where[s["station_id"]]},
              "properties": {"id": s["station_id"], "kind": "station",
                             "reference": s["reference"],
                             "heading_deg": round(s["heading_deg"], 4),
                             "station_error_95_m": _round(s["station_error_95_m"]),
                             "ellipsoid_major_m": _round(s["ellipsoid_major_m"]),
                             "meets_requirement": s["meets_requirement"]}} for s in stations]
    feats += [{"type": "Feature",
               "geometry": {"type": "Point", "coordinates": where["marker", m["marker_id"]]},
               "properties": {"id": m["marker_id"], "kind": "marker", "control": m["control"],
                              "ellipsoid_major_m": _round(m["ellipsoid_major_m"]),
                              "n_stations": m["n_stations"],
                              "stations": m["stations"].split()}} for m in markers]
    feats += [{"type": "Feature",
               "geometry": {"type": "LineString",
                            "coordinates": [where[o["station_id"]],
                                            where["marker", o["marker_id"]]]},
               "properties": {"kind": "tie", "station_id": o["station_id"],
                              "marker_id": o["marker_id"], "status": o["status"],
                              "max_abs_w": _round(o["max_abs_w"], 3),
                              "test_w": _round(o["test_w"], 3)}}
              for o in observations if ("marker", o["marker_id"]) in where]
    prov = doc["provenance"]
    return {"type": "FeatureCollection", "name": "markerplan adjust: network",
            **geojson_crs_members(crs, doc["frame"]), "datum": doc["datum"]["description"],
            "markerplan_version": prov["markerplan_version"],
            "config_sha256": prov["config_sha256"], "features": feats}


def _round(value: float | None, digits: int = 5) -> float | None:
    if value is None or not math.isfinite(value):
        return None
    return round(float(value), digits)
