"""A survey-sized DEM as a surveyor brings it: a 1 km x 1 km GeoTIFF in UTM (EPSG:32633) at
0.25 m cells with nodata around an irregular measured area and holes in it, and a short
traverse of stations in one part of it. ``markerplan plan`` reads only the window the
stations can see; this prints how much of the raster that is, the read time against reading
the whole raster (the baseline, same run), and the plan's markers, status, time and peak memory.

    .venv/bin/python benchmarks/real_dem.py [--size-m 1000] [--cell-m 0.25] [--keep DIR]

Prints one line per figure and a final JSON object.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: Stations of the traverse: offsets from the raster's centre, m.
TRAVERSE = ((-60.0, -20.0), (-30.0, 0.0), (0.0, 10.0), (30.0, 0.0), (60.0, 20.0))


def write_survey_dem(path: Path, size_m: float, cell_m: float, seed: int = 7) -> tuple:
    """Write the benchmark's GeoTIFF (float32, deflate, 512 x 512 tiles, nodata NaN); return
    ``(centre_xy, n_cells, n_valid)``."""
    import rasterio
    from rasterio.crs import CRS
    from rasterio.transform import from_origin

    from visibility.terrain import fractal_surface

    n = int(round(size_m / cell_m))
    rng = np.random.default_rng(seed)
    heights = fractal_surface((n, n), cell_m, hurst=0.8, roughness_1m_m=0.03, rolloff_m=50.0,
                              rng=rng).astype(np.float32)
    u = (np.arange(n) + 0.5) * cell_m - size_m / 2  # offsets from the centre, m
    gx, gy = np.meshgrid(u, u[::-1])
    angle = np.arctan2(gy, gx)
    radius = 0.42 * size_m * (1 + 0.12 * np.sin(3 * angle) + 0.06 * np.cos(7 * angle))
    valid = np.hypot(gx, gy) <= radius
    for cx, cy, r in ((-150.0, 80.0, 25.0), (120.0, -40.0, 15.0), (10.0, 32.0, 6.0)):
        valid &= np.hypot(gx - cx, gy - cy) > r  # holes: shadows of a photogrammetry survey
    heights[~valid] = np.nan
    x0, y0 = 500_000.0, 4_100_000.0
    profile = dict(driver="GTiff", width=n, height=n, count=1, dtype="float32", nodata=np.nan,
                   crs=CRS.from_epsg(32633), transform=from_origin(x0, y0 + size_m, cell_m,
                                                                   cell_m),
                   tiled=True, blockxsize=512, blockysize=512, compress="deflate")
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(heights, 1)
    return (x0 + size_m / 2, y0 + size_m / 2), n * n, int(valid.sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size-m", type=float, default=1000.0)
    ap.add_argument("--cell-m", type=float, default=0.25)
    ap.add_argument("--keep", type=Path, help="Write the inputs and the plan here.")
    args = ap.parse_args()

    from visibility.dem import read_dem

    root = args.keep or Path(tempfile.mkdtemp(prefix="markerplan-real-dem-"))
    root.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    centre, n_cells, n_valid = write_survey_dem(root / "survey.tif", args.size_m, args.cell_m)
    print(f"raster: {n_cells:,} cells ({args.size_m:g} m, {args.cell_m:g} m cells), "
          f"{100 * n_valid / n_cells:.0f} % measured, written in {time.perf_counter() - t:.1f} s")
    rows = [f"S{k + 1},{centre[0] + dx:.2f},{centre[1] + dy:.2f}"
            for k, (dx, dy) in enumerate(TRAVERSE)]
    (root / "stations.csv").write_text("id,x_m,y_m\n" + "\n".join(rows) + "\n")

    t = time.perf_counter()
    whole = read_dem(root / "survey.tif")
    t_whole = time.perf_counter() - t
    del whole
    out = root / "plan"
    cmd = [str(Path(sys.executable).with_name("markerplan")), "plan",
           "--dem", str(root / "survey.tif"), "--stations", str(root / "stations.csv"),
           "--json", "--out", str(out), "--overwrite"]
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    t_plan = time.perf_counter() - t
    peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    if proc.returncode:
        sys.exit(f"plan failed: {proc.stderr.strip().splitlines()[-1]}")
    summary = json.loads(proc.stdout)
    doc = json.loads((out / "plan.json").read_text())
    window = doc["provenance"]["inputs"]["dem_window"]
    t = time.perf_counter()
    part = read_dem(root / "survey.tif", window=tuple(window))
    t_window = time.perf_counter() - t
    n_read = part.heights_m.size
    print(f"window the stations see: {part.shape[1]} x {part.shape[0]} cells = {n_read:,} "
          f"({100 * n_read / n_cells:.1f} % of the raster, {n_cells / n_read:.0f}x fewer)")
    print(f"read: whole raster {t_whole:.2f} s, window {t_window:.3f} s "
          f"({t_whole / t_window:.0f}x faster)")
    print(f"plan: {doc['n_markers']} markers, status {doc['solver']['status']}, worst station "
          f"{summary['worst_station_error_m']:.3f} m, {t_plan:.1f} s wall, peak RSS "
          f"{peak_mb:.0f} MB; candidates dropped: {doc['candidates']['dropped']}")
    print(json.dumps({
        "raster_cells": n_cells, "window_cells": n_read, "cells_ratio": n_cells / n_read,
        "read_whole_s": t_whole, "read_window_s": t_window, "read_ratio": t_whole / t_window,
        "n_markers": doc["n_markers"], "status": doc["solver"]["status"],
        "worst_station_error_m": summary["worst_station_error_m"], "plan_wall_s": t_plan,
        "plan_peak_rss_mb": peak_mb, "timings_s": summary["timings_s"]}))


if __name__ == "__main__":
    main()
