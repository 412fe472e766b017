"""Synthetic turntable scans built by ray casting an analytic scene (used by several tests)."""

import numpy as np
import pytest

from pipeline.chain.synthesis import synthesize
from pipeline.scans.rig import VLP16_ELEVATION_DEG, MountingOffsets, frame_poses
from pipeline.scans.scan_format import StationScan


def sensor_directions(azimuth_step_deg):
    """Unit ray directions in the sensor frame, (16 * n_az, 3), with laser ids and azimuths."""
    az = np.radians(np.arange(0, 360, azimuth_step_deg))
    om = np.radians(VLP16_ELEVATION_DEG)
    a, o = np.meshgrid(az, om)
    d = np.stack([np.cos(o) * np.sin(a), np.cos(o) * np.cos(a), np.sin(o)], -1).reshape(-1, 3)
    laser = np.repeat(np.arange(16), az.size)
    return d, laser, a.reshape(-1)


def _ray_sphere(o, d, c, r):
    oc = o - c
    b = d @ oc
    disc = b ** 2 - (oc @ oc - r ** 2)
    t = -b - np.sqrt(np.maximum(disc, 0))
    return np.where((disc > 0) & (t > 0), t, np.inf)


def _ray_box(o, d, lo, hi):
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - o) / d
        t2 = (hi - o) / d
    tmin = np.nanmax(np.minimum(t1, t2), axis=1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((tmax >= tmin) & (tmin > 0), tmin, np.inf)


def synthetic_scan(offsets=None, n_frames=120, azimuth_step_deg=0.4,
                   spheres=(), boxes=(), ground_z=-1.0, ground_tilt=(0.0, 0.0), noise_m=0.005,
                   max_range_m=40.0, seed=0, station_id="S1"):
    """Ray-cast a station: ground plane ``z = ground_z + tx x + ty y``, spheres (centre, r),
    axis-aligned boxes (lo, hi), all in the station frame; rig with ``offsets``."""
    offsets = MountingOffsets() if offsets is None else offsets
    rng = np.random.default_rng(seed)
    dirs_s, laser, az = sensor_directions(azimuth_step_deg)
    angles = np.linspace(0, 2 * np.pi, n_frames, endpoint=False)
    rot, trans = frame_poses(angles, offsets)
    out = {k: [] for k in ("xyz", "frame", "laser", "az", "range")}
    tx, ty = ground_tilt
    for f in range(n_frames):
        d = dirs_s @ rot[f].T
        o = trans[f]
        denom = d[:, 2] - tx * d[:, 0] - ty * d[:, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (ground_z + tx * o[0] + ty * o[1] - o[2]) / denom
        t = np.where(t > 0, t, np.inf)
        for c, r in spheres:
            t = np.minimum(t, _ray_sphere(o, d, np.asarray(c, float), r))
        for lo, hi in boxes:
            t = np.minimum(t, _ray_box(o, d, np.asarray(lo, float), np.asarray(hi, float)))
        hit = t < max_range_m
        rr = t[hit] + rng.normal(0, noise_m, hit.sum())
        out["xyz"].append(dirs_s[hit] * rr[:, None])
        out["frame"].append(np.full(hit.sum(), f))
        out["laser"].append(laser[hit])
        out["az"].append(az[hit])
        out["range"].append(rr)
    cat = {k: np.concatenate(v) for k, v in out.items()}
    return StationScan(turntable_angle_rad=angles, frame_index=cat["frame"].astype(np.uint32),
                       laser_id=cat["laser"].astype(np.uint8),
                       spin_azimuth_rad=cat["az"].astype(np.float32),
                       range_m=cat["range"].astype(np.float32),
                       xyz_sensor_m=cat["xyz"].astype(np.float32),
                       metadata={"station_id": station_id, "source": "test"}).validate()


def test_synthesis_with_true_offsets_puts_ground_flat():
    off = MountingOffsets(np.radians(0.3), np.radians(0.3), (0.015, 0.0))
    scan = synthetic_scan(off, n_frames=60, noise_m=0.0)
    ok = synthesize(scan, off)
    bad = synthesize(scan)
    ground_ok = np.abs(ok.xyz_m[:, 2] + 1.0)
    ground_bad = np.abs(bad.xyz_m[:, 2] + 1.0)
    assert ground_ok.max() < 1e-4  # float32 storage of sensor coordinates
    assert np.percentile(ground_bad, 90) > 0.01
    np.testing.assert_allclose(ok.range_m, np.linalg.norm(ok.xyz_m, axis=1))


def test_sphere_hits_are_on_the_sphere():
    c = np.array([3.0, 1.0, -0.5])
    scan = synthetic_scan(spheres=[(c, 0.1)], n_frames=90, noise_m=0.0)
    cloud = synthesize(scan)
    d = np.abs(np.linalg.norm(cloud.xyz_m - c, axis=1) - 0.1)
    on = d < 0.001
    assert on.sum() > 20
    assert d[on].max() == pytest.approx(0, abs=1e-5)
