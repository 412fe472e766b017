"""One station's rays, sky included: cast them all, or skip the provable misses first.

The rays are every beam of a full VLP-16 turntable scan (600 rpm, 1,808 firing cycles of 16
lasers a frame, 800 frames: 23.1 M rays, about half of them into the sky) from 1 m above the
centre of the 1.04 M-triangle DEM of ``benchmarks/raycast.py``. Prints the best wall and CPU
time (of ``--repeat`` interleaved runs) to get every ray's first-hit distance (``inf`` for a
miss) by

  (a) :meth:`visibility.scene.RayScene.intersect_unit` on all rays at once (pre-built float64
      directions; chunks over all cores);
  (a2) frame by frame as the simulator would without culling: build each frame's directions,
      cast them all (frames over all cores, like :func:`visibility.simulate.simulate_scan`);
  (b) frame by frame as the simulator did until 2026-12-02: the per-ray horizon test (every
      ray's z, then the azimuth bin of the rays between the lowest and highest bound), then
      cast the rest;
  (c) frame by frame as the simulator does now: :meth:`visibility.horizon.PatternBound.may_hit`
      (the same decisions, from the pattern's columns), then cast the rest ((a2), (b) and (c)
      build the cast rays' directions alike, as the simulator does now, so b/c is the
      decisions' cost alone);
  (o) the ceiling of any culling: frame by frame, cast only the rays known (from (a)) to hit;
  (d) Open3D's ``RaycastingScene.cast_rays`` on all rays at once (a pre-built float32 (n, 6)
      tensor; its own threads on all cores), when ``open3d`` is installed
      (``.venv/bin/pip install open3d``; its Linux wheel also needs the system's
      ``libusb-1.0-0``); it is no dependency of markerplan,

and the ratios from the same run. (a), (a2), (o), (b) and (c) must give identical distances;
(d) the same hits.

Usage: ``python -u benchmarks/station_rays.py [--frames 800] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from raycast import lunar_dem  # noqa: E402

_FRAMES_PER_TASK = 8
_MAX_RANGE_M = 100.0


def _per_frame(cast_frame, n_frames: int, n: int, threads: int) -> np.ndarray:
    """(F, n) distances: ``cast_frame(f)`` for every frame ``f``, frames over ``threads``."""
    out = np.empty((n_frames, n))

    def work(a: int) -> None:
        for f in range(a, min(a + _FRAMES_PER_TASK, n_frames)):
            out[f] = cast_frame(f)

    with ThreadPoolExecutor(threads) as pool:
        list(pool.map(work, range(0, n_frames, _FRAMES_PER_TASK)))
    return out


def _cast_subset(scene, origin: np.ndarray, pattern: np.ndarray, rotation: np.ndarray,
                 may_hit: np.ndarray) -> np.ndarray:
    """(n,) distances of one frame casting only the rays ``may_hit`` (the rest miss)."""
    rows = np.flatnonzero(may_hit)
    d = np.take(pattern, rows, axis=0) @ rotation.T
    dist = np.full(len(pattern), np.inf)
    dist[rows] = scene.intersect_unit(np.broadcast_to(origin, d.shape), d, _MAX_RANGE_M,
                                      threads=1).distance_m
    return dist


def _open3d_scene(mesh):
    """Open3D's raycasting scene of the same triangles, or None (with how to get it)."""
    try:
        import open3d as o3d
    except ImportError as exc:
        print(f"(d) skipped: open3d not importable ({exc}); install it with "
              "'.venv/bin/pip install open3d' (Linux also needs the libusb-1.0-0 package)")
        return None
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices_local.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    return scene


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=800, help="frames of the turntable turn")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from pipeline.scans.rig import MountingOffsets, frame_poses
    from visibility.horizon import HorizonBound, PatternBound
    from visibility.scene import RayScene
    from visibility.sensor import firing_pattern, sensor_directions

    dem = lunar_dem(np.random.default_rng(0))
    scene = RayScene(dem)
    laser, azimuth = firing_pattern(600)
    pattern = sensor_directions(laser, azimuth)
    rotations, _ = frame_poses(2 * np.pi * np.arange(args.frames) / args.frames,
                               MountingOffsets())
    origin = np.array([0.0, 0.0, float(dem.height_at(np.zeros((1, 2)))[0]) + 1.0])
    bound = HorizonBound(dem, origin, reach_m=_MAX_RANGE_M)
    beams = PatternBound(bound, pattern)
    n, n_rays = len(pattern), args.frames * len(pattern)
    everything = np.ones(n, dtype=bool)
    directions = np.concatenate([pattern @ r.T for r in rotations])  # as (b) and (c) build them
    origins = np.broadcast_to(origin, directions.shape)
    scene.intersect(origin[None], np.array([[0.0, 0.0, -1.0]]))  # Embree builds its BVH lazily
    o3d_scene = _open3d_scene(scene.mesh)
    cores = os.cpu_count() or 1
    hit = np.isfinite(scene.intersect_unit(origins, directions, _MAX_RANGE_M).distance_m)
    hit = hit.reshape(-1, n)
    rot = rotations

    def old_rule(r: np.ndarray) -> np.ndarray:  # the simulator's line until 2026-12-02
        return bound.may_hit_z(pattern @ r[2], lambda rows: pattern[rows] @ r.T)

    runs = {
        "a": lambda: scene.intersect_unit(origins, directions, _MAX_RANGE_M,
                                          threads=cores).distance_m.reshape(-1, n),
        "a2": lambda: _per_frame(lambda f: _cast_subset(scene, origin, pattern, rot[f], everything),
                                 args.frames, n, cores),
        "o": lambda: _per_frame(lambda f: _cast_subset(scene, origin, pattern, rot[f], hit[f]),
                                args.frames, n, cores),
        "b": lambda: _per_frame(lambda f: _cast_subset(scene, origin, pattern, rot[f],
                                                       old_rule(rot[f])),
                                args.frames, n, cores),
        "c": lambda: _per_frame(lambda f: _cast_subset(scene, origin, pattern, rot[f],
                                                       beams.may_hit(rot[f])),
                                args.frames, n, cores),
    }
    if o3d_scene is not None:
        import open3d as o3d

        rays = np.empty((n_rays, 6), np.float32)
        rays[:, :3] = origin - scene.origin_m
        rays[:, 3:] = directions
        rays = o3d.core.Tensor(rays)
        o3d_scene.cast_rays(rays[:10])
        runs["d"] = lambda: o3d_scene.cast_rays(rays, nthreads=0)["t_hit"].numpy()
    n_cast = sum(int(beams.may_hit(r).sum()) for r in rotations)
    print(f"DEM {dem.shape[1]} x {dem.shape[0]} cells, {scene.n_triangles:,} triangles; "
          f"{args.frames} frames x {n:,} rays = {n_rays:,} rays; {n_cast:,} cast after "
          f"culling; {cores} cores", flush=True)
    best = {k: np.inf for k in runs}
    cpu = {k: np.inf for k in runs}
    result = {}
    for rep in range(args.repeat):
        for k, fn in runs.items():
            t0, c0 = time.perf_counter(), time.process_time()
            result[k] = fn()
            best[k] = min(best[k], time.perf_counter() - t0)
            cpu[k] = min(cpu[k], time.process_time() - c0)
        print(f"run {rep + 1}: " + "  ".join(f"{k} {best[k]:.2f} s" for k in runs), flush=True)
    same = all(np.array_equal(result["a"], result[k]) for k in ("a2", "o", "b", "c"))
    print(f"{int(hit.sum()):,} rays hit; a, a2, o, b and c give identical distances: {same}")
    if "d" in result:
        t = result["d"].reshape(-1, n)
        agree = np.mean(np.isfinite(t) == hit)
        err = np.abs(t[hit] - result["a"][hit]).max()
        print(f"Open3D agrees on hit or miss for {agree:.4%} of rays, distances within "
              f"{err:.1e} m")
    names = {"a": "cast every ray (RayScene, all at once)",
             "a2": "cast every ray, frame by frame",
             "o": "cast only the rays that hit (ceiling)",
             "b": "per-ray bound, then cast (until 2026-12-02)",
             "c": "pattern bound, then cast (now)",
             "d": "Open3D RaycastingScene.cast_rays"}
    for k in runs:
        print(f"({k:2s}) {names[k]:44s}: {best[k]:6.2f} s  {n_rays / best[k] / 1e6:6.2f} M rays/s  "
              f"(CPU {cpu[k]:.2f} s, all threads)")
    ratios = [f"c vs {k}: {best[k] / best['c']:.2f}x" for k in ("a", "a2", "b")]
    ratios.append(f"o vs a: {best['a'] / best['o']:.2f}x")
    if "d" in best:
        ratios += [f"a vs d: {best['d'] / best['a']:.2f}x", f"c vs d: {best['d'] / best['c']:.2f}x"]
    print("speed-ups (time of the other / time of the first): " + ", ".join(ratios)
          + f"  (best of {args.repeat}; load average {os.getloadavg()[0]:.2f})")


if __name__ == "__main__":
    main()
