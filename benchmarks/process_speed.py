"""Processing time of one default-site station (800 frames): a baseline checkout against this one.

The station is simulated once (mounting offsets 0.3 deg, 0.3 deg, 15 mm, as in
``benchmarks/process.py``) and cached (``--scan``; reused when it exists). Each repeat then runs
:func:`pipeline.chain.process.process_station` on it in a fresh subprocess, once with the baseline's
code on ``PYTHONPATH`` and once with this tree's, alternating, so both see the same machine
load. Each subprocess processes the station twice: the first run is the first station of a fresh
process (it pays one-time start-ups, such as loading compiled kernels), the second is what every
further station of a process (``verify``, ``range-study``) costs. Printed, for both: the median
and every time of each side (wall clock, and CPU time of all the process's threads, which other
processes' load inflates less), the ratios, the median per-stage (wall) times of the first run;
whether the two runs of a side gave the same table; and how far the two marker tables and
calibrations differ: the largest difference of the marker centres (metres, accepted and rejected
apart), of every other float column and of the estimated offsets (radians for the angles, metres
for the axis offset), whether every other column (ids, counts, estimator, verdicts and reasons)
is identical, and whether the offsets and the accepted markers' centres are within
:data:`OFFSET_TOLERANCE` and :data:`CENTRE_TOLERANCE_M` (round-off of exact rewrites; rejected
candidates' ill-conditioned fits are only printed).

Make the baseline with ``git worktree add /tmp/base-<rev> <rev>``, a revision with pipeline's
subpackages (``pipeline/chain/process.py``): the worker imports the baseline's modules by this
tree's paths.

Usage: ``python -u benchmarks/process_speed.py --base /tmp/base-<rev>
[--scan /tmp/mp-speed/station0.scan.npz] [--repeats 5]``
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import astuple, fields
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]

#: Largest marker-centre difference from the baseline accepted as round-off, metres.
CENTRE_TOLERANCE_M = 1e-9
#: Largest difference of an estimated offset accepted as round-off (radians or metres).
OFFSET_TOLERANCE = 1e-9


def simulate(scan_path: Path, frames: int, station: int = 0) -> None:
    """Simulate one station of the default site and write ``scan_path`` and its truth beside.

    Parameters
    ----------
    scan_path : Path
        ``<name>.scan.npz`` to write; the truth goes to :func:`truth_path` of it.
    frames : int
        Frames per turntable turn.
    station : int
        Index into the default site's ``station_ids``.
    """
    from pipeline.scans.rig import MountingOffsets
    from pipeline.scans.scan_format import write_scan, write_truth
    from visibility.sensor import RigConfig
    from visibility.simulate import simulate_station
    from visibility.sites import load_site

    rig = RigConfig(frames_per_turn=frames,
                    offsets=MountingOffsets(np.radians(0.3), np.radians(0.3), (0.015, 0.0)))
    scan, truth = simulate_station(load_site("default"), station, rig=rig, seed=0)
    scan_path.parent.mkdir(parents=True, exist_ok=True)
    write_scan(scan_path, scan)
    write_truth(truth_path(scan_path), truth)


def truth_path(scan_path: Path) -> Path:
    """The simulation truth file beside ``scan_path`` (``.scan.npz`` -> ``.truth.json``)."""
    return scan_path.with_name(scan_path.name.replace(".scan.npz", ".truth.json"))


def _worker(scan_path: Path) -> None:
    """Process the scan with whichever ``pipeline`` is importable; print one JSON line."""
    import pipeline
    from pipeline.chain.evaluation import read_reference
    from pipeline.chain.process import process_station
    from pipeline.scans.scan_format import read_scan
    from pipeline.tables.marker_table import MarkerRow

    scan = read_scan(scan_path)
    ref = read_reference(truth_path(scan_path))
    t0, c0 = time.perf_counter(), time.process_time()
    res = process_station(scan, None, ref)
    total, cpu = time.perf_counter() - t0, time.process_time() - c0
    t0, c0 = time.perf_counter(), time.process_time()
    again = process_station(scan, None, ref)
    again_total, again_cpu = time.perf_counter() - t0, time.process_time() - c0
    print(json.dumps({"code": str(Path(pipeline.__file__).parents[1]), "total_s": total,
                      "cpu_s": cpu, "again_total_s": again_total, "again_cpu_s": again_cpu,
                      "again_same": repr(again.rows) == repr(res.rows), "stages_s": res.timings_s,
                      "columns": [f.name for f in fields(MarkerRow)],
                      "rows": [astuple(r) for r in res.rows],
                      "offsets": res.calibration["offsets"]}, default=float))


def run_worker(script: str, tree: Path, arguments: list[str]) -> dict:
    """Run ``script --worker ...`` with ``tree`` first on ``PYTHONPATH``, one BLAS thread.

    Returns the JSON object the worker printed on its last line; exits when the worker imported
    ``pipeline`` from anywhere but ``tree``.
    """
    env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, script, "--worker", *arguments], env=env,
                         capture_output=True, text=True, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if Path(result["code"]).resolve() != tree.resolve():
        sys.exit(f"the worker imported pipeline from {result['code']}, not {tree}")
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, help="checkout of the baseline revision")
    ap.add_argument("--scan", type=Path, default=Path("/tmp/mp-speed/station0.scan.npz"))
    ap.add_argument("--frames", type=int, default=800)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        _worker(args.worker)
        return
    if args.base is None or not (args.base / "pipeline" / "chain" / "process.py").is_file():
        sys.exit("give --base, a checkout of a baseline with pipeline/chain/process.py "
                 "(git worktree add /tmp/base-<rev> <rev>)")
    if not args.scan.is_file():
        print(f"simulating the station into {args.scan} ...", flush=True)
        simulate(args.scan, args.frames)
    sides = {"base": args.base, "new": HERE}
    runs: dict[str, list[dict]] = {name: [] for name in sides}
    print(f"load average before: {os.getloadavg()[0]:.2f}", flush=True)
    for k in range(args.repeats):
        for name, tree in sides.items():
            runs[name].append(run_worker(__file__, tree, [str(args.scan)]))
            r = runs[name][-1]
            print(f"  repeat {k + 1} {name:4s} first {r['total_s']:6.2f} s wall, "
                  f"{r['cpu_s']:6.2f} s CPU; again {r['again_total_s']:6.2f} s wall, "
                  f"{r['again_cpu_s']:6.2f} s CPU (load {os.getloadavg()[0]:.2f})", flush=True)
    for key, what in (("total_s", "wall"), ("cpu_s", "CPU (all threads)"),
                      ("again_total_s", "again, wall"), ("again_cpu_s", "again, CPU")):
        med = {name: float(np.median([r[key] for r in rs])) for name, rs in runs.items()}
        for name, rs in runs.items():
            times = ", ".join(f"{r[key]:.2f}" for r in rs)
            print(f"{name} {what} ({sides[name]}): median {med[name]:.2f} s  [{times}]")
        print(f"ratio base / new, {what}: {med['base'] / med['new']:.2f}")
    for name, rs in runs.items():
        print(f"{name}: the second run gave the first's marker table every time: "
              f"{all(r['again_same'] for r in rs)}")
    print("median per-stage times of the first run, s (base / new):")
    stages = dict.fromkeys([s for rs in runs.values() for s in rs[0]["stages_s"]])
    for stage in stages:
        b, n = (np.median([r["stages_s"].get(stage, 0.0) for r in runs[name]])
                for name in sides)
        print(f"  {stage:24s} {b:6.2f} / {n:6.2f}")
    _compare(runs["base"][0], runs["new"][0])


def _compare(base: dict, new: dict) -> None:
    """Print the largest differences between two workers' marker tables and offsets.

    The tolerances apply to the offsets and the accepted markers; the rejected candidates'
    float columns are printed only (their fits, on few points or not on a sphere, are so
    ill-conditioned that round-off moves them by up to millimetres).
    """
    from pipeline.tables.marker_table import MarkerRow

    names = [f.name for f in fields(MarkerRow)]
    centre = [names.index(c) for c in ("x_m", "y_m", "z_m")]
    accepted = names.index("accepted")
    # max differences: [accepted, rejected] x [centre, other float columns]
    diff = np.zeros((2, 2))
    exact = len(base["rows"]) == len(new["rows"])
    for b, n in zip(base["rows"], new["rows"], strict=False):
        for i, (u, v) in enumerate(zip(b, n, strict=True)):
            if isinstance(u, float) and isinstance(v, float):
                d = abs(u - v) if np.isfinite(u) or np.isfinite(v) else 0.0
                cell = (0 if b[accepted] else 1, 0 if i in centre else 1)
                diff[cell] = max(diff[cell], d)
            elif u != v:
                exact = False
                print(f"  differs in {names[i]}: base {b}\n  new  {n}")
    ob, on = base["offsets"], new["offsets"]
    d_off = max(float(np.max(np.abs(np.subtract(ob[k], on[k])))) for k in ob)
    ok = exact and diff[0, 0] <= CENTRE_TOLERANCE_M and d_off <= OFFSET_TOLERANCE
    print(f"marker table: {len(new['rows'])} rows (base {len(base['rows'])}); ids, counts, "
          f"verdicts, reasons identical: {exact}")
    print(f"  max centre difference: accepted {diff[0, 0]:.3g} m, rejected {diff[1, 0]:.3g} m;"
          f" other float columns: accepted {diff[0, 1]:.3g}, rejected {diff[1, 1]:.3g}")
    print(f"  max offset difference {d_off:.3g}; within tolerance (accepted centres "
          f"{CENTRE_TOLERANCE_M:g} m, offsets {OFFSET_TOLERANCE:g}): {ok}")

if __name__ == "__main__":
    main()
