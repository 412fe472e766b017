"""Simulated turntable scans: cast every VLP-16 beam of every frame into a :class:`RayScene`.

For frame ``f`` at turntable angle ``theta_f`` the sensor pose in the station frame comes from
:func:`pipeline.rig.frame_poses` (the geometry contract, true mounting offsets applied), and
the station frame sits at ``position`` in the site frame, rotated by ``heading`` (level: zero
roll and pitch). A beam of channel ``i`` at spin azimuth ``alpha`` leaves the LiDAR centre along
``Rz(heading) R_f d_S(i, alpha)``. Its first hit (terrain or marker sphere) gives the true range;
the measured range adds Gaussian noise, optional incidence-angle noise, and is rounded to the
2 mm resolution; returns outside [min, max] range or lost to dropout are discarded. The point
stored in the sensor frame is ``range * d_S`` along the *nominal* beam.

Rays that provably cannot hit anything (steeper than the conservative
:class:`visibility.scene.HorizonBound` in their azimuth bin) are skipped without changing the
result. Randomness: frame ``f`` uses ``numpy.random.default_rng([seed, f])``, so output is
independent of threading and the same seed gives byte-identical files.
"""

from __future__ import annotations

import json
import os
import zlib
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from pathlib import Path

import numpy as np

from markerplan.errors import ConfigError, DataError
from markerplan.provenance import provenance
from pipeline.rig import frame_poses, rot_z, station_to_site_matrix
from pipeline.scan_format import POINT_FIELDS, StationScan, write_scan, write_truth
from visibility.dem import DEM
from visibility.scene import HorizonBound, RayScene
from visibility.sensor import (
    BEAM_DIVERGENCE_RAD,
    VLP16_ELEVATION_RAD,
    RigConfig,
    SensorConfig,
    firing_pattern,
    sensor_directions,
)
from visibility.sites import Site

_FRAMES_PER_TASK = 8


def simulate_scan(scene: RayScene, position_m: np.ndarray, heading_rad: float,
                  sensor: SensorConfig, rig: RigConfig, seed: int,
                  frames: Sequence[int] | None = None,
                  progress: Callable[[int], None] | None = None,
                  threads: int | None = None) -> dict[str, np.ndarray]:
    """Cast one station's turntable scan into ``scene``.

    Parameters
    ----------
    scene : RayScene
        Terrain and marker spheres, site frame.
    position_m : (3,) float
        Site-frame position of the station-frame origin (the nominal LiDAR centre), metres.
    heading_rad : float
        Station heading (rotation about site z), radians.
    sensor, rig : SensorConfig, RigConfig
    seed : int
        Frame ``f`` draws from ``default_rng([seed, f])``.
    frames : sequence of int, optional
        Frame indices to simulate (default: all ``rig.frames_per_turn``).
    progress : callable, optional
        Called with the number of frames just finished.
    threads : int, optional
        Worker threads (default: all cores).

    Returns
    -------
    points : dict
        ``frame_index`` (N,) uint32, ``laser_id`` (N,) uint8, ``spin_azimuth_rad`` (N,)
        float32, ``range_m`` (N,) float32, ``xyz_sensor_m`` (N, 3) float32, ``sphere_index``
        (N,) int64 (marker hit, -1 terrain), ``n_rays`` and ``n_cast`` (int, rays in the
        pattern and rays actually cast).
    """
    position, frame_ids = _simulate_iv(scene.dem, position_m, rig, frames)
    offsets = rig.offsets
    rotation, translation = frame_poses(rig.turntable_angles_rad()[frame_ids], offsets)
    m = station_to_site_matrix(heading_rad)
    horizon = HorizonBound(scene.dem, position, float(np.hypot(*offsets.axis_offset_m)),
                           scene.sphere_centres_m, scene.sphere_radius_m, sensor.max_range_m)
    tasks = [np.arange(a, min(a + _FRAMES_PER_TASK, len(frame_ids)))
             for a in range(0, len(frame_ids), _FRAMES_PER_TASK)]

    laser, az0 = firing_pattern(sensor.rpm, 0.0)
    pattern = (laser, az0, sensor_directions(laser, az0))

    def work(rows: np.ndarray) -> list[dict]:
        out = [_frame(scene, horizon, int(frame_ids[r]), m @ rotation[r],
                      position + m @ translation[r], sensor, seed, pattern) for r in rows]
        if progress is not None:
            progress(len(rows))
        return out

    threads = threads or os.cpu_count() or 1
    if threads == 1:
        results = [work(t) for t in tasks]
    else:
        with ThreadPoolExecutor(threads) as pool:
            results = list(pool.map(work, tasks))
    parts = [p for chunk in results for p in chunk]
    keys = (*POINT_FIELDS, "xyz_sensor_m", "sphere_index")
    points = {k: np.concatenate([p[k] for p in parts]) for k in keys}
    points["n_rays"] = int(sum(p["n_rays"] for p in parts))
    points["n_cast"] = int(sum(p["n_cast"] for p in parts))
    return points


def _simulate_iv(dem: DEM, position_m: np.ndarray, rig: RigConfig,
                 frames: Sequence[int] | None) -> tuple[np.ndarray, np.ndarray]:
    position = np.asarray(position_m, dtype=float).reshape(-1)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise ConfigError(f"position_m must be three finite numbers, got {position_m!r}")
    _station_inside_iv(dem, position[:2], "station")
    if frames is None:
        return position, np.arange(rig.frames_per_turn)
    ids = np.asarray(frames, dtype=np.int64).reshape(-1)
    if len(ids) == 0 or ids.min() < 0 or ids.max() >= rig.frames_per_turn:
        raise ConfigError(f"frames must be indices in [0, {rig.frames_per_turn}), got "
                          f"{len(ids)} values spanning "
                          f"{ids.min() if len(ids) else None}..{ids.max() if len(ids) else None}")
    return position, np.unique(ids)


def _station_inside_iv(dem: DEM, xy: np.ndarray, label: str) -> None:
    if not dem.contains(np.asarray(xy, dtype=float)[None, :2])[0]:
        xmin, xmax, ymin, ymax = dem.extent()
        raise DataError(f"{label} at ({xy[0]:.2f}, {xy[1]:.2f}) m lies outside the DEM "
                        f"[{xmin:.1f}, {xmax:.1f}] x [{ymin:.1f}, {ymax:.1f}] m; move the "
                        "station inside or use a larger DEM")


def _frame(scene: RayScene, horizon: HorizonBound, frame: int, rotation: np.ndarray,
           origin: np.ndarray, sensor: SensorConfig, seed: int,
           pattern: tuple[np.ndarray, np.ndarray, np.ndarray]) -> dict:
    """Simulate one frame. ``rotation``/``origin``: sensor -> site pose of this frame.

    ``pattern`` is the firing pattern at phase 0 (laser ids, azimuths, sensor-frame unit
    directions); this frame's random phase ``phi`` turns it by ``rot_z(-phi)`` (the spin
    azimuth runs clockwise from +y).
    """
    rng = np.random.default_rng([seed, frame])
    phase = rng.uniform(0.0, sensor.azimuth_step_rad)
    laser, az0, d0 = pattern
    spin = rot_z(-phase)
    if sensor.beam_divergence:
        d_beam, rot = _diverge(laser, az0 + phase, rng), rotation
    else:
        d_beam, rot = d0, rotation @ spin
    keep = np.flatnonzero(horizon.may_hit_z(d_beam @ rot[2], lambda idx: d_beam[idx] @ rot.T))
    hits = scene.intersect_unit(np.broadcast_to(origin, (len(keep), 3)), d_beam[keep] @ rot.T,
                                max_range_m=sensor.max_range_m, threads=1,
                                incidence=sensor.incidence_noise_m > 0)
    true_range = hits.distance_m
    sigma: float | np.ndarray = sensor.range_noise_m
    if sensor.incidence_noise_m > 0:
        cosi = np.clip(np.nan_to_num(hits.cos_incidence, nan=1.0), 1e-12, 1.0)
        tan = np.minimum(np.sqrt(1 - cosi ** 2) / cosi, 10.0)
        sigma = np.hypot(sigma, sensor.incidence_noise_m * tan)
    with np.errstate(invalid="ignore"):
        measured = true_range + sigma * rng.standard_normal(len(keep))
        if sensor.range_resolution_m > 0:
            measured = np.round(measured / sensor.range_resolution_m) * sensor.range_resolution_m
        ok = (measured >= sensor.min_range_m) & (measured <= sensor.max_range_m)
    if sensor.dropout_prob > 0:
        ok &= rng.random(len(keep)) >= sensor.dropout_prob
    sel = keep[ok]
    r = measured[ok]
    return {
        "frame_index": np.full(len(sel), frame, dtype=np.uint32),
        "laser_id": laser[sel],
        "spin_azimuth_rad": np.mod(az0[sel] + phase, 2 * np.pi).astype(np.float32),
        "range_m": r.astype(np.float32),
        "xyz_sensor_m": (r[:, None] * (d0[sel] @ spin.T)).astype(np.float32),
        "sphere_index": hits.sphere_index[ok],
        "n_rays": len(laser),
        "n_cast": len(keep),
    }


def _diverge(laser: np.ndarray, az: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Beam directions sampled uniformly inside the elliptical 3 x 1.5 mrad footprint."""
    n = len(laser)
    rad = np.sqrt(rng.random(n))
    ang = rng.uniform(0, 2 * np.pi, n)
    d_az = 0.5 * BEAM_DIVERGENCE_RAD[0] * rad * np.cos(ang)
    d_el = 0.5 * BEAM_DIVERGENCE_RAD[1] * rad * np.sin(ang)
    w = VLP16_ELEVATION_RAD[laser.astype(np.int64)] + d_el
    a = az + d_az / np.cos(w)
    return np.column_stack([np.cos(w) * np.sin(a), np.cos(w) * np.cos(a), np.sin(w)])


def _station_seed(seed: int, station_id: str) -> int:
    """Per-station seed: stable across runs, independent of which stations are simulated."""
    return int(np.random.SeedSequence([seed, zlib.crc32(station_id.encode())])
               .generate_state(1)[0])


def _scan_from_points(points: dict, rig: RigConfig, sensor: SensorConfig, station_id: str,
                      config: dict) -> StationScan:
    meta = {"station_id": station_id, "source": "simulated",
            "sensor": sensor.to_metadata(), "rig": rig.to_metadata(),
            "n_rays": points["n_rays"], "n_rays_cast": points["n_cast"],
            "provenance": provenance(config)}
    return StationScan(turntable_angle_rad=rig.turntable_angles_rad(), metadata=meta,
                       **{k: points[k] for k in (*POINT_FIELDS, "xyz_sensor_m")})


def _truth(station_id: str, position: np.ndarray, heading_rad: float, rig: RigConfig,
           marker_ids: Sequence[str], marker_centres_m: np.ndarray, marker_radius_m: float,
           points: dict, rock_centres_m: np.ndarray, rock_radii_m: np.ndarray,
           config: dict) -> dict:
    m = station_to_site_matrix(heading_rad)
    counts = np.bincount(points["sphere_index"][points["sphere_index"] >= 0],
                         minlength=len(marker_ids))
    markers = [{"id": mid, "centre_site_m": [float(v) for v in c],
                "centre_station_m": [float(v) for v in m.T @ (c - position)],
                "n_points": int(counts[k])}
               for k, (mid, c) in enumerate(zip(marker_ids, marker_centres_m, strict=True))]
    rocks = [{"centre_site_m": [float(v) for v in c], "radius_m": float(r)}
             for c, r in zip(rock_centres_m, rock_radii_m, strict=True)]
    return {
        "station_id": station_id,
        "station_pose": {"position_m": [float(v) for v in position],
                         "heading_rad": float(heading_rad), "roll_rad": 0.0, "pitch_rad": 0.0},
        "mounting_offsets": rig.offsets.to_dict(),
        "marker_radius_m": float(marker_radius_m),
        "markers": markers,
        "rocks": rocks,
        "provenance": provenance(config),
    }


def _config(sensor: SensorConfig, rig: RigConfig, seed: int, **extra) -> dict:
    return {"sensor": asdict(sensor), "rig": rig.to_metadata(), "seed": int(seed), **extra}


def simulate_station(site: Site, station_index: int, sensor: SensorConfig | None = None,
                     rig: RigConfig | None = None, seed: int = 0,
                     frames: Sequence[int] | None = None,
                     progress: Callable[[int], None] | None = None,
                     scene: RayScene | None = None,
                     threads: int | None = None) -> tuple[StationScan, dict]:
    """Simulate one station of a site.

    Parameters
    ----------
    site : Site
    station_index : int
        Index into ``site.station_ids``.
    sensor, rig : SensorConfig, RigConfig, optional
        Defaults: 600 rpm, 1.5 cm noise; 1.0 m height, 800 frames, no mounting offsets.
    seed : int
        Simulation seed (combined with the station id).
    frames : sequence of int, optional
        Subset of frame indices (tests); default all.
    progress : callable, optional
        Called with the number of frames finished.
    scene : RayScene, optional
        Pre-built scene of this site with its markers (re-used across stations).
    threads : int, optional

    Returns
    -------
    scan : StationScan
        Metadata per :mod:`pipeline.scan_format` (no mounting offsets).
    truth : dict
        For :func:`pipeline.scan_format.write_truth`; markers carry ``centre_site_m``,
        ``centre_station_m`` and the number of simulated points ``n_points``.
    """
    sensor = sensor or SensorConfig()
    rig = rig or RigConfig()
    if not 0 <= station_index < len(site.station_ids):
        raise ConfigError(f"station_index must be in [0, {len(site.station_ids)}), got "
                          f"{station_index}")
    station_id = site.station_ids[station_index]
    xy = site.station_xy_m[station_index]
    _station_inside_iv(site.dem, xy, f"station {station_id}")
    position = np.array([*xy, site.dem.height_at(xy[None])[0] + rig.lidar_height_m])
    heading = float(site.station_heading_rad[station_index])
    scene = scene or site_scene(site)
    sseed = _station_seed(seed, station_id)
    points = simulate_scan(scene, position, heading, sensor, rig, sseed, frames, progress, threads)
    config = _config(sensor, rig, seed, site=site.name, site_seed=site.seed,
                     station_id=station_id)
    scan = _scan_from_points(points, rig, sensor, station_id, config)
    truth = _truth(station_id, position, heading, rig, site.marker_ids, site.marker_centres_m,
                   site.marker_radius_m, points, site.rock_centres_m, site.rock_radii_m,
                   {**config, "mounting_offsets": rig.offsets.to_dict()})
    return scan, truth


def site_scene(site: Site, threads: int | None = None) -> RayScene:
    """The scene of ``site``: its DEM (rocks baked in) and its as-built marker spheres."""
    return RayScene(site.dem, site.marker_centres_m, site.marker_radius_m, threads=threads)


def simulate_site(site: Site, out_dir: str | Path, sensor: SensorConfig | None = None,
                  rig: RigConfig | None = None, seed: int = 0,
                  station_ids: Sequence[str] | None = None,
                  progress: Callable[[int], None] | None = None) -> list[dict]:
    """Simulate stations of ``site`` into ``out_dir``.

    Writes ``station_<id>.scan.npz`` and ``station_<id>.truth.json`` per station.

    Parameters
    ----------
    site : Site
    out_dir : str or Path
        Existing folder.
    sensor, rig : optional
    seed : int
    station_ids : sequence of str, optional
        Stations to simulate (default all).
    progress : callable, optional
        Called with the number of frames finished.

    Returns
    -------
    summary : list of dict
        Per station: ``station_id``, ``n_points``, ``scan``, ``truth`` file names, and points
        per marker.
    """
    out = Path(out_dir)
    ids = list(site.station_ids) if station_ids is None else list(station_ids)
    unknown = [s for s in ids if s not in site.station_ids]
    if unknown:
        raise ConfigError(f"unknown station id(s) {', '.join(unknown)}; site {site.name!r} has "
                          f"{', '.join(site.station_ids)}")
    scene = site_scene(site)
    summary = []
    for sid in ids:
        k = site.station_ids.index(sid)
        scan, truth = simulate_station(site, k, sensor, rig, seed, progress=progress, scene=scene)
        scan_path = write_scan(out / f"station_{sid}.scan.npz", scan)
        truth_path = write_truth(out / f"station_{sid}.truth.json", truth)
        summary.append({"station_id": sid, "n_points": scan.n_points,
                        "scan": scan_path.name, "truth": truth_path.name,
                        "marker_points": {m["id"]: m["n_points"] for m in truth["markers"]}})
    return summary


def write_site_json(path: str | Path, site: Site, rig: RigConfig) -> Path:
    """Write the site layout (reference coordinates) as JSON, site frame.

    Keys: ``site``, ``seed``, ``marker_radius_m``, ``markers`` [{``id``, ``centre_site_m``}],
    ``stations`` [{``id``, ``position_m``, ``heading_rad``}], ``craters``, ``rocks``,
    ``boundary_xy_m``, ``dem`` (shape, origin, cell size, CRS) and ``provenance``.
    """
    positions = site.station_xy_m
    z = site.dem.height_at(positions) + rig.lidar_height_m
    body = {
        "site": site.name, "seed": site.seed, "marker_radius_m": site.marker_radius_m,
        "markers": [{"id": i, "centre_site_m": [float(v) for v in c]}
                    for i, c in zip(site.marker_ids, site.marker_centres_m, strict=True)],
        "stations": [{"id": i, "position_m": [float(p[0]), float(p[1]), float(h)],
                      "heading_rad": float(a)}
                     for i, p, h, a in zip(site.station_ids, positions, z,
                                           site.station_heading_rad, strict=True)],
        "craters": [c.to_dict() for c in site.craters],
        "rocks": site.rocks,
        "boundary_xy_m": site.boundary_xy_m.tolist(),
        "dem": {"shape": list(site.dem.shape), "origin_m": list(site.dem.origin_m),
                "cell_size_m": site.dem.cell_size_m, "crs": site.dem.crs},
        "provenance": provenance({"site": site.name, "seed": site.seed,
                                  "rig": rig.to_metadata()}),
    }
    path = Path(path)
    path.write_text(json.dumps(body, indent=1, sort_keys=True) + "\n")
    return path


def simulate_markers(dem: DEM, station_position_m: np.ndarray, heading_rad: float,
                     marker_centres_m: np.ndarray, sensor: SensorConfig | None = None,
                     rig: RigConfig | None = None, seed: int = 0,
                     marker_radius_m: float = 0.1, marker_ids: Sequence[str] | None = None,
                     station_id: str = "S1", frames: Sequence[int] | None = None,
                     progress: Callable[[int], None] | None = None,
                     threads: int | None = None) -> tuple[StationScan, dict]:
    """Simulate one station seeing arbitrary markers on a DEM (range study, what-ifs).

    Parameters
    ----------
    dem : DEM
        Terrain, site frame (e.g. flat or gently rough).
    station_position_m : (3,) float
        Site-frame LiDAR centre (station-frame origin), metres. Use ground + 1.0 m.
    heading_rad : float
        Station heading, radians.
    marker_centres_m : (m, 3) float
        Marker centres, site frame, metres (e.g. 1..50 m away, centre = ground + radius).
    sensor, rig : optional
        As in :func:`simulate_station`.
    seed : int
    marker_radius_m : float
    marker_ids : sequence of str, optional
        Default ``M01``, ``M02``, ...
    station_id : str
    frames, progress, threads : optional
        As in :func:`simulate_scan`.

    Returns
    -------
    scan : StationScan
    truth : dict
        As :func:`simulate_station` (no rocks).

    Examples
    --------
    >>> import numpy as np
    >>> from visibility.dem import DEM
    >>> dem = DEM(np.zeros((101, 101)), (-5.0, -5.0), 0.1)
    >>> scan, truth = simulate_markers(dem, [0, 0, 1.0], 0.0, [[3.0, 0, 0.1]],
    ...                                frames=range(0, 800, 100))
    >>> truth["markers"][0]["centre_station_m"]
    [3.0, 0.0, -0.9]
    """
    sensor = sensor or SensorConfig()
    rig = rig or RigConfig()
    centres = np.asarray(marker_centres_m, dtype=float).reshape(-1, 3)
    ids = list(marker_ids) if marker_ids is not None else [f"M{k + 1:02d}"
                                                          for k in range(len(centres))]
    if len(ids) != len(centres):
        raise ConfigError(f"marker_ids has {len(ids)} ids for {len(centres)} marker centres; "
                          "give one id per marker")
    scene = RayScene(dem, centres, marker_radius_m, threads=threads)
    position = np.asarray(station_position_m, dtype=float)
    points = simulate_scan(scene, position, heading_rad, sensor, rig, seed, frames, progress,
                           threads)
    config = _config(sensor, rig, seed, station_id=station_id,
                     marker_centres_m=centres.tolist(), station_position_m=position.tolist(),
                     heading_rad=float(heading_rad))
    scan = _scan_from_points(points, rig, sensor, station_id, config)
    truth = _truth(station_id, position, heading_rad, rig, ids, centres, marker_radius_m,
                   points, np.zeros((0, 3)), np.zeros(0),
                   {**config, "mounting_offsets": rig.offsets.to_dict()})
    return scan, truth
