"""The 95 % figures side by side: Monte-Carlo calibration through the adjustment, and what each
figure costs in markers, in the same run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/error_figures.py [--draws 2000]
        [--sites default,large] [--time-limit 120] [--requirement 0.10] [--grid-spacing 1.0]
        [--skip-plans] [--skip-calibration]

Calibration (:mod:`planner.studies.figure_calibration`): per geometry, ``--draws`` simulated
observation sets, each adjusted (network: Gauss-Newton on the non-linear model; known control:
the 4-parameter fit) and each station's worst error over its 10 m working disc measured on 720
rim points; the share of station-draws above each figure, with Wilson 95 % intervals. A
calibrated 95 % figure is exceeded in 5 %. The local requirement's pair figures likewise: each
consecutive pair's worst relative position (or distance) error over both discs (72 rim points
each, as ``verify`` measures it) against the pair's figures.

Plans (``plan_sites``, one process, the same candidate sites for both figures): markers and
status in known control and network mode (the integer program, with ``--time-limit``), and the
network greedy baseline, judged by the quantile and by the ellipsoid figure; the ratio of the
two figures at the plan's stations. Prints one line per figure and a final JSON object.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def _wilson(k: int, n: int) -> tuple[float, float]:
    from error_model.detection import wilson_interval

    return wilson_interval(k, n)


def calibration(draws: int) -> list[dict]:
    from planner.studies.figure_calibration import (
        known_control_calibration,
        network_calibration,
        pair_calibration,
    )

    cases = [lambda: network_calibration(6, draws, seed=1),
             lambda: network_calibration(6, draws, seed=2),
             lambda: network_calibration(10, draws, seed=3, spacing_m=20.0),
             lambda: known_control_calibration(4, draws, seed=1),
             lambda: known_control_calibration(4, draws, seed=3),
             lambda: known_control_calibration(8, draws, seed=4),
             lambda: pair_calibration(6, draws, seed=1, kind="position"),
             lambda: pair_calibration(6, draws, seed=1, kind="distance"),
             lambda: pair_calibration(10, draws, seed=3, spacing_m=20.0, kind="position"),
             lambda: pair_calibration(10, draws, seed=3, spacing_m=20.0, kind="distance")]
    out = []
    print(f"calibration: {draws} draws per case")
    for make in cases:
        t = time.perf_counter()
        cal = make()
        row = cal.to_json()
        n = cal.worst_m.size
        for f in ("quantile", "ellipsoid"):
            k = int(np.sum(cal.worst_m > cal.figures_m[f][None]))
            row[f"{f}_wilson"] = _wilson(k, n)
        row["ratio_quantile_to_ellipsoid"] = float(np.mean(cal.figures_m["quantile"]
                                                           / cal.figures_m["ellipsoid"]))
        row["time_s"] = round(time.perf_counter() - t, 1)
        lo, hi = row["quantile_wilson"]
        print(f"  {row['case']}: {n} station-draws; quantile {1e3 * row['quantile_mean_m']:.1f} mm "
              f"exceeded {100 * row['quantile_exceeded']:.2f} % ({100 * lo:.2f}-{100 * hi:.2f}); "
              f"ellipsoid {1e3 * row['ellipsoid_mean_m']:.1f} mm exceeded "
              f"{100 * row['ellipsoid_exceeded']:.2f} %; quantile / ellipsoid "
              f"{row['ratio_quantile_to_ellipsoid']:.3f}; {row['time_s']} s")
        out.append(row)
    return out


def plans(site: str, time_limit: float, requirement_m: float, grid_spacing_m: float) -> dict:
    from error_model import default_model
    from markerplan.errors import InfeasiblePlanError
    from planner.accuracy.figure import ErrorFigure
    from planner.accuracy.network import network_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.program import plan_sites
    from planner.program.baselines import greedy_network
    from planner.run import build_problem

    inputs = load_inputs(site)
    base = PlanConfig(time_limit_s=time_limit, chance_epsilon=None, requirement_m=requirement_m,
                      grid_spacing_m=grid_spacing_m)
    problem, cand, _, _ = build_problem(inputs, base, default_model(), progress=False)
    out = {"site": site, "n_stations": problem.n_stations, "n_candidates": len(cand),
           "requirement_m": requirement_m}
    print(f"site {site}: {problem.n_stations} stations, {len(cand)} candidate sites, "
          f"requirement {requirement_m:g} m")
    for figure in ("quantile", "ellipsoid"):
        row = {}
        for mode, cfg in (("known_control", base.replace(error_figure=figure)),
                          ("network", base.replace(error_figure=figure, network=True))):
            t = time.perf_counter()
            try:
                r = plan_sites(problem, cfg)
                sol = r.solution
                row[mode] = {"markers": int(r.selected.sum()), "status": sol.status,
                             "dual_bound": sol.dual_bound, "gap": sol.gap,
                             "worst_station_error_m": float(r.check.error_m.max()),
                             "time_s": round(time.perf_counter() - t, 1)}
                if mode == "network":
                    net = network_model(problem, cfg)
                    cov = net.covariance(net.information(r.selected))
                    blocks = cov.station(np.arange(problem.n_stations))
                    ratio = ErrorFigure("quantile").station_errors(blocks, cfg.working_radius_m) \
                        / ErrorFigure("ellipsoid").station_errors(blocks, cfg.working_radius_m)
                    row[mode]["ratio_quantile_to_ellipsoid"] = [float(ratio.min()),
                                                                float(np.median(ratio)),
                                                                float(ratio.max())]
            except InfeasiblePlanError as exc:
                row[mode] = {"error": str(exc), "time_s": round(time.perf_counter() - t, 1)}
            print(f"  {figure}, {mode}: {row[mode]}")
        t = time.perf_counter()
        cfg = base.replace(error_figure=figure, network=True)
        try:
            g = greedy_network(problem, cfg, network_model(problem, cfg))
            row["network_greedy"] = {"markers": g.n_markers,
                                     "time_s": round(time.perf_counter() - t, 1)}
        except InfeasiblePlanError as exc:
            row["network_greedy"] = {"error": str(exc)}
        print(f"  {figure}, network greedy: {row['network_greedy']}")
        out[figure] = row
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=2000)
    ap.add_argument("--sites", default="default,large")
    ap.add_argument("--time-limit", type=float, default=120.0)
    ap.add_argument("--requirement", type=float, default=0.10, help="requirement_m")
    ap.add_argument("--grid-spacing", type=float, default=1.0, help="grid_spacing_m (network "
                    "mode takes at most 20,000 tying sites: 2.5 on large)")
    ap.add_argument("--skip-plans", action="store_true")
    ap.add_argument("--skip-calibration", action="store_true")
    args = ap.parse_args()
    result = {}
    if not args.skip_calibration:
        result["calibration"] = calibration(args.draws)
    if not args.skip_plans:
        result["plans"] = [plans(s, args.time_limit, args.requirement, args.grid_spacing)
                           for s in args.sites.split(",")]
    print(json.dumps(result))


if __name__ == "__main__":
    main()
