import numpy as np
import pytest

from pipeline.scans.rig import MountingOffsets, frame_poses, sensor_to_station


def _sensor_dir(omega, alpha):
    return np.array([np.cos(omega) * np.sin(alpha), np.cos(omega) * np.cos(alpha), np.sin(omega)])


def test_nominal_mount_spin_sweeps_vertical_plane():
    # azimuth 0 points up, 90 deg along turntable +y, 180 deg down; laser elevation fans along +x
    rot, trans = frame_poses(np.array([0.0]), MountingOffsets())
    np.testing.assert_allclose(rot[0] @ _sensor_dir(0, 0), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(rot[0] @ _sensor_dir(0, np.pi / 2), [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(rot[0] @ _sensor_dir(0, np.pi), [0, 0, -1], atol=1e-12)
    d = rot[0] @ _sensor_dir(np.radians(15), np.pi / 2)
    np.testing.assert_allclose(d, [np.sin(np.radians(15)), np.cos(np.radians(15)), 0], atol=1e-12)
    np.testing.assert_allclose(trans, 0)


def test_rotations_are_proper():
    off = MountingOffsets(0.01, -0.02, (0.015, 0.0))
    rot, _ = frame_poses(np.linspace(0, 2 * np.pi, 7), off)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0)
    np.testing.assert_allclose(rot @ rot.transpose(0, 2, 1), np.broadcast_to(np.eye(3), rot.shape),
                               atol=1e-12)


def test_axis_offset_rotates_with_turntable():
    off = MountingOffsets(axis_offset_m=(0.015, 0.0))
    _, trans = frame_poses(np.array([0.0, np.pi / 2, np.pi]), off)
    np.testing.assert_allclose(trans, [[0.015, 0, 0], [0, 0.015, 0], [-0.015, 0, 0]], atol=1e-12)


@pytest.mark.parametrize("theta", [0.0, 1.0, np.pi])
def test_reverse_frame_sees_same_plane(theta):
    # frame theta at azimuth a and frame theta+pi at azimuth -a look the same direction
    rot, _ = frame_poses(np.array([theta, theta + np.pi]), MountingOffsets())
    a = 0.7
    np.testing.assert_allclose(rot[0] @ _sensor_dir(0, a), rot[1] @ _sensor_dir(0, -a), atol=1e-12)


def test_sensor_to_station_matches_frame_poses():
    off = MountingOffsets(0.003, 0.004, (0.01, -0.005))
    angles = np.array([0.1, 2.0])
    p = np.array([[1.0, 2.0, 3.0], [0.5, -1.0, 2.0]])
    out = sensor_to_station(p, np.array([0, 1]), angles, off)
    rot, trans = frame_poses(angles, off)
    np.testing.assert_allclose(out[1], rot[1] @ p[1] + trans[1])
