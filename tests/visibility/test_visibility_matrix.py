import numpy as np
import pytest

from planner.config import PlanConfig
from planner.problem.usability import OCCLUDED, USABLE, problem_from_visibility
from tests.planner.instances import AnalyticModel
from visibility.dem import DEM
from visibility.scene import RayScene
from visibility.terrain import fresh_crater_profile
from visibility.visibility_matrix import AngularSampling, disc_pattern, visibility_matrix


def _dem(height_fn=None, half=25.0, cell=0.1):
    x = np.arange(-half, half + 1e-9, cell)
    xx, yy = np.meshgrid(x, x)
    h = np.zeros_like(xx) if height_fn is None else height_fn(xx, yy)
    return DEM(h, (-half, -half), cell)


@pytest.fixture(scope="module")
def flat_scene():
    return RayScene(_dem())


def test_geometry_on_flat_ground(flat_scene):
    st = np.array([[0.0, 0.0, 1.0]])
    sites = np.array([[10.0, 0.0, 0.1], [0.0, -5.0, 0.1], [-3.0, 4.0, 0.1], [20.0, 20.0, 0.1]])
    v = visibility_matrix(flat_scene, st, sites, max_range_m=15.0, progress=False)
    assert v.site.tolist() == [0, 1, 2]  # (20, 20) is out of range
    assert np.allclose(v.distance_m, np.linalg.norm(sites[:3] - st, axis=1))
    assert np.allclose(np.degrees(v.bearing_rad), [0.0, -90.0, 126.8698976])
    assert np.allclose(v.elevation_rad, np.arctan2(-0.9, [10.0, 5.0, 5.0]))
    # a marker resting on flat ground is (almost) fully visible
    assert np.all(v.visible_fraction >= 0.9)


def test_expected_points_follow_the_angular_sampling(flat_scene):
    st = np.array([[0.0, 0.0, 1.0]])
    sites = np.array([[5.0, 0.0, 1.0], [10.0, 0.0, 1.0]])  # level with the LiDAR: e = 0
    s = AngularSampling()
    v = visibility_matrix(flat_scene, st, sites, sampling=s, progress=False)
    omega = 2 * np.pi * (1 - np.sqrt(1 - (0.1 / v.distance_m) ** 2))
    lines = 2 * 16 * 800 / (2 * np.pi)
    assert np.allclose(v.expected_points, omega * lines / s.azimuth_step_rad)
    assert v.expected_points[0] / v.expected_points[1] == pytest.approx(4.0, rel=0.01)


def test_crater_rim_hides_a_site_inside_the_crater():
    diameter, centre = 8.0, np.array([10.0, 0.0])
    dem = _dem(lambda x, y: fresh_crater_profile(np.hypot(x - centre[0], y - centre[1]),
                                                 diameter))
    scene = RayScene(dem)
    st_xy = np.array([[0.0, 0.0]])
    st = np.column_stack([st_xy, dem.height_at(st_xy) + 1.0])
    sites_xy = np.array([[10.0, 0.0], [-10.0, 0.0], [10.0, 6.0]])
    sites = np.column_stack([sites_xy, dem.height_at(sites_xy) + 0.1])
    v = visibility_matrix(scene, st, sites, progress=False)
    assert v.visible_fraction[0] == 0.0  # on the crater floor, behind the near rim
    assert v.visible_fraction[1] >= 0.9  # same distance on open ground
    p = problem_from_visibility(v, AnalyticModel(), PlanConfig(), ["S1"], st,
                                ["floor", "open", "beside"], sites)
    assert p.pair_reason[0] == OCCLUDED and p.pair_reason[1] == USABLE
    # a site beside the crater, seen over open ground, is visible
    st2 = np.column_stack([[13.0], [6.0], dem.height_at([[13.0, 6.0]]) + 1.0])
    v2 = visibility_matrix(scene, st2, sites[[2]], progress=False)
    assert v2.visible_fraction[0] >= 0.9


def test_a_wall_partly_hides_a_marker_and_batching_does_not_matter():
    dem = _dem(lambda x, y: np.where(np.abs(x - 5.0) < 0.3, 1.2, 0.0))
    scene = RayScene(dem)
    st = np.array([[0.0, 0.0, 1.0], [0.0, 3.0, 1.0]])
    sites = np.array([[10.0, 0.0, 0.1], [5.6, 0.0, 1.3], [-6.0, 0.0, 0.1]])
    a = visibility_matrix(scene, st, sites, progress=False)
    b = visibility_matrix(scene, st, sites, batch_rays=24, progress=False)
    assert np.array_equal(a.visible_fraction, b.visible_fraction)
    pairs = zip(a.station.tolist(), a.site.tolist(), strict=True)
    frac = dict(zip(pairs, a.visible_fraction, strict=True))
    assert frac[(0, 0)] == 0.0 and frac[(0, 2)] >= 0.9
    assert 0.0 < frac[(0, 1)] < 1.0  # sits on the wall top: its lower part is hidden
    assert a.n_rays == len(a) * 24 and a.rays_per_s > 0


def test_disc_pattern_and_bad_input(flat_scene):
    p = disc_pattern(500)
    assert np.isclose(np.mean(np.sum(p**2, axis=1)), 0.5, atol=0.01)  # uniform on the disc
    with pytest.raises(ValueError, match="station_position_m"):
        visibility_matrix(flat_scene, np.zeros((2, 2)), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="rays_per_marker"):
        visibility_matrix(flat_scene, np.zeros((1, 3)), np.zeros((1, 3)), rays_per_marker=0)
    empty = visibility_matrix(flat_scene, np.zeros((1, 3)), np.zeros((0, 3)), progress=False)
    assert len(empty) == 0
