"""Stations, markers and traverse chosen over an area of interest (``markerplan plan --aoi``).

Runs :func:`planner.design.plan.design_plan` on a site preset and an AOI rectangle and prints,
one line each: the run's inputs (candidates, cells), its stages' wall times, the joint
program's status / objective / bound / gap, and for the plan, the greedy-viewpoint and
regular-grid baselines and (on a preset) the published hand layout: stations, markers, AOI
covered, requirement met, route length and mission time; then peak RSS. Finally one JSON
object.

    .venv/bin/python -u benchmarks/aoi_plan.py [--site default] [--aoi X0,Y0,X1,Y1]
        [--route-start X,Y] [--time-limit 120] [--scheduler none|local] [--network]
        [--chance-epsilon none|EPS] [--check-coverage] [--frames N] [--set KEY=VALUE ...]

``--check-coverage`` checks the predicted coverage of the chosen stations independently: each
is simulated on the site's true terrain with the plan's markers and processed by the chain
(:func:`planner.coverage.achieved.achieved_coverage`), its ground points rasterised over the
AOI cells and compared, cell by cell, with the predicted count
(:func:`planner.coverage.achieved.compare_coverage`), with the same range, incidence and density
limits. ``--frames`` scans fewer turntable frames (faster; the density is scaled to a full turn).
"""

from __future__ import annotations

import argparse
import json
import resource
import time

import numpy as np
from shapely.geometry import box


def _pair(text: str) -> tuple[float, ...]:
    return tuple(float(v) for v in text.split(","))


def _setting(text: str) -> tuple[str, object]:
    key, value = text.split("=", 1)
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def main() -> None:
    from error_model.default import default_detection_model, default_model
    from planner.config import PlanConfig
    from planner.design.plan import design_plan
    from planner.design.run import mission_time_record
    from planner.distributed import executor
    from planner.problem.inputs import load_inputs

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="default")
    ap.add_argument("--aoi", type=_pair, default=(-20.0, -20.0, 20.0, 20.0),
                    help="x0,y0,x1,y1 of the AOI rectangle, m")
    ap.add_argument("--route-start", type=_pair, default=None)
    ap.add_argument("--time-limit", type=float, default=120.0)
    ap.add_argument("--scheduler", default="none")
    ap.add_argument("--network", action="store_true")
    ap.add_argument("--chance-epsilon", default="none")
    ap.add_argument("--check-coverage", action="store_true")
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--set", type=_setting, action="append", default=[])
    args = ap.parse_args()

    eps = None if args.chance_epsilon == "none" else float(args.chance_epsilon)
    config = PlanConfig(time_limit_s=args.time_limit, chance_epsilon=eps, network=args.network,
                        **dict(args.set))
    t0 = time.perf_counter()
    inputs = load_inputs(args.site)
    t_inputs = time.perf_counter() - t0
    aoi = box(*args.aoi)
    with executor(args.scheduler, progress=False) as tasks:
        t = time.perf_counter()
        outcome = design_plan(inputs, config, default_model(), aoi, keepouts=(),
                              route_start_xy=args.route_start, progress=False,
                              map_groups=tasks, detection_model=default_detection_model())
        wall = time.perf_counter() - t
    d = outcome.design
    j = d.joint
    sol = j.solution
    print(f"site {args.site}, AOI {args.aoi} ({aoi.area:g} m^2, {len(d.grid)} cells of "
          f"{d.grid.cell_m:g} m); {len(d.candidate_ids)} candidate stations "
          f"({len(j.excluded)} cannot meet the marker rules), "
          f"{len(d.uncoverable)} cells no candidate covers; inputs {t_inputs:.1f} s")
    print("stages: " + ", ".join(f"{k} {v:.1f} s" for k, v in outcome.timings_s.items()))
    print(f"joint program: {sol.status}, objective {sol.objective:.0f} s, bound "
          f"{sol.dual_bound:.0f} s, gap {100 * sol.gap:.1f} %, {j.iterations} solve(s), "
          f"{j.n_cuts} cut(s), {j.stations.sum()} stations, {j.selected.sum()} markers")
    n_new = int(np.sum(~outcome.problem.site_existing[outcome.result.selected]))
    print(f"final plan of the chosen stations: {n_new} markers "
          f"({outcome.result.status}), all stations pass: {bool(outcome.result.check.ok.all())}")
    rows = []
    for o in d.options:
        n_markers = n_new if o.name == "plan" else o.n_markers
        t_total = (mission_time_record(d.costs, o.route, o.n_stations, n_new)
                   if o.name == "plan" else o.time_s)["total"]
        rows.append({"name": o.name, "stations": o.n_stations, "markers": n_markers,
                     "covered": round(o.covered_fraction, 4), "meets": o.meets_requirement,
                     "route_m": None if o.route is None else round(o.route.length_m, 1),
                     "mission_min": None if t_total is None else round(t_total / 60, 1),
                     "note": o.note})
        print(f"  {o.name:7s} stations {o.n_stations:4d}  markers {n_markers:4d}  covered "
              f"{100 * o.covered_fraction:5.1f} %  meets {str(o.meets_requirement):5s}  route "
              + ("     —" if o.route is None else f"{o.route.length_m:7.1f} m")
              + ("" if t_total is None else f"  mission {t_total / 60:6.1f} min")
              + (f"  ({o.note})" if o.note else ""))
    result = {"site": args.site, "aoi": list(args.aoi), "cells": len(d.grid),
              "candidates": len(d.candidate_ids), "joint": {
                  "status": sol.status, "objective_s": sol.objective,
                  "bound_s": sol.dual_bound, "gap": sol.gap},
              "options": rows, "wall_s": round(wall, 1),
              "timings_s": {k: round(v, 2) for k, v in outcome.timings_s.items()}}
    if args.check_coverage:
        result["coverage_check"] = _check(outcome, config, args.frames)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"wall {wall:.1f} s; peak RSS {peak:.0f} MB (largest worker {children:.0f} MB)")
    result.update(peak_rss_mb=round(peak), worker_peak_rss_mb=round(children))
    print(json.dumps(result))


def _check(outcome, config, frames: int | None) -> dict:
    """Achieved coverage of the chosen stations by simulation and processing, against the
    predicted count of each AOI cell."""
    from planner.coverage.achieved import achieved_coverage, compare_coverage
    from visibility.sites import load_site

    d = outcome.design
    site = load_site(outcome.inputs.site_name, outcome.inputs.site_seed)
    t = time.perf_counter()
    markers = outcome.problem.site_xyz[outcome.result.selected]
    achieved = achieved_coverage(
        site.dem, d.station_position_m, d.station_heading_rad, d.grid.centre_xy_m,
        d.grid.cell_m, config.cover_min_density_per_m2, seed=0, marker_xyz_m=markers,
        frames_per_turn=frames, max_range_m=config.cover_max_range_m,
        max_incidence_rad=np.radians(config.cover_max_incidence_deg))
    predicted = d.coverage.count(d.order)
    agreement = compare_coverage(predicted, achieved.stations_covering,
                                 config.cover_min_stations, d.grid.centre_xy_m,
                                 d.station_position_m[:, :2])
    rec = agreement.to_dict()
    rec.update(_pairs(d, achieved, config.cover_min_density_per_m2))
    print(f"coverage check ({len(d.order)} stations simulated and processed"
          + (f", {frames} frames each" if frames else "") + f", {time.perf_counter() - t:.0f} s):"
          f" predicted covered {100 * rec['predicted_covered_fraction']:.1f} %, achieved "
          f"{100 * rec['achieved_covered_fraction']:.1f} %, cells agreeing "
          f"{100 * rec['agreement_fraction']:.1f} %; cells whose count of covering stations "
          f"agrees {100 * rec['count_agreement']:.1f} %; station-cell pairs: "
          f"{rec['pairs_both']} both, {rec['pairs_predicted_only']} predicted only, "
          f"{rec['pairs_achieved_only']} achieved only; achieved/predicted density in pairs "
          f"both count: median {rec['density_ratio_median']:.3f} ({json.dumps(rec)})")
    return rec


def _pairs(design, achieved, min_density: float) -> dict:
    """Station x cell pairs covered in the prediction and in the scans, and the density ratio
    of the pairs both cover."""
    cov = design.coverage
    rank = np.full(len(design.candidate_ids), -1)
    rank[design.order] = np.arange(design.order.size)
    on = rank[cov.station] >= 0
    n_cells = len(design.grid)
    predicted = dict(zip(rank[cov.station[on]] * n_cells + cov.cell[on],
                         cov.density_per_m2[on], strict=True))
    dens = achieved.station_density_per_m2.tocoo()
    hit = dens.data >= min_density
    scanned = dict(zip(dens.row[hit] * n_cells + dens.col[hit], dens.data[hit], strict=True))
    both = sorted(set(predicted) & set(scanned))
    ratio = np.array([scanned[k] / predicted[k] for k in both])
    counts = np.bincount(cov.cell[on], minlength=n_cells)
    return {"count_agreement": float(np.mean(counts == achieved.stations_covering)),
            "pairs_both": len(both), "pairs_predicted_only": len(set(predicted) - set(scanned)),
            "pairs_achieved_only": len(set(scanned) - set(predicted)),
            "density_ratio_median": float(np.median(ratio)) if ratio.size else float("nan"),
            "density_ratio_p10_p90": [float(v) for v in np.percentile(ratio, [10, 90])]
            if ratio.size else None}


if __name__ == "__main__":
    main()
