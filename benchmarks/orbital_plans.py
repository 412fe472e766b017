"""Plans made on the orbital-grade DEM, verified on the truth terrain (issue 28, item 6).

For each site seed: the naive plan (``chance_epsilon`` None) made on the preset's fine truth
terrain and on its orbital planning DEM (:func:`visibility.sites.planning_dem`), and — when a
detection model is shipped (or with ``--chance``) — the chance-constrained plan on the orbital
DEM twice: without the terrain handling (the DEM taken as exact: the detection model's chances
only) and with it (the chances times P(visible),
:func:`planner.problem.terrain_uncertainty.visible_probability`); each verified (known
control) on the truth terrain (:func:`planner.verify.known_control.on_truth_terrain`) with
``--verify-seeds`` noise seeds.
Prints one line per verification and, per variant, its markers and pass rate with the Wilson
95 % interval; a final JSON object. Each verification is a full simulation of every station
(about a minute on 2 cores for ``default``).

First, cheaply, the calibration of P(visible) itself (:func:`visibility_calibration`): for
every usable pair of the first site seed's orbital problem, P(visible) from K realisations
against whether the pair is visible on the truth terrain (stations and markers seated on the
truth ground), in bins of P, with the Brier score beside the planning DEM's 0/1 verdict's.

    OPENBLAS_NUM_THREADS=1 nice -n 10 .venv/bin/python benchmarks/orbital_plans.py \\
        [--site default] [--site-seeds 0,1,2] [--verify-seeds 0] [--chance] [--out DIR]
        [--realisations 8] [--calibration-only]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path


def shipped_detection_model():
    """The shipped detection model, or ``None`` while none is shipped (the chance-constrained
    plan, which multiplies P(visible) into it, then cannot be made)."""
    from error_model.default import default_detection_model
    from markerplan.errors import InputFileError

    try:
        return default_detection_model()
    except InputFileError:
        return None


def visibility_calibration(site: str, site_seed: int, realisations: int, model) -> dict:
    """P(visible) on the orbital DEM against visibility on the truth terrain, usable pairs."""
    import numpy as np

    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.problem.sight import angular_sampling
    from planner.problem.terrain_uncertainty import visible_probability
    from planner.run import build_problem
    from visibility.orbital import reseated
    from visibility.sites import load_site
    from visibility.visibility_matrix import tiled_visibility

    config = PlanConfig(chance_epsilon=None)
    inputs = load_inputs(site, site_seed, terrain="orbital")
    problem, _, vis, _ = build_problem(inputs, config, model, progress=False)
    n_sites = len(problem.site_xyz)
    t = time.perf_counter()
    p = visible_probability(inputs, vis, problem.site_xyz, config, realisations, seed=0)
    p_s = time.perf_counter() - t
    truth = load_site(site, site_seed).dem
    seen, _ = tiled_visibility(truth, reseated(inputs.station_xyz, inputs.dem, truth),
                               reseated(problem.site_xyz, inputs.dem, truth),
                               inputs.marker_radius_m, config.max_range_m,
                               config.rays_per_marker, angular_sampling(), progress=False)
    usable = problem.pair_station[problem.pair_usable] * n_sites \
        + problem.pair_site[problem.pair_usable]
    key = vis.station * n_sites + vis.site
    at = np.searchsorted(key, usable)  # both sorted by station, then site
    p_u, planned = p[at], (vis.visible_fraction[at] >= config.min_visible_fraction)
    seen_key = seen.station * n_sites + seen.site
    truly = np.isin(usable, seen_key[seen.visible_fraction >= config.min_visible_fraction])
    bins = []
    for lo, hi in ((0.0, 0.3), (0.3, 0.6), (0.6, 0.8), (0.8, 0.95), (0.95, 1.01)):
        b = (p_u >= lo) & (p_u < hi)
        if b.any():
            bins.append({"p": [lo, min(hi, 1.0)], "pairs": int(b.sum()),
                         "mean_p": round(float(p_u[b].mean()), 3),
                         "truly_visible": round(float(truly[b].mean()), 3)})
            print(f"P(visible) in [{lo:.2f}, {min(hi, 1.0):.2f}): {b.sum():5d} pairs, mean "
                  f"{p_u[b].mean():.3f}, visible on the truth {truly[b].mean():.3f}")
    rec = {"pairs": int(len(usable)), "visible_probability_s": round(p_s, 2),
           "realisations": realisations, "bins": bins,
           "brier_p": round(float(np.mean((p_u - truly) ** 2)), 4),
           "brier_planning_verdict": round(float(np.mean((planned.astype(float) - truly) ** 2)), 4)}
    print(f"{len(usable)} usable pairs, P(visible) K={realisations} in {p_s:.1f} s; Brier "
          f"{rec['brier_p']} (planning DEM's 0/1 verdict {rec['brier_planning_verdict']})")
    return rec


def plan_and_verify(site: str, site_seed: int, terrain: str, epsilon, verify_seeds, out: Path,
                    model, detection_model=None) -> dict:
    """Make one plan (``make_plan``) into ``out`` and verify it on the truth for each seed;
    ``terrain`` ``"orbital-exact"``: on the orbital DEM with its height error ignored."""
    from dataclasses import replace

    from planner.config import PlanConfig
    from planner.outputs.plan_file import load_plan
    from planner.outputs.report import write_plan_files
    from planner.problem.inputs import load_inputs
    from planner.run import make_plan
    from planner.verify.known_control import on_truth_terrain, verify_plan

    config = PlanConfig(chance_epsilon=epsilon)
    inputs = load_inputs(site, site_seed, terrain=terrain.removesuffix("-exact"),
                         sight_radius_m=config.max_range_m)
    if terrain.endswith("-exact"):
        inputs = replace(inputs, height_error=None)
    t = time.perf_counter()
    outcome = make_plan(inputs, config, model, "default", progress=False,
                        detection_model=None if epsilon is None else detection_model)
    plan_s = time.perf_counter() - t
    out.mkdir(parents=True, exist_ok=True)
    doc = write_plan_files(outcome, out)
    plan = on_truth_terrain(load_plan(out / "plan.json"))
    passed = []
    for seed in verify_seeds:
        t = time.perf_counter()
        checks = verify_plan(plan, model, seed=seed, progress=False)
        ok = all(c.passed for c in checks)
        passed.append(ok)
        lost = "; ".join(f"{c.station_id}: {c.reason}" for c in checks if not c.passed)
        print(f"{site} seed {site_seed} {terrain:13s} eps={epsilon} markers {doc['n_markers']} "
              f"verify seed {seed}: {'PASS' if ok else 'FAIL'} ({time.perf_counter() - t:.0f} s)"
              + (f" [{lost}]" if lost else ""), flush=True)
    return {"site_seed": site_seed, "terrain": terrain, "epsilon": epsilon,
            "n_markers": doc["n_markers"], "plan_s": round(plan_s, 2), "passed": passed,
            "chance": doc.get("chance")}


def main() -> None:
    from error_model import default_model
    from error_model.detection import wilson_interval

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="default", choices=["default", "large"])
    ap.add_argument("--site-seeds", default="0,1,2")
    ap.add_argument("--verify-seeds", default="0")
    ap.add_argument("--chance", action="store_true",
                    help="Also the chance-constrained plan on the orbital DEM (default: when "
                         "a detection model is shipped).")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--realisations", type=int, default=8)
    ap.add_argument("--calibration-only", action="store_true")
    args = ap.parse_args()
    site_seeds = [int(s) for s in args.site_seeds.split(",")]
    verify_seeds = [int(s) for s in args.verify_seeds.split(",")]
    variants = [("truth", None), ("orbital", None)]
    detection_model = shipped_detection_model()
    if args.chance or detection_model is not None:
        variants += [("orbital-exact", 0.05), ("orbital", 0.05)]
    model = default_model()
    calibration = visibility_calibration(args.site, site_seeds[0], args.realisations, model)
    if args.calibration_only:
        print(json.dumps({"site": args.site, "calibration": calibration}))
        return
    out = args.out or Path(tempfile.mkdtemp(prefix="orbital-plans-"))
    rows = [plan_and_verify(args.site, s, terrain, eps, verify_seeds,
                            out / f"{terrain}-{eps}-{s}", model, detection_model)
            for s in site_seeds for terrain, eps in variants]
    summary = {}
    for terrain, eps in variants:
        mine = [r for r in rows if r["terrain"] == terrain and r["epsilon"] == eps]
        k = sum(sum(r["passed"]) for r in mine)
        n = sum(len(r["passed"]) for r in mine)
        low, high = wilson_interval(k, n)
        name = f"{terrain} plan, " + ("naive" if eps is None else f"chance eps={eps}")
        if eps is not None and terrain == "orbital":
            name += " with P(visible)"
        summary[name] = {"markers": [r["n_markers"] for r in mine], "n_passed": k, "n": n,
                         "wilson_95": [round(low, 3), round(high, 3)]}
        print(f"{name:32s} markers {summary[name]['markers']}: passed {k} of {n} on the truth "
              f"terrain (95 % {100 * low:.0f}-{100 * high:.0f} %)")
    print(json.dumps({"site": args.site, "verify_seeds": verify_seeds, "summary": summary,
                      "calibration": calibration, "runs": rows}, default=str))


if __name__ == "__main__":
    main()
