"""Sensor physics of the simulator: each term switchable and checked against an
analytic or Monte-Carlo expectation."""

import json

import numpy as np
import pytest

from pipeline.scans.rig import MountingOffsets
from pipeline.scans.scan_format import read_scan, read_truth, write_scan
from pipeline.scans.sensor_noise import RangeNoise
from tests.cli.invoke import run_cli
from tests.visibility.test_simulate import _flat, _frames_facing, _station_points
from visibility.dem import DEM
from visibility.horizon import PatternBound
from visibility.sensor import RigConfig, SensorConfig, TurntableErrors
from visibility.simulate import simulate_markers
from visibility.turntable import turntable_errors

EXACT = SensorConfig(range_noise_m=0.0, range_resolution_m=0.0)


def _wall(x_m=5.5, half=8.0, cell=0.25):
    """Flat ground z = 0 with a 10 m high wall from ``x_m`` on (rising over the cell before)."""
    dem = _flat(half=half, cell=cell)
    x, _ = dem.grid_xy()
    heights = np.where(x[None, :] >= x_m, 10.0, 0.0) * np.ones(dem.shape)
    return DEM(heights, dem.origin_m, cell)


def _ground_residuals(sensor, frames=range(0, 800, 40)):
    """Measured minus true range of ground returns (ground z = 0, LiDAR at 1 m, no offsets),
    with the true range and tan(incidence) of each return."""
    scan, _ = simulate_markers(_flat(), [0, 0, 1.0], 0.0, np.zeros((0, 3)), sensor, RigConfig(),
                               seed=1, frames=frames)
    r = scan.range_m.astype(float)
    true_r = -1.0 / (scan.xyz_sensor_m[:, 1] / scan.range_m)  # plane z = -1 in T: S.y -> T.z
    keep = true_r < 10.0
    true_r = true_r[keep]
    return r[keep] - true_r, true_r, np.sqrt(true_r ** 2 - 1.0)  # cos(i) = 1 / true range


def test_range_noise_follows_the_one_formula_at_every_range_and_incidence():
    sensor = SensorConfig(range_noise_m=0.008, range_noise_per_m=0.002, incidence_noise_m=0.004)
    resid, true_r, tan_i = _ground_residuals(sensor)
    expected = sensor.range_noise().total_sigma_m(true_r, tan_i)
    for lo, hi in ((1.0, 2.0), (2.0, 4.0), (4.0, 10.0)):
        sel = (true_r >= lo) & (true_r < hi)
        assert sel.sum() > 5000
        z = resid[sel] / expected[sel]
        assert np.std(z) == pytest.approx(1.0, rel=0.03), (lo, hi)
        assert abs(np.mean(resid[sel])) < 1e-3
    # switched off, the far returns are as noisy as the near ones
    base = SensorConfig(range_noise_m=0.008)
    resid0, true_r0, _ = _ground_residuals(base)
    far = true_r0 >= 4.0
    assert np.std(resid0[far]) == pytest.approx(float(RangeNoise(0.008).total_sigma_m(5.0)),
                                                rel=0.03)
    assert np.std(resid[true_r >= 4.0]) > 2 * np.std(resid0[far])


def _sphere_before_wall(beam_divergence, **sensor):
    """A free 0.1 m sphere 5 m along +x at LiDAR height, a wall about 0.3 m behind it (the DEM
    rises from x = 5.25 to 5.5)."""
    centre = np.array([5.0, 0.0, 1.0])
    config = SensorConfig(**{**EXACT.__dict__, "beam_divergence": beam_divergence, **sensor})
    scan, truth = simulate_markers(_wall(), [0, 0, 1.0], 0.0, [centre], config, RigConfig(),
                                   seed=2, frames=_frames_facing(0.0, 10.0))
    p = _station_points(scan, MountingOffsets()) + [0, 0, 1.0]
    return scan, truth, p, centre


def test_footprint_gives_mixed_returns_at_the_silhouette_only():
    plain, t_plain, p_plain, centre = _sphere_before_wall(False)
    wide, t_wide, p_wide, _ = _sphere_before_wall(True)

    def between(p):  # neither on the sphere's visible half nor on the wall
        near_axis = np.hypot(p[:, 1], p[:, 2] - 1.0) < 0.12
        return near_axis & (p[:, 0] > centre[0] + 0.01) & (p[:, 0] < 5.2)

    assert between(p_plain).sum() == 0
    mixed = between(p_wide)
    assert mixed.sum() >= 10
    # mixed points lie just outside the silhouette, along beams that graze the sphere
    c = centre - [0, 0, 1.0]  # the sphere seen from the LiDAR centre
    d = p_wide[mixed] - [0, 0, 1.0]
    angle = np.arccos(d @ c / np.linalg.norm(d, axis=1) / np.linalg.norm(c))
    rho = np.arcsin(0.1 / np.linalg.norm(c))
    assert np.all(np.abs(angle - rho) < 1.6e-3)
    # beams well inside the silhouette return the same range as without the footprint
    key = {(f, la, az): r for f, la, az, r in zip(plain.frame_index, plain.laser_id,
                                                  plain.spin_azimuth_rad, plain.range_m,
                                                  strict=True)}
    d_all = p_wide - [0, 0, 1.0]
    ang_all = np.arccos(np.clip(d_all @ c / np.linalg.norm(d_all, axis=1) / 5.0, -1, 1))
    inside = np.flatnonzero(ang_all < rho - 2e-3)
    assert len(inside) > 20
    for i in inside:
        k = (wide.frame_index[i], wide.laser_id[i], wide.spin_azimuth_rad[i])
        assert key[k] == wide.range_m[i]
    # the mixed returns count for the marker only where most of the footprint is on it
    assert abs(t_wide["markers"][0]["n_points"] - t_plain["markers"][0]["n_points"]) < 10
    assert wide.metadata["sensor"]["beam_divergence_rad"] == [3.0e-3, 1.5e-3]


def test_far_background_gives_the_strongest_return_not_a_mix():
    # the ground is 500 m below: a grazing beam's sub-rays hit the sphere or nothing, and the
    # misses carry no energy, so every return is the mean of sphere hits: on the visible half
    # of the sphere's depth, never behind it (the footprint's hits on the curved edge spread
    # over a few cm of range, so the point along the nominal beam may leave the surface)
    centre = np.array([5.0, 0.0, 1.0])
    sensor = SensorConfig(**{**EXACT.__dict__, "beam_divergence": True})
    scan, truth = simulate_markers(_flat(z=-500.0, half=1.0), [0, 0, 1.0], 0.0, [centre], sensor,
                                   RigConfig(), frames=_frames_facing(0.0, 10.0))
    p = _station_points(scan, MountingOffsets()) + [0, 0, 1.0]
    dist = np.linalg.norm(p - centre, axis=1)
    assert len(p) == truth["markers"][0]["n_points"] > 20
    assert np.all(p[:, 0] < centre[0] + 1e-3)
    assert np.all(np.abs(dist - 0.1) < 0.04)
    assert np.median(np.abs(dist - 0.1)) < 1e-4


def test_turntable_error_terms_have_the_expected_spread():
    errors = TurntableErrors(encoder_noise_rad=1e-4, backlash_rad=4e-4, sync_jitter_s=2e-3,
                             wobble_rad=5e-5)
    rig = RigConfig(frames_per_turn=800, turntable=errors)
    frames = np.arange(20000) % 800
    angle, wobble = turntable_errors(rig, 600, 3, np.arange(20000))
    rate = 2 * np.pi / (800 * 60 / 600)
    expected = np.sqrt(1e-4 ** 2 + 4e-4 ** 2 / 12 + (rate * 2e-3) ** 2)
    assert np.std(angle) == pytest.approx(expected, rel=0.03)
    assert np.std(wobble, axis=0) == pytest.approx([5e-5, 5e-5], rel=0.03)
    # frame f's errors do not depend on which other frames are simulated
    sub_angle, sub_wobble = turntable_errors(rig, 600, 3, np.array([7, 4000]))
    np.testing.assert_array_equal(sub_angle, angle[[7, 4000]])
    np.testing.assert_array_equal(sub_wobble, wobble[[7, 4000]])
    # switching one term off leaves the others' draws
    no_backlash = RigConfig(turntable=TurntableErrors(1e-4, 0.0, 2e-3, 5e-5))
    a2, w2 = turntable_errors(no_backlash, 600, 3, frames[:50])
    np.testing.assert_array_equal(w2, wobble[:50])
    assert not np.array_equal(a2, angle[:50])


def _per_frame_fit(scan, select, design, target):
    """Least-squares fit per frame of ``design(p) @ x = target(p)`` over the selected nominal
    station-frame points; returns the frames, solutions (F, k) and the largest residual."""
    p = _station_points(scan, MountingOffsets())
    keep = select(p)
    p, fi = p[keep], scan.frame_index[keep]  # sorted by frame
    frames, sols, worst = [], [], 0.0
    for q, f in zip(np.split(p, np.flatnonzero(np.diff(fi)) + 1),
                    fi[np.r_[0, np.flatnonzero(np.diff(fi)) + 1]], strict=True):
        if len(q) < 20:
            continue
        a, b = design(q), target(q)
        x = np.linalg.lstsq(a, b, rcond=None)[0]
        frames.append(f)
        sols.append(x)
        worst = max(worst, float(np.abs(a @ x - b).max()))
    return np.array(frames), np.array(sols), worst


def test_encoder_noise_rotates_each_frame_rigidly():
    sigma = 2e-3
    rig = RigConfig(turntable=TurntableErrors(encoder_noise_rad=sigma))
    scan, truth = simulate_markers(_wall(x_m=5.0, half=10.0), [0, 0, 1.0], 0.0, np.zeros((0, 3)),
                                   EXACT, rig, seed=4, frames=_frames_facing(0.0, 25.0))
    np.testing.assert_array_equal(scan.turntable_angle_rad, rig.turntable_angles_rad())
    # the wall's face is the plane x = 4.75 + 0.025 h (h = z + 1 the site height); nominal
    # points of a frame are the true ones turned by -delta about z, which leaves z, so
    # x cos(delta) - y sin(delta) = 4.75 + 0.025 (z + 1) exactly
    frames, sol, worst = _per_frame_fit(
        scan, lambda p: (p[:, 0] > 4.6) & (p[:, 2] > 0.0) & (p[:, 2] < 8.0),
        lambda q: np.column_stack([q[:, 0], -q[:, 1]]),
        lambda q: 4.75 + 0.025 * (q[:, 2] + 1.0))
    assert len(frames) > 80
    assert worst < 2e-5  # each frame is one rigid rotation (float32 points)
    np.testing.assert_allclose(np.hypot(sol[:, 0], sol[:, 1]), 1.0, atol=1e-5)
    delta = np.arctan2(sol[:, 1], sol[:, 0])
    errors = truth["turntable_frame_errors"]
    truth_delta = dict(zip(errors["frames"], errors["angle_error_rad"], strict=True))
    np.testing.assert_allclose(delta, [truth_delta[f] for f in frames], atol=2e-6)
    assert np.std(delta) == pytest.approx(sigma, rel=0.2)


def test_wobble_tilts_each_frame_and_culling_stays_exact(monkeypatch):
    sigma = 2e-3
    rig = RigConfig(offsets=MountingOffsets(0.0, 0.0, (0.05, 0.0)),
                    turntable=TurntableErrors(wobble_rad=sigma))
    frames = range(0, 800, 5)
    scan, truth = simulate_markers(_flat(), [0, 0, 1.0], 0.0, np.zeros((0, 3)), EXACT, rig,
                                   seed=5, frames=frames)
    # ground z = -1 in the station frame; with the tilt Rx(wx) Ry(wy) the nominal points of a
    # frame obey z = -1 - wx y + wy x (small angles; the 5 cm axis offset adds < 1e-6 m)
    offsets = MountingOffsets(0.0, 0.0, (0.05, 0.0))
    p = _station_points(scan, offsets)
    got, want = [], []
    errors = truth["turntable_frame_errors"]
    wobble = dict(zip(errors["frames"], errors["wobble_rad"], strict=True))
    for f in np.unique(scan.frame_index)[:60]:
        q = p[(scan.frame_index == f) & (np.hypot(p[:, 0], p[:, 1]) < 4.0)]
        a = np.column_stack([q[:, 0], -q[:, 1], np.ones(len(q))])
        got.append(np.linalg.lstsq(a, q[:, 2], rcond=None)[0][:2])
        want.append(wobble[int(f)][::-1])
    np.testing.assert_allclose(got, want, atol=2e-5)
    # the horizon bound never drops a ray that could hit (footprint and wobble included)
    sensor = SensorConfig(**{**EXACT.__dict__, "beam_divergence": True})
    centres = [[3.0, 1.0, 0.1], [-4.0, 2.0, 0.3], [0.0, -6.0, 0.1]]
    culled, _ = simulate_markers(_flat(), [0, 0, 1.0], 0.0, centres, sensor, rig, seed=6,
                                 frames=range(0, 800, 25))
    monkeypatch.setattr(PatternBound, "may_hit",
                        lambda self, rotation: np.ones(len(self.pattern), dtype=bool))
    full, _ = simulate_markers(_flat(), [0, 0, 1.0], 0.0, centres, sensor, rig, seed=6,
                               frames=range(0, 800, 25))
    assert culled.metadata["n_rays_cast"] < full.metadata["n_rays_cast"]
    for name in ("frame_index", "laser_id", "spin_azimuth_rad", "range_m", "xyz_sensor_m"):
        np.testing.assert_array_equal(getattr(culled, name), getattr(full, name))


def test_all_terms_on_byte_identical_for_threads(tmp_path):
    sensor = SensorConfig(range_noise_per_m=0.001, incidence_noise_m=0.005, beam_divergence=True,
                          dropout_prob=0.01)
    rig = RigConfig(turntable=TurntableErrors(1e-4, 2e-4, 1e-3, 5e-5))
    blobs = []
    for threads in (1, 2):
        scan, truth = simulate_markers(_flat(), [0, 0, 1.0], 0.0, [[3.0, 1.0, 0.1]], sensor, rig,
                                       seed=7, frames=range(0, 800, 40), threads=threads,
                                       sensor_profile="test")
        blobs.append(write_scan(tmp_path / f"{threads}.scan.npz", scan).read_bytes())
        blobs.append(json.dumps(truth, sort_keys=True))
    assert blobs[0] == blobs[2] and blobs[1] == blobs[3]
    assert scan.metadata["sensor_profile"] == "test"
    assert scan.metadata["rig"]["turntable_errors"]["backlash_rad"] == 2e-4


def test_simulate_command_takes_a_profile(tmp_path, capsys):
    out = tmp_path / "d"
    code, stdout, err = run_cli(capsys, ["simulate", "--station-ids", "S1", "--frames", "4",
                                         "--sensor-profile", "datasheet", "--out", str(out),
                                         "--json"])
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["sensor_profile"]["name"] == "datasheet"
    meta = read_scan(out / "station_S1.scan.npz").metadata
    assert meta["sensor_profile"] == "datasheet" and meta["sensor"]["range_noise_m"] == 0.015
    # a profile file: its turntable errors reach the rig, the options override its sensor
    assert read_truth(out / "station_S1.truth.json")["turntable_frame_errors"] is None
    profile = {"format": "markerplan-sensor-profile", "format_version": 1, "name": "mine",
               "sensor": {"range_noise_m": 0.02, "beam_divergence": True},
               "turntable": {"encoder_noise_rad": 1e-4}}
    (tmp_path / "mine.json").write_text(json.dumps(profile))
    out2 = tmp_path / "m"
    code, stdout, err = run_cli(capsys, ["simulate", "--station-ids", "S1", "--frames", "4",
                                         "--sensor-profile", str(tmp_path / "mine.json"),
                                         "--no-beam-divergence", "--incidence-noise-mm", "3",
                                         "--out", str(out2), "--json"])
    assert code == 0, err
    meta = read_scan(out2 / "station_S1.scan.npz").metadata
    assert meta["sensor_profile"] == "mine"
    assert meta["sensor"]["range_noise_m"] == 0.02 and meta["sensor"]["incidence_noise_m"] == 0.003
    assert meta["sensor"]["beam_divergence"] is False
    assert meta["rig"]["turntable_errors"]["encoder_noise_rad"] == 1e-4
    truth = read_truth(out2 / "station_S1.truth.json")
    assert len(truth["turntable_frame_errors"]["angle_error_rad"]) == 4


def test_per_channel_range_offsets_shift_each_channel_by_its_own_draw():
    """Exact ranges plus the channel offsets: each channel's ground residuals are its offset."""
    sensor = SensorConfig(range_noise_m=0.0, range_resolution_m=0.0, laser_range_bias_m=0.02,
                          unit_seed=3)
    bias, _, _ = sensor.laser_biases()
    scan, _ = simulate_markers(_flat(), [0, 0, 1.0], 0.0, np.zeros((0, 3)), sensor, RigConfig(),
                               seed=1, frames=range(0, 800, 80))
    # the reported direction is nominal; plane z = -1 in T: S.y -> T.z
    true_r = -1.0 / (scan.xyz_sensor_m[:, 1] / scan.range_m)
    for channel in np.unique(scan.laser_id):
        sel = scan.laser_id == channel
        assert np.allclose(scan.range_m[sel] - true_r[sel], bias[channel], atol=2e-5)
    assert np.std(bias) > 0.005  # 16 draws of sigma 2 cm
    other = SensorConfig(laser_range_bias_m=0.02, unit_seed=4).laser_biases()[0]
    assert not np.allclose(bias, other)  # another unit, other offsets


def test_per_channel_angle_offsets_move_the_hit_not_the_reported_direction():
    """With an elevation offset the beam hits the flat ground elsewhere: the reported point
    along the nominal direction then lies off the plane by the offset's geometry."""
    sensor = SensorConfig(range_noise_m=0.0, range_resolution_m=0.0,
                          laser_angle_bias_rad=2e-3, unit_seed=5)
    _, elevation_bias, azimuth_bias = sensor.laser_biases()
    assert np.abs(elevation_bias).max() > 1e-3 and np.abs(azimuth_bias).max() > 1e-3
    off, _ = simulate_markers(_flat(), [0, 0, 1.0], 0.0, np.zeros((0, 3)), sensor, RigConfig(),
                              seed=1, frames=range(0, 800, 80))
    exact, _ = simulate_markers(_flat(), [0, 0, 1.0], 0.0, np.zeros((0, 3)), EXACT, RigConfig(),
                                seed=1, frames=range(0, 800, 80))
    height = lambda scan: scan.xyz_sensor_m[:, 1]  # noqa: E731  T.z of the point, -1 on the plane
    assert np.allclose(height(exact), -1.0, atol=1e-5)
    assert np.abs(height(off) + 1.0).max() > 0.005  # points leave the plane


def test_periodic_turntable_error_is_the_second_harmonic_of_the_table_angle():
    """Only the periodic term on: frames 180 deg apart share their error (it does not cancel
    between the two faces), its amplitude is A, and it is a sinusoid of twice the angle."""
    rig = RigConfig(turntable=TurntableErrors(periodic_error_rad=1e-3))
    frames = np.arange(800)
    angle, wobble = turntable_errors(rig, 600, 7, frames)
    assert np.allclose(angle[:400], angle[400:], atol=1e-15)
    assert np.abs(angle).max() == pytest.approx(1e-3, rel=1e-3)
    theta = 2 * np.pi * frames / 800
    design = np.column_stack([np.sin(2 * theta), np.cos(2 * theta)])
    coef, *_ = np.linalg.lstsq(design, angle, rcond=None)
    assert np.allclose(design @ coef, angle, atol=1e-12)
    assert np.hypot(*coef) == pytest.approx(1e-3, rel=1e-9)
    assert not wobble.any()
