"""Network greedy step cost: the incremental covariance against the full recompute, same run.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -u benchmarks/network_greedy.py [--site km]
        [--grid-spacing 4] [--requirement 2.5] [--steps 10] [--greedy-steps 5000]

Builds the site's network problem (``km``: datum at the station nearest the centre), runs
``greedy_network`` once (at most ``--greedy-steps`` steps: markers, wall time), then adds
``--steps`` sites one at a time, twice per phase, and times each step both ways:

- old: ``net.information(selected)`` and ``net.covariance`` of it (and, while some station
  is undetermined, of the regularised ``J + 0.05 J_all`` too), as the greedy did per step;
- new: :meth:`planner.network_accuracy.GrowingCovariance.add` on the layout (and on the
  regularised information while undetermined).

Phase "undetermined" starts from the greedy's directions-only cover (stations not yet tied)
and adds tying sites spread over the site list; phase "determined" starts from every tying
site but the last ``--steps`` and adds those. Prints one line per phase and a final JSON
object.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def _replay(net, start: np.ndarray, sites: np.ndarray, j_all: np.ndarray) -> dict:
    """Seconds per step of the old and the new update over ``sites`` added to ``start``."""
    from planner.network_accuracy import GrowingCovariance

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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="km")
    ap.add_argument("--grid-spacing", type=float, default=4.0, help="Candidate grid, m.")
    ap.add_argument("--requirement", type=float, default=2.5, help="requirement_m, m.")
    ap.add_argument("--steps", type=int, default=10, help="Steps timed per phase.")
    ap.add_argument("--greedy-steps", type=int, default=5000,
                    help="max_steps of the greedy run (its wall time is printed).")
    args = ap.parse_args()

    from error_model import default_model
    from markerplan.errors import InfeasiblePlanError
    from planner.baselines import greedy_cover, greedy_network
    from planner.config import PlanConfig
    from planner.network_accuracy import network_model
    from planner.planning import build_problem, load_inputs

    inputs = load_inputs(args.site)
    ref = None
    if args.site == "km":
        # as benchmarks/km_plan.py: the station nearest the site's centre (the origin)
        ref = inputs.station_ids[int(np.argmin(np.hypot(*inputs.station_xyz[:, :2].T)))]
    config = PlanConfig(grid_spacing_m=args.grid_spacing, requirement_m=args.requirement,
                        network=True, reference_station=ref)
    t = time.perf_counter()
    problem, _, _, _ = build_problem(inputs, config, default_model(), progress=False)
    net = network_model(problem, config)
    print(f"site {args.site}: {problem.n_stations} stations, {net.n_params} pose parameters, "
          f"{int(net.tying.sum())} tying sites; built in {time.perf_counter() - t:.0f} s")
    t = time.perf_counter()
    try:
        g = greedy_network(problem, config, net, max_steps=args.greedy_steps)
        greedy = f"{g.n_markers} markers"
    except InfeasiblePlanError as exc:  # e.g. stations still untied after --greedy-steps
        greedy = f"no passing layout after at most {args.greedy_steps} steps ({str(exc)[:60]}...)"
    greedy_s = time.perf_counter() - t
    print(f"greedy_network: {greedy} in {greedy_s:.1f} s")
    start = greedy_cover(problem, config.replace(network=False, requirement_m=1e9)).selected
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
