"""Simulated turntable scans: cast every VLP-16 beam of every frame into a :class:`RayScene`.

For frame ``f`` at turntable angle ``theta_f`` the sensor pose in the station frame comes from
:func:`pipeline.scans.rig.frame_poses` (the geometry contract, true mounting offsets applied), and
the station frame sits at ``position`` in the site frame, rotated by ``heading`` and, for a
station levelled to a curved body's local vertical, by its ``roll`` and ``pitch``
(:func:`pipeline.scans.rig.station_to_site_matrix`; default level: zero roll and pitch). A beam of
channel ``i`` at spin azimuth ``alpha`` leaves the LiDAR centre along
``Rz(heading) Ry(pitch) Rx(roll) R_f d_S(i, alpha)``. Its first hit (terrain or marker sphere)
gives the true range.
The point stored in the sensor frame is ``range * d_S`` along the *nominal* beam, and the scan
stores the *nominal* turntable angles. Sensor physics (``docs/simulator.md``, "Sensor physics";
each term is off when its parameter is zero or false):

Range noise (``SensorConfig.range_noise_m``, ``range_noise_per_m``, ``incidence_noise_m``,
``range_resolution_m``)
    Gaussian with the standard deviation of :meth:`pipeline.scans.sensor_noise.RangeNoise.sigma_m`
    at the true range and incidence, then rounded to the 2 mm resolution (VLP-16 datasheet
    63-9229). Returns outside [min, max] range or lost to ``dropout_prob`` are discarded.
Beam footprint and mixed returns (``SensorConfig.beam_divergence``, ``footprint_samples``)
    The VLP-16 beam diverges 3.0 mrad along the spin x 1.5 mrad across it
    (:data:`visibility.sensor.BEAM_DIVERGENCE_RAD`). Only where the footprint can straddle a
    marker's silhouette does this change a return (a beam whose angle from the sphere's centre
    direction is within ``asin(R / d) +- (1.5 mrad + margin)``); there
    ``footprint_samples`` sub-rays are cast in a fixed sunflower (Vogel) pattern that fills the
    elliptical footprint with equal areas (:func:`footprint_offsets_rad`), each carrying an
    equal share of the pulse energy (a top-hat beam; the ``cos(i) / r^2`` variation of the echo
    within one footprint is neglected). The sub-ray ranges are grouped: ranges closer than
    :data:`PULSE_SEPARATION_M` to the next one merge into one echo. The single-return
    (strongest) mode of the VLP-16 (manual 63-9243, "Laser Return Modes") reports the group
    with the largest energy share (ties: the nearest), at the energy-weighted mean range of its
    sub-rays: at an edge with background closer than the pulse separation the range lies
    between foreground and background (mixed pixels, Hebert and Krotkov 1992; Tuley, Vandapel
    and Hebert 2005). A beam none of whose sub-rays hits returns nothing. Every other beam is
    one central ray.
Turntable errors (``RigConfig.turntable``, :class:`visibility.sensor.TurntableErrors`)
    Frame ``f`` is taken at the true angle ``theta_f + e_enc + e_backlash + rate * e_sync``
    (encoder noise N(0, sigma_enc), backlash U(-b/2, b/2), synchronisation jitter N(0,
    sigma_sync) s at the table rate ``2 pi / (frames_per_turn * 60 / rpm)``), with the
    turntable axis tilted by ``Rx(w_x) Ry(w_y)``, ``w ~ N(0, sigma_wobble)`` (bearing wobble,
    about the turntable-frame origin), plus a periodic error ``A sin(2 theta_f + phi)`` (the
    second harmonic of the table angle: an elliptical bearing race or encoder disc; unlike the
    per-frame terms it is the same for every frame that sees a marker, so it does not average
    out, and unlike the first harmonic it does not cancel between the two faces, which see a
    marker 180 degrees apart). They perturb only the simulated pose; the scan keeps the
    nominal angles, as the processing chain must. The truth file lists each frame's errors.

Per-channel offsets (``SensorConfig.laser_range_bias_m``, ``laser_angle_bias_rad``,
``unit_seed``)
    Each of the 16 lasers of a unit has its own constant range offset and elevation and azimuth
    offsets, the residual of the factory calibration (Glennie and Lichti 2010, 2016, and Kidd
    2017 measured per-laser range offsets of centimetres and angular offsets of a few tenths of
    a milliradian to milliradians on Velodyne HDL-32E/VLP-16 units; the datasheet's +-3 cm
    "accuracy" includes them). They are drawn once per unit
    (:meth:`visibility.sensor.SensorConfig.laser_biases`) and shared by every station of a run.
    On this rig all 16 lasers sweep every marker as the table turns, so a marker's centre
    moves by the mean of the offsets, nearly alike for all markers: they change edge lengths
    little (see docs/simulator.md, "Calibrating the sensor"). The rays are cast along the true
    directions; the scan reports the nominal ones.

Rays that provably cannot hit anything (steeper than the conservative
:class:`visibility.horizon.HorizonBound` in their azimuth bin, built around the lowest and
widest perturbed LiDAR centre; decided per frame by :class:`visibility.horizon.PatternBound`)
are skipped without changing the result; near-silhouette beams are never skipped. A frame's
noise and dropout are drawn for the rays cast, in pattern order, so the culling decisions are
part of the output's definition (they are kept exactly). Randomness: frame ``f`` draws its
phase, noise and dropout from ``numpy.random.default_rng([seed, f])`` and its turntable errors
from ``default_rng([seed, f, 1])`` (always five draws, so switching one term off leaves the
others), so output is independent of threading and of which frames are simulated, and the same
seed gives byte-identical files.
"""

from __future__ import annotations

import json
import math
import os
import zlib
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from markerplan.constants import GOLDEN_ANGLE_RAD
from markerplan.errors import ConfigError
from markerplan.provenance import provenance
from pipeline.scans.rig import frame_poses, rot_x, rot_y, rot_z, station_to_site_matrix
from pipeline.scans.scan_format import POINT_FIELDS, StationScan, write_scan, write_truth
from visibility.dem import DEM
from visibility.horizon import HorizonBound, PatternBound
from visibility.scene import RayScene
from visibility.sensor import (
    BEAM_DIVERGENCE_RAD,
    VLP16_ELEVATION_RAD,
    RigConfig,
    SensorConfig,
    beam_directions,
    firing_pattern,
    sensor_directions,
)
from visibility.sites import Site
from visibility.turntable import turntable_errors

_FRAMES_PER_TASK = 8
#: Echoes of one pulse closer than this merge into one return, metres. Velodyne's manuals give
#: one metre as the smallest separation at which two objects give two returns (VLS-128 manual
#: 63-9483, "Dual Return Mode"); it matches a pulse of a few nanoseconds.
PULSE_SEPARATION_M = 1.0
#: Added to the footprint's half major axis in the near-silhouette test, radians (float32
#: directions, the icosphere proxy's tolerance).
SILHOUETTE_MARGIN_RAD = 1e-4


@dataclass(frozen=True)
class _Setup:
    """What every frame of one scan shares."""

    scene: RayScene
    horizon: PatternBound
    """The horizon bound applied to ``d_true``."""
    sensor: SensorConfig
    seed: int
    laser: np.ndarray
    """(n,) uint8 channel of each firing."""
    az0: np.ndarray
    """(n,) nominal spin azimuth at phase 0, radians."""
    d0: np.ndarray
    """(n, 3) nominal sensor-frame unit directions at phase 0 (what the scan reports)."""
    channel_elevation: np.ndarray
    """(16,) true elevation of each channel (nominal plus its offset), radians."""
    azimuth: np.ndarray
    """(n,) true spin azimuth at phase 0 (plus the channel's offset), radians."""
    d_true: np.ndarray
    """(n, 3) true directions at phase 0 (the rays cast)."""
    range_bias: np.ndarray
    """(n,) the channel's constant range offset of each firing, metres."""
    footprint: np.ndarray
    """(k, 2) sub-ray offsets (along the spin, across it), radians; empty without footprint."""


def simulate_scan(scene: RayScene, position_m: np.ndarray, heading_rad: float,
                  sensor: SensorConfig, rig: RigConfig, seed: int,
                  frames: Sequence[int] | None = None,
                  progress: Callable[[int], None] | None = None,
                  threads: int | None = None, station_id: str = "S1",
                  roll_rad: float = 0.0, pitch_rad: float = 0.0) -> dict[str, np.ndarray]:
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
        Frame ``f`` draws from ``default_rng([seed, f])`` (turntable errors from
        ``default_rng([seed, f, 1])``).
    frames : sequence of int, optional
        Frame indices to simulate (default: all ``rig.frames_per_turn``).
    progress : callable, optional
        Called with the number of frames just finished.
    threads : int, optional
        Worker threads (default: all cores).
    station_id : str
        Names the station in messages.
    roll_rad, pitch_rad : float
        Tilt of the station frame, rad: ``Rz(heading) Ry(pitch) Rx(roll)`` maps it to the site
        frame (a station levelled to a curved body's local vertical,
        :meth:`pipeline.network.body.Body.vertical_tilt`); default level.

    Returns
    -------
    points : dict
        ``frame_index`` (N,) uint32, ``laser_id`` (N,) uint8, ``spin_azimuth_rad`` (N,)
        float32, ``range_m`` (N,) float32, ``xyz_sensor_m`` (N, 3) float32, ``sphere_index``
        (N,) int64 (marker hit, -1 terrain), ``n_rays`` and ``n_cast`` (int, rays in the
        pattern and rays actually cast, sub-rays included), ``frames`` (F,) int64 (the frames
        simulated), ``angle_error_rad`` (F,) and ``wobble_rad`` (F, 2) (their turntable errors,
        see :func:`turntable_errors`).
    """
    position, frame_ids = _simulate_iv(scene.dem, position_m, rig, frames, station_id)
    angle_error, wobble = turntable_errors(rig, sensor.rpm, seed, frame_ids)
    rotation, translation = frame_poses(rig.turntable_angles_rad()[frame_ids] + angle_error,
                                        rig.offsets)
    tilt = rot_x(wobble[:, 0]) @ rot_y(wobble[:, 1])
    rotation, translation = tilt @ rotation, np.einsum("fij,fj->fi", tilt, translation)
    m = station_to_site_matrix(heading_rad, roll_rad, pitch_rad)
    # the bound holds for origins in a level disc; wobble and the station's tilt lower some of
    # them, and the tilt may widen the disc by up to |origin| sin(tilt)
    low = min(0.0, float((translation @ m[2]).min()))
    widen = float(np.linalg.norm(translation, axis=1).max()) * math.sin(
        min(math.hypot(roll_rad, pitch_rad), math.pi / 2))
    horizon = HorizonBound(scene.dem, position + [0.0, 0.0, low],
                           float(np.hypot(translation[:, 0], translation[:, 1]).max()) + widen,
                           scene.sphere_centres_m, scene.sphere_radius_m, sensor.max_range_m)
    tasks = [np.arange(a, min(a + _FRAMES_PER_TASK, len(frame_ids)))
             for a in range(0, len(frame_ids), _FRAMES_PER_TASK)]
    laser, az0 = firing_pattern(sensor.rpm, 0.0)
    range_bias, elevation_bias, azimuth_bias = sensor.laser_biases()
    channel = laser.astype(np.int64)
    channel_elevation = VLP16_ELEVATION_RAD + elevation_bias
    azimuth = az0 + azimuth_bias[channel]
    d_true = beam_directions(channel_elevation[channel], azimuth)
    setup = _Setup(scene, PatternBound(horizon, d_true), sensor, seed, laser, az0,
                   sensor_directions(laser, az0), channel_elevation, azimuth, d_true,
                   range_bias[channel],
                   footprint_offsets_rad(sensor.footprint_samples) if sensor.beam_divergence
                   else np.zeros((0, 2)))

    def work(rows: np.ndarray) -> list[dict]:
        out = [_frame(setup, int(frame_ids[r]), m @ rotation[r], position + m @ translation[r])
               for r in rows]
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
    points.update(frames=frame_ids, angle_error_rad=angle_error, wobble_rad=wobble)
    return points


def footprint_offsets_rad(n: int) -> np.ndarray:
    """Sub-ray offsets filling the VLP-16 beam footprint: a sunflower (Vogel) pattern.

    Sample ``k`` of ``n`` sits at radius ``sqrt((k + 0.5) / n)`` and angle ``k`` times the
    golden angle on the unit disc (equal areas per sample), scaled to the ellipse of semi-axes
    ``BEAM_DIVERGENCE_RAD / 2`` (1.5 mrad along the spin, 0.75 mrad across it).

    Returns
    -------
    offsets : (n, 2) float
        Angular offsets along the spin and across it (in elevation), radians.

    Examples
    --------
    >>> off = footprint_offsets_rad(7)
    >>> off.shape, bool(np.all(np.hypot(off[:, 0] / 1.5e-3, off[:, 1] / 0.75e-3) < 1))
    ((7, 2), True)
    """
    k = np.arange(n)
    rho = np.sqrt((k + 0.5) / n)
    angle = k * GOLDEN_ANGLE_RAD
    return np.column_stack([0.5 * BEAM_DIVERGENCE_RAD[0] * rho * np.cos(angle),
                            0.5 * BEAM_DIVERGENCE_RAD[1] * rho * np.sin(angle)])


def _simulate_iv(dem: DEM, position_m: np.ndarray, rig: RigConfig,
                 frames: Sequence[int] | None, station_id: str
                 ) -> tuple[np.ndarray, np.ndarray]:
    position = np.asarray(position_m, dtype=float).reshape(-1)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise ConfigError(f"position_m must be three finite numbers, got {position_m!r}")
    _station_on_dem_iv(dem, position[:2], station_id)
    if frames is None:
        return position, np.arange(rig.frames_per_turn)
    ids = np.asarray(frames, dtype=np.int64).reshape(-1)
    if len(ids) == 0 or ids.min() < 0 or ids.max() >= rig.frames_per_turn:
        raise ConfigError(f"frames must be indices in [0, {rig.frames_per_turn}), got "
                          f"{len(ids)} values spanning "
                          f"{ids.min() if len(ids) else None}..{ids.max() if len(ids) else None}")
    return position, np.unique(ids)


def _station_on_dem_iv(dem: DEM, xy: np.ndarray, station_id: str) -> None:
    """Refuse a station at ``xy`` (site frame, m) off ``dem``'s grid (the message names the
    DEM's size) or on its nodata (:meth:`visibility.dem.DEM.require_inside`)."""
    dem.require_inside(np.asarray(xy, dtype=float)[None, :2], [station_id], "station",
                       "move the station onto the DEM or use a DEM covering it")


def _frame(setup: _Setup, frame: int, rotation: np.ndarray, origin: np.ndarray) -> dict:
    """Simulate one frame. ``rotation``/``origin``: true sensor -> site pose of this frame.

    The firing pattern is stored at phase 0; this frame's random phase ``phi`` turns it by
    ``rot_z(-phi)`` (the spin azimuth runs clockwise from +y).
    """
    sensor, scene = setup.sensor, setup.scene
    rng = np.random.default_rng([setup.seed, frame])
    phase = rng.uniform(0.0, sensor.azimuth_step_rad)
    d_true = setup.d_true
    spin = rot_z(-phase)
    rot = rotation @ spin
    may_hit = setup.horizon.may_hit(rot)
    incidence = sensor.incidence_noise_m > 0
    is_near = np.zeros(len(d_true), dtype=bool)
    if len(setup.footprint):
        is_near[_near_silhouette(setup, rot, origin)] = True
    cast = np.flatnonzero(may_hit | is_near)
    is_central = ~is_near[cast]
    central, near = cast[is_central], cast[~is_central]
    hits = scene.intersect_unit(np.broadcast_to(origin, (len(central), 3)),
                                np.take(d_true, central, axis=0) @ rot.T,
                                max_range_m=sensor.max_range_m,
                                threads=1, incidence=incidence)
    true_range = np.empty(len(cast))
    sphere = np.empty(len(cast), dtype=np.int64)
    tan_i = np.zeros(len(cast))
    true_range[is_central], sphere[is_central] = hits.distance_m, hits.sphere_index
    if incidence:
        tan_i[is_central] = _tan_incidence(hits.cos_incidence)
    if len(near):
        mixed = _mixed_returns(setup, near, rot, origin, incidence)
        true_range[~is_central], sphere[~is_central], tan_i[~is_central] = mixed
    with np.errstate(invalid="ignore"):  # misses (inf) become NaN and fail the range test
        sigma = sensor.range_noise().sigma_m(true_range, tan_i)
        measured = (true_range + setup.range_bias[cast]
                    + sigma * rng.standard_normal(len(cast)))
        if sensor.range_resolution_m > 0:
            measured = np.round(measured / sensor.range_resolution_m) * sensor.range_resolution_m
        ok = (measured >= sensor.min_range_m) & (measured <= sensor.max_range_m)
    if sensor.dropout_prob > 0:
        ok &= rng.random(len(cast)) >= sensor.dropout_prob
    sel = cast[ok]
    r = measured[ok]
    return {
        "frame_index": np.full(len(sel), frame, dtype=np.uint32),
        "laser_id": setup.laser[sel],
        "spin_azimuth_rad": np.mod(setup.az0[sel] + phase, 2 * np.pi).astype(np.float32),
        "range_m": r.astype(np.float32),
        "xyz_sensor_m": (r[:, None] * (setup.d0[sel] @ spin.T)).astype(np.float32),
        "sphere_index": sphere[ok],
        "n_rays": len(setup.laser),
        "n_cast": len(central) + len(near) * len(setup.footprint),
    }


def _tan_incidence(cos_incidence: np.ndarray) -> np.ndarray:
    """tan of the incidence angle from its |cos| (misses, NaN, give 0)."""
    c = np.clip(np.nan_to_num(cos_incidence, nan=1.0), 1e-12, 1.0)
    return np.sqrt(1.0 - c ** 2) / c


def _near_silhouette(setup: _Setup, rot: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Indices of the beams whose footprint may straddle a marker's silhouette.

    A beam is near the silhouette of a sphere of radius ``R`` whose centre lies at distance
    ``d`` if its angle from the centre direction is within ``asin(R / d) +- h``, ``h`` the
    footprint's half major axis plus :data:`SILHOUETTE_MARGIN_RAD`.
    """
    scene = setup.scene
    u = scene.sphere_centres_m - origin
    dist = np.linalg.norm(u, axis=1)
    radius = scene.sphere_radius_m
    reach = (dist > radius) & (dist - radius <= setup.sensor.max_range_m)
    # sphere centre directions in the frame of the phase-0 pattern, and the band's outer radius
    v = (rot.T @ (u[reach] / dist[reach, None]).T)
    rho = np.arcsin(radius / dist[reach])
    half = 0.5 * max(BEAM_DIVERGENCE_RAD) + SILHOUETTE_MARGIN_RAD
    # cheap first cut: channels whose elevation is within the band of a sphere's elevation
    close = (np.abs(setup.channel_elevation[:, None] - np.arcsin(np.clip(v[2], -1, 1))[None, :])
             <= (rho + half)[None, :])
    spheres = close.any(axis=0)
    rows = np.flatnonzero(close[:, spheres].any(axis=1)[setup.laser])
    if not len(rows):
        return rows
    cosang = setup.d_true[rows] @ v[:, spheres]  # (k, m') cosines beam-to-centre
    cos_lo = np.cos(np.minimum(rho[spheres] + half, np.pi))  # farthest from the centre
    cos_hi = np.cos(np.maximum(rho[spheres] - half, 0.0))  # nearest
    return rows[((cosang >= cos_lo) & (cosang <= cos_hi)).any(axis=1)]


def _mixed_returns(setup: _Setup, beams: np.ndarray, rot: np.ndarray, origin: np.ndarray,
                   incidence: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The one (strongest) return of each footprint-sampled beam (see the module docstring).

    Returns
    -------
    range_m : (b,) float
        Energy-weighted mean range of the strongest echo group, ``inf`` if no sub-ray hit.
    sphere_index : (b,) int64
        The marker hit by at least half of that group's sub-rays, else -1.
    tan_incidence : (b,) float
        Mean tan(incidence) of the group (0 without ``incidence``).
    """
    k = len(setup.footprint)
    w = setup.channel_elevation[setup.laser[beams]]
    el = (w[:, None] + setup.footprint[None, :, 1]).ravel()
    az = (setup.azimuth[beams][:, None] + setup.footprint[None, :, 0] / np.cos(w)[:, None]).ravel()
    d = beam_directions(el, az) @ rot.T
    hits = setup.scene.intersect_unit(np.broadcast_to(origin, (len(d), 3)), d,
                                      max_range_m=setup.sensor.max_range_m, threads=1,
                                      incidence=incidence)
    order = np.argsort(hits.distance_m.reshape(-1, k), axis=1, kind="stable")
    r = np.take_along_axis(hits.distance_m.reshape(-1, k), order, axis=1)
    sph = np.take_along_axis(hits.sphere_index.reshape(-1, k), order, axis=1)
    hit = np.isfinite(r)
    with np.errstate(invalid="ignore"):
        gap = np.diff(r, axis=1) > PULSE_SEPARATION_M
    group = np.concatenate([np.zeros((len(r), 1), np.int64), np.cumsum(gap, axis=1)], axis=1)
    group[~hit] = k  # misses carry no energy
    share = np.stack([(group == g).sum(axis=1) for g in range(k)], axis=1)
    members = group == np.argmax(share, axis=1)[:, None]  # ties: the nearest group
    n = members.sum(axis=1)
    mean_range = np.where(n > 0, np.where(members, r, 0.0).sum(axis=1) / np.maximum(n, 1),
                          np.inf)
    on_marker = members & (sph >= 0)
    first = np.take_along_axis(sph, np.argmax(on_marker, axis=1)[:, None], axis=1)[:, 0]
    label = np.where(2 * on_marker.sum(axis=1) >= np.maximum(n, 1), first, -1)
    tan_i = np.zeros(len(r))
    if incidence:
        t = np.take_along_axis(_tan_incidence(hits.cos_incidence).reshape(-1, k), order, axis=1)
        tan_i = np.where(members, t, 0.0).sum(axis=1) / np.maximum(n, 1)
    return mean_range, label, tan_i


def _station_seed(seed: int, station_id: str) -> int:
    """Per-station seed: stable across runs, independent of which stations are simulated."""
    return int(np.random.SeedSequence([seed, zlib.crc32(station_id.encode())])
               .generate_state(1)[0])


def _scan_from_points(points: dict, rig: RigConfig, sensor: SensorConfig, station_id: str,
                      config: dict) -> StationScan:
    meta = {"station_id": station_id, "source": "simulated",
            "sensor": sensor.to_metadata(), "rig": rig.to_metadata(),
            "sensor_profile": config["sensor_profile"],
            "n_rays": points["n_rays"], "n_rays_cast": points["n_cast"],
            "provenance": provenance(config)}
    return StationScan(turntable_angle_rad=rig.turntable_angles_rad(), metadata=meta,
                       **{k: points[k] for k in (*POINT_FIELDS, "xyz_sensor_m")})


def _truth(station_id: str, position: np.ndarray, heading_rad: float, rig: RigConfig,
           marker_ids: Sequence[str], marker_centres_m: np.ndarray, marker_radius_m: float,
           points: dict, rock_centres_m: np.ndarray, rock_radii_m: np.ndarray,
           config: dict, roll_rad: float = 0.0, pitch_rad: float = 0.0) -> dict:
    m = station_to_site_matrix(heading_rad, roll_rad, pitch_rad)
    counts = np.bincount(points["sphere_index"][points["sphere_index"] >= 0],
                         minlength=len(marker_ids))
    markers = [{"id": mid, "centre_site_m": [float(v) for v in c],
                "centre_station_m": [float(v) for v in m.T @ (c - position)],
                "n_points": int(counts[k])}
               for k, (mid, c) in enumerate(zip(marker_ids, marker_centres_m, strict=True))]
    rocks = [{"centre_site_m": [float(v) for v in c], "radius_m": float(r)}
             for c, r in zip(rock_centres_m, rock_radii_m, strict=True)]
    turntable = None
    if rig.turntable.enabled:
        turntable = {"frames": points["frames"].tolist(),
                     "angle_error_rad": points["angle_error_rad"].tolist(),
                     "wobble_rad": points["wobble_rad"].tolist()}
    return {
        "station_id": station_id,
        "station_pose": {"position_m": [float(v) for v in position],
                         "heading_rad": float(heading_rad), "roll_rad": float(roll_rad),
                         "pitch_rad": float(pitch_rad)},
        "mounting_offsets": rig.offsets.to_dict(),
        "marker_radius_m": float(marker_radius_m),
        "markers": markers,
        "rocks": rocks,
        "turntable_frame_errors": turntable,
        "provenance": provenance(config),
    }


def _config(sensor: SensorConfig, rig: RigConfig, seed: int, sensor_profile: str | None,
            **extra) -> dict:
    return {"sensor": asdict(sensor), "rig": rig.to_metadata(), "seed": int(seed),
            "sensor_profile": sensor_profile, **extra}


def simulate_station(site: Site, station_index: int, sensor: SensorConfig | None = None,
                     rig: RigConfig | None = None, seed: int = 0,
                     frames: Sequence[int] | None = None,
                     progress: Callable[[int], None] | None = None,
                     scene: RayScene | None = None,
                     threads: int | None = None,
                     sensor_profile: str | None = None) -> tuple[StationScan, dict]:
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
    sensor_profile : str, optional
        Name of the sensor profile ``sensor`` and ``rig.turntable`` come from (recorded as the
        scan metadata's ``sensor_profile``; ``None``: library defaults).

    Returns
    -------
    scan : StationScan
        Metadata per :mod:`pipeline.scans.scan_format` (no mounting offsets).
    truth : dict
        For :func:`pipeline.scans.scan_format.write_truth`; markers carry ``centre_site_m``,
        ``centre_station_m`` and the number of simulated points ``n_points``;
        ``turntable_frame_errors`` is ``None`` or {``frames``, ``angle_error_rad``,
        ``wobble_rad``} (:func:`turntable_errors` of the simulated frames).
    """
    sensor = sensor or SensorConfig()
    rig = rig or RigConfig()
    if not 0 <= station_index < len(site.station_ids):
        raise ConfigError(f"station_index must be in [0, {len(site.station_ids)}), got "
                          f"{station_index}")
    station_id = site.station_ids[station_index]
    xy = site.station_xy_m[station_index]
    _station_on_dem_iv(site.dem, xy, station_id)
    position = np.array([*xy, site.dem.height_at(xy[None])[0] + rig.lidar_height_m])
    heading = float(site.station_heading_rad[station_index])
    scene = scene or site_scene(site)
    sseed = _station_seed(seed, station_id)
    points = simulate_scan(scene, position, heading, sensor, rig, sseed, frames, progress, threads,
                           station_id)
    config = _config(sensor, rig, seed, sensor_profile, site=site.name, site_seed=site.seed,
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
                  progress: Callable[[int], None] | None = None,
                  sensor_profile: str | None = None) -> list[dict]:
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
    sensor_profile : str, optional
        As in :func:`simulate_station`.

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
        scan, truth = simulate_station(site, k, sensor, rig, seed, progress=progress, scene=scene,
                                       sensor_profile=sensor_profile)
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
                     threads: int | None = None,
                     sensor_profile: str | None = None, roll_rad: float = 0.0,
                     pitch_rad: float = 0.0) -> tuple[StationScan, dict]:
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
    sensor_profile : str, optional
        As in :func:`simulate_station`.
    roll_rad, pitch_rad : float
        Tilt of the station frame, rad (:func:`simulate_scan`; default level); the truth's
        ``station_pose`` records it.

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
                           threads, station_id, roll_rad, pitch_rad)
    # a tilt is recorded only when there is one: a level station's provenance stays as it was
    tilt = ({"roll_rad": float(roll_rad), "pitch_rad": float(pitch_rad)}
            if roll_rad or pitch_rad else {})
    config = _config(sensor, rig, seed, sensor_profile, station_id=station_id,
                     marker_centres_m=centres.tolist(), station_position_m=position.tolist(),
                     heading_rad=float(heading_rad), **tilt)
    scan = _scan_from_points(points, rig, sensor, station_id, config)
    truth = _truth(station_id, position, heading_rad, rig, ids, centres, marker_radius_m,
                   points, np.zeros((0, 3)), np.zeros(0),
                   {**config, "mounting_offsets": rig.offsets.to_dict()}, roll_rad, pitch_rad)
    return scan, truth
