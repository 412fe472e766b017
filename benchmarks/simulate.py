"""Time and ray count of one full default-site station (800 frames, 600 rpm).

Prints the time to build the site, the Embree scene (including the lazy BVH build), the
simulation itself (all cores), and writing the scan file, with the number of rays in the
pattern, rays actually cast after horizon culling, and points returned.

Usage: ``python benchmarks/simulate.py [--station 0] [--repeat 2] [--write]``
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--station", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--write", action="store_true", help="also time write_scan")
    args = ap.parse_args()

    from pipeline.scans.scan_format import write_scan
    from visibility.simulate import simulate_station, site_scene
    from visibility.sites import load_site

    t0 = time.perf_counter()
    site = load_site("default")
    t_site = time.perf_counter() - t0
    t0 = time.perf_counter()
    scene = site_scene(site)
    scene.intersect(site.station_position_m[:1], np.array([[0.0, 0.0, -1.0]]))
    t_scene = time.perf_counter() - t0
    print(f"default site: {t_site:.2f} s; scene {scene.n_triangles:,} triangles + "
          f"{len(site.marker_ids)} spheres built in {t_scene:.2f} s; {os.cpu_count()} cores")
    times, cpu = [], []
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        scan, truth = simulate_station(site, args.station, seed=0, scene=scene)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    meta = scan.metadata
    print(f"station {scan.station_id}: {scan.n_frames} frames, {meta['n_rays']:,} rays in the "
          f"pattern, {meta['n_rays_cast']:,} cast after culling, {scan.n_points:,} points")
    print(f"simulation time: best {min(times):.2f} s of {args.repeat} "
          f"({', '.join(f'{t:.2f}' for t in times)}); "
          f"{meta['n_rays'] / min(times) / 1e6:.2f} M pattern rays/s; CPU time "
          f"{min(cpu):.2f} s (all threads); load average {os.getloadavg()[0]:.2f}")
    print("points per marker: " + ", ".join(f"{m['id']} {m['n_points']}"
                                            for m in truth["markers"]))
    if args.write:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            path = write_scan(Path(tmp) / "s.scan.npz", scan)
            print(f"write_scan: {time.perf_counter() - t0:.2f} s, "
                  f"{path.stat().st_size / 1e6:.0f} MB")


if __name__ == "__main__":
    main()
