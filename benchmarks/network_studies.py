"""Network-mode studies: known control against network mode, error against
distance from the reference, the trade-off curve, what a heading prior buys, and the greedy and
regular-grid baselines, per site.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/network_studies.py [--sites default]
        [--grid-spacing 1.0] [--time-limit 60] [--requirement 0.10]
        [--requirements 0.03,0.035,0.04,0.05,0.06,0.08,0.10,0.15,0.20]
        [--heading-priors none,2,1,0.5,0.1]
        [--prior-requirements 0.10] [--reference S1] [--studies abcde] [--out DIR]

    # large (heavy; a coarser candidate grid and a time limit per plan):
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/network_studies.py --sites large \
        --grid-spacing 3 --time-limit 120

``--grid-spacing`` applies to every site unless given per site (``--grid-spacing
default=1,large=3``). Prints the tables of every site (errors in cm, 95 %, relative to the
reference station), then one JSON object; ``--out DIR`` also writes
``<site>_error_vs_distance.png`` and ``<site>_tradeoff.png``. The study code is
:mod:`planner.studies.network` (shared with ``notebooks/06_network_mode.py``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",") if v.strip()]


def _sigmas(text: str) -> list[float | None]:
    return [None if v.strip().lower() == "none" else float(v) for v in text.split(",")
            if v.strip()]


def _per_site(text: str, sites: list[str]) -> dict[str, float]:
    """``1.0`` (every site) or ``default=1,large=3``."""
    if "=" not in text:
        return dict.fromkeys(sites, float(text))
    given = {k.strip(): float(v) for k, v in (p.split("=") for p in text.split(","))}
    missing = [s for s in sites if s not in given]
    if missing:
        raise SystemExit(f"--grid-spacing names no spacing for site(s) {', '.join(missing)}")
    return given


def _log(letter: str, doc: dict) -> None:
    """Progress on stderr: each study's table as soon as it is done."""
    from planner.studies import network as ns

    lines = ns.report_lines(doc, letter, header=False)
    print(f"[{doc['site']}, {time.strftime('%H:%M:%S')}]" + "\n".join(lines), file=sys.stderr,
          flush=True)


def run_site(site: str, args, grid_spacing_m: float) -> dict:
    from error_model import default_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.run import build_problem, plan_bounds
    from planner.studies import network as ns

    t0 = time.perf_counter()
    inputs = load_inputs(site)
    config = PlanConfig(grid_spacing_m=grid_spacing_m, time_limit_s=args.time_limit,
                        requirement_m=args.requirement, reference_station=args.reference)
    problem, cand, _, _ = build_problem(inputs, config, default_model(), progress=False)
    t_build = time.perf_counter() - t0
    doc, _ = ns.run_studies(problem, config, plan_bounds(inputs, problem),
                            _floats(args.requirements), _sigmas(args.heading_priors),
                            args.studies, args.grid_step,
                            info={"site": site, "n_candidates": len(cand)},
                            prior_requirements_m=_floats(args.prior_requirements)
                            if args.prior_requirements else None, on_study=_log)
    doc["build_time_s"] = round(t_build, 2)
    doc["total_time_s"] = round(time.perf_counter() - t0, 2)
    print("\n".join(ns.report_lines(doc)))
    print(f"(problem built in {t_build:.1f} s; site total {doc['total_time_s']:.1f} s)")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        if "distance" in doc:
            ns.plot_error_vs_distance(doc, out / f"{site}_error_vs_distance.png")
        if "tradeoff" in doc or "heading_prior" in doc:
            ns.plot_tradeoff_and_prior(doc, out / f"{site}_tradeoff.png")
    sys.stdout.flush()
    return doc


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sites", default="default", help="comma-separated, e.g. default,large")
    ap.add_argument("--grid-spacing", default="1.0",
                    help="candidate grid, m: one value or per site (default=1,large=3)")
    ap.add_argument("--time-limit", type=float, default=60.0, help="per plan, s")
    ap.add_argument("--requirement", type=float, default=0.10, help="requirement_m of (a, b, d, e)")
    ap.add_argument("--requirements", default="0.03,0.035,0.04,0.05,0.06,0.08,0.10,0.15,0.20",
                    help="trade-off curve (c), m")
    ap.add_argument("--heading-priors", default="none,2,1,0.5,0.1",
                    help="heading-prior sigmas of (d), deg ('none': no prior)")
    ap.add_argument("--prior-requirements", default=None,
                    help="requirements of (d), m (default: --requirement)")
    ap.add_argument("--reference", default=None,
                    help="reference station id (default: the first station)")
    ap.add_argument("--studies", default="abcde", help="letters: a modes, b distance, "
                    "c trade-off, d heading prior, e baselines")
    ap.add_argument("--grid-step", type=float, default=0.5,
                    help="regular-grid baseline: spacing step, m")
    ap.add_argument("--out", default=None, help="folder for the PNG figures")
    args = ap.parse_args()
    sites = [s.strip() for s in args.sites.split(",") if s.strip()]
    spacing = _per_site(args.grid_spacing, sites)
    results = []
    for site in sites:
        results.append(run_site(site, args, spacing[site]))
        print()
    print(json.dumps(results))


if __name__ == "__main__":
    main()
