"""Network greedy step cost: the incremental covariance against the full recompute, same run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -u benchmarks/network_greedy.py [--site km]
        [--grid-spacing 4] [--requirement 2.5] [--steps 10] [--greedy-steps 5000]
        [--base DIR [--repeats 3]] [--curve [--fractions 1,0.1] [--heading-prior DEG]]

Builds the site's network problem (``km``: datum at the station nearest the centre), runs
``greedy_network`` once (at most ``--greedy-steps`` steps: markers, wall time), then adds
``--steps`` sites one at a time, twice per phase, and times each step both ways:

- old: ``net.information(selected)`` and ``net.covariance`` of it (and, while some station
  is undetermined, of the regularised ``J + 0.05 J_all`` too), as the greedy did per step;
- new: :meth:`planner.accuracy.growing.GrowingCovariance.add` on the layout (and on the
  regularised information while undetermined).

Phase "undetermined" starts from the greedy's directions-only cover (stations not yet tied)
and adds tying sites spread over the site list; phase "determined" starts from every tying
site but the last ``--steps`` and adds those. Prints one line per phase and a final JSON
object.

With ``--base DIR`` (a checkout of another revision) it instead times the whole
``greedy_network`` of the built problem (pickled once) with that checkout's code and with this
tree's, in alternating subprocesses (``--repeats`` each, one BLAS thread), and prints each
side's times, the ratio of the medians and whether both selected the same sites. A huge
``--requirement`` (e.g. 1e6) times the tie-first phase alone.

With ``--curve`` it prints, instead, the worst, 90th-percentile and median station error
relative to the datum for the greedy's directions-only cover plus a random share of the tying
sites (each share of ``--fractions``; seed 0): how many markers a network requirement takes.
"""

from __future__ import annotations

import argparse
import json
import pickle
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from process_speed import run_worker


def _replay(net, start: np.ndarray, sites: np.ndarray, j_all: np.ndarray) -> dict:
    """Seconds per step of the old and the new update over ``sites`` added to ``start``."""
    from planner.accuracy.growing import GrowingCovariance

    selected = start.copy()
    old = []
    for j in sites:
        selected[j] = True
        t = time.perf_counter()
        info = net.information(selected)
        cov = net.covariance(info)
        if not cov.determined.all():
            net.covariance(info + 0.05 * j_all)
        old.append(time.perf_counter() - t)
    layout = GrowingCovariance(net, net.information(start))
    regularised = None if layout.determined.all() else \
        GrowingCovariance(net, layout.j + 0.05 * j_all)
    new = []
    for j in sites:
        t = time.perf_counter()
        layout.add(int(j))
        if regularised is not None:
            regularised.add(int(j))
        new.append(time.perf_counter() - t)
    undetermined = int(np.sum(~net.covariance(net.information(start)).determined))
    return {"steps": len(sites), "undetermined_at_start": undetermined,
            "old_s_per_step": float(np.mean(old)), "new_s_per_step": float(np.mean(new)),
            "ratio_old_over_new": float(np.sum(old) / np.sum(new))}


def _worker(problem_file: Path) -> None:
    """Time ``greedy_network`` on the pickled (problem, config); print a JSON line."""
    import planner
    from markerplan.errors import InfeasiblePlanError
    from planner.program.baselines import greedy_network

    with open(problem_file, "rb") as f:
        problem, config = pickle.load(f)
    t = time.perf_counter()
    try:
        selected = greedy_network(problem, config).selected
    except InfeasiblePlanError as exc:  # stuck: where it stopped
        selected = exc.selected
    print(json.dumps({"code": str(Path(planner.__file__).parents[1]),
                      "s": time.perf_counter() - t,
                      "sites": np.flatnonzero(selected).tolist()}))


def _against(base: Path, problem, config, repeats: int) -> dict:
    """Alternate ``greedy_network`` runs of ``base`` and this tree; print and return figures."""
    here = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        problem_file = Path(tmp) / "problem.pkl"
        with open(problem_file, "wb") as f:
            pickle.dump((problem, config), f)
        runs = {"base": [], "new": []}
        for _ in range(repeats):
            for name, tree in (("base", base), ("new", here)):
                runs[name].append(run_worker(__file__, tree, [str(problem_file)]))
    times = {name: [r["s"] for r in rs] for name, rs in runs.items()}
    out = {name: {"median_s": statistics.median(t), "s": t} for name, t in times.items()}
    out["ratio_base_over_new"] = out["base"]["median_s"] / out["new"]["median_s"]
    sites = {name: {tuple(r["sites"]) for r in rs} for name, rs in runs.items()}
    out["same_sites"] = len(sites["base"] | sites["new"]) == 1
    out["n_sites"] = len(runs["new"][0]["sites"])
    for name in ("base", "new"):
        print(f"{name}: median {out[name]['median_s']:.1f} s "
              f"({', '.join(f'{t:.1f}' for t in times[name])})")
    print(f"ratio base/new {out['ratio_base_over_new']:.2f}; {out['n_sites']} sites, same sites "
          f"on both sides and every repeat: {out['same_sites']}")
    return out


def _curve(problem, config, net, fractions: list[float]) -> list[dict]:
    """Station errors of the directions-only cover plus random shares of the tying sites."""
    from planner.program.baselines import greedy_cover

    cover = greedy_cover(problem, config.as_known_control(requirement_m=1e9)).selected
    tying = np.flatnonzero(net.tying)
    rng = np.random.default_rng(0)
    rows = []
    for f in fractions:
        x = cover.copy()
        x[rng.choice(tying, int(f * tying.size), replace=False)] = True
        err = net.station_errors_from(net.covariance(net.information(x)))
        tied = err[np.isfinite(err)]
        rows.append({"fraction": f, "sites": int(x.sum()), "untied": int(err.size - tied.size),
                     "worst_m": float(tied.max()), "p90_m": float(np.percentile(tied, 90)),
                     "median_m": float(np.median(tied))})
        print(f"cover + {f:.0%} of the tying sites: {rows[-1]['sites']} sites, "
              f"{rows[-1]['untied']} stations untied; station error worst "
              f"{rows[-1]['worst_m']:.2f} m, 90th percentile {rows[-1]['p90_m']:.2f} m, median "
              f"{rows[-1]['median_m']:.2f} m", flush=True)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="km")
    ap.add_argument("--grid-spacing", type=float, default=4.0, help="Candidate grid, m.")
    ap.add_argument("--requirement", type=float, default=2.5, help="requirement_m, m.")
    ap.add_argument("--steps", type=int, default=10, help="Steps timed per phase.")
    ap.add_argument("--greedy-steps", type=int, default=5000,
                    help="max_steps of the greedy run (its wall time is printed).")
    ap.add_argument("--base", type=Path, help="time the whole greedy against this checkout")
    ap.add_argument("--repeats", type=int, default=3, help="Runs per side with --base.")
    ap.add_argument("--curve", action="store_true",
                    help="print station errors against the share of tying sites instead")
    ap.add_argument("--fractions", default="1,0.6,0.3,0.1,0.05,0.02",
                    help="shares of the tying sites for --curve (comma-separated)")
    ap.add_argument("--heading-prior", type=float,
                    help="heading_prior_sigma_deg of the network (default none)")
    ap.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        _worker(args.worker)
        return

    from error_model import default_model
    from markerplan.errors import InfeasiblePlanError
    from planner.accuracy.network import network_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.program.baselines import greedy_cover, greedy_network
    from planner.run import build_problem

    inputs = load_inputs(args.site)
    ref = None
    if args.site == "km":
        # as benchmarks/km_plan.py: the station nearest the site's centre (the origin)
        ref = inputs.station_ids[int(np.argmin(np.hypot(*inputs.station_xyz[:, :2].T)))]
    config = PlanConfig(grid_spacing_m=args.grid_spacing, requirement_m=args.requirement,
                        network=True, reference_station=ref,
                        heading_prior_sigma_deg=args.heading_prior)
    t = time.perf_counter()
    problem, _, _, _ = build_problem(inputs, config, default_model(), progress=False)
    net = network_model(problem, config)
    print(f"site {args.site}: {problem.n_stations} stations, {net.n_params} pose parameters, "
          f"{int(net.tying.sum())} tying sites; built in {time.perf_counter() - t:.0f} s")
    if args.curve:
        rows = _curve(problem, config, net, [float(f) for f in args.fractions.split(",")])
        print(json.dumps(rows))
        return
    if args.base:
        if not (args.base / "planner" / "baselines.py").is_file():
            sys.exit(f"--base {args.base} is not a markerplan checkout")
        print(json.dumps(_against(args.base, problem, config, args.repeats)))
        return
    t = time.perf_counter()
    try:
        g = greedy_network(problem, config, net, max_steps=args.greedy_steps)
        greedy = f"{g.n_markers} markers"
    except InfeasiblePlanError as exc:  # e.g. stations still untied after --greedy-steps
        greedy = f"no passing layout after at most {args.greedy_steps} steps ({str(exc)[:60]}...)"
    greedy_s = time.perf_counter() - t
    print(f"greedy_network: {greedy} in {greedy_s:.1f} s")
    start = greedy_cover(problem, config.as_known_control(requirement_m=1e9)).selected
    j_all = net.information(net.tying)
    out = {"site": args.site, "n_params": net.n_params, "greedy": greedy, "greedy_s": greedy_s}
    # the same sites both ways: every k-th tying site outside the cover, then every tying site
    # but the last --steps of them (a determined layout)
    spare = np.flatnonzero(net.tying & ~start)
    first = spare[::max(spare.size // args.steps, 1)][:args.steps]
    last = np.flatnonzero(net.tying)[-args.steps:]
    end = net.tying.copy()
    end[last] = False
    for phase, begin, sites in (("undetermined", start, first), ("determined", end, last)):
        r = _replay(net, begin, sites, j_all)
        out[phase] = r
        print(f"{phase} phase ({r['undetermined_at_start']} stations undetermined at the "
              f"start): {r['steps']} steps, full recompute {r['old_s_per_step']:.3f} s/step, "
              f"incremental {r['new_s_per_step']:.3f} s/step: {r['ratio_old_over_new']:.1f} x")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
