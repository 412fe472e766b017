"""The compiled loops of :mod:`pipeline.kernels` against the plain numpy code they replaced."""

import numpy as np
import pytest

from pipeline import kernels
from pipeline.chain.ground import local_ground_height
from pipeline.scans.sensor_noise import RangeNoise
from pipeline.sphere_centres.geometric_sphere_fit import lsq_fixed_radius
from pipeline.sphere_centres.line_of_sight_fit import _MIN_COS_INCIDENCE, _los_solve


def _numpy_lsq_fixed_radius(points, radius, centre, max_iter=50, tol=1e-10):
    """The numpy Gauss-Newton ``lsq_fixed_radius`` was before it was compiled."""
    c = np.asarray(centre, dtype=float).copy()
    for _ in range(max_iter):
        d = points - c
        n = np.linalg.norm(d, axis=1)
        u = d / np.maximum(n, 1e-12)[:, None]
        try:
            step = np.linalg.solve(u.T @ u, u.T @ (n - radius))
        except np.linalg.LinAlgError:
            break
        c = c + step
        if np.linalg.norm(step) < tol:
            break
    return c


def _numpy_los_fixed(rng, beam, centre, radius, noise, max_iter=50, tol=1e-10):
    """The plain line-of-sight Gauss-Newton (fixed radius), step capped at half the radius."""
    c = np.asarray(centre, dtype=float).copy()
    cov = np.full((3, 3), np.nan)
    for _ in range(max_iter):
        along = beam @ c
        h = np.sqrt(np.maximum(radius ** 2 - (c @ c - along ** 2),
                               (radius * _MIN_COS_INCIDENCE) ** 2))
        t = along - h
        jac = (t[:, None] * beam - c) / h[:, None]
        tan_i = np.sqrt(np.maximum(radius ** 2 - h ** 2, 0.0)) / h
        w = 1.0 / noise.total_sigma_m(rng, tan_i) ** 2
        cov = np.linalg.inv(jac.T @ (w[:, None] * jac))
        step = -cov @ (jac.T @ (w * (rng - t)))
        length = float(np.linalg.norm(step))
        damp = min(1.0, 0.5 * radius / max(length, 1e-300))
        c = c + damp * step
        if length * damp < tol:
            break
    return c, cov


def _cap(gen, centre, radius, n, noise_m):
    """Points on the sensor-facing cap of a sphere (sensor at the origin), with range noise."""
    u = gen.normal(size=(4 * n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    u = u[u @ centre < -0.3 * np.linalg.norm(centre)][:n]
    p = centre + radius * u
    rng = np.linalg.norm(p, axis=1) + gen.normal(0, noise_m, len(p))
    return rng[:, None] * p / np.linalg.norm(p, axis=1)[:, None]


@pytest.mark.parametrize("n", [6, 40, 2000])
def test_fixed_radius_fit_is_the_numpy_gauss_newton(n):
    gen = np.random.default_rng(n)
    centre = np.array([4.0, -2.0, -0.8])
    p = _cap(gen, centre, 0.1, n, 0.01)
    start = centre + gen.normal(0, 0.02, 3)
    np.testing.assert_allclose(lsq_fixed_radius(p, 0.1, start),
                               _numpy_lsq_fixed_radius(p, 0.1, start), rtol=0, atol=1e-10)
    np.testing.assert_allclose(lsq_fixed_radius(p.astype(np.float32), 0.1, start),
                               _numpy_lsq_fixed_radius(p.astype(np.float32).astype(float), 0.1,
                                                       start), rtol=0, atol=1e-10)


@pytest.mark.parametrize("n", [6, 40, 2000])
def test_line_of_sight_fit_is_the_numpy_gauss_newton(n):
    """Same centre and covariance, with the incidence term of the noise and without it."""
    gen = np.random.default_rng(10 + n)
    centre = np.array([-6.0, 3.0, -0.9])
    p = _cap(gen, centre, 0.1, n, 0.015)
    rng = np.linalg.norm(p, axis=1)
    beam = p / rng[:, None]
    start = centre + gen.normal(0, 0.03, 3)
    for noise in (RangeNoise(0.015), RangeNoise(0.015, incidence_noise_m=0.01)):
        got_c, got_r, got_cov = _los_solve(rng, beam, start, 0.1, noise)
        want_c, want_cov = _numpy_los_fixed(rng, beam, start, 0.1, noise)
        assert got_r == 0.1
        np.testing.assert_allclose(got_c, want_c, rtol=0, atol=1e-10)
        np.testing.assert_allclose(got_cov, want_cov, rtol=1e-8, atol=0)


def test_line_of_sight_fit_stops_on_a_singular_system():
    """Beams all along one line leave the normal matrix singular: the start comes back, with
    a NaN covariance, as when numpy's inverse raised."""
    beam = np.tile([1.0, 0.0, 0.0], (5, 1))
    start = np.array([3.0, 0.0, 0.0])
    c, cov = kernels.los_gauss_newton_fixed(np.full(5, 2.9), beam, start, 0.1, np.full(5, 1e-4),
                                            0.0, 0.1, 50, 1e-10)
    np.testing.assert_array_equal(c, start)
    assert np.isnan(cov).all()


def test_lowest_in_cells_is_the_grid_minimum():
    """Each point gets the lowest z of its ``floor(x / cell), floor(y / cell)`` cell, negative
    coordinates and cell edges included."""
    gen = np.random.default_rng(3)
    xyz = np.column_stack([gen.uniform(-7, 5, 20000), gen.uniform(-3, 9, 20000),
                           gen.normal(0, 0.3, 20000)])
    xyz[:50, :2] = np.round(xyz[:50, :2] * 2) / 2  # on the edges of 0.5 m cells
    got = local_ground_height(xyz, 0.5)
    cells = np.floor(xyz[:, :2] / 0.5).astype(np.int64)
    _, inverse = np.unique(cells, axis=0, return_inverse=True)
    lowest = np.full(inverse.max() + 1, np.inf)
    np.minimum.at(lowest, inverse, xyz[:, 2])
    np.testing.assert_array_equal(got, lowest[inverse])


def test_points_without_a_position_get_no_ground_and_no_range_band():
    """A NaN x, y or range is left out (ground NaN, so never "above ground"; never in a band)
    instead of indexing the grid or the bins with an undefined integer."""
    from pipeline.chain.gate import within_range_bands

    xyz = np.array([[0.1, 0.1, -1.0], [np.nan, 0.2, -3.0], [0.2, np.inf, -2.0], [0.3, 0.3, -0.5]])
    got = local_ground_height(xyz, 0.5)
    np.testing.assert_array_equal(got, [-1.0, np.nan, np.nan, -1.0])
    assert np.isnan(local_ground_height(xyz[1:3], 0.5)).all()
    rng = np.array([5.0, np.nan, 5.1, -1.0, 9.0])
    np.testing.assert_array_equal(within_range_bands(rng, np.array([[5.0, 0, 0]]), 0.3), [0, 2])


def test_planning_does_not_load_numba():
    """numba costs 0.4 s and 90 MB to import: `plan` (which imports the rig and the sphere fit
    for their constants and poses) must not pay for it."""
    import subprocess
    import sys

    code = ("import sys, planner.cli.plan, planner.cli.verify, planner.cli.simulate; "
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
