"""VLP-16 constants, firing pattern and rig config against the Velodyne manual."""

import numpy as np
import pytest

from markerplan.errors import ConfigError
from visibility import sensor as S


def test_vertical_angles_in_firing_order():
    assert S.VLP16_ELEVATION_DEG == (-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15)
    assert S.FIRING_ORDER == tuple(range(16))
    np.testing.assert_allclose(np.degrees(S.VLP16_ELEVATION_RAD), S.VLP16_ELEVATION_DEG)
    # 16 firings of 2.304 us fit in the 55.296 us sequence (manual: 18.432 us recharge)
    assert 16 * S.FIRING_INTERVAL_S == pytest.approx(S.FIRING_CYCLE_S - 18.432e-6)


@pytest.mark.parametrize(("rpm", "step_deg"), [(300, 0.1), (600, 0.2), (1200, 0.4)])
def test_azimuth_step_matches_datasheet(rpm, step_deg):
    assert np.degrees(S.azimuth_step_rad(rpm)) == pytest.approx(step_deg, rel=0.01)


def test_firing_pattern_orders_lasers_and_interpolates_azimuth():
    laser, az = S.firing_pattern(600, phase_rad=0.0)
    step = S.azimuth_step_rad(600)
    n_cycles = int(np.floor(2 * np.pi / step))
    assert len(laser) == 16 * n_cycles
    np.testing.assert_array_equal(laser[:32], np.tile(np.arange(16), 2))
    # channel i fires i * 2.304 us into the sequence
    np.testing.assert_allclose(az[:16], np.arange(16) * 2.304 / 55.296 * step, atol=1e-12)
    np.testing.assert_allclose(az[16] - az[0], step, atol=1e-12)
    assert az.min() >= 0 and az.max() < 2 * np.pi


def test_sensor_directions_follow_the_rig_convention():
    d = S.sensor_directions(np.array([1, 15]), np.array([0.0, np.pi / 2]))
    np.testing.assert_allclose(d[0], [0, np.cos(np.radians(1)), np.sin(np.radians(1))])
    np.testing.assert_allclose(d[1], [np.cos(np.radians(15)), 0, np.sin(np.radians(15))],
                               atol=1e-15)


@pytest.mark.parametrize("rpm", [299, 330, 1260])
def test_invalid_rpm_refused(rpm):
    with pytest.raises(ConfigError, match="rpm"):
        S.SensorConfig(rpm=rpm)


def test_defaults_documented():
    cfg = S.SensorConfig()
    assert cfg.range_noise_m == pytest.approx(0.015)
    assert cfg.range_resolution_m == 0.002
    assert cfg.max_range_m == 100.0 and cfg.min_range_m == 0.4
    meta = cfg.to_metadata()
    assert len(meta["laser_elevation_rad"]) == 16 and meta["rpm"] == 600
    rig = S.RigConfig()
    assert rig.frames_per_turn == 800 and rig.lidar_height_m == 1.0
    assert rig.turntable_angles_rad()[1] == pytest.approx(2 * np.pi / 800)


@pytest.mark.parametrize("frames", [0, -3])
def test_nonpositive_frames_refused(frames):
    with pytest.raises(ConfigError, match="frames_per_turn"):
        S.RigConfig(frames_per_turn=frames)
