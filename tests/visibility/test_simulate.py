"""Scan simulation: geometry through pipeline.scans.rig, analytic ranges, point counts, seeding."""

import numpy as np
import pytest

from markerplan.errors import ConfigError, DataError
from pipeline.scans.rig import MountingOffsets, rot_z, sensor_to_station, station_to_site_matrix
from pipeline.scans.scan_format import read_truth, write_scan, write_truth
from visibility.dem import DEM
from visibility.sensor import VLP16_ELEVATION_RAD, RigConfig, SensorConfig, azimuth_step_rad
from visibility.simulate import simulate_markers

EXACT = SensorConfig(range_noise_m=0.0, range_resolution_m=0.0)


def _flat(z=0.0, half=12.0, cell=0.25):
    n = int(2 * half / cell) + 1
    return DEM(np.full((n, n), z), (-half, -half), cell)


def _station_points(scan, offsets):
    return sensor_to_station(scan.xyz_sensor_m.astype(float), scan.frame_index,
                             scan.turntable_angle_rad, offsets)


def _frames_facing(azimuth_rad, half_width_deg=22.0, frames_per_turn=800):
    """Frames whose spin plane (T.y axis = theta + 90 deg, or -90) points near ``azimuth``."""
    theta = 2 * np.pi * np.arange(frames_per_turn) / frames_per_turn
    keep = np.zeros(frames_per_turn, dtype=bool)
    for side in (np.pi / 2, -np.pi / 2):
        diff = np.angle(np.exp(1j * (theta + side - azimuth_rad)))
        keep |= np.abs(diff) < np.radians(half_width_deg)
    return np.flatnonzero(keep)


def test_flat_ground_ranges_and_sphere_surface_are_exact():
    offsets = MountingOffsets(np.radians(0.3), np.radians(-0.2), (0.02, -0.01))
    rig = RigConfig(offsets=offsets)
    position = np.array([0.5, -0.3, 1.0])
    heading = 0.7
    centre = np.array([4.0, 1.5, 0.1])
    scan, truth = simulate_markers(_flat(), position, heading, [centre], EXACT, rig, seed=3,
                                   frames=range(0, 800, 7))
    p_station = _station_points(scan, offsets)
    p_site = p_station @ station_to_site_matrix(heading).T + position
    on = np.linalg.norm(p_site - centre, axis=1) < 0.1 + 1e-3
    assert on.sum() > 50
    # sphere points on the analytic surface, ground points on the plane z = 0
    np.testing.assert_allclose(np.linalg.norm(p_site[on] - centre, axis=1), 0.1, atol=5e-5)
    np.testing.assert_allclose(p_site[~on, 2], 0.0, atol=1e-4)
    # the truth file's station-frame centre agrees with the same transform
    c_station = np.array(truth["markers"][0]["centre_station_m"])
    np.testing.assert_allclose(station_to_site_matrix(heading) @ c_station + position, centre)
    assert truth["markers"][0]["n_points"] == on.sum()
    # the stored range is the norm of the stored sensor-frame point
    np.testing.assert_allclose(np.linalg.norm(scan.xyz_sensor_m, axis=1), scan.range_m,
                               rtol=1e-6)


def _expected_hits(distance_m, radius_m, elevation_rad, rpm, frames_per_turn):
    """Analytic number of returns on a sphere for the tilted-turntable pattern.

    Laser i (elevation w) at spin azimuth a and turntable angle t points along
    d_T = (sin w, cos w sin a, cos w cos a) rotated by t about z. The Jacobian of
    (a, t) -> direction is |d d/da x d d/dt| = sqrt(cos^2 w - sin^2 e) for a direction of
    elevation e, and every direction is reached twice per turn (cos a = sin e / cos w has two
    roots). Sample density per steradian: sum_i 2 / (da dt sqrt(cos^2 w_i - sin^2 e)).
    Times the solid angle of the sphere, 2 pi (1 - sqrt(1 - (r/d)^2)).
    """
    da = azimuth_step_rad(rpm)
    dt = 2 * np.pi / frames_per_turn
    density = np.sum(2.0 / (da * dt * np.sqrt(np.cos(VLP16_ELEVATION_RAD) ** 2
                                              - np.sin(elevation_rad) ** 2)))
    solid = 2 * np.pi * (1 - np.sqrt(1 - (radius_m / distance_m) ** 2))
    return density * solid


@pytest.mark.parametrize(("distance", "rpm"), [(2.0, 600), (5.0, 600), (10.0, 300), (20.0, 1200)])
def test_point_count_on_a_sphere_matches_the_angular_sampling(distance, rpm):
    # a free-floating sphere at the LiDAR height, ground far below out of reach
    dem = _flat(z=-500.0, half=1.0)
    az = np.radians(35.0)
    centre = np.array([distance * np.cos(az), distance * np.sin(az), 1.0])
    sensor = SensorConfig(rpm=rpm, range_noise_m=0.0)
    scan, truth = simulate_markers(dem, [0, 0, 1.0], 0.0, [centre], sensor, RigConfig(),
                                   frames=_frames_facing(az))
    n = truth["markers"][0]["n_points"]
    expected = _expected_hits(distance, 0.1, 0.0, rpm, 800)
    assert n == pytest.approx(expected, rel=0.15)


def test_injected_offset_moves_the_merged_cloud_as_predicted():
    offsets = MountingOffsets(0.0, 0.0, (0.03, -0.02))
    centre = np.array([5.0, 0.0, 1.0])
    dem = _flat(z=-500.0, half=1.0)
    frames = _frames_facing(0.0)
    scan, _ = simulate_markers(dem, [0, 0, 1.0], 0.0, [centre], EXACT,
                               RigConfig(offsets=offsets), frames=frames)
    c_station = centre - [0, 0, 1.0]
    right = _station_points(scan, offsets)
    wrong = _station_points(scan, MountingOffsets())
    np.testing.assert_allclose(np.linalg.norm(right - c_station, axis=1), 0.1, atol=5e-5)
    # ignoring the offset shifts each frame's points by -Rz(theta) (dx, dy, 0)
    theta = scan.turntable_angle_rad[scan.frame_index]
    shift = -(rot_z(theta) @ np.array([0.03, -0.02, 0.0]))
    np.testing.assert_allclose(wrong - right, shift, atol=1e-6)
    assert np.abs(np.linalg.norm(wrong - c_station, axis=1) - 0.1).max() > 0.01

    # a vertical-axis error rotates every frame about the sensor's spin axis
    eps = np.radians(0.5)
    tilted = MountingOffsets(eps, 0.0, (0.0, 0.0))
    scan2, _ = simulate_markers(dem, [0, 0, 1.0], 0.0, [centre], EXACT,
                                RigConfig(offsets=tilted), frames=frames)
    ok = _station_points(scan2, tilted)
    bad = _station_points(scan2, MountingOffsets())
    np.testing.assert_allclose(np.linalg.norm(ok - c_station, axis=1), 0.1, atol=5e-5)
    # the error rotates each point about S.z: displacement 2 sin(eps/2) r cos(laser elevation)
    moved = np.linalg.norm(bad - ok, axis=1)
    lever = scan2.range_m * np.cos(VLP16_ELEVATION_RAD[scan2.laser_id])
    np.testing.assert_allclose(moved, 2 * np.sin(eps / 2) * lever, rtol=1e-5)


def test_range_noise_and_quantisation():
    sensor = SensorConfig(range_noise_m=0.015)
    scan, truth = simulate_markers(_flat(), [0, 0, 1.0], 0.0, np.zeros((0, 3)), sensor,
                                   RigConfig(), frames=range(0, 800, 40))
    r = scan.range_m.astype(float)
    np.testing.assert_allclose(r / 0.002, np.round(r / 0.002), atol=1e-3)
    p = _station_points(scan, MountingOffsets())
    true_r = -1.0 / (scan.xyz_sensor_m[:, 1] / scan.range_m)  # plane z = -1 in T: S.y -> T.z
    near = r < 8
    resid = r[near] - true_r[near]
    assert np.std(resid) == pytest.approx(np.hypot(0.015, 0.002 / np.sqrt(12)), rel=0.05)
    assert abs(np.mean(resid)) < 1e-3
    assert p[:, 2].mean() == pytest.approx(-1.0, abs=2e-3)


def test_same_seed_gives_byte_identical_files(tmp_path):
    centre = [[3.0, 1.0, 0.1]]
    runs = []
    for seed, threads in ((5, 1), (5, 2), (6, 2)):
        scan, truth = simulate_markers(_flat(), [0, 0, 1.0], 0.0, centre,
                                       SensorConfig(dropout_prob=0.01, beam_divergence=True,
                                                    incidence_noise_m=0.01),
                                       RigConfig(), seed=seed, frames=range(0, 800, 50),
                                       threads=threads)
        a = write_scan(tmp_path / f"{seed}_{threads}.scan.npz", scan).read_bytes()
        b = write_truth(tmp_path / f"{seed}_{threads}.truth.json", truth).read_bytes()
        runs.append((a, b))
    assert runs[0] == runs[1]
    assert runs[0][0] != runs[2][0]
    body = read_truth(tmp_path / "5_1.truth.json")
    assert body["mounting_offsets"] == MountingOffsets().to_dict()


def test_station_outside_dem_refused():
    with pytest.raises(DataError, match="outside the DEM"):
        simulate_markers(_flat(half=2.0), [5.0, 0, 1.0], 0.0, [[1.0, 0, 0.1]], frames=[0])
    with pytest.raises(ConfigError, match="frames"):
        simulate_markers(_flat(), [0, 0, 1.0], 0.0, [[1.0, 0, 0.1]], frames=[800])


def test_station_outside_a_2x2_dem_names_the_dem_size():
    """The station itself is named, with the DEM's size and what the stations need, not a
    point on an internal grid; off the DEM and on nodata are told apart."""
    tiny = DEM(np.zeros((2, 2)), (0.0, 0.0), 1.0)
    with pytest.raises(DataError, match=r"station S7 at \(5.00, 0.00\) m lies outside the DEM "
                                        r"\(2 x 2 cells of 1 m\) \[0.0, 1.0\] x \[0.0, 1.0\] m"):
        simulate_markers(tiny, [5.0, 0, 1.0], 0.0, [[0.5, 0.5, 0.1]], station_id="S7",
                         frames=[0])
    valid = np.ones((3, 3), bool)
    valid[1, 1] = False
    holed = DEM(np.zeros((3, 3)), (0.0, 0.0), 1.0, valid=valid)
    with pytest.raises(DataError, match="station S1 at .* stands on DEM nodata"):
        simulate_markers(holed, [1.0, 1.0, 1.0], 0.0, [[0.5, 0.5, 0.1]], frames=[0])
