"""The loss study: where the station chain loses markers, per distance, elevation, incidence,
slope, crater-rim distance, visible fraction and expected points, per stage.

Two layouts (:mod:`planner.studies.loss_study`):

``level``
    One station 1 m above a level field, one 0.20 m marker at each distance of the published
    range experiment (1-50 m, golden-angle azimuths), like ``range-study`` but through the full
    chain.
``default``
    The default site's seven stations and its relief (craters, rocks, boulders), with markers on
    a jittered 4 m grid over the working area, split into ``--groups`` interleaved sets (seed
    ``i`` scans set ``i % groups``).

Every scan is simulated with the shipped (calibrated) sensor profile and processed by the chain
as ``verify`` processes it; each marker in range gets the stage that lost it (or ``accepted``)
and the planner's covariates for the pair. Printed: per bin of each covariate, the pairs, the
detection rate (a candidate fitted on the marker), the acceptance rate and the losses per stage;
then the quality gate's reasons and the false accepts (accepted candidates that are no marker).
``--csv FILE`` also writes every row as a fate table (:mod:`pipeline.tables.fate_table`, the
input of a detection model). A study that prints: it
asserts nothing about the figures.

Usage: ``python -u benchmarks/loss_study.py --layout level --seeds 4 [--frame-step 1]
[--scheduler local --workers 2] [--csv /tmp/losses.csv]``
"""

from __future__ import annotations

import argparse
import collections
import sys
import time

import numpy as np

from pipeline.tables.fate_table import FATE_STAGES, write_fate_table
from planner.studies.loss_study import (
    level_layout,
    loss_jobs,
    loss_table,
    relief_layout,
    run_loss_study,
)

#: Bin edges of each covariate printed.
BINS = {
    "distance_m": [1.0, 1.5, 2.5, 3.5, 5.5, 8.0, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0, 51.0],
    "elevation_deg": [-90.0, -30.0, -15.0, -8.0, -4.0, -2.0, 0.0, 90.0],
    "incidence_deg": [0.0, 60.0, 75.0, 82.0, 86.0, 88.0, 90.1],
    "slope_deg": [0.0, 2.0, 5.0, 10.0, 20.0, 90.0],
    "rim_distance_m": [0.0, 0.5, 1.0, 2.0, 4.0, np.inf],
    "visible_fraction": [0.0, 0.25, 0.5, 0.75, 0.95, 1.01],
    "expected_points": [0.0, 25.0, 50.0, 100.0, 300.0, 1000.0, 3000.0, np.inf],
}


def _print_table(rows: list[dict], column: str) -> None:
    table = loss_table(rows, column, BINS[column])
    if not table:
        return
    stages = FATE_STAGES[:-1]
    print(f"\n{column}: bin | pairs | detected | accepted | " + " | ".join(stages))
    for t in table:
        print(f"  [{t['lo']:g}, {t['hi']:g}) | {t['n']} | {t['detected']:.3f} | "
              f"{t['accepted']:.3f} | " + " | ".join(str(t[s]) for s in stages))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layout", choices=("level", "default"), default="level")
    ap.add_argument("--seeds", type=int, default=4, help="scans per station (default 4)")
    ap.add_argument("--frame-step", type=int, default=1,
                    help="simulate every k-th of the 800 frames (default 1: all)")
    ap.add_argument("--groups", type=int, default=4,
                    help="interleaved marker sets of the default layout (default 4)")
    ap.add_argument("--scheduler", default="none", help="none, local or tcp://HOST:PORT")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--csv", default=None, help="write every row to this CSV file")
    args = ap.parse_args()
    if args.seeds < 1 or args.frame_step < 1 or args.groups < 1:
        sys.exit("--seeds, --frame-step and --groups must be positive integers")
    from planner.distributed import executor

    if args.layout == "level":
        layout, groups = level_layout(), 1
    else:
        from visibility.sites import load_site

        layout, groups = relief_layout(load_site("default")), args.groups
    frames = range(0, 800, args.frame_step)
    jobs = loss_jobs(layout, range(args.seeds), groups=groups, frames=frames)
    t0 = time.perf_counter()
    with executor(args.scheduler, args.workers, True) as ex:
        scans = run_loss_study(layout, jobs, ex)
    elapsed = time.perf_counter() - t0
    rows = [r for s in scans for r in s.rows]
    print(f"layout {layout.name}: {len(layout.station_ids)} station(s), "
          f"{len(layout.marker_ids)} marker sites, {len(jobs)} scans of {len(frames)} frames, "
          f"{len(rows)} station-marker pairs in {elapsed:.0f} s")
    for column in BINS:
        _print_table(rows, column)
    reasons = collections.Counter(f"{r['stage']}: {r['reason']}" for r in rows
                                  if r["stage"] not in ("accepted", "not_in_view"))
    print("\nlosses by stage and reason:")
    for reason, n in reasons.most_common():
        print(f"  {n:5d}  {reason}")
    print(f"\nfalse accepts: {sum(s.false_accepts for s in scans)} in {len(scans)} scans")
    if args.csv:
        write_fate_table(args.csv, rows)
        print(f"rows -> {args.csv}")


if __name__ == "__main__":
    main()
