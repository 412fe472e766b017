"""CPU time of one station's angle self-calibration, synthesis and detection: a baseline
checkout against this one, stage by stage.

:mod:`benchmarks.process_speed` times the whole chain by wall clock; on a shared machine the
per-stage wall times of a few hundred milliseconds drown in other processes' load. Here each
stage runs alone, ``--inner`` times in one process, and its CPU time (all threads) is taken;
the minimum over every run of a side is the figure least inflated by load. The stages, on the
cached scan of :mod:`benchmarks.process_speed`:

- ``calibrate_angles``: :func:`pipeline.chain.calibration.estimate_rotation_offsets` from zero
  offsets (the chain's first call);
- ``synthesis``: :func:`pipeline.chain.synthesis.synthesize` with those angles and a 15 mm axis
  offset;
- ``ground+cluster+gate``: :func:`pipeline.chain.process.detect_candidates` on that cloud.

Each repeat runs a fresh subprocess per side (baseline code on ``PYTHONPATH``, then this
tree's), alternating, so both see the same load. Printed: per stage, the minimum and median CPU
time of each side and the ratio of the minima; and whether both sides gave the same offsets
(largest difference), the same cloud (bit for bit) and the same candidate clusters.

Usage: ``python -u benchmarks/station_stages_speed.py --base /tmp/base-main
[--scan /tmp/mp-speed/station0.scan.npz] [--repeats 3] [--inner 3]``
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from process_speed import run_worker

HERE = Path(__file__).resolve().parents[1]
STAGES = ("calibrate_angles", "synthesis", "ground+cluster+gate")


def _worker(scan_path: Path, inner: int) -> None:
    """Time the stages with whichever ``pipeline`` is importable; print one JSON line."""
    import pipeline
    from pipeline.chain.calibration import estimate_rotation_offsets
    from pipeline.chain.process import detect_candidates
    from pipeline.chain.stages import build_config
    from pipeline.chain.synthesis import synthesize
    from pipeline.scans.rig import MountingOffsets
    from pipeline.scans.scan_format import read_scan

    scan = read_scan(scan_path)
    cfg = build_config()
    times: dict[str, list[float]] = {s: [] for s in STAGES}

    def timed(stage, fn, *args):
        out = None
        for _ in range(inner):
            c0 = time.process_time()
            out = fn(*args)
            times[stage].append(time.process_time() - c0)
        return out

    angles = timed("calibrate_angles", estimate_rotation_offsets, scan, MountingOffsets(),
                   cfg.calibrate.calibration())[0]
    offsets = MountingOffsets(angles.vertical_axis_error_rad, angles.lframe_tilt_rad,
                              (0.015, 0.0))
    cloud = timed("synthesis", synthesize, scan, offsets)
    detection = timed("ground+cluster+gate", detect_candidates, cloud, cfg)
    digest = hashlib.sha256()
    for arr in (cloud.xyz_m, cloud.range_m):
        digest.update(np.ascontiguousarray(arr).tobytes())
    print(json.dumps({"code": str(Path(pipeline.__file__).parents[1]), "times_s": times,
                      "angles": [angles.vertical_axis_error_rad, angles.lframe_tilt_rad],
                      "cloud_sha256": digest.hexdigest(),
                      "clusters": [m.tolist() for m in detection.clusters]}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=Path, help="checkout of the baseline revision")
    ap.add_argument("--scan", type=Path, default=Path("/tmp/mp-speed/station0.scan.npz"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--inner", type=int, default=3, help="runs of each stage per process")
    ap.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        _worker(args.worker, args.inner)
        return
    if args.base is None or not (args.base / "pipeline" / "chain" / "process.py").is_file():
        sys.exit("give --base, a checkout of a baseline with pipeline/chain/process.py "
                 "(git -C <repo> archive <rev> | tar -x -C <dir>)")
    if not args.scan.is_file():
        sys.exit(f"no scan at {args.scan}: run benchmarks/process_speed.py once to simulate it")
    sides = {"base": args.base, "new": HERE}
    runs: dict[str, list[dict]] = {name: [] for name in sides}
    print(f"load average before: {os.getloadavg()[0]:.2f}", flush=True)
    for k in range(args.repeats):
        for name, tree in sides.items():
            runs[name].append(run_worker(__file__, tree, [str(args.scan), "--inner",
                                                          str(args.inner)]))
            print(f"  repeat {k + 1} {name}: done (load {os.getloadavg()[0]:.2f})", flush=True)
    print(f"CPU time per stage, s: min / median of {args.repeats} x {args.inner} runs "
          f"(base {args.base}, new {HERE})")
    for stage in STAGES:
        t = {name: [x for r in rs for x in r["times_s"][stage]] for name, rs in runs.items()}
        print(f"  {stage:22s} base {min(t['base']):6.3f} / {np.median(t['base']):6.3f}   "
              f"new {min(t['new']):6.3f} / {np.median(t['new']):6.3f}   "
              f"ratio of minima base / new {min(t['base']) / min(t['new']):5.2f}")
    b, n = runs["base"][0], runs["new"][0]
    print(f"angles: max difference {np.max(np.abs(np.subtract(b['angles'], n['angles']))):.3g}"
          f" rad; cloud bit-identical: {b['cloud_sha256'] == n['cloud_sha256']}; "
          f"candidate clusters identical: {b['clusters'] == n['clusters']} "
          f"({len(n['clusters'])} clusters)")


if __name__ == "__main__":
    main()
