"""Planner benchmark on the ``large`` site: visibility-matrix time and rays/s, and the integer
program's time to proven optimality against the greedy cover's objective, in the same run.

    .venv/bin/python benchmarks/plan.py [--site large] [--grid-spacing 2.0] [--time-limit 120]

Prints one line per figure and a final JSON object.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="large")
    ap.add_argument("--grid-spacing", type=float, default=2.0)
    ap.add_argument("--time-limit", type=float, default=120.0)
    ap.add_argument("--rays-per-marker", type=int, default=24)
    args = ap.parse_args()

    from error_model import default_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.program import plan_sites
    from planner.program.baselines import greedy_cover
    from planner.run import build_problem

    t = time.perf_counter()
    inputs = load_inputs(args.site)
    t_site = time.perf_counter() - t
    config = PlanConfig(grid_spacing_m=args.grid_spacing, time_limit_s=args.time_limit,
                        rays_per_marker=args.rays_per_marker)
    problem, cand, vis, timings = build_problem(inputs, config, default_model())
    print(f"site {args.site}: {len(inputs.station_ids)} stations, {len(cand)} candidate sites "
          f"(grid {args.grid_spacing:g} m), site build {t_site:.1f} s")
    print(f"visibility matrix: {len(vis)} pairs, {vis.n_rays} rays in {vis.elapsed_s:.2f} s "
          f"= {vis.rays_per_s:,.0f} rays/s ({int(problem.pair_usable.sum())} usable pairs); "
          f"scene build {timings['scene']:.2f} s")
    t = time.perf_counter()
    result = plan_sites(problem, config)
    t_plan = time.perf_counter() - t
    sol = result.solution
    print(f"MILP: {int(result.selected.sum())} markers, status {sol.status}, objective "
          f"{sol.objective:g}, dual bound {sol.dual_bound:g}, gap {sol.gap:.3g}, "
          f"{result.iterations} solve(s), {result.n_cuts} cut(s), solver "
          f"{result.solve_time_s:.2f} s, loop total {t_plan:.2f} s")
    t = time.perf_counter()
    greedy = greedy_cover(problem, config)
    t_greedy = time.perf_counter() - t
    print(f"greedy cover: {greedy.n_markers} markers in {t_greedy:.2f} s "
          f"(MILP saves {greedy.n_markers - int(result.selected.sum())})")
    print(json.dumps({
        "site": args.site, "n_stations": len(inputs.station_ids), "n_candidates": len(cand),
        "n_pairs": len(vis), "n_rays": vis.n_rays, "visibility_s": round(vis.elapsed_s, 3),
        "rays_per_s": round(vis.rays_per_s), "milp_status": sol.status,
        "milp_markers": int(result.selected.sum()), "milp_dual_bound": sol.dual_bound,
        "milp_gap": sol.gap, "milp_solver_s": round(result.solve_time_s, 3),
        "milp_loop_s": round(t_plan, 3), "greedy_markers": greedy.n_markers,
        "greedy_s": round(t_greedy, 3),
        "worst_station_error_m": float(np.max(result.check.error_m))}))


if __name__ == "__main__":
    main()
