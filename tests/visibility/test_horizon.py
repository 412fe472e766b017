"""Sky culling: the horizon bound never drops a ray that hits, and the simulated scan is the
same with and without it."""

import numpy as np

from pipeline.scans.rig import MountingOffsets, rot_x, rot_z
from pipeline.scans.scan_format import POINT_FIELDS
from visibility.horizon import HorizonBound, PatternBound
from visibility.scene import RayScene
from visibility.sensor import (
    RigConfig,
    SensorConfig,
    TurntableErrors,
    firing_pattern,
    sensor_directions,
)
from visibility.simulate import simulate_markers
from visibility.terrain import CraterSpec, TerrainSpec, generate_terrain


def _rough_terrain():
    spec = TerrainSpec(extent_m=(-15, 15, -15, 15), cell_size_m=0.1, rock_abundance=0.05,
                       rock_diameter_range_m=(0.2, 1.0), crater_density=0.05,
                       crater_diameter_range_m=(1.0, 4.0), roughness_1m_m=0.05)
    return generate_terrain(spec, np.random.default_rng(4))


def test_horizon_bound_never_culls_a_hit():
    terrain = _rough_terrain()
    centres = np.array([[3.0, 2.0, 0.8], [-1.0, -6.0, 0.5]])
    scene = RayScene(terrain.dem, centres)
    origin = np.array([0.5, -0.5, terrain.dem.height_at(np.array([[0.5, -0.5]]))[0] + 1.0])
    rng = np.random.default_rng(5)
    n = 400000
    el = np.arcsin(rng.uniform(-0.3, 1.0, n))
    az = rng.uniform(0, 2 * np.pi, n)
    d = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    # origins scattered within 5 cm horizontally (mounting offset)
    o = origin + np.column_stack([rng.uniform(-0.035, 0.035, (n, 2)), np.zeros(n)])
    hits = scene.intersect(o, d, max_range_m=100.0)
    bound = HorizonBound(terrain.dem, origin, 0.05, centres, 0.1, reach_m=100.0)
    may = bound.may_hit(d)
    assert np.all(may[hits.hit])
    assert may.mean() < 0.5  # and it does cull the sky


def test_pattern_bound_decides_as_the_per_ray_bound():
    terrain = _rough_terrain()
    origin = np.array([0.0, 0.0, terrain.dem.height_at(np.zeros((1, 2)))[0] + 1.0])
    bound = HorizonBound(terrain.dem, origin, 0.05, reach_m=100.0)
    laser, azimuth = firing_pattern(600)
    pattern = sensor_directions(laser, azimuth)
    beams = PatternBound(bound, pattern)
    rng = np.random.default_rng(6)
    kept = []
    for theta, tilt in zip(rng.uniform(0, 2 * np.pi, 12), rng.normal(0, 0.3, 12), strict=True):
        rotation = rot_z(theta) @ rot_x(np.pi / 2 + tilt)  # spin axis near horizontal
        may = beams.may_hit(rotation)
        np.testing.assert_array_equal(may, bound.may_hit(pattern @ rotation.T))
        kept.append(may.mean())
    assert 0.2 < min(kept) and max(kept) < 0.8


def test_scan_is_identical_with_and_without_culling(monkeypatch):
    # the station stands in a 16 m crater whose rim rises 12-19 degrees above the LiDAR; one
    # marker sits on the inner rim, one just behind the crest (only its top peeks over the
    # horizon), one on the floor
    spec = TerrainSpec(extent_m=(-14, 14, -14, 14), cell_size_m=0.1, crater_density=0.0,
                       craters=(CraterSpec((0.0, 0.0), 16.0),), roughness_1m_m=0.03)
    dem = generate_terrain(spec, np.random.default_rng(1)).dem
    station = np.array([1.5, -1.0, dem.height_at(np.array([[1.5, -1.0]]))[0] + 1.0])
    xy = np.array([[8.0, 0.5], [-0.73, 8.34], [-3.0, -2.0]])
    centres = np.column_stack([xy, dem.height_at(xy) + 0.1])
    sensor = SensorConfig(range_noise_m=0.0, range_resolution_m=0.0, beam_divergence=True)
    rig = RigConfig(offsets=MountingOffsets(0.002, -0.003, (0.05, -0.02)),
                    turntable=TurntableErrors(wobble_rad=2e-3))
    runs = []
    for cull in (True, False):
        if not cull:
            monkeypatch.setattr(PatternBound, "may_hit",
                                lambda self, rotation: np.ones(len(self.pattern), dtype=bool))
        runs.append(simulate_markers(dem, station, 0.4, centres, sensor, rig, seed=2,
                                     frames=range(3, 800, 25)))
    (culled, truth_c), (full, truth_f) = runs
    assert culled.metadata["n_rays_cast"] < 0.8 * full.metadata["n_rays_cast"]
    for name in (*POINT_FIELDS, "xyz_sensor_m"):
        np.testing.assert_array_equal(getattr(culled, name), getattr(full, name))
    counts = [m["n_points"] for m in truth_c["markers"]]
    assert counts == [m["n_points"] for m in truth_f["markers"]]
    assert min(counts) > 0
