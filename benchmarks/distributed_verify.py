"""Distributed verify: one process against a dask LocalCluster, and a projection to a km site.

In one run:

1. plans the ``large`` preset (``markerplan plan --site large``) and reads the planning
   visibility time from its timings line (per station: visibility seconds / stations);
2. verifies the first ``--stations`` stations of that plan with the same seed, as
   ``markerplan verify`` does (:func:`planner.verify.known_control.map_stations` with
   :func:`planner.verify.known_control.check_station`, each station's processing timed inside its
   task): (a) ``--scheduler none``, the single-process baseline (Embree on all cores),
   (b) a LocalCluster of ``--workers`` worker processes (one thread each), its start-up and
   the DEM's broadcast included;
   alternating (a, b, a, b, ... ``--repeat`` times each, so that other work on a shared machine
   hits both alike), and checks both give the same station checks;
3. prints the wall times, the ratio of the fastest a to the fastest b, the per-task costs
   (simulation, processing, planning visibility), and a table of the projected time of a
   ``--km-stations`` station site on N workers: N = 1 is the baseline's per-station cost,
   N = 2 the measured cluster, larger N on paper: start-up + ceil(S / N) x (cluster seconds
   per task per worker).

The machine is shared (other work may run), so the figures that matter are the ratios.

Usage: ``python -u benchmarks/distributed_verify.py [--stations 6] [--repeat 2] [--workers 2]
[--km-stations 311]`` (not ``distributed.py``: a script's folder comes first on ``sys.path``, so
that name would hide the ``distributed`` package).
"""

from __future__ import annotations

import argparse
import functools
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from error_model.default import default_model
from pipeline.surveys.survey import ProcessingSettings, processing_config
from planner.distributed import IN_PROCESS, LOCAL, executor
from planner.outputs.plan_file import load_plan
from planner.verify.known_control import check_station, map_stations


def timed(process, *args):
    """``process(*args)`` and its wall seconds (a station task's processing time)."""
    t0 = time.perf_counter()
    result = process(*args)
    return result, time.perf_counter() - t0


def plan_large(out: Path) -> tuple[float, int]:
    """Plan the ``large`` preset into ``out``; (planning visibility seconds, stations)."""
    cli = str(Path(sys.executable).parent / "markerplan")
    run = subprocess.run([cli, "plan", "--site", "large", "--out", str(out), "--overwrite"],
                         capture_output=True, text=True, check=True)
    seconds = float(re.search(r"visibility ([0-9.]+) s", run.stderr).group(1))
    return seconds, len(load_plan(out / "plan.json").stations)


def verify(plan, ids, scheduler, workers):
    """Wall seconds of verifying ``ids``, the checks, and the processing seconds per task."""
    model = default_model()
    check = functools.partial(check_station, tuple(plan.marker_ids), plan.marker_xyz_m,
                              processing_config(ProcessingSettings(marker_radius_m=plan.marker_radius_m)),
                              model, plan.requirement_m, plan.working_radius_m, 0)
    t0 = time.perf_counter()
    with executor(scheduler, workers) as ex:
        ex.map(abs, [0, 0], desc="start")  # a local cluster starts at its first map of 2+ tasks
        started = time.perf_counter() - t0
        done = map_stations(plan, functools.partial(timed, check), 0, station_ids=ids,
                            executor=ex)
    return time.perf_counter() - t0, started, [c for c, _ in done], [t for _, t in done]


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--stations", type=int, default=6)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--km-stations", type=int, default=311,
                        help="stations of the projected site (default: the km preset's 311)")
    args = parser.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        vis_s, n_planned = plan_large(Path(tmp) / "plan")
        print(f"planned `large` in {time.perf_counter() - t0:.1f} s: {n_planned} stations, "
              f"planning visibility {vis_s:.2f} s", flush=True)
        plan = load_plan(Path(tmp) / "plan" / "plan.json")
    ids = [s.id for s in plan.stations[:args.stations]]
    print(f"verifying {len(ids)} stations ({', '.join(ids)}); load average "
          f"{os.getloadavg()[0]:.1f}", flush=True)
    one, many = [], []
    for r in range(args.repeat):
        one.append(verify(plan, ids, IN_PROCESS, None))
        print(f"round {r + 1}: (a) --scheduler none: {one[-1][0]:.1f} s; load average "
              f"{os.getloadavg()[0]:.1f}", flush=True)
        many.append(verify(plan, ids, LOCAL, args.workers))
        print(f"round {r + 1}: (b) LocalCluster of {args.workers} workers: {many[-1][0]:.1f} s "
              f"(start-up and DEM broadcast {many[-1][1]:.1f} s); load average "
              f"{os.getloadavg()[0]:.1f}", flush=True)
    t_one, _, checks_one, proc_one = min(one, key=lambda run: run[0])
    t_many, startup, checks_many, proc_many = min(many, key=lambda run: run[0])
    same = checks_one == checks_many
    n = len(ids)
    task_one = t_one / n
    proc = sum(proc_one) / n
    per_task_worker = (t_many - startup) / math.ceil(n / args.workers)
    vis = vis_s / n_planned
    print(f"\nfastest (a) {t_one:.1f} s, fastest (b) {t_many:.1f} s: ratio a/b = "
          f"{t_one / t_many:.2f}x (aim >= 1.7x); same checks: {same}")
    print("\nper-task costs (seconds, this machine):")
    print(f"  station task, one process (all cores) : {task_one:.2f}")
    print(f"    simulation (task - processing)      : {task_one - proc:.2f}")
    print(f"    processing (pipeline + registration): {proc:.2f}")
    print(f"  station task per worker, cluster      : {per_task_worker:.2f}"
          f" (processing {sum(proc_many) / n:.2f})")
    print(f"  planning visibility per station       : {vis:.3f} (in process)")
    print(f"\nprojected verify of a km site, S = {args.km_stations} stations at the per-task costs "
          "above; paper rows: start-up + ceil(S/N) x cluster task time")
    print("| N workers | verify (s) | speed-up vs N=1 | planning visibility, serial (s) | source |")
    print("|---:|---:|---:|---:|---|")
    base = args.km_stations * task_one
    for workers in (1, 2, 4, 8, 16, 32, 64):
        if workers == 1:
            t, src = base, "measured per task (a)"
        else:
            t = startup + math.ceil(args.km_stations / workers) * per_task_worker
            src = "measured per task (b)" if workers == args.workers else "paper"
        print(f"| {workers} | {t:.0f} | {base / t:.1f}x | {args.km_stations * vis:.0f} | {src} |")


if __name__ == "__main__":
    main()
