"""Terrain laws: crater morphology, size-frequency distributions, fractal scaling, seeding."""

import numpy as np
import pytest

from visibility.terrain import (
    CraterSpec,
    TerrainSpec,
    crater_patch,
    fractal_surface,
    fresh_crater_profile,
    generate_terrain,
    sample_crater_diameters,
    sample_rock_diameters,
)


def test_fresh_crater_has_pike_depth_and_rim():
    D = 6.0
    r = np.array([0.0, D / 2, 5 * D / 2, 10 * D])
    dz = fresh_crater_profile(r, D)
    assert dz[1] == pytest.approx(0.036 * D)           # rim height (Pike 1977)
    assert dz[1] - dz[0] == pytest.approx(0.196 * D)   # rim-to-floor depth
    assert dz[2] == pytest.approx(0.0) and dz[3] == 0.0
    # ejecta falls off as (r/R)^-3 near the rim (McGetchin et al. 1973), taper aside
    near = fresh_crater_profile(np.array([D / 2 * 1.5]), D)[0]
    assert near / dz[1] == pytest.approx(1.5 ** -3, rel=0.02)


def test_degraded_crater_is_shallower_and_smoother():
    x = np.arange(-20, 20.001, 0.05)
    fresh = crater_patch(CraterSpec((0.0, 0.0), 6.0, 0.0), x, x, 0.05)
    old = crater_patch(CraterSpec((0.0, 0.0), 6.0, 0.02), x, x, 0.05)
    assert fresh[2] / 6.0 == pytest.approx(0.196, rel=0.01)
    assert old[2] / 6.0 < 0.15
    slope = [np.abs(np.gradient(p[0], 0.05)).max() for p in (fresh, old)]
    assert slope[1] < 0.7 * slope[0]


def test_crater_sfd_follows_the_power_law():
    rng = np.random.default_rng(1)
    d = sample_crater_diameters(rng, 1e6, 0.01, 2.0, (1.0, 100.0))
    expected = 1e6 * 0.01 * (1.0 - 100.0 ** -2)
    assert len(d) == pytest.approx(expected, rel=0.01)
    # cumulative counts: N(>2)/N(>1) = 2^-2 for b = 2
    assert np.mean(d > 2.0) == pytest.approx(0.25 - 1e-4, abs=0.01)


def test_rock_sfd_follows_golombek_rapp():
    rng = np.random.default_rng(2)
    k, area = 0.05, 1e5
    d = sample_rock_diameters(rng, area, k, (0.1, 2.0))
    q = 1.79 + 0.152 / k
    covered = np.sum(np.pi * d ** 2 / 4) / area
    assert covered == pytest.approx(k * (np.exp(-q * 0.1) - np.exp(-q * 2.0)), rel=0.05)


def test_fractal_surface_has_target_roughness_and_hurst_scaling():
    rng = np.random.default_rng(3)
    cell, H = 0.05, 0.85
    z = fractal_surface((1024, 1024), cell, H, 0.02, 1000.0, rng)

    def nu(lag_m):
        k = int(round(lag_m / cell))
        return np.sqrt(np.mean((z[:, k:] - z[:, :-k]) ** 2))

    assert nu(1.0) == pytest.approx(0.02, rel=1e-6)
    slope = np.log(nu(0.8) / nu(0.1)) / np.log(8.0)
    assert slope == pytest.approx(H, abs=0.07)


def test_generation_is_seeded():
    spec = TerrainSpec(extent_m=(-5, 5, -5, 5), cell_size_m=0.02, crater_density=0.1,
                       rock_abundance=0.05, rock_diameter_range_m=(0.2, 0.5))
    a = generate_terrain(spec, np.random.default_rng(7))
    b = generate_terrain(spec, np.random.default_rng(7))
    c = generate_terrain(spec, np.random.default_rng(8))
    np.testing.assert_array_equal(a.dem.heights_m, b.dem.heights_m)
    assert not np.array_equal(a.dem.heights_m, c.dem.heights_m)
    assert len(a.craters) > 0 and len(a.rock_radii_m) > 0
    # rocks stand above the surrounding ground
    tops = a.rock_centres_m[:, 2] + a.rock_radii_m
    np.testing.assert_allclose(a.dem.height_at(a.rock_centres_m[:, :2]), tops, atol=0.005)
