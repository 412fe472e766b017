"""The orbital-grade planning DEM (visibility.orbital, visibility.sites.planning_dem): block
means of the truth, sub-cell rocks gone, and a height-error field whose measured RMS and
correlation length are the declared ones."""

from dataclasses import replace

import numpy as np
import pytest

from markerplan.errors import ConfigError
from visibility.dem import DEM
from visibility.orbital import (
    HeightError,
    block_average,
    height_error_field,
    orbital_dem,
)
from visibility.sites import ORBITAL_GRADES, load_site, planning_dem


def measured_correlation_length(field: np.ndarray, cell_m: float) -> float:
    """The lag (m) where the field's sample autocorrelation along x and y falls to 1/e,
    interpolated between whole cells."""
    f = field - field.mean()
    var = np.mean(f * f)
    lags = np.arange(0, 40)
    rho = np.array([1.0] + [0.5 * (np.mean(f[:, :-k] * f[:, k:]) + np.mean(f[:-k] * f[k:]))
                            / var for k in lags[1:]])
    k = int(np.argmax(rho < np.exp(-1.0)))
    t = (rho[k - 1] - np.exp(-1.0)) / (rho[k - 1] - rho[k])
    return (k - 1 + t) * cell_m


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("rms_m, correlation_m", [(0.3, 10.0), (0.5, 20.0), (0.05, 4.0)])
def test_field_rms_and_correlation_length_are_the_declared_ones(seed, rms_m, correlation_m):
    # 300 x 300 cells of 2 m: 60 (rms 0.3, corr 10) to 150 correlation lengths across
    field = height_error_field((300, 300), 2.0, HeightError(rms_m, correlation_m),
                               np.random.default_rng(seed))
    n_eff = (600.0 / correlation_m) ** 2  # independent patches, about
    assert abs(field.std() / rms_m - 1.0) < 4.0 / np.sqrt(n_eff) + 0.02
    assert abs(field.mean()) < 4.0 * rms_m / np.sqrt(n_eff)
    assert measured_correlation_length(field, 2.0) == pytest.approx(correlation_m, rel=0.08)


def test_field_below_a_cell_is_white_and_seeded():
    e = HeightError(0.2, 0.5)
    a = height_error_field((200, 200), 2.0, e, np.random.default_rng(5))
    b = height_error_field((200, 200), 2.0, e, np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)
    assert a.std() == pytest.approx(0.2, rel=0.03)
    assert abs(np.corrcoef(a[:, :-1].ravel(), a[:, 1:].ravel())[0, 1]) < 0.03


def test_block_means_match_the_truth_and_ragged_edge_is_dropped():
    rng = np.random.default_rng(0)
    truth = DEM(rng.normal(size=(43, 61)), (-3.0, 5.0), 0.1)
    coarse = block_average(truth, 0.5)
    assert coarse.shape == (8, 12) and coarse.cell_size_m == pytest.approx(0.5)
    assert coarse.origin_m == pytest.approx((-3.0 + 0.2, 5.0 + 0.2))  # centre of 5 x 5 cells
    np.testing.assert_allclose(coarse.heights_m[2, 3],
                               truth.heights_m[10:15, 15:20].mean(), atol=1e-12)
    np.testing.assert_allclose(coarse.heights_m.mean(), truth.heights_m[:40, :60].mean(),
                               atol=1e-12)
    # the coarse cell centre is where the block's fine cells centre
    x, y = coarse.grid_xy()
    fx, fy = truth.grid_xy()
    assert x[3] == pytest.approx(fx[15:20].mean()) and y[2] == pytest.approx(fy[10:15].mean())


def test_orbital_dem_is_block_means_plus_the_declared_error():
    truth = load_site("default").dem
    error = HeightError(0.3, 10.0)
    dem = orbital_dem(truth, 2.0, error, seed=4)
    means = block_average(truth, 2.0)
    residual = dem.heights_m - means.heights_m
    assert residual.std() == pytest.approx(0.3, rel=0.35)  # 30 x 30 cells: ~6 x 6 patches
    np.testing.assert_array_equal(dem.heights_m, orbital_dem(truth, 2.0, error, 4).heights_m)
    assert not np.array_equal(dem.heights_m, orbital_dem(truth, 2.0, error, 5).heights_m)
    exact = orbital_dem(truth, 2.0, HeightError(0.0, 10.0))
    np.testing.assert_array_equal(exact.heights_m, means.heights_m)


def test_a_rock_below_the_cell_is_gone():
    # flat 0.1 m truth with a 0.2 m rock (a 0.2 m-high bump 0.2 m across) at (1.0, 1.0)
    truth = DEM(np.zeros((80, 80)), (0.0, 0.0), 0.1)
    xx, yy = np.meshgrid(*truth.grid_xy())
    r = np.hypot(xx - 1.0, yy - 1.0)
    truth.heights_m[:] = np.where(r <= 0.1, 0.1 + np.sqrt(np.clip(0.01 - r**2, 0, None)), 0.0)
    assert truth.heights_m.max() == pytest.approx(0.2)
    coarse = orbital_dem(truth, 2.0, HeightError(0.0, 10.0))
    assert coarse.heights_m.max() < 0.02  # its 2 m cell's mean: 0.2 m x (0.03 m² / 4 m²)
    assert coarse.height_at(np.array([[1.0, 1.0]]))[0] < 0.02


def test_preset_orbital_planning_dems():
    for name in ("default", "large"):
        assert ORBITAL_GRADES[name].cell_m == 2.0
    site = load_site("default")
    dem = planning_dem(site, "orbital")
    assert dem.cell_size_m == 2.0 and dem.shape == (30, 30)
    assert planning_dem(site, "truth") is site.dem
    assert np.all(dem.contains(site.marker_centres_m[:, :2]))
    assert np.all(dem.contains(site.station_xy_m))
    # the site's rocks are in the truth and not in the planning DEM
    on_rocks = site.rock_centres_m[dem.contains(site.rock_centres_m[:, :2]), :2]
    top = site.dem.height_at(on_rocks) - block_average(site.dem, 2.0).height_at(on_rocks)
    assert np.median(top) > 0.05
    with pytest.raises(ConfigError, match="no orbital planning DEM"):
        planning_dem(replace(site, name="km"), "orbital")


@pytest.mark.parametrize("args, needle", [
    ((-0.1, 10.0), "outside \\[0, 50\\] m"),
    ((float("nan"), 10.0), "not a finite number"),
    ((51.0, 10.0), "outside \\[0, 50\\] m"),
    ((float("inf"), 10.0), "not a finite number"),
    ((0.3, 0.0), "correlation length 0 m is outside"),
    ((0.3, -5.0), "correlation length -5 m is outside"),
    ((0.3, 1e9), "correlation length"),
    (("abc", 10.0), "not a finite number"),
])
def test_bad_height_error_refused_in_one_line(args, needle):
    with pytest.raises(ConfigError, match=needle) as info:
        HeightError(*args)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("cell, needle", [(0.25, "not a whole multiple"), (0.0, "outside"),
                                          (500.0, "outside"), (float("nan"), "not a finite")])
def test_bad_orbital_cell_refused(cell, needle):
    with pytest.raises(ConfigError, match=needle):
        block_average(DEM(np.zeros((40, 40)), (0.0, 0.0), 0.1), cell)


def test_parse():
    assert HeightError.parse("0.3") == HeightError(0.3, 10.0)
    assert HeightError.parse(" 0.5 , 20 ") == HeightError(0.5, 20.0)
    for bad in ("", "0.3,", "1,2,3"):
        with pytest.raises(ConfigError, match="RMS_M"):
            HeightError.parse(bad)


def test_field_drawn_coarse_and_interpolated_keeps_its_rms_and_correlation():
    # 10 m correlation on 0.25 m cells: drawn on 1.25 m cells, cubic-spline interpolated
    error = HeightError(0.3, 10.0)
    fields = [height_error_field((1000, 1000), 0.25, error, np.random.default_rng(s))
              for s in range(3)]
    rms = np.sqrt(np.mean([np.mean(f**2) for f in fields]))
    assert rms == pytest.approx(0.3, rel=0.06)
    lengths = [measured_correlation_length(f[::4, ::4], 1.0) for f in fields]
    assert np.mean(lengths) == pytest.approx(10.0, rel=0.06)
    # smooth between the coarse nodes: neighbouring fine cells differ as the covariance says,
    # sd = rms sqrt(2 (1 - exp(-(0.25 / 10)^2))) = 10.6 mm
    step_sd = np.sqrt(np.mean([np.mean(np.diff(f, axis=1) ** 2) for f in fields]))
    assert step_sd == pytest.approx(0.3 * np.sqrt(2 * (1 - np.exp(-(0.25 / 10) ** 2))), rel=0.1)
