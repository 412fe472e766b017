"""Embree scene: analytic ranges on a plane, exact sphere hits, culling bound, threading."""

import numpy as np
import pytest

from markerplan.errors import ConfigError
from visibility.dem import DEM
from visibility.scene import RayScene


def _flat(z=0.0, half=20.0, cell=0.5, x0=1000.0):
    n = int(2 * half / cell) + 1
    return DEM(np.full((n, n), z), (x0 - half, -half), cell)


def _down_rays(rng, n, origin):
    el = rng.uniform(-np.pi / 2, -0.1, n)
    az = rng.uniform(0, 2 * np.pi, n)
    d = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return np.broadcast_to(origin, (n, 3)), d


def test_flat_plane_gives_analytic_ranges():
    # far from the site origin on purpose: the scene must recentre before float32
    scene = RayScene(_flat(z=250.0))
    rng = np.random.default_rng(0)
    o, d = _down_rays(rng, 20000, np.array([1003.0, -2.0, 251.3]))
    hits = scene.intersect(o, d, incidence=True)
    expected = 1.3 / -d[:, 2]
    inside = np.all(np.abs((o + expected[:, None] * d)[:, :2] - [1000, 0]) < 19.9, axis=1)
    np.testing.assert_allclose(hits.distance_m[inside], expected[inside], atol=2e-5)
    assert np.all(hits.sphere_index == -1)
    np.testing.assert_allclose(hits.cos_incidence[inside], -d[inside, 2], atol=1e-5)
    up = scene.intersect(o[:5], -d[:5], incidence=True)
    assert np.all(np.isinf(up.distance_m)) and np.all(np.isnan(up.cos_incidence))


def test_max_range_turns_far_hits_into_misses():
    scene = RayScene(_flat())
    o = np.array([[1000.0, 0.0, 1.0]] * 2)
    d = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, -0.1]])
    hits = scene.intersect(o, d, max_range_m=5.0)
    assert hits.distance_m[0] == pytest.approx(1.0)
    assert np.isinf(hits.distance_m[1])


def _brute_force(o, d, centres, r, plane_z):
    t_plane = np.where(d[:, 2] < 0, (plane_z - o[:, 2]) / d[:, 2], np.inf)
    best, idx = t_plane.copy(), np.full(len(o), -1)
    for k, c in enumerate(centres):
        oc = o - c
        b = np.einsum("ij,ij->i", d, oc)
        disc = b * b - (np.einsum("ij,ij->i", oc, oc) - r * r)
        t = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
        closer = t < best
        best[closer], idx[closer] = t[closer], k
    return best, idx


def test_sphere_hits_are_exact_and_first():
    r = 0.1
    # two spheres resting on the plane (touching it) and one floating behind the first
    centres = np.array([[1004.0, 0.0, r], [1004.0, 0.25, r], [1006.0, 0.0, 0.3]])
    scene = RayScene(_flat(), centres, r)
    rng = np.random.default_rng(1)
    o = np.array([1000.0, 0.0, 1.0])
    # aim at the spheres, including grazing rays and the sphere/ground contact
    targets = centres[rng.integers(0, 3, 60000)] + rng.normal(0, 0.07, (60000, 3))
    d = targets - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(o, d.shape)
    hits = scene.intersect(o, d)
    t_ref, k_ref = _brute_force(o, d, centres, r, 0.0)
    on = hits.sphere_index >= 0
    assert on.sum() > 20000
    np.testing.assert_array_equal(hits.sphere_index, k_ref)
    np.testing.assert_allclose(hits.distance_m, t_ref, atol=2e-5)
    p = o[on] + hits.distance_m[on, None] * d[on]
    err = np.abs(np.linalg.norm(p - centres[hits.sphere_index[on]], axis=1) - r)
    assert err.max() < 0.5e-3
    assert err.max() < 1e-9  # analytic refinement: exact to float64


def test_threads_do_not_change_results():
    centres = np.array([[1003.0, 1.0, 0.1]])
    scene = RayScene(_flat(), centres)
    rng = np.random.default_rng(2)
    o, d = _down_rays(rng, 300000, np.array([1000.0, 0.0, 1.0]))
    a = scene.intersect(o, d, threads=1)
    b = scene.intersect(o, d, threads=2)
    np.testing.assert_array_equal(a.distance_m, b.distance_m)
    np.testing.assert_array_equal(a.sphere_index, b.sphere_index)


def test_line_of_sight_blocked_by_a_ridge():
    h = np.zeros((41, 41))
    h[:, 20] = 2.0  # a wall along x = 0
    scene = RayScene(DEM(h, (-10.0, -10.0), 0.5))
    o = np.array([[-5.0, 0.0, 1.0], [-5.0, 0.0, 1.0]])
    t = np.array([[-1.0, 3.0, 0.5], [5.0, 0.0, 1.0]])
    np.testing.assert_array_equal(scene.line_of_sight(o, t), [True, False])


def test_bad_rays_refused():
    scene = RayScene(_flat())
    with pytest.raises(ConfigError, match="directions must have shape"):
        scene.intersect(np.zeros((4, 3)), np.zeros((4, 2)))
    with pytest.raises(ConfigError, match="non-zero"):
        scene.intersect(np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(ConfigError, match="sphere_centres_m"):
        RayScene(_flat(), np.zeros((2, 2)))
