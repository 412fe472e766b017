"""Markers a network needs under each requirement kind: relative to the datum (constant or
a + b ppm, datum at the first station or at the centre) and local (between stations within
``--within`` m: relative position, or distance), both 95 % figures.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -u benchmarks/network_requirements.py
        [--site large] [--grid-spacing 2.5] [--requirement 0.10] [--ppm 0,200]
        [--within 50] [--kinds datum,local,distance] [--figures ellipsoid,quantile]
        [--heading-prior DEG] [--heading-aid sun-sensor|star-tracker] [--heading-bias DEG]
        [--odometry-percent P] [--odometry-heading DEG_PER_M] [--search-time-limit 300]
        [--plan-time-limit 0] [--local-markers] [--save-layouts DIR]

For every combination it runs the network greedy (``greedy_network``: markers, wall time), then
the local search that prunes its layout and swaps pairs of its sites for one
(``planner.program.local_search.local_search``: markers left, removals, swaps, wall time) and,
with ``--plan-time-limit S > 0``, the integer program too (markers, status, proven bound, gap).
Each layout is re-judged here from its covariance: the worst ratio of a station's error to its
allowance ``a + b ppm d`` (``d`` its horizontal distance from the datum, computed in this
script), or of a pair's relative error to ``--requirement`` for the local kinds. Prints one
line per case and a final JSON object. No chance constraint (the
requirement alone is measured). With ``--save-layouts DIR`` each case's best passing layout
(fewest markers of the local search's and the program's) is written to ``DIR/<case>.npz``
(:func:`planner.studies.layout_geometry.save_layout`), for the suite's independent re-check
(``tests/planner/test_large_layouts.py``).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def cases(problem, base, ppms, within_m, kinds, figures=("ellipsoid", "quantile")):
    """(label, config) of every requirement kind asked for: datum at the first station and at
    the station nearest the centre with each ppm term; local position and distance within
    ``within_m`` (datum at the centre, not judged); each of ``figures``."""
    xy = problem.station_xyz[:, :2]
    centre = problem.station_ids[int(np.argmin(np.linalg.norm(xy - xy.mean(axis=0), axis=1)))]
    for figure in figures:
        if "datum" in kinds:
            for datum in (problem.station_ids[0], centre):
                for ppm in ppms:
                    yield (f"{figure}, datum {datum}, {base.requirement_m:g} m + {ppm:g} ppm",
                           base.replace(error_figure=figure, reference_station=datum,
                                        requirement_ppm=ppm))
        for kind in ("position", "distance"):
            if ("local" if kind == "position" else "distance") in kinds:
                yield (f"{figure}, local {kind} {base.requirement_m:g} m within {within_m:g} m",
                       base.replace(error_figure=figure, reference_station=centre,
                                    datum_requirement=False,
                                    local_requirement_m=base.requirement_m,
                                    local_within_m=within_m, local_kind=kind))


def judged(problem, config, selected) -> float:
    """Worst station error over its allowance, recomputed from the layout's covariance and the
    distances computed here; for a local requirement, the worst pair's relative error over
    its allowance (and of each judged marker pair's, with ``local_markers``)."""
    from planner.accuracy.local import local_accuracy
    from planner.accuracy.local_markers import local_marker_accuracy
    from planner.accuracy.network import network_model

    net = network_model(problem, config)
    local = local_accuracy(net, config)
    if local is not None:
        cov = net.covariance(net.information(selected))
        worst = float(np.max(local.errors(cov) / local.pairs.allowed_m))
        markers = local_marker_accuracy(net, config)
        if markers is not None:
            pairs = markers.pairs(selected)
            worst = max(worst, float(np.max(markers.errors(cov, pairs) / pairs.allowed_m,
                                            initial=0.0)))
        return worst
    err = net.station_errors(selected)
    ref = problem.station_ids.index(config.reference_station)
    d = np.hypot(*(problem.station_xyz[:, :2] - problem.station_xyz[ref, :2]).T)
    return float(np.max(err / (config.requirement_m + config.requirement_ppm * 1e-6 * d)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="large")
    ap.add_argument("--grid-spacing", type=float, default=2.5, help="grid_spacing_m")
    ap.add_argument("--requirement", type=float, default=0.10, help="requirement_m")
    ap.add_argument("--ppm", default="0,200", help="requirement_ppm values, comma-separated")
    ap.add_argument("--within", type=float, default=50.0, help="local_within_m, m")
    ap.add_argument("--heading-prior", type=float, default=None,
                    help="heading_prior_sigma_deg of every station (e.g. 0.00278: a 10 arcsec "
                         "star tracker); default none")
    ap.add_argument("--heading-aid", default=None, help="heading_aid (sun-sensor, star-tracker)")
    ap.add_argument("--heading-bias", type=float, default=None,
                    help="heading_bias_sigma_deg (default: the aid class's, else none)")
    ap.add_argument("--odometry-percent", type=float, default=None, help="odometry_percent")
    ap.add_argument("--odometry-heading", type=float, default=None,
                    help="odometry_heading_deg_per_m")
    ap.add_argument("--figures", default="ellipsoid,quantile", help="error figures to run")
    ap.add_argument("--search-time-limit", type=float, default=300.0,
                    help="the local search's time limit after the greedy, s")
    ap.add_argument("--kinds", default="datum,local,distance",
                    help="requirement kinds: datum, local (position), distance")
    ap.add_argument("--local-markers", action="store_true",
                    help="the local kinds also judge every pair of selected markers within "
                         "--within (local_markers)")
    ap.add_argument("--plan-time-limit", type=float, default=0.0,
                    help="also run the integer program with this time limit, s (0: greedy only)")
    ap.add_argument("--save-layouts", default=None,
                    help="write each case's best passing layout to DIR/<case>.npz")
    args = ap.parse_args()

    from error_model import default_model
    from markerplan.errors import InfeasiblePlanError
    from planner.accuracy.checks import evaluate_layout
    from planner.accuracy.network import network_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.program import plan_sites
    from planner.program.baselines import greedy_network
    from planner.program.local_search import local_search
    from planner.run import build_problem

    inputs = load_inputs(args.site)
    base = PlanConfig(network=True, chance_epsilon=None, requirement_m=args.requirement,
                      grid_spacing_m=args.grid_spacing,
                      heading_prior_sigma_deg=args.heading_prior, heading_aid=args.heading_aid,
                      heading_bias_sigma_deg=args.heading_bias,
                      odometry_percent=args.odometry_percent,
                      odometry_heading_deg_per_m=args.odometry_heading,
                      time_limit_s=args.plan_time_limit or 60.0)
    problem, cand, _, _ = build_problem(inputs, base, default_model(), progress=False)
    print(f"site {args.site}: {problem.n_stations} stations, {len(cand)} candidate sites")
    out = {"site": args.site, "n_stations": problem.n_stations, "n_candidates": len(cand),
           "aids": base.aids_record(), "cases": []}
    print(f"aids: {json.dumps(base.aids_record())}")
    for label, cfg in cases(problem, base, [float(v) for v in args.ppm.split(",")],
                            args.within, args.kinds.split(","), args.figures.split(",")):
        if args.local_markers and cfg.local_requirement_m is not None:
            cfg, label = cfg.replace(local_markers=True), label + " (and markers)"
        row, layouts = {"case": label}, {}
        t = time.perf_counter()
        try:
            g = greedy_network(problem, cfg, network_model(problem, cfg))
            row["greedy"] = {"markers": g.n_markers, "time_s": round(time.perf_counter() - t, 1),
                             "worst_error_over_allowance": round(judged(problem, cfg,
                                                                        g.selected), 4)}
            pruned = local_search(problem, cfg, network_model(problem, cfg), g.selected,
                                  deadline=time.perf_counter() + args.search_time_limit)
            layouts["pruned"] = pruned.selected
            row["pruned"] = {**pruned.record(), "worst_error_over_allowance": round(
                judged(problem, cfg, pruned.selected), 4),
                "checked": bool(evaluate_layout(problem, pruned.selected, cfg).all_ok)}
        except InfeasiblePlanError as exc:
            row["greedy"] = {"error": str(exc)[:200]}
        if args.plan_time_limit > 0:
            t = time.perf_counter()
            try:
                r = plan_sites(problem, cfg)
                sol = r.solution
                layouts["plan"] = r.selected
                row["plan"] = {"markers": int(r.selected.sum()), "status": sol.status,
                               "dual_bound": sol.dual_bound, "gap": sol.gap,
                               "time_s": round(time.perf_counter() - t, 1),
                               "worst_error_over_allowance": round(judged(problem, cfg,
                                                                          r.selected), 4)}
            except InfeasiblePlanError as exc:
                row["plan"] = {"error": str(exc)[:200]}
        if args.save_layouts:
            _save_best(args.save_layouts, problem, cfg, label, row, layouts)
        print(f"  {label}: {json.dumps({k: v for k, v in row.items() if k != 'case'})}",
              flush=True)
        out["cases"].append(row)
    print(json.dumps(out))


def _save_best(folder, problem, config, label, row, layouts) -> None:
    """Write the case's passing layout with the fewest markers (the local search's or the
    program's) to ``folder/<label as a file name>.npz``, with its label, source and count."""
    import re
    from pathlib import Path

    from planner.studies.layout_geometry import save_layout

    passing = {k: sel for k, sel in layouts.items()
               if row[k].get("worst_error_over_allowance", 2.0) <= 1.0}
    if not passing:
        return
    best = min(passing, key=lambda k: int(passing[k].sum()))
    name = re.sub(r"[^a-z0-9]+", "-", label.lower()).strip("-")
    Path(folder).mkdir(parents=True, exist_ok=True)
    save_layout(Path(folder) / f"{name}.npz", problem, config, passing[best],
                {"label": label, "source": best, "markers": int(passing[best].sum())})


if __name__ == "__main__":
    main()
