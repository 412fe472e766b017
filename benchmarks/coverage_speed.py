"""Predicted AOI coverage speed (:func:`planner.coverage.sight.coverage_matrix`).

A square AOI of ``--aoi-m`` metres at the centre of a site preset, at ``--cell-m`` cells,
covered from candidate stations on a regular grid every ``--spacing-m`` metres inside it (LiDAR
1 m above the ground; 20 x 20 = 400 stations for the defaults on ``default``). Prints the AOI
grid, the pairs and rays, the ray-casting time and rate, the whole call's wall time and its
peak resident memory growth, the share of AOI cells covered once and twice, and the uncovered
summary; then the covered radius on flat ground with the default settings (largest covered
and smallest uncovered cell-centre distance from one station, against ``h tan(85 deg)``).

Example::

    python benchmarks/coverage_speed.py                      # default site, 40 m AOI, 400 stations
    python benchmarks/coverage_speed.py --site large --aoi-m 100   # 2500 stations
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np
import shapely

from planner.coverage.grid import aoi_grid
from planner.coverage.raster import uncovered_summary
from planner.coverage.sight import CoverageSettings, coverage_matrix
from visibility.dem import DEM
from visibility.sites import load_site


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="default")
    ap.add_argument("--aoi-m", type=float, default=40.0)
    ap.add_argument("--cell-m", type=float, default=1.0)
    ap.add_argument("--spacing-m", type=float, default=2.0)
    args = ap.parse_args()
    dem = load_site(args.site).dem
    x0, x1, y0, y1 = dem.extent()
    cx, cy, half = 0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * args.aoi_m
    settings = CoverageSettings(cell_m=args.cell_m)
    grid = aoi_grid(dem, shapely.box(cx - half, cy - half, cx + half, cy + half), args.cell_m)
    g = np.arange(-half + 0.5 * args.spacing_m, half, args.spacing_m)
    xx, yy = np.meshgrid(cx + g, cy + g)
    xy = np.column_stack([xx.ravel(), yy.ravel()])
    st = np.column_stack([xy, dem.height_at(xy) + 1.0])
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t = time.perf_counter()
    m = coverage_matrix(dem, st, grid, settings)
    wall = time.perf_counter() - t
    rss = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0) / 1024
    count = m.count()
    print(f"{args.site}: DEM {dem.shape} at {dem.cell_size_m:g} m; AOI {args.aoi_m:g} m at "
          f"{grid.cell_m:g} m = {len(grid)} cells; {len(st)} stations")
    print(f"{len(m)} pairs, {m.n_rays} rays in {m.elapsed_s:.3f} s ({m.rays_per_s:.3g} rays/s); "
          f"coverage_matrix {wall:.2f} s wall, peak RSS +{rss:.0f} MB; "
          f"load average {os.getloadavg()[0]:.1f}")
    print(f"cells covered >= 1: {np.mean(count >= 1):.1%}, >= 2: {np.mean(count >= 2):.1%}, "
          f"median {np.median(count):g} stations")
    print("uncovered:", uncovered_summary(m, grid, st, settings).text or "none")
    flat = DEM(np.zeros((121, 121)), (-30.0, -30.0), 0.5)
    fg = aoi_grid(flat, shapely.box(-29, -29, 29, 29), settings.cell_m)
    fm = coverage_matrix(flat, np.array([[0.0, 0.0, 1.0]]), fg, settings)
    r = np.hypot(*fg.centre_xy_m.T)
    miss = np.setdiff1d(np.arange(len(fg)), fm.cell)
    print(f"flat ground, LiDAR 1 m: covered out to {r[fm.cell].max():.2f} m, first uncovered "
          f"{r[miss].min():.2f} m (h tan({settings.max_incidence_deg:g} deg) = "
          f"{np.tan(np.radians(settings.max_incidence_deg)):.2f} m)")


if __name__ == "__main__":
    main()
