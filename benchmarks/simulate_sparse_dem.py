"""``markerplan simulate`` and ``markerplan plan`` on a sparse DEM too large to read whole.

Writes a ``--size`` x ``--size`` float32 GeoTIFF of 1 m cells (tiled, deflate, sparse: only a
``--data`` x ``--data`` block of heights around the site-frame origin is written, the rest is
nodata and takes no disk), and two stations near the origin. Then, in one run, each command
runs ``--repeat`` times as its own process (``markerplan`` of this environment) on that DEM:

(a) ``plan --dem big.tif --stations stations.csv`` (reads the DEM by window, as far as the
    stations see: ``max_range_m``);
(b) ``simulate --dem big.tif --stations stations.csv --frames F`` (reads the DEM by window
    around its stations and the preset's markers, grown by the sensor's maximum range).

It prints each run's exit code, wall time and peak resident memory (``ru_maxrss`` of that
process, from ``os.wait4``), the fastest of each, and the ratios b/a. Reading the DEM whole
would take ``size**2 * 8`` bytes (80 GB at 100,000); both commands refuse that
(``visibility.dem.MAX_DEM_CELLS``).

Usage: ``python benchmarks/simulate_sparse_dem.py [--size 100000] [--data 512] [--frames 8]
[--repeat 2]``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def write_sparse_dem(path: Path, size: int, data: int) -> None:
    """A ``size`` x ``size`` GeoTIFF (EPSG:32633, 1 m cells, centred on the origin) holding
    zeros in a ``data`` x ``data`` block at its centre and nodata elsewhere."""
    import rasterio
    from rasterio.transform import from_origin
    from rasterio.windows import Window

    with rasterio.open(path, "w", driver="GTiff", height=size, width=size, count=1,
                       dtype="float32", crs="EPSG:32633",
                       transform=from_origin(-size / 2, size / 2, 1.0, 1.0), tiled=True,
                       blockxsize=256, blockysize=256, compress="deflate", sparse_ok=True,
                       nodata=-9999) as dst:
        start = (size - data) // 2
        dst.write(np.zeros((data, data), "float32"), 1, window=Window(start, start, data, data))


def run(args: list[str]) -> tuple[int, float, float]:
    """Run ``markerplan args`` as a child process: exit code, wall seconds, peak RSS (MB)."""
    exe = Path(sys.executable).with_name("markerplan")
    t0 = time.perf_counter()
    child = subprocess.Popen([str(exe), *args], stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE)
    _, status, usage = os.wait4(child.pid, 0)
    wall = time.perf_counter() - t0
    err = child.stderr.read().decode(errors="replace")
    child.stderr.close()
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        print(f"  markerplan {' '.join(args[:1])} failed: {err.strip().splitlines()[-1:]}")
    return code, wall, usage.ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=100_000)
    ap.add_argument("--data", type=int, default=512)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()

    folder = Path(tempfile.mkdtemp(prefix="simulate_sparse_dem_"))
    try:
        dem = folder / "big.tif"
        t0 = time.perf_counter()
        write_sparse_dem(dem, args.size, args.data)
        print(f"DEM {args.size:,} x {args.size:,} cells ({args.size ** 2 * 8 / 1e9:,.0f} GB as "
              f"float64), {dem.stat().st_size / 1e6:.1f} MB on disk, written in "
              f"{time.perf_counter() - t0:.2f} s")
        stations = folder / "stations.csv"
        stations.write_text("id,x_m,y_m\nS1,0,0\nS2,10,5\n")
        commands = {
            "a plan": ["plan", "--dem", str(dem), "--stations", str(stations)],
            "b simulate": ["simulate", "--dem", str(dem), "--stations", str(stations),
                           "--frames", str(args.frames)],
        }
        best: dict[str, tuple[float, float]] = {}
        for r in range(args.repeat):
            for name, command in commands.items():
                out = folder / f"out_{r}_{name.split()[1]}"
                code, wall, rss = run([*command, "--out", str(out)])
                print(f"round {r + 1} {name:>10}: exit {code}, {wall:6.2f} s wall, "
                      f"peak RSS {rss:7.1f} MB")
                if code == 0:
                    w, m = best.get(name, (float("inf"), 0.0))
                    best[name] = (min(w, wall), max(m, rss))
                shutil.rmtree(out, ignore_errors=True)
        for name, (wall, rss) in best.items():
            print(f"{name:>10}: fastest {wall:.2f} s wall, peak RSS {rss:.1f} MB")
        if len(best) == 2:
            (wa, ma), (wb, mb) = best["a plan"], best["b simulate"]
            print(f"simulate / plan: wall {wb / wa:.2f}, peak RSS {mb / ma:.2f}")
    finally:
        shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
