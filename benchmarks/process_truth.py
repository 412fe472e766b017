"""Station processing against simulator truth on several stations: a baseline against this tree.

For changes to :func:`pipeline.chain.process.process_station` that move results (not exact rewrites;
``benchmarks/process_speed.py`` checks those to round-off on one station). Stations 0..K-1 of
the default site are simulated once each (800 frames, mounting offsets 0.3 deg, 0.3 deg, 15 mm,
seed 0, as in ``process_speed.py``) and cached in ``--cache`` (``station<k>.scan.npz`` and
``station<k>.truth.json``; reused when they exist). Each scan is then processed in a fresh
subprocess with the baseline's code first on ``PYTHONPATH`` and in one with this tree's, one
BLAS thread (:func:`process_speed.run_worker`). The cache does not record ``--frames``: use a
new ``--cache`` folder when changing it.

Printed, per station and side: the truth markers in view (at least one simulated point on them)
matched by an accepted row, the accepted rows, the mean and largest centre error of the accepted
matched markers against truth (mm; ``error_m`` of the marker table), the errors of the estimated
mounting offsets against the true ones (vertical-axis error and L-frame tilt in degrees, axis
offset as the length of the (dx, dy) difference in mm) and the CPU time of the worker. Then,
over all stations and per side: matched markers, mean / largest / 95th percentile of the
accepted errors; the largest change of a marker's error between base and new (markers accepted
and matched on both sides, paired by station and ``marker_id``) and how many differ at all
(none when base and new are the same code); the markers one side finds
and the other does not; and the CPU ratio base / new (median of the per-station ratios, and the
ratio of the sums). A study that prints: it asserts nothing about the figures.

Make the baseline with ``git worktree add /tmp/base-<rev> <rev>`` (or ``git archive``), a revision
with pipeline's subpackages (``pipeline/chain/process.py``): the worker imports the baseline's
modules by this tree's paths.

Usage: ``python -u benchmarks/process_truth.py --base /tmp/base-<rev> [--stations 0,1]
[--cache /tmp/mp-truth]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import process_speed

#: Stations studied by default (fewer when the default site has fewer).
DEFAULT_STATIONS = 6

EXAMPLE = """example:
  OPENBLAS_NUM_THREADS=1 python -u benchmarks/process_truth.py --base /tmp/base-<rev> \\
      --stations 0,1 --cache /tmp/mp-truth
"""


def _station_list(text: str | None, n_site: int) -> list[int]:
    """Station indices from ``--stations`` ("0,2,3"), default the first min(6, n_site)."""
    if text is None:
        return list(range(min(DEFAULT_STATIONS, n_site)))
    try:
        stations = sorted({int(t) for t in text.split(",")})
    except ValueError:
        sys.exit(f"--stations takes comma-separated station indices such as 0,1,2; got {text!r}")
    if not stations or not all(0 <= k < n_site for k in stations):
        sys.exit(f"--stations must be indices in [0, {n_site}) (the default site's stations); "
                 f"got {text!r}")
    return stations


def summarise(result: dict, truth: dict) -> dict:
    """One worker's figures against its station's truth.

    Parameters
    ----------
    result : dict
        A ``process_speed`` worker's output (``columns``, ``rows``, ``offsets``, ``cpu_s``).
    truth : dict
        The station's simulation truth (:func:`pipeline.scans.scan_format.read_truth`).

    Returns
    -------
    dict
        ``in_view`` (set of truth marker ids with simulated points), ``errors_m`` (dict
        marker id -> centre error, metres, of the accepted matched rows), ``n_accepted``,
        ``offset_errors`` (vertical-axis error deg, L-frame tilt deg, axis offset mm),
        ``cpu_s``.
    """
    rows = [dict(zip(result["columns"], r, strict=True)) for r in result["rows"]]
    errors = {r["marker_id"]: r["error_m"] for r in rows if r["accepted"] and r["marker_id"]}
    est, true = result["offsets"], truth["mounting_offsets"]
    offset_errors = (
        float(np.degrees(est["vertical_axis_error_rad"] - true["vertical_axis_error_rad"])),
        float(np.degrees(est["lframe_tilt_rad"] - true["lframe_tilt_rad"])),
        1e3 * float(np.hypot(*np.subtract(est["axis_offset_m"], true["axis_offset_m"]))))
    return {"in_view": {m["id"] for m in truth["markers"] if m["n_points"] > 0},
            "errors_m": errors, "n_accepted": sum(bool(r["accepted"]) for r in rows),
            "offset_errors": offset_errors, "cpu_s": result["cpu_s"]}


def _station_line(name: str, s: dict) -> str:
    err = 1e3 * np.array(list(s["errors_m"].values()))
    mean, top = (f"{err.mean():7.3f}", f"{err.max():7.3f}") if err.size else ("      -",) * 2
    dv, dt, dd = s["offset_errors"]
    return (f"  {name:4s} matched {len(s['in_view'] & s['errors_m'].keys()):2d}/"
            f"{len(s['in_view']):2d} in view, {s['n_accepted']:2d} accepted; error mean {mean}"
            f" max {top} mm; offsets: vertical axis {dv:+.5f} deg, L-frame tilt {dt:+.5f} deg,"
            f" axis offset {dd:6.3f} mm; CPU {s['cpu_s']:6.2f} s")


def report(summaries: dict[str, dict[str, dict]]) -> None:
    """Print the figures over all stations.

    Parameters
    ----------
    summaries : dict
        ``{station_id: {"base": summary, "new": summary}}`` of :func:`summarise`.
    """
    print(f"over {len(summaries)} station(s):")
    for name in ("base", "new"):
        err = 1e3 * np.array([e for s in summaries.values()
                              for e in s[name]["errors_m"].values()])
        matched = sum(len(s[name]["in_view"] & s[name]["errors_m"].keys())
                      for s in summaries.values())
        in_view = sum(len(s[name]["in_view"]) for s in summaries.values())
        stats = (f"mean {err.mean():.3f}, max {err.max():.3f}, 95th percentile "
                 f"{np.percentile(err, 95):.3f} mm" if err.size else "no accepted markers")
        print(f"  {name:4s} matched {matched}/{in_view} in view; accepted errors: {stats}")
    change, worst, n_paired, n_differ = 0.0, "", 0, 0
    only: dict[str, list[str]] = {"base": [], "new": []}
    for sid, s in summaries.items():
        b, n = s["base"]["errors_m"], s["new"]["errors_m"]
        for marker in sorted(b.keys() & n.keys()):
            n_paired += 1
            n_differ += n[marker] != b[marker]
            if abs(n[marker] - b[marker]) > abs(change):
                change, worst = n[marker] - b[marker], f" ({sid}/{marker})"
        only["base"] += [f"{sid}/{m}" for m in sorted(b.keys() - n.keys())]
        only["new"] += [f"{sid}/{m}" for m in sorted(n.keys() - b.keys())]
    print(f"  largest change of a marker's error, new - base: {1e3 * change:+.6f} mm{worst}; "
          f"{n_differ} of {n_paired} markers found by both sides differ at all")
    for name, markers in only.items():
        print(f"  accepted and matched by {name} only: {', '.join(markers) or 'none'}")
    cpu = np.array([[s[name]["cpu_s"] for name in ("base", "new")] for s in summaries.values()])
    print(f"  CPU base / new: median of per-station ratios {np.median(cpu[:, 0] / cpu[:, 1]):.2f},"
          f" ratio of sums {cpu[:, 0].sum() / cpu[:, 1].sum():.2f} "
          f"({cpu[:, 0].sum():.1f} s / {cpu[:, 1].sum():.1f} s)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=EXAMPLE,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", type=Path, required=True,
                    help="checkout of the baseline revision (its pipeline/ is imported)")
    ap.add_argument("--stations", help="comma-separated indices of the default site's stations "
                    f"(default: the first {DEFAULT_STATIONS}, or all when fewer)")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/mp-truth"),
                    help="folder of the simulated scans and truths, reused (default %(default)s)")
    ap.add_argument("--frames", type=int, default=800, help="frames per turn (default 800)")
    args = ap.parse_args()
    if not (args.base / "pipeline" / "chain" / "process.py").is_file():
        sys.exit(f"--base {args.base} has no pipeline/chain/process.py; give a checkout of the "
                 "baseline with pipeline's subpackages (git worktree add /tmp/base-<rev> <rev>)")
    from pipeline.scans.scan_format import read_truth
    from visibility.sites import load_site

    site = load_site("default")
    stations = _station_list(args.stations, len(site.station_ids))
    sides = {"base": args.base, "new": process_speed.HERE}
    summaries: dict[str, dict[str, dict]] = {}
    for k in stations:
        scan = args.cache / f"station{k}.scan.npz"
        if not (scan.is_file() and process_speed.truth_path(scan).is_file()):
            print(f"simulating station {k} into {scan} ...", flush=True)
            process_speed.simulate(scan, args.frames, k)
        truth = read_truth(process_speed.truth_path(scan))
        sid = truth["station_id"]
        print(f"station {k} ({sid}):", flush=True)
        summaries[sid] = {}
        for name, tree in sides.items():
            result = process_speed.run_worker(process_speed.__file__, tree, [str(scan)])
            summaries[sid][name] = summarise(result, truth)
            print(_station_line(name, summaries[sid][name]), flush=True)
    report(summaries)


if __name__ == "__main__":
    main()
