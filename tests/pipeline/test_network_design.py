"""The shared observation model's design blocks are the derivatives of ``t + R p``."""

import numpy as np

from pipeline.network.design import pose_design_blocks
from pipeline.scans.rig import station_to_site_matrix


def _mapped(pose, p):
    return pose[:3] + station_to_site_matrix(pose[3], pose[4], pose[5]) @ p


def test_blocks_are_the_derivatives_of_the_observation_equation():
    rng = np.random.default_rng(0)
    p = rng.uniform(-20, 20, (6, 3))
    angles = np.column_stack([rng.uniform(-np.pi, np.pi, 6), rng.normal(0, 0.05, (6, 2))])
    q, h = pose_design_blocks(p, angles)
    eps = 1e-6
    for i in range(6):
        pose = np.r_[rng.normal(0, 10, 3), angles[i]]
        np.testing.assert_allclose(q[i], _mapped(pose, p[i]) - pose[:3], atol=1e-12)
        for c in range(6):
            d = np.zeros(6)
            d[c] = eps
            numeric = (_mapped(pose + d, p[i]) - _mapped(pose - d, p[i])) / (2 * eps)
            np.testing.assert_allclose(h[i, :, c], numeric, atol=1e-7)


def test_zero_angles_are_the_unrotated_model():
    p = np.random.default_rng(1).uniform(-20, 20, (5, 3))
    q0, h0 = pose_design_blocks(p)
    q, h = pose_design_blocks(p, np.zeros((5, 3)))
    np.testing.assert_array_equal(q0, q)
    np.testing.assert_array_equal(h0, h)
