"""Coverage achieved by simulate + process (:mod:`planner.coverage.achieved`), held against the
rig's angular sampling computed here independently of it: on a plane the ground-point density
per m² of horizontal area at horizontal distance ``rho`` from a LiDAR at height ``h`` is
``density_per_sr(e) * cos(i) / r**2 / cos(s)`` (``e`` the elevation, ``i`` the incidence on the
plane, ``s`` its slope, ``r`` the range)."""

from __future__ import annotations

import numpy as np
import pytest

from markerplan.errors import ConfigError
from planner.coverage.achieved import achieved_coverage, compare_coverage
from visibility.dem import DEM
from visibility.sensor import azimuth_step_rad
from visibility.visibility_matrix import AngularSampling

#: The rig's sampling at 600 rpm (the simulator's spin), full turn.
SAMPLING = AngularSampling(azimuth_step_rad(600), 800)
#: Frames simulated in the tests (an eighth of a turn's; densities are scaled to a full turn).
FRAMES = 100
HEIGHT_M = 1.0


def _cells(half_m: float, cell_m: float) -> np.ndarray:
    g = np.arange(-half_m + cell_m / 2, half_m, cell_m)
    x, y = np.meshgrid(g, g, indexing="ij")
    return np.column_stack([x.ravel(), y.ravel()])


def _plane(half_m: float, slope: float = 0.0, cell_m: float = 0.2) -> DEM:
    """A plane ``z = slope * x`` over [-half_m, half_m]², DEM cells of ``cell_m``."""
    n = int(round(2 * half_m / cell_m)) + 1
    x = -half_m + cell_m * np.arange(n)
    return DEM(np.tile(slope * x, (n, 1)), (-half_m, -half_m), cell_m)


def _analytic_density(station: np.ndarray, xy: np.ndarray, slope: float = 0.0) -> np.ndarray:
    """Points per m² of horizontal area on the plane ``z = slope x`` at ``xy``, full turn."""
    ground = np.column_stack([xy, slope * xy[:, 0]])
    beam = ground - station
    r = np.linalg.norm(beam, axis=1)
    elevation = np.arcsin(beam[:, 2] / r)
    normal = np.array([-slope, 0.0, 1.0]) / np.hypot(slope, 1.0)
    cos_i = -(beam @ normal) / r
    return SAMPLING.density_per_sr(elevation) * cos_i / r ** 2 * np.hypot(slope, 1.0)


def test_flat_ground_radius_matches_the_sampling():
    """One station on flat ground: the covered cells form the disc of the analytic covered
    radius (area-equivalent radius within 3 %), and each ring's density is the analytic one."""
    station = np.array([0.1, 0.05, HEIGHT_M])
    cells, cell_m, density = _cells(10.0, 0.5), 0.5, 3000.0
    got = achieved_coverage(_plane(12.0), station[None], [0.3], cells, cell_m, density, seed=1,
                            frames_per_turn=FRAMES)
    rho = np.linspace(0.5, 20.0, 100_000)
    profile = _analytic_density(station, station[:2] + np.column_stack([rho, 0 * rho]))
    radius = rho[np.argmax(profile < density)]  # about 7.3 m
    achieved_radius = np.sqrt(got.stations_covering.sum() * cell_m ** 2 / np.pi)
    assert abs(achieved_radius - radius) < 0.03 * radius
    distance = np.hypot(*(cells - station[:2]).T)
    outside = np.abs(distance - radius) > 2 * cell_m  # cells whose verdict is not borderline
    assert np.array_equal(got.covered()[outside], distance[outside] < radius)
    ratio = got.best_density_per_m2 / _analytic_density(station, cells)
    ring = (distance > 3.0) & (distance < 9.0)
    assert abs(np.median(ratio[ring]) - 1.0) < 0.05
    agree = compare_coverage(distance < radius, got.stations_covering, 1, cells, station[None])
    assert agree.agreement_fraction > 0.97
    for d in (agree.predicted_only_distance_m, agree.achieved_only_distance_m):
        assert d is None or abs(d - radius) < cell_m  # they disagree only on the rim


def test_tilted_plane_density_per_horizontal_area():
    """On a 10 deg plane the density follows cos(incidence) / r² per horizontal m² (uphill
    denser, downhill sparser) within 6 % in every direction."""
    slope = np.tan(np.radians(10.0))
    station = np.array([0.0, 0.0, HEIGHT_M])
    cells, cell_m = _cells(8.0, 0.5), 0.5
    got = achieved_coverage(_plane(10.0, slope), station[None], [0.0], cells, cell_m, 1000.0,
                            seed=2, frames_per_turn=FRAMES)
    distance = np.hypot(*cells.T)
    ratio = got.best_density_per_m2 / _analytic_density(station, cells, slope)
    for side in (cells[:, 0] > 2, cells[:, 0] < -2, cells[:, 1] > 2, cells[:, 1] < -2):
        ring = side & (distance > 3.0) & (distance < 7.0)
        assert abs(np.median(ratio[ring]) - 1.0) < 0.06
    uphill = (cells[:, 0] > 4) & (np.abs(cells[:, 1]) < 1)
    downhill = (cells[:, 0] < -4) & (np.abs(cells[:, 1]) < 1)
    expected = _analytic_density(station, cells, slope)
    analytic = expected[uphill].sum() / expected[downhill].sum()
    measured = got.best_density_per_m2[uphill].sum() / got.best_density_per_m2[downhill].sum()
    assert analytic > 1.1 and abs(measured / analytic - 1.0) < 0.03


@pytest.mark.parametrize(("limit", "radius", "tolerance"), [
    ({"max_incidence_rad": np.radians(85.0)}, HEIGHT_M * np.tan(np.radians(85.0)), 0.04),
    ({"max_range_m": 6.0}, np.sqrt(6.0 ** 2 - HEIGHT_M ** 2), 0.03),
])
def test_range_and_incidence_limits_bound_the_disc(limit, radius, tolerance):
    """At 100 points per m² (analytic radius 22.7 m) the incidence limit of 85 deg binds at
    11.4 m and a range limit of 6 m at 5.9 m on flat ground; both are judged from the points
    (their centroid and fitted plane), not from the DEM. At 85 deg the incidence changes by
    only 0.4 deg per metre, so the few-tenths-of-a-degree tilt of a plane fitted to a cell's
    points of a 100-frame scan widens the disc by 2-3 % (0.5 % at 400 frames)."""
    cells, cell_m = _cells(14.0, 0.5), 0.5
    got = achieved_coverage(_plane(15.0), [[0.0, 0.0, HEIGHT_M]], [0.0], cells, cell_m, 100.0,
                            seed=6, frames_per_turn=FRAMES, **limit)
    achieved_radius = np.sqrt(got.stations_covering.sum() * cell_m ** 2 / np.pi)
    assert abs(achieved_radius - radius) < tolerance * radius


def test_a_ridge_hides_the_cells_behind_it():
    """A 1.5 m ridge 3 m east of the station: no ground point behind it, its mirror west is
    covered; with a second station beyond the ridge the hidden cells are covered once."""
    dem = _plane(12.0)
    heights = dem.heights_m.copy()
    x, y = np.meshgrid(*dem.grid_xy(), indexing="xy")
    heights[(x >= 3.0) & (x <= 3.6) & (np.abs(y) <= 5.0)] = 1.5
    dem = DEM(heights, dem.origin_m, dem.cell_size_m)
    cells, cell_m = _cells(10.0, 1.0), 1.0
    station = np.array([[0.0, 0.0, HEIGHT_M]])
    got = achieved_coverage(dem, station, [0.0], cells, cell_m, 300.0, seed=3,
                            frames_per_turn=50)
    behind = (cells[:, 0] > 5) & (cells[:, 0] < 9) & (np.abs(cells[:, 1]) < 2)
    mirror = (cells[:, 0] < -5) & (cells[:, 0] > -9) & (np.abs(cells[:, 1]) < 2)
    assert behind.sum() == mirror.sum() == 16
    assert np.all(got.best_density_per_m2[behind] == 0)
    assert np.all(got.stations_covering[mirror] == 1)
    both = achieved_coverage(dem, np.vstack([station, [[8.0, 0.0, HEIGHT_M]]]), [0.0, 1.0],
                             cells, cell_m, 300.0, seed=3, frames_per_turn=50)
    assert np.all(both.stations_covering[behind] == 1)
    assert np.array_equal(both.stations_covering_at(300.0), both.stations_covering)


def test_same_seed_same_coverage():
    args = (_plane(6.0), [[0.0, 0.0, HEIGHT_M]], [0.0], _cells(5.0, 0.5), 0.5, 2000.0)
    a = achieved_coverage(*args, seed=4, frames_per_turn=20)
    b = achieved_coverage(*args, seed=4, frames_per_turn=20)
    c = achieved_coverage(*args, seed=5, frames_per_turn=20)
    assert np.array_equal(a.best_density_per_m2, b.best_density_per_m2)
    assert np.array_equal(a.stations_covering, b.stations_covering)
    assert a.config == b.config and a.config["frames_per_turn"] == 20
    assert not np.array_equal(a.best_density_per_m2, c.best_density_per_m2)


def test_points_fall_into_their_cells():
    """The rasterisation against numpy's 2-D histogram, on an AOI of every third 0.5 m cell
    (not a rectangle) with points beyond its edges."""
    from planner.coverage.achieved import _CellGrid

    xyz = np.random.default_rng(0).uniform(-7.0, 7.0, (20_000, 3))
    full = _cells(5.0, 0.5)
    counts, seen = _CellGrid(full[::3], 0.5).counts(xyz, np.zeros(3), None, None)
    edges = np.arange(-5.0, 5.001, 0.5)
    histogram = np.histogram2d(xyz[:, 0], xyz[:, 1], bins=[edges, edges])[0]
    ij = np.rint((full[::3] + 4.75) / 0.5).astype(int)
    assert np.array_equal(counts, histogram[ij[:, 0], ij[:, 1]])
    assert np.array_equal(seen, counts > 0)


def test_compare_coverage_counts_and_distances():
    cells = np.array([[0.0, 0], [1, 0], [2, 0], [3, 0], [4, 0], [10, 0]])
    agree = compare_coverage([2, 2, 1, 0, 1, 0], [2, 1, 1, 1, 0, 0], 2, cells,
                             np.array([[0.0, 0.0, 1.0], [10.0, 0.0, 1.0]]))
    assert (agree.both, agree.predicted_only, agree.achieved_only, agree.neither) == (1, 1, 0, 4)
    assert agree.predicted_only_cells.tolist() == [1]
    assert agree.predicted_only_distance_m == 1.0 and agree.achieved_only_distance_m is None
    assert agree.to_dict()["agreement_fraction"] == pytest.approx(5 / 6)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"cell_xy": [[0.0, 0.0], [0.7, 0.0]]}, "regular grid"),
    ({"cell_xy": [[0.0, 0.0], [0.0, 0.0]]}, "twice"),
    ({"station_heading_rad": [0.0, 1.0]}, "`station_heading_rad`"),
    ({"min_density_per_m2": 0.0}, "`min_density_per_m2`"),
    ({"frames_per_turn": 900}, "`frames_per_turn`"),
    ({"max_incidence_rad": 2.0}, "`max_incidence_rad`"),
])
def test_bad_input_is_refused_before_scanning(kwargs, message):
    args = {"dem": _plane(2.0), "station_position_m": [[0.0, 0.0, 1.0]],
            "station_heading_rad": [0.0], "cell_xy": [[0.0, 0.0]], "cell_m": 0.5,
            "min_density_per_m2": 100.0, **kwargs}
    with pytest.raises(ConfigError, match=message):
        achieved_coverage(**args)


def test_docstring_examples():
    import doctest

    import planner.coverage.achieved as module

    assert doctest.testmod(module).failed == 0
