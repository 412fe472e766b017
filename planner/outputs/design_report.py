"""A plan that chose its stations (``plan --aoi``): its ``plan.json`` section and report.

:func:`design_record` is the ``"design"`` section of ``plan.json`` (the area of interest, the
coverage requirement and what could not be covered, patch by patch, the rover's limits, the
joint program's status and bound, the traverse, the mission time and the other ways to survey
the area); :func:`station_route_fields` adds each station's place on the route to its record, and
:func:`design_markdown` is the report's section.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from markerplan.writing import json_float
from planner.coverage.raster import REASONS, UncoveredPatch
from planner.design.run import SurveyDesign, SurveyOption, mission_time_record


def _rounded(v, digits: int = 3) -> float | None:
    return None if v is None else round(float(v), digits)


def _patch_record(patch: UncoveredPatch) -> dict:
    """One connected patch of uncoverable cells for ``plan.json``: cells, area, bounding box
    ``[x0, y0, x1, y1]`` m and how many cells each limit stops."""
    return {"n_cells": patch.n_cells, "area_m2": _rounded(patch.area_m2),
            "bounds_m": [_rounded(v) for v in patch.bounds_m],
            "reasons": {REASONS[r]: int(n) for r, n in enumerate(patch.reason_count) if n}}


def option_record(option: SurveyOption) -> dict:
    """One way to survey the area (the plan, a baseline, the hand layout) for ``plan.json``."""
    rec = {"n_stations": option.n_stations, "n_markers": option.n_markers,
           "covered_fraction": round(option.covered_fraction, 6),
           "meets_requirement": option.meets_requirement,
           "route_length_m": None if option.route is None else _rounded(option.route.length_m),
           "mission_time_s": {k: _rounded(v, 1) for k, v in option.time_s.items()}}
    if option.spacing_m is not None:
        rec["spacing_m"] = _rounded(option.spacing_m)
    if option.note:
        rec["note"] = option.note
    return rec


def design_record(design: SurveyDesign, n_markers: int) -> dict:
    """The ``"design"`` section of ``plan.json``.

    Parameters
    ----------
    design : SurveyDesign
    n_markers : int
        New markers of the final plan (its mission time counts these).
    """
    joint, route, grid = design.joint, design.route, design.grid
    sol = joint.solution
    costs = design.costs
    plan = option_record(replace(
        design.options[0], n_markers=int(n_markers),
        time_s=mission_time_record(costs, route, design.order.size, n_markers)))
    counts = design.traffic.counts()
    total_nodes = int(sum(counts.values()))
    unc = design.uncoverable
    return {
        "aoi": {"area_m2": _rounded(design.aoi.area, 2), "n_cells": len(grid),
                "cell_m": _rounded(grid.cell_m, 4),
                "bounds_m": [_rounded(v) for v in design.aoi.bounds]},
        "coverage": {"uncoverable_cells": len(unc), "uncoverable_area_m2": _rounded(unc.area_m2),
                     "uncoverable": unc.text or None,
                     "uncoverable_patches": [_patch_record(p) for p in unc.patches],
                     "n_pairs": int(design.coverage.station.size)},
        "trafficability": {"nodes": total_nodes, "not_trafficable": counts},
        "candidate_stations": {"n": len(design.candidate_ids),
                               "excluded": len(joint.excluded)},
        "joint_program": {
            "status": sol.status, "proven_optimal": sol.status == "optimal",
            "objective_s": _rounded(json_float(sol.objective), 1),
            "dual_bound_s": _rounded(json_float(sol.dual_bound), 1),
            "gap": json_float(sol.gap), "iterations": joint.iterations,
            "accuracy_cuts": joint.n_cuts, "n_stations": int(joint.stations.sum()),
            "n_markers": int(joint.selected.sum()),
            "objective": "station_time_s x stations + marker_time_s x markers + the drive "
                         "time of the program's closed tour (each leg rounded to the second)",
            "tour_edges": "every pair of candidates" if joint.tour_complete else
                          "each candidate's nearest neighbours and the route start (the bound "
                          "holds for tours over those edges)"},
        "route": {"start_xy_m": [_rounded(v) for v in design.route_start_xy],
                  "start": design.route_start_source,
                  "length_m": _rounded(route.length_m),
                  "legs_m": [_rounded(v) for v in route.leg_m],
                  "solver": route.solver},
        "costs": {"station_time_s": costs.station_s, "marker_time_s": costs.marker_s,
                  "drive_speed_m_s": costs.drive_m_per_s},
        "options": {"plan": plan,
                    **{o.name: option_record(o) for o in design.options[1:]}},
    }


def station_route_fields(design: SurveyDesign) -> list[dict]:
    """Per chosen station, in route order: its order, the leg that reaches it, the drive so
    far, its heading and how many AOI cells it covers."""
    legs = design.route.leg_m
    covered = np.bincount(design.coverage.station, minlength=len(design.candidate_ids))
    heading = np.degrees(design.station_heading_rad)
    return [{"route_order": k + 1, "leg_m": _rounded(legs[k]),
             "drive_m": _rounded(legs[:k + 1].sum()),
             "heading_deg": _rounded(heading[k], 2),
             "cells_covered": int(covered[c])}
            for k, c in enumerate(design.order)]


def _minutes(seconds) -> str:
    return "—" if seconds is None else f"{seconds / 60:.0f} min"


def _route_solver(solver: dict) -> str:
    """How the tour was found, for the report."""
    name = " ".join(str(solver[k]) for k in ("name", "version") if k in solver)
    if "stop" in solver:
        name += f", {solver['stop']}"
    return name + ("; proven shortest for these stations" if solver.get("proven_optimal")
                   else "; a heuristic tour, not proven shortest")


def design_markdown(doc: dict) -> list[str]:
    """The report's "Stations chosen over the area of interest" section (no lines without
    a design)."""
    d = doc.get("design")
    if d is None:
        return []
    jp, route, aoi, cov = d["joint_program"], d["route"], d["aoi"], d["coverage"]
    lines = ["", "## Stations chosen over the area of interest", "",
             f"The area of interest ({aoi['area_m2']:g} m², {aoi['n_cells']} cells of "
             f"{aoi['cell_m']:g} m) is covered from {d['options']['plan']['n_stations']} "
             f"station(s) chosen among {d['candidate_stations']['n']} candidates on trafficable "
             f"ground ({d['candidate_stations']['excluded']} of them could not meet the marker "
             "rules with every site).", "",
             f"- joint program of stations and markers: **{jp['status']}**"
             + (" (proven optimal)" if jp["proven_optimal"] else
                f" — not proven optimal: no choice costs less than {jp['dual_bound_s']} s, gap "
                f"{100 * (jp['gap'] or 0):.1f} %")
             + f"; {jp['n_stations']} station(s) and {jp['n_markers']} marker(s), objective "
               f"{jp['objective_s']} s ({jp['objective']})",
             f"- traverse from the route start, {route['start']}, ({route['start_xy_m'][0]:g}, "
             f"{route['start_xy_m'][1]:g}) m and back: **{route['length_m']:g} m** over "
             f"trafficable ground ({_route_solver(route['solver'])})"]
    if cov["uncoverable_cells"]:
        lines.append(f"- left out of the coverage requirement: {cov['uncoverable']}")
    lines += ["", "| way to survey | stations | markers | AOI covered | meets requirement | "
              "drive | stations time | markers time | drive time | mission time |",
              "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|"]
    names = {"plan": "this plan", "greedy": "greedy viewpoints, then markers",
             "grid": "regular grid", "hand": "published hand layout"}
    for name, o in d["options"].items():
        t = o["mission_time_s"]
        label = names.get(name, name) + (f" ({o['spacing_m']:g} m)" if "spacing_m" in o else "")
        lines.append(f"| {label} | {o['n_stations']} | {o['n_markers']} | "
                     f"{100 * o['covered_fraction']:.1f} % | "
                     f"{'yes' if o['meets_requirement'] else 'no'} | "
                     + ("—" if o["route_length_m"] is None else f"{o['route_length_m']:.0f} m")
                     + f" | {_minutes(t['stations'])} | {_minutes(t['markers'])} | "
                     f"{_minutes(t['drive'])} | {_minutes(t['total'])} |")
    notes = [f"- {names.get(n, n)}: {o['note']}" for n, o in d["options"].items() if "note" in o]
    c = d["costs"]
    lines += ["", f"Mission time counts {c['station_time_s']:g} s per station, "
                  f"{c['marker_time_s']:g} s per marker and the drive at "
                  f"{c['drive_speed_m_s']:g} m/s.", *([""] + notes if notes else [])]
    return lines
