"""Coverage achieved by the default site's 7 published stations over a 40 m x 40 m AOI.

Each station is simulated (full turn by default), processed and its ground points rasterised
over the AOI's 1 m cells (:func:`planner.coverage.achieved.achieved_coverage`) once; the
per-cell densities are then judged at every ``--density`` (points per m², full turn). Prints per
station its time (simulate, process, rasterise) and points, then per density the covered
fraction and the cells covered by two or more stations. ``--max-range-m`` and
``--max-incidence-deg`` add the prediction's range and incidence limits (judged from the
points). With ``--predicted FILE.npz`` (``cell_xy`` (c, 2): the predicted grid's cell centres,
which then replace the AOI's own 1 m cells; ``count_<density>`` (c,) per ``--density``, e.g.
``count_100``, or one ``count``: the predicted number of stations covering each cell) also
the agreement for one and two stations (:func:`planner.coverage.achieved.compare_coverage`).
``--save FILE.npz`` keeps the achieved counts per density and the best density.

Usage: ``python benchmarks/coverage_check.py [--frames 800] [--density 100 1000]
[--max-range-m 30 --max-incidence-deg 85] [--predicted pred.npz] [--save achieved.npz]``
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time

import numpy as np

#: Half-width of the AOI square, m, and its cell, m.
AOI_HALF_M, CELL_M = 20.0, 1.0


def aoi_cells() -> np.ndarray:
    """(1600, 2) cell centres of the AOI, x-major, site frame, m."""
    g = np.arange(-AOI_HALF_M + CELL_M / 2, AOI_HALF_M, CELL_M)
    x, y = np.meshgrid(g, g, indexing="ij")
    return np.column_stack([x.ravel(), y.ravel()])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=800)
    ap.add_argument("--density", type=float, nargs="+", default=[100.0, 1000.0],
                    help="minimum ground points per m², full turn")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-range-m", type=float)
    ap.add_argument("--max-incidence-deg", type=float)
    ap.add_argument("--predicted", help=".npz with cell_xy and count_<density> (or count)")
    ap.add_argument("--save", help="write the achieved counts per density to this .npz")
    args = ap.parse_args()

    from planner.coverage.achieved import achieved_coverage, compare_coverage
    from visibility.sites import load_site

    site = load_site("default")
    predicted = None if args.predicted is None else dict(np.load(args.predicted))
    cells = aoi_cells() if predicted is None else predicted["cell_xy"]
    incidence = None if args.max_incidence_deg is None else np.radians(args.max_incidence_deg)
    densities = sorted(args.density)
    t0 = time.perf_counter()
    cov = achieved_coverage(
        site.dem, site.station_position_m, site.station_heading_rad, cells, CELL_M,
        densities[0], args.seed, marker_xyz_m=site.marker_centres_m,
        marker_radius_m=site.marker_radius_m, frames_per_turn=args.frames,
        max_range_m=args.max_range_m, max_incidence_rad=incidence, station_ids=site.station_ids)
    wall = time.perf_counter() - t0
    print(f"default site, {len(site.station_ids)} stations, {args.frames} frames, AOI "
          f"{2 * AOI_HALF_M:g} m square at {CELL_M:g} m ({len(cells)} cells), range limit "
          f"{args.max_range_m}, incidence limit {args.max_incidence_deg}; {os.cpu_count()} "
          f"cores, load {os.getloadavg()[0]:.1f}; {wall:.1f} s in all, peak RSS "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6:.2f} GB")
    for sid, t, n, g, c in zip(cov.station_ids, cov.timings_s, cov.n_points, cov.n_ground,
                               cov.n_in_cells, strict=True):
        print(f"  {sid}: simulate {t['simulate']:.1f} s, process {t['process']:.1f} s, "
              f"rasterise {t['rasterise']:.1f} s; {n:,} points, {g:,} ground, {c:,} in the AOI")
    mean = cov.summary()["mean_time_per_station_s"]
    print(f"  mean per station: {sum(mean.values()):.1f} s ("
          + ", ".join(f"{k} {v:.1f}" for k, v in mean.items()) + ")")
    saved = {}
    for density in densities:
        count = cov.stations_covering_at(density)
        print(f"min density {density:g} /m²: covered {np.mean(count >= 1):.3f} "
              f"({np.sum(count >= 1)} cells), by >= 2 stations {np.mean(count >= 2):.3f} "
              f"({np.sum(count >= 2)} cells)")
        saved[f"stations_covering_{density:g}"] = count
        if predicted is not None:
            expected = predicted.get(f"count_{density:g}", predicted.get("count"))
            for k in (1, 2):
                agree = compare_coverage(expected, count, k, cells, site.station_xy_m)
                print(f"  against --predicted, >= {k} station(s): "
                      + json.dumps(agree.to_dict()))
    saved["best_density_per_m2"] = cov.best_density_per_m2
    if args.save:
        np.savez(args.save, cell_xy=cells, **saved)


if __name__ == "__main__":
    main()
