"""Ray-casting throughput on a >= 1 M-triangle lunar DEM.

Prints rays/s for
  (a) our engine (:class:`visibility.scene.RayScene`, thread pool over chunks, all cores),
  (b) raw embreex ``EmbreeScene.run(query="DISTANCE")`` on the same scene in one thread (the
      same output as (a) for a terrain-only scene: the hit distance),
  (c) trimesh's default ``mesh.ray.intersects_first`` (on a subsample of rays if slow),
and the ratios a/b and a/c from the same run. The rays are a real station's VLP-16 turntable
beams that reach the ground (sky rays removed), from 1 m above the terrain.

Usage: ``python benchmarks/raycast.py [--rays 2000000] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def _rays(dem, n_rays: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    from pipeline.scans.rig import MountingOffsets, frame_poses
    from visibility.sensor import firing_pattern, sensor_directions

    laser, az = firing_pattern(600)
    d_s = sensor_directions(laser, az)
    frames = rng.permutation(800)
    rot, _ = frame_poses(2 * np.pi * frames / 800, MountingOffsets())
    origin = np.array([0.0, 0.0, float(dem.height_at(np.array([[0.0, 0.0]]))[0]) + 1.0])
    dirs = []
    total = 0
    for r in rot:
        d = d_s @ r.T
        d = d[d[:, 2] < -0.02]  # beams that reach the ground within the DEM
        dirs.append(d)
        total += len(d)
        if total >= n_rays:
            break
    d = np.concatenate(dirs)[:n_rays]
    return np.broadcast_to(origin, d.shape).copy(), d


def lunar_dem(rng: np.random.Generator):
    """The benchmark terrain: 72 m x 72 m at 0.1 m (1.04 M triangles), craters 1-8 m."""
    from visibility.terrain import TerrainSpec, generate_terrain

    spec = TerrainSpec(extent_m=(-36.0, 36.0, -36.0, 36.0), cell_size_m=0.1,
                       crater_density=0.004, crater_diameter_range_m=(1.0, 8.0))
    return generate_terrain(spec, rng).dem


def _timed(fn) -> tuple[float, float]:
    """Wall and CPU (all threads) seconds of one call."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=2_000_000)
    ap.add_argument("--trimesh-rays", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    import trimesh

    from visibility.scene import RayScene

    rng = np.random.default_rng(0)
    dem = lunar_dem(rng)
    t0 = time.perf_counter()
    scene = RayScene(dem)
    o, d = _rays(dem, args.rays, rng)
    scene.intersect(o[:10], d[:10])  # Embree builds its BVH lazily on the first query
    build = time.perf_counter() - t0
    cores = os.cpu_count()
    print(f"DEM {dem.shape[1]} x {dem.shape[0]} cells, {scene.n_triangles:,} triangles; "
          f"scene build {build:.2f} s; {len(o):,} rays; {cores} cores")

    local_o = (o - scene.origin_m).astype(np.float32)
    d32 = d.astype(np.float32)
    mesh = trimesh.Trimesh(scene.mesh.vertices_local.astype(np.float64), scene.mesh.faces,
                           process=False)
    engine = type(mesh.ray).__module__ + "." + type(mesh.ray).__name__
    n_c = min(args.trimesh_rays, len(o))
    mesh.ray.intersects_first(local_o[:10].astype(float), d[:10])  # build its acceleration
    runs = {
        # (a) our engine, all cores
        "a": lambda: scene.intersect(o, d, threads=cores),
        # (b) raw embreex, one thread, same scene and output
        "b": lambda: scene._scene.run(local_o, d32, query="DISTANCE"),
        # (c) trimesh's default intersects_first
        "c": lambda: mesh.ray.intersects_first(local_o[:n_c].astype(float), d[:n_c]),
    }
    # interleave the engines so that load from other processes hits all of them alike
    best = {k: np.inf for k in runs}
    cpu = {k: np.inf for k in runs}
    for _ in range(args.repeat):
        for k, fn in runs.items():
            wall, c = _timed(fn)
            best[k], cpu[k] = min(best[k], wall), min(cpu[k], c)
    t_a, t_b, t_c = best["a"], best["b"], best["c"]

    # the engines agree
    ours = scene.intersect(o[:n_c], d[:n_c])
    raw = scene._scene.run(local_o[:n_c], d32[:n_c], query="DISTANCE")
    raw = np.where(raw < 1e30, raw, np.inf)
    same = np.isinf(ours.distance_m) & np.isinf(raw)
    with np.errstate(invalid="ignore"):
        agree = np.mean(same | (np.abs(ours.distance_m - raw) < 1e-4))
    ra, rb, rc = len(o) / t_a, len(o) / t_b, n_c / t_c
    print(f"(a) markerplan RayScene, {cores} threads : {ra / 1e6:8.3f} M rays/s  "
          f"(CPU {cpu['a']:.3f} s for {len(o):,} rays)")
    print(f"(b) raw embreex, 1 thread           : {rb / 1e6:8.3f} M rays/s  "
          f"(CPU {cpu['b']:.3f} s)")
    print(f"(c) trimesh intersects_first        : {rc / 1e6:8.3f} M rays/s  "
          f"({engine}, {n_c:,} rays)")
    print(f"a/b = {ra / rb:.2f}   a/c = {ra / rc:.1f}   (a and b agree on {agree:.1%} of rays; "
          f"best of {args.repeat} interleaved runs; load average {os.getloadavg()[0]:.2f})")
    print(f"CPU-time bound on idle cores: a/b <= {cores} x {cpu['b']:.3f} / {cpu['a']:.3f} = "
          f"{cores * cpu['b'] / cpu['a']:.2f}")


if __name__ == "__main__":
    main()
