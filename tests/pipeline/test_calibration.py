import numpy as np
import pytest
from scipy.spatial import cKDTree

from markerplan.errors import ConfigError, DataError
from pipeline.chain.calibration import (
    CalibrationConfig,
    NearestNeighbours,
    direct_face,
    estimate_axis_offset,
    estimate_rotation_offsets,
)
from pipeline.chain.gate import RangeIndex
from pipeline.chain.synthesis import synthesize
from pipeline.scans.rig import MountingOffsets
from pipeline.sphere_centres.sphere_fit import fit_sphere
from tests.pipeline.test_synthesis import synthetic_scan

TRUE = MountingOffsets(np.radians(0.3), np.radians(0.3), (0.015, 0.0))
SPHERES = [(np.array([2.5 * np.cos(a), 2.5 * np.sin(a), -0.9]), 0.1)
           for a in np.radians(np.arange(10, 360, 45))]


@pytest.fixture(scope="module")
def scan():
    return synthetic_scan(TRUE, n_frames=400, azimuth_step_deg=0.4, spheres=SPHERES,
                          ground_tilt=(0.02, -0.01), noise_m=0.01, max_range_m=12.0, seed=5)


def test_faces_split_the_scan(scan):
    face = direct_face(scan)
    assert 0.4 < face.mean() < 0.6


def test_rotation_offsets_recovered_with_unknown_axis_offset(scan):
    off, cov, n, rms = estimate_rotation_offsets(scan, MountingOffsets())
    assert abs(np.degrees(off.vertical_axis_error_rad) - 0.3) < 0.02
    assert abs(np.degrees(off.lframe_tilt_rad) - 0.3) < 0.02
    assert n > 1000 and rms < 0.01
    assert np.all(np.sqrt(np.diag(cov)) < np.radians(0.01))


def _sphere_members(scan, offsets):
    """Inlier indices and centres of the known spheres in the cloud synthesised with offsets."""
    cloud = synthesize(scan, offsets)
    index = RangeIndex(cloud.xyz_m)
    members, centres = [], []
    for c, r in SPHERES:
        m = index.within(c, 0.3)
        fit = fit_sphere(cloud.xyz_m[m], r, centre0_m=c)
        members.append(m[fit.used])
        centres.append(fit.centre_m)
    return members, np.array(centres)


def test_axis_offset_from_sphere_consistency(scan):
    start = MountingOffsets(TRUE.vertical_axis_error_rad, TRUE.lframe_tilt_rad, (0.0, 0.0))
    offsets = start
    for _ in range(2):  # re-fit the spheres (new inlier sets) with the new offset
        members, centres = _sphere_members(scan, offsets)
        offsets, cov, n, rms = estimate_axis_offset(scan, offsets, members, 0.1, centres)
    assert n == len(SPHERES)
    np.testing.assert_allclose(offsets.axis_offset_m, TRUE.axis_offset_m, atol=0.002)
    assert np.all(np.sqrt(np.diag(cov)) < 0.002)


def test_a_false_sphere_is_dropped_from_the_axis_offset_fit(scan):
    """A candidate whose direct and reverse faces belong to different objects (as a rock or a
    clipped marker accepted on a smeared cloud can) is an outlier; without rejecting it the
    offset is pulled far off."""
    start = MountingOffsets(TRUE.vertical_axis_error_rad, TRUE.lframe_tilt_rad, (0.0, 0.0))
    members, centres = _sphere_members(scan, TRUE)
    face = direct_face(scan)
    a, b = members[0], members[1]
    false = np.r_[a[face[a]], b[~face[b]]]
    members, centres = [*members, false], np.vstack([centres, centres[0]])
    off, _, n, _ = estimate_axis_offset(scan, start, members, 0.1, centres)
    assert n == len(SPHERES)
    np.testing.assert_allclose(off.axis_offset_m, TRUE.axis_offset_m, atol=0.002)
    naive, _, n_all, _ = estimate_axis_offset(scan, start, members, 0.1, centres,
                                              CalibrationConfig(sphere_outlier_chi2=1e12))
    assert n_all == len(SPHERES) + 1
    assert np.linalg.norm(np.subtract(naive.axis_offset_m, TRUE.axis_offset_m)) > 0.004


def test_no_spheres_leaves_offset_unchanged(scan):
    off, cov, n, _ = estimate_axis_offset(scan, TRUE, [], 0.1, np.zeros((0, 3)))
    assert off == TRUE and n == 0 and np.isnan(cov).all()


def test_config_and_data_errors(scan):
    with pytest.raises(ConfigError, match="neighbours"):
        CalibrationConfig(neighbours=2).validate()
    with pytest.raises(ConfigError, match="sphere_outlier_chi2"):
        CalibrationConfig(sphere_outlier_chi2=0).validate()
    with pytest.raises(DataError, match="calibration range band"):
        estimate_rotation_offsets(scan, config=CalibrationConfig(min_range_m=50,
                                                                 max_range_m=60))


def _assert_fresh_tree_answer(nn, pa, pb):
    """``nn``'s 10 nearest neighbours of ``pa`` in ``pb`` equal a fresh tree's, bit for bit."""
    dist, idx = nn.query(pa, pb)
    want_d, want_i = cKDTree(pb).query(pa, k=10)
    np.testing.assert_array_equal(idx, want_i)
    np.testing.assert_array_equal(dist, want_d)


@pytest.mark.parametrize(("step_m", "builds", "ball_searches"),
                         [(1e-4, 1, False), (1e-3, 1, True), (0.2, 4, False)])
def test_nearest_neighbours_reuse_gives_fresh_tree_answers(monkeypatch, step_m, builds,
                                                           ball_searches):
    """Moving both point sets by tiny steps (the tree is reused), small ones (reused, with
    ball searches where the candidates cannot prove the answer) and large ones (rebuilt),
    every query equals a fresh cKDTree query: same neighbours, same order, bit-identical
    distances."""
    calls = []
    ball = NearestNeighbours._ball
    monkeypatch.setattr(NearestNeighbours, "_ball",
                        lambda self, *a: calls.append(1) or ball(self, *a))
    gen = np.random.default_rng(3)
    pb = gen.uniform(-5, 5, (20000, 3))
    pb[:, 2] *= 0.05  # a thin slab, like the ground the reverse face sees
    pa = pb[gen.choice(pb.shape[0], 2000, replace=False)] + gen.normal(0, 0.02, (2000, 3))
    nn = NearestNeighbours(10)
    for _ in range(4):
        _assert_fresh_tree_answer(nn, pa, pb)
        pb = pb + gen.normal(0, step_m, pb.shape)
        pa = pa + gen.normal(0, step_m, pa.shape)
    assert nn.builds == builds
    assert bool(calls) == ball_searches


def test_nearest_neighbours_with_fewer_reference_points_than_candidates():
    """With fewer reference points than k + spare every point is a candidate; the answers
    still equal a fresh tree's."""
    gen = np.random.default_rng(4)
    pb, pa = gen.normal(size=(12, 3)), gen.normal(size=(30, 3))
    nn = NearestNeighbours(10)
    for _ in range(3):
        _assert_fresh_tree_answer(nn, pa, pb)
        pb = pb + gen.normal(0, 1e-4, pb.shape)
        pa = pa + gen.normal(0, 1e-4, pa.shape)
