"""Network-mode planning benchmark: ``plan --network`` against greedy and known-control mode on
the ``default`` and ``large`` sites, in the same run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/plan_network.py [--sites default,large]
        [--grid-spacing 1.0] [--time-limit 600] [--requirement 0.10] [--greedy-batch 1]

(One BLAS thread: the 600 x 600 covariance of ``large`` is many times faster on a busy 2-core
machine without thread oversubscription.)

Per site: the known-control optimum (markers, worst station error, and its worst error when
judged as a network tied to the first station), the network-mode plan (markers, status, dual
bound, gap, worst station and marker error, solves, cuts, time) and the network greedy baseline
(markers, time). Prints one line per figure and a final JSON object.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def _run(site: str, grid_spacing: float, time_limit: float, greedy_batch: int,
         requirement_m: float) -> dict:
    from error_model import default_model
    from markerplan.errors import InfeasiblePlanError
    from planner.accuracy.network import network_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.program import plan_sites
    from planner.program.baselines import greedy_network
    from planner.run import build_problem

    inputs = load_inputs(site)
    config = PlanConfig(grid_spacing_m=grid_spacing, time_limit_s=time_limit,
                        requirement_m=requirement_m)
    problem, cand, _, _ = build_problem(inputs, config, default_model(), progress=False)
    out = {"site": site, "n_stations": problem.n_stations, "n_candidates": len(cand),
           "requirement_m": requirement_m}
    print(f"site {site}: {problem.n_stations} stations, {len(cand)} candidate sites "
          f"(grid {grid_spacing:g} m), requirement {requirement_m:g} m")
    t = time.perf_counter()
    kc = plan_sites(problem, config)
    out["known_control"] = {"markers": int(kc.selected.sum()), "status": kc.status,
                            "worst_station_error_m": float(kc.check.error_m.max()),
                            "time_s": round(time.perf_counter() - t, 2)}
    net_cfg = config.replace(network=True)
    net = network_model(problem, net_cfg)
    as_net = net.station_errors(kc.selected)
    out["known_control"]["as_network_worst_m"] = float(as_net.max())
    out["known_control"]["as_network_failing"] = int((as_net > config.requirement_m).sum())
    print(f"  known control: {out['known_control']['markers']} markers ({kc.status}), worst "
          f"{kc.check.error_m.max():.3f} m; judged as a network: worst {as_net.max():.3f} m, "
          f"{out['known_control']['as_network_failing']} of {problem.n_stations} stations fail")
    t = time.perf_counter()
    try:
        r = plan_sites(problem, net_cfg)
        sol = r.solution
        out["network"] = {"markers": int(r.selected.sum()), "status": sol.status,
                          "objective": sol.objective, "dual_bound": sol.dual_bound,
                          "gap": sol.gap, "iterations": r.iterations, "cuts": r.n_cuts,
                          "worst_station_error_m": float(r.check.error_m.max()),
                          "worst_marker_error_m": float(np.nanmax(r.check.marker_error_m)),
                          "time_s": round(time.perf_counter() - t, 2)}
        print(f"  network plan: {out['network']['markers']} markers, status {sol.status}, "
              f"dual bound {sol.dual_bound:g}, gap {sol.gap:.3g}, worst station "
              f"{out['network']['worst_station_error_m']:.3f} m, worst marker "
              f"{out['network']['worst_marker_error_m']:.3f} m, {r.iterations} solves, "
              f"{r.n_cuts} cuts, {out['network']['time_s']:.1f} s")
    except InfeasiblePlanError as exc:
        out["network"] = {"error": str(exc), "time_s": round(time.perf_counter() - t, 2)}
        print(f"  network plan: failed after {out['network']['time_s']:.1f} s: {exc}")
    t = time.perf_counter()
    try:
        g = greedy_network(problem, net_cfg, net, batch=greedy_batch)
        out["greedy"] = {"markers": g.n_markers, "time_s": round(time.perf_counter() - t, 2),
                         "batch": greedy_batch}
        print(f"  greedy (network, batch {greedy_batch}): {g.n_markers} markers in "
              f"{out['greedy']['time_s']:.1f} s")
    except InfeasiblePlanError as exc:
        out["greedy"] = {"error": str(exc)}
        print(f"  greedy (network): {exc}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sites", default="default,large")
    ap.add_argument("--grid-spacing", type=float, default=1.0)
    ap.add_argument("--time-limit", type=float, default=600.0)
    ap.add_argument("--requirement", type=float, default=0.10, help="requirement_m")
    ap.add_argument("--greedy-batch", type=int, default=1,
                    help="greedy: sites added per step (best of that many worst stations)")
    args = ap.parse_args()
    results = [_run(s, args.grid_spacing, args.time_limit, args.greedy_batch, args.requirement)
               for s in args.sites.split(",")]
    print(json.dumps(results))


if __name__ == "__main__":
    main()
