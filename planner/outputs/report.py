"""Plan outputs: ``plan.json`` (versioned schema), ``markers.csv``, ``markers.geojson``,
``report.md``, and the one-object JSON summary of ``markerplan plan --json``.

The CSV tables open with their header (:data:`MARKER_COLUMNS`, :data:`STATION_COLUMNS`), so
pandas, QGIS and spreadsheets read them with default settings; beside each, ``.csvt`` gives
QGIS / GDAL the column types and, when the DEM has a CRS, ``.prj`` its WKT
(:func:`markerplan.writing.write_gis_sidecars`). Their frame is ``plan.json``'s ``frame`` and
``site.crs`` / ``site.crs_wkt``.

``plan.json`` schema ``markerplan-plan`` version 1 (all lengths in metres, site frame = the
DEM's CRS when it has one):

- ``schema``, ``schema_version``
- ``provenance``: :func:`markerplan.provenance.provenance` of the resolved configuration, with
  the error model, solver and inputs;
- ``frame``: the coordinate frame in words (:func:`frame_note`: the DEM's CRS by name, or the
  local site frame);
- ``site``: name, seed, CRS name (None: local site frame), marker radius, boundary;
- ``requirement``: requirement_m, requirement_ppm and the requirement in words, sectors,
  markers, working radius, redundant, the 95 % figure;
- ``solver``: name, HiGHS version, threads, time limit, target gap, status, objective, dual
  bound, gap, iterations, cuts, ``local_search`` (large network plans: the greedy start's
  markers and how many its pruning removed) and ``root_relaxation`` (large network plans: the
  root bound, LP solves, tangent and count rows, time and why it stopped);
- ``markers``: id, x_m, y_m, z_m, existing, stations that use it;
- ``stations``: id, position, heading, predicted error, markers used, occupied sectors,
  (redundant mode) worst error after losing one marker, meets_requirement;
- ``baselines``: greedy, regular grid, as-built — markers, meets_requirement, saved, and
  ``note`` (why it falls short: a stuck network greedy's message) when there is one;
- ``candidates`` and ``visibility``: counts.

No file holds a timing, so the same inputs give byte-identical files; :func:`plan_timings`
gives them to the command's stderr and ``--json`` summary instead.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from markerplan.provenance import provenance
from markerplan.writing import json_float, write_gis_sidecars
from planner.accuracy.requirement import (
    datum_clause,
    datum_text,
    requirement_record,
    requirement_text,
)
from planner.outputs.chance_report import chance_markdown, chance_sections
from planner.outputs.design_report import design_markdown, design_record, station_route_fields
from planner.outputs.gis import crs_name, geojson_crs_members, geojson_positions, write_plan_gpkg
from planner.outputs.local_report import local_markdown, local_record, write_pairs_csv
from planner.outputs.plan_file import SCHEMA, SCHEMA_VERSION, write_plan
from planner.problem.usability import sector_index
from planner.program.highs import solver_record

FRAME_NOTE = ("site frame: local metres (x, y horizontal, z up); not geographic coordinates, "
              "not WGS84")


def frame_note(crs: str | None) -> str:
    """The plan's coordinate frame in words: :data:`FRAME_NOTE` without a CRS, else the DEM's
    CRS by name.

    >>> frame_note(None) == FRAME_NOTE
    True
    """
    if crs is None:
        return FRAME_NOTE
    return f"the DEM's CRS, {crs_name(crs)}: x, y in metres of that CRS, z up (DEM heights, m)"



def plan_record(outcome) -> dict:
    """The ``plan.json`` document of a :class:`~planner.run.PlanOutcome`."""
    inp, cfg, prob, res = outcome.inputs, outcome.config, outcome.problem, outcome.result
    sol = res.solution
    sel = np.flatnonzero(res.selected)
    used_by: dict[int, list[str]] = {int(j): [] for j in sel}
    stations = []
    for s in range(prob.n_stations):
        idx = prob.selected_pairs(s, res.selected)
        for j in prob.pair_site[idx]:
            used_by[int(j)].append(prob.station_ids[s])
        rec = {"id": prob.station_ids[s],
               "x_m": json_float(prob.station_xyz[s, 0]), "y_m": json_float(prob.station_xyz[s, 1]),
               "z_m": json_float(prob.station_xyz[s, 2]),
               "heading_rad": json_float(inp.station_heading_rad[s]),
               "predicted_error_m": json_float(res.check.error_m[s]),
               "n_markers": int(res.check.count[s]), "n_sectors": int(res.check.sectors[s]),
               "markers": [prob.site_ids[j] for j in prob.pair_site[idx]],
               "sectors": sorted({int(k) for k in sector_index(prob.pair_bearing_rad[idx],
                                                                 cfg.n_sectors)}),
               "meets_requirement": bool(res.check.ok[s])}
        if res.check.worst_loss_error_m is not None:
            rec["worst_loss_error_m"] = json_float(res.check.worst_loss_error_m[s])
            rec["worst_loss_sectors"] = int(res.check.worst_loss_sectors[s])
        stations.append(rec)
    markers = [{"id": prob.site_ids[j], "x_m": json_float(prob.site_xyz[j, 0]),
                "y_m": json_float(prob.site_xyz[j, 1]), "z_m": json_float(prob.site_xyz[j, 2]),
                "existing": bool(prob.site_existing[j]), "stations": used_by[int(j)],
                **({"control": bool(prob.site_control[j])}
                   if prob.site_control_sigma_m is not None else {})}
               for j in sel]
    n_plan = len(sel)
    baselines = {}
    for b in outcome.baselines:
        key = b.name.replace(" ", "_")
        baselines[key] = {"n_markers": b.n_markers, "meets_requirement": b.meets_requirement,
                          "saved_by_plan": b.n_markers - n_plan if b.meets_requirement else None,
                          "marker_ids": [prob.site_ids[j] for j in np.flatnonzero(b.selected)]}
        if b.spacing_m is not None:
            baselines[key]["spacing_m"] = b.spacing_m
        if b.note is not None:
            baselines[key]["note"] = b.note
    if outcome.as_built is not None:
        ab = outcome.as_built
        baselines["as_built"] = {
            "n_markers": len(inp.as_built_ids), "meets_requirement": ab.all_ok,
            "saved_by_plan": len(inp.as_built_ids) - n_plan,
            "station_error_m": [json_float(v) for v in ab.error_m],
            "station_sectors": [int(v) for v in ab.sectors]}
    solver = {**solver_record(cfg.time_limit_s, cfg.mip_gap), "status": sol.status,
              "objective": json_float(sol.objective), "dual_bound": json_float(sol.dual_bound),
              "gap": json_float(sol.gap),
              "iterations": res.iterations, "accuracy_cuts": res.n_cuts,
              "proven_optimal": sol.status == "optimal",
              "local_search": None if res.pruning is None else res.pruning.record(),
              "root_relaxation": res.root}
    vis = outcome.visibility
    network = _network_record(outcome, stations, markers) if cfg.network else None
    doc = {
        "schema": SCHEMA, "schema_version": SCHEMA_VERSION,
        "provenance": provenance(cfg.to_dict(), error_model=outcome.model_name,
                                 detection_model=(outcome.detection or {}).get("name"),
                                 solver={"name": solver["name"], "status": sol.status},
                                 inputs=inp.sources),
        "frame": frame_note(inp.dem.crs),
        "site": {"name": inp.site_name, "seed": inp.site_seed, "crs": crs_name(inp.dem.crs),
                 "crs_wkt": inp.dem.crs,
                 "marker_radius_m": inp.marker_radius_m,
                 "boundary_xy_m": None if inp.boundary_xy is None
                 else np.asarray(inp.boundary_xy).tolist()},
        "requirement": requirement_record(cfg),
        "solver": solver,
        "n_markers": n_plan,
        "meets_requirement": bool(res.check.all_ok),
        "markers": markers,
        "stations": stations,
        "baselines": baselines,
        "candidates": {"n_sites": prob.n_sites,
                       "dropped": outcome.candidates.dropped if outcome.candidates else None},
        "visibility": {"n_pairs": int(prob.pair_station.size),
                       "n_usable": int(prob.pair_usable.sum()),
                       "n_rays": int(vis.n_rays) if vis is not None else 0},
    }
    if network is not None:
        doc["network"], local = network
        if local is not None:
            doc["local"] = local
    doc.update(chance_sections(outcome))
    for rec in doc["stations"] if "chance" in doc else ():
        rec["pass_probability"] = doc["chance"]["stations"][rec["id"]]["pass_probability"]
    if outcome.design is not None:
        doc["design"] = design_record(outcome.design,
                                      int(np.sum(~prob.site_existing[res.selected])))
        for rec, route in zip(doc["stations"], station_route_fields(outcome.design),
                              strict=True):
            rec.update(route)
    return doc


def _network_record(outcome, stations: list[dict], markers: list[dict]
                    ) -> tuple[dict, dict | None]:
    """Network mode: the datum, per-station ties, largest MDB effects, allowances and
    per-marker errors (added in place to ``stations`` and ``markers``), and the weakest
    stations; with the local requirement's section
    (:func:`planner.outputs.local_report.local_record`, None without one)."""
    from planner.accuracy.network import network_model
    from planner.accuracy.reliability import layout_reliability, station_bias_record

    cfg, prob, res = outcome.config, outcome.problem, outcome.result
    net = network_model(prob, cfg)
    ties = net.ties(res.selected)
    bias = station_bias_record(net, layout_reliability(net, res.selected))
    for k, rec in enumerate(stations):
        rec["allowed_error_m"] = json_float(net.allowed_station_m[k])
        rec["tied_to"] = {prob.station_ids[o]: int(ties[k, o]) for o in np.flatnonzero(ties[k])}
        rec.update(bias[rec["id"]])
    for rec, j in zip(markers, np.flatnonzero(res.selected), strict=True):
        rec["predicted_error_m"] = json_float(res.check.marker_error_m[j])
        rec["allowed_error_m"] = json_float(net.allowed_site_m[j])
    allowed = net.allowed_station_m
    relative = np.where(np.isfinite(allowed), res.check.error_m / allowed, res.check.error_m)
    order = np.argsort(-np.nan_to_num(relative, posinf=1e300), kind="stable")
    effect = np.array([math.inf if s["bias_effect_m"] is None else s["bias_effect_m"]
                       for s in stations])
    worst_bias = stations[int(np.argmax(effect))] if stations else None
    return {"datum": {**net.datum_record(), **cfg.aids_record()},
            "weakest_stations": [{"id": prob.station_ids[k],
                                  "predicted_error_m": json_float(res.check.error_m[k])}
                                 for k in order[:5]],
            "worst_marker_error_m": json_float(np.nanmax(res.check.marker_error_m))
            if res.selected.any() else None,
            "n_station_ties": int((np.triu(ties) > 0).sum()),
            "reliability": {"max_bias_effect_m": cfg.max_bias_effect_m,
                            "worst_bias_effect": None if worst_bias is None else {
                                "station": worst_bias["id"],
                                "bias_effect_m": worst_bias["bias_effect_m"],
                                "caused_by": worst_bias["bias_effect_caused_by"]}}}, \
        local_record(outcome, net)


def plan_timings(outcome) -> dict[str, float]:
    """Wall-clock seconds of the plan's steps (candidates, scene, visibility, solver)."""
    return {**{k: round(v, 3) for k, v in outcome.timings_s.items()},
            "solver": round(outcome.result.solve_time_s, 3)}


def write_plan_files(outcome, folder: Path) -> dict:
    """Write plan.json, markers.csv (with .csvt and, with a CRS, .prj), markers.geojson,
    plan.gpkg (:func:`planner.outputs.gis.write_plan_gpkg`) and report.md into ``folder``
    (network mode: also stations.csv and its sidecars, each station's error relative to the
    datum and its ties; a plan that chose its stations: stations.csv with each station's
    place on the route, and coverage.tif).

    Returns the ``plan.json`` document.
    """
    folder = Path(folder)
    doc = plan_record(outcome)
    write_plan(doc, folder / "plan.json")
    _write_markers_csv(doc, folder / "markers.csv")
    if "local" in doc:
        write_pairs_csv(doc, folder / "pairs.csv")
        if "marker_pairs" in doc["local"]:
            write_pairs_csv(doc, folder / "marker_pairs.csv", markers=True)
    if "network" in doc or "design" in doc:
        _write_stations_csv(doc, folder / "stations.csv")
    if "network" in doc:
        _write_reliability_csv(outcome, folder / "reliability.csv")
    if outcome.design is not None:
        write_design_coverage(outcome.design, folder)
    _write_geojson(doc, outcome.inputs.dem.crs, folder / "markers.geojson")
    write_plan_gpkg(outcome, doc, folder / "plan.gpkg")
    (folder / "report.md").write_text(report_markdown(doc))
    return doc


#: ``markers.csv`` of a plan: header and ``.csvt`` column types.
MARKER_COLUMNS = ("id", "x_m", "y_m", "z_m", "existing", "n_stations", "stations")
MARKER_TYPES = ("String", "Real", "Real", "Real", "Integer", "Integer", "String")
#: ``stations.csv`` of a network plan: header and ``.csvt`` column types.
STATION_COLUMNS = ("id", "x_m", "y_m", "z_m", "network_error_m", "meets_requirement",
                   "n_markers", "tied_to", "error_relative_to")
STATION_TYPES = ("String", "Real", "Real", "Real", "Real", "Integer", "Integer", "String",
                 "String")
#: ... of a known-control plan that chose its stations (the route's columns follow).
KNOWN_STATION_COLUMNS = ("id", "x_m", "y_m", "z_m", "predicted_error_m", "meets_requirement",
                         "n_markers")
KNOWN_STATION_TYPES = ("String", "Real", "Real", "Real", "Real", "Integer", "Integer")
#: ... and the route's columns of a plan that chose its stations.
ROUTE_COLUMNS = ("route_order", "leg_m", "drive_m", "heading_deg", "cells_covered")
ROUTE_TYPES = ("Integer", "Real", "Real", "Real", "Integer")


def _write_markers_csv(doc: dict, path: Path) -> None:
    """``markers.csv`` (header first), its ``.csvt`` and, with a CRS, its ``.prj``."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(MARKER_COLUMNS)
        for m in doc["markers"]:
            w.writerow([m["id"], f"{m['x_m']:.3f}", f"{m['y_m']:.3f}", f"{m['z_m']:.3f}",
                        int(m["existing"]), len(m["stations"]), " ".join(m["stations"])])
    write_gis_sidecars(path, MARKER_TYPES, doc["site"]["crs_wkt"])


def _relative_to(datum: dict) -> str:
    """What the report's errors are relative to: the datum, or in a free network nothing (its
    per-station and per-marker figures are datum-free and not judged)."""
    if datum.get("kind") == "free":
        return (f"{datum_clause(datum)}; station and marker figures are datum-free, not "
                "judged against a requirement (only the local requirement is)")
    return f"every error is relative to the datum, {datum_clause(datum)}"


def _write_stations_csv(doc: dict, path: Path) -> None:
    """``stations.csv`` (header first), its ``.csvt`` and, with a CRS, its ``.prj``: network
    mode's (``error_relative_to`` names the datum), then, for a plan that chose its stations,
    each station's place on the route (:data:`ROUTE_COLUMNS`; rows in route order)."""
    network = "network" in doc
    route = "design" in doc
    datum = datum_text(doc["network"]["datum"]) if network else None
    columns = (STATION_COLUMNS if network else KNOWN_STATION_COLUMNS) \
        + (ROUTE_COLUMNS if route else ())
    types = (STATION_TYPES if network else KNOWN_STATION_TYPES) + (ROUTE_TYPES if route else ())
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for s in doc["stations"]:
            err = s["predicted_error_m"]
            row = [s["id"], f"{s['x_m']:.3f}", f"{s['y_m']:.3f}", f"{s['z_m']:.3f}",
                   "inf" if err is None else f"{err:.4f}", int(s["meets_requirement"]),
                   s["n_markers"]]
            if network:
                row += [" ".join(f"{k}:{v}" for k, v in s["tied_to"].items()), datum]
            if route:
                row += [s["route_order"], f"{s['leg_m']:.3f}", f"{s['drive_m']:.3f}",
                        f"{s['heading_deg']:.2f}", s["cells_covered"]]
            w.writerow(row)
    write_gis_sidecars(path, types, doc["site"]["crs_wkt"])


def write_design_coverage(design, folder: Path) -> Path:
    """``coverage.tif`` of a plan that chose its stations: per AOI cell, how many chosen
    stations cover it and the best predicted point density
    (:func:`planner.coverage.raster.write_coverage_raster`)."""
    from planner.coverage.raster import coverage_raster, write_coverage_raster

    raster = coverage_raster(design.coverage, design.grid, design.order)
    return write_coverage_raster(raster, folder)


def _write_reliability_csv(outcome, path: Path) -> None:
    """Network mode's ``reliability.csv`` (header first): one row per planned observation,
    :data:`planner.accuracy.reliability.RELIABILITY_COLUMNS` (``inf`` for an infinite MDB or
    effect, an empty ``effect_station`` when no station moves)."""
    from planner.accuracy.network import network_model
    from planner.accuracy.reliability import (
        RELIABILITY_COLUMNS,
        layout_reliability,
        reliability_rows,
    )

    net = network_model(outcome.problem, outcome.config)
    rows = reliability_rows(net, layout_reliability(net, outcome.result.selected))

    def cell(v):
        if v is None:
            return "inf"
        if isinstance(v, bool):
            return int(v)
        return f"{v:.6f}" if isinstance(v, float) else v

    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(RELIABILITY_COLUMNS)
        for r in rows:
            w.writerow([("" if r[c] is None else r[c]) if c == "effect_station" else cell(r[c])
                        for c in RELIABILITY_COLUMNS])


def _write_geojson(doc: dict, crs: str | None, path: Path) -> None:
    """Markers and stations as GeoJSON Points: WGS84 longitude/latitude when the DEM's CRS is an
    Earth CRS, else site frame / DEM CRS (:mod:`planner.outputs.gis`); ``x_m``, ``y_m`` are
    always in the plan's frame."""
    rows = doc["markers"] + doc["stations"]
    where = geojson_positions(crs, [[r["x_m"], r["y_m"], r["z_m"]] for r in rows])
    props = [{"id": m["id"], "kind": "marker", "existing": m["existing"],
              "stations": m["stations"]} for m in doc["markers"]]
    props += [{"id": s["id"], "kind": "station", "predicted_error_m": s["predicted_error_m"]}
              for s in doc["stations"]]
    feats = [{"type": "Feature", "geometry": {"type": "Point", "coordinates": xyz},
              "properties": {**p, "x_m": r["x_m"], "y_m": r["y_m"]}}
             for xyz, p, r in zip(where, props, rows, strict=True)]
    gj = {"type": "FeatureCollection", "name": f"markerplan plan ({doc['site']['name']})",
          **geojson_crs_members(crs, doc["frame"]), "features": feats}
    path.write_text(json.dumps(gj, indent=2) + "\n")


def _fmt(v, unit="m", digits=3):
    return "n/a" if v is None else f"{v:.{digits}f} {unit}"


def report_markdown(doc: dict) -> str:
    """Human report of a ``plan.json`` document (Markdown)."""
    req, sol = doc["requirement"], doc["solver"]
    lines = [f"# Marker plan — site `{doc['site']['name']}`", "",
             f"**{doc['n_markers']} markers** meet the requirement at "
             f"{sum(s['meets_requirement'] for s in doc['stations'])} of "
             f"{len(doc['stations'])} stations: predicted 95 % registered-position error "
             f"≤ {requirement_text(req)} over a {req['working_radius_m']:g} m working radius, "
             f"≥ {req['min_markers']} markers in ≥ {req['min_sectors']} of {req['n_sectors']} "
             f"sectors" + (", surviving the loss of any one marker" if req["redundant"] else "")
             + ".", "", f"95 % figure: {req['error_figure_text']}.", "",
             "## Solver", "",
             f"- {sol['name']}" + (f" {sol['version']}" if "version" in sol else "")
             + f" status **{sol['status']}**"
             + (" (proven optimal)" if sol["proven_optimal"] else
                " — not proven optimal"),
             f"- objective {sol['objective']}, dual bound {sol['dual_bound']}, gap {sol['gap']}",
             f"- {sol['iterations']} solve(s), {sol['accuracy_cuts']} accuracy cut(s), "
             f"solver time limit {sol['time_limit_s']:g} s, target gap {sol['target_gap']:g}"
             + (f", {sol['threads']} thread(s)" if "threads" in sol else "")]
    search = sol.get("local_search")
    if search:
        lines.append(f"- started from the network greedy's {search['start_markers']} markers, "
                     f"improved by local search to {search['markers']} ({search['removed']} "
                     f"removed, {search.get('swaps', 0)} pairs swapped for one, in "
                     f"{search['time_s']:g} s"
                     + ("" if search["finished"] else ", stopped by its time share") + ")")
    lines += ["", "## Compared with", "", "| layout | markers | meets requirement | plan saves |",
             "|---|---:|---|---:|"]
    for name, b in doc["baselines"].items():
        label = name.replace("_", " ")
        if "spacing_m" in b:
            label += f" ({b['spacing_m']:g} m)"
        saved = b.get("saved_by_plan")
        lines.append(f"| {label} | {b['n_markers']} | {'yes' if b['meets_requirement'] else 'no'}"
                     f" | {saved if saved is not None else '—'} |")
    notes = [f"- {name.replace('_', ' ')}: {b['note']}" for name, b in doc["baselines"].items()
             if "note" in b]
    if notes:
        lines += ["", *notes]
    lines += design_markdown(doc)
    if "network" in doc:
        net = doc["network"]
        lines += ["", "## Network", "",
                  f"Network mode: markers are unknowns; {_relative_to(net['datum'])}; roll and "
                  f"pitch from the inclinometer "
                  f"({net['datum']['inclinometer_sigma_deg']:g} deg 1-sigma). "
                  f"{net['n_station_ties']} station pairs share markers; worst "
                  f"marker {_fmt(net['worst_marker_error_m'])}.", "",
                  "Weakest stations: " + ", ".join(f"{w['id']} ({_fmt(w['predicted_error_m'])})"
                                                   for w in net["weakest_stations"]) + ".", "",
                  _bias_sentence(net["reliability"]), "",
                  "| station | tied to (shared markers) |", "|---|---|"]
        for s in doc["stations"]:
            lines.append(f"| {s['id']} | " + (", ".join(f"{k} ({v})" for k, v in
                                                         s["tied_to"].items()) or "—") + " |")
    lines += local_markdown(doc)
    lines += chance_markdown(doc)
    bias = "network" in doc
    lines += ["", "## Stations", "",
              "| station | predicted error | markers | sectors | markers used |"
              + (" largest MDB effect (observation) |" if bias else ""),
              "|---|---:|---:|---:|---|" + ("---|" if bias else "")]
    for s in doc["stations"]:
        lines.append(f"| {s['id']} | {_fmt(s['predicted_error_m'])} | {s['n_markers']} | "
                     f"{s['n_sectors']} | {', '.join(s['markers'])} |"
                     + (f" {_bias_cell(s)} |" if bias else ""))
    lines += ["", "## Markers (" + doc["frame"] + ")", "", "| id | x | y | z | used by |",
              "|---|---:|---:|---:|---|"]
    for m in doc["markers"]:
        lines.append(f"| {m['id']}{' (existing)' if m['existing'] else ''} | {m['x_m']:.2f} | "
                     f"{m['y_m']:.2f} | {m['z_m']:.2f} | {', '.join(m['stations'])} |")
    vis = doc["visibility"]
    lines += ["", "## Inputs", "",
              f"- {doc['candidates']['n_sites']} candidate sites; "
              f"{vis['n_pairs']} station-site pairs in range, {vis['n_usable']} usable",
              f"- error model: {doc['provenance']['error_model']}; detection model: "
              f"{doc['provenance'].get('detection_model') or 'none'}; markerplan "
              f"{doc['provenance']['markerplan_version']}; config sha256 "
              f"`{doc['provenance']['config_sha256'][:12]}`", ""]
    return "\n".join(lines)


def _bias_cell(station: dict) -> str:
    """A station's largest MDB effect and the observation causing it."""
    cause = station["bias_effect_caused_by"]
    if station["bias_effect_m"] is None:
        return "inf (undetermined)" if cause is None else \
            f"inf ({cause['station']}→{cause['site']} uncontrolled)"
    return "0 (datum or no observation moves it)" if cause is None else \
        f"{station['bias_effect_m']:.3f} m ({cause['station']}→{cause['site']})"


def _bias_sentence(rel: dict) -> str:
    """The network's worst MDB effect (and the bound, when one is set)."""
    worst = rel["worst_bias_effect"]
    bound = ("" if rel["max_bias_effect_m"] is None
             else f" (bound `max_bias_effect_m` {rel['max_bias_effect_m']:g} m)")
    if worst is None:
        return "Reliability: no station."
    cause = worst["caused_by"]
    value = "inf" if worst["bias_effect_m"] is None else f"{worst['bias_effect_m']:.3f} m"
    return (f"Reliability: an undetected bias of minimal detectable size (alpha0 0.1 %, power "
            f"80 %, per component) in one observation moves a station by at most {value}, "
            f"station {worst['station']}"
            + (f" by {cause['station']}→{cause['site']}" if cause else "") + bound
            + "; every observation in reliability.csv.")


def summary(doc: dict, out: Path) -> dict:
    """The one-object ``--json`` summary of a plan."""
    return {"out": str(out), "site": doc["site"]["name"], "n_markers": doc["n_markers"],
            "meets_requirement": doc["meets_requirement"],
            "status": doc["solver"]["status"], "objective": doc["solver"]["objective"],
            "dual_bound": doc["solver"]["dual_bound"], "gap": doc["solver"]["gap"],
            "worst_station_error_m": max((s["predicted_error_m"] or math.inf)
                                         for s in doc["stations"]),
            "baselines": {k: {"n_markers": v["n_markers"],
                              "meets_requirement": v["meets_requirement"],
                              **({"note": v["note"]} if "note" in v else {})}
                          for k, v in doc["baselines"].items()},
            "markers": [m["id"] for m in doc["markers"]],
            **({"mode": "network",
                "reference_station": doc["network"]["datum"]["reference_station"],
                "datum": datum_text(doc["network"]["datum"]),
                "worst_marker_error_m": doc["network"]["worst_marker_error_m"]}
               if "network" in doc else {})}
