"""The predicted coverage matrix: analytic flat-plane radii, occlusion, tiling, nodata."""

import numpy as np
import pytest
import shapely

from markerplan.errors import ConfigError
from planner.coverage.density import ground_density_per_m2
from planner.coverage.grid import aoi_grid
from planner.coverage.sight import CoverageSettings, coverage_matrix
from visibility.dem import DEM

H = 1.0  # LiDAR height, m


def flat(n=121, cell=0.5, origin=-30.0, heights=None, valid=None):
    z = np.zeros((n, n)) if heights is None else heights
    return DEM(z, (origin, origin), cell, valid=valid)


def covered_radius(settings, dem=None, station=(0.0, 0.0)):
    """Largest horizontal distance of a covered cell and smallest of an uncovered one, m."""
    dem = dem or flat()
    grid = aoi_grid(dem, shapely.box(-29, -29, 29, 29), settings.cell_m)
    st = np.array([[*station, H]])
    m = coverage_matrix(dem, st, grid, settings)
    r = np.hypot(*(grid.centre_xy_m - station).T)
    miss = np.setdiff1d(np.arange(len(grid)), m.cell)
    return r[m.cell].max(), r[miss].min(), m


@pytest.mark.parametrize("inc", [60.0, 80.0, 85.0])
def test_flat_radius_incidence_binds(inc):
    """On flat ground the covered radius is h tan(max incidence): every cell nearer is
    covered, none farther."""
    s = CoverageSettings(max_incidence_deg=inc, min_density_per_m2=0.0)
    inner, outer, _ = covered_radius(s)
    edge = H * np.tan(np.radians(inc))
    assert inner <= edge < outer
    assert outer - inner < s.cell_m * np.sqrt(2)


def test_flat_radius_range_binds():
    s = CoverageSettings(max_range_m=6.0, max_incidence_deg=89.0, min_density_per_m2=0.0)
    inner, outer, m = covered_radius(s)
    edge = np.sqrt(6.0 ** 2 - H ** 2)
    assert inner <= edge < outer
    assert m.distance_m.max() <= 6.0


def test_flat_radius_density_binds():
    """The density limit binds where density_per_sr(e) h / (d r^2) falls below it."""
    s = CoverageSettings(max_incidence_deg=89.0, min_density_per_m2=300.0)
    inner, outer, m = covered_radius(s)
    d = np.linspace(1, 30, 20001)
    r = np.hypot(d, H)
    dens = ground_density_per_m2(r, -np.arctan2(H, d), H / r)
    edge = d[np.flatnonzero(dens >= 300.0).max()]
    assert 14 < edge < 17  # the density, not the incidence limit (57 m), binds
    assert inner <= edge < outer
    assert m.density_per_m2.min() >= 300.0


def test_defaults_flat_radius():
    """Default settings on flat ground at 1 m: the 85-degree incidence limit binds, 11.43 m."""
    inner, outer, m = covered_radius(CoverageSettings())
    assert inner <= 11.43 < outer
    assert np.degrees(m.incidence_rad.max()) <= 85.0


def test_wall_hides_cells_behind_it():
    """A 2 m wall along x = 4 m hides the cells beyond it (x > 4.5 m) from a station at the
    origin, keeps those in front, and a station beyond the wall sees them."""
    dem = flat()
    x, _ = dem.grid_xy()
    h = np.zeros(dem.shape)
    h[:, np.abs(x - 4.0) < 0.3] = 2.0
    wall = flat(heights=h)
    grid = aoi_grid(wall, shapely.box(-10, -3, 10, 3), 1.0)
    s = CoverageSettings()
    m = coverage_matrix(wall, np.array([[0.0, 0.0, H], [8.0, 0.0, H]]), grid, s)
    cx = grid.centre_xy_m[:, 0]
    seen0 = m.cell[m.station == 0]
    assert not np.any(cx[seen0] > 4.5)
    assert np.any(cx[seen0] < 3.5)
    seen1 = m.cell[m.station == 1]
    assert np.any((cx[seen1] > 5.0) & (cx[seen1] < 8.0))
    # on flat ground without the wall station 0 covers cells out to 11 m on the +x side
    flat_m = coverage_matrix(dem, np.array([[0.0, 0.0, H]]), aoi_grid(
        dem, shapely.box(-10, -3, 10, 3), 1.0), s)
    assert np.any(cx[flat_m.cell] > 6.0)


def rough(seed=4):
    rng = np.random.default_rng(seed)
    h = np.cumsum(np.cumsum(rng.normal(0, 0.02, (121, 121)), 0), 1)
    return flat(heights=h - h.mean())


def test_tiled_equals_one_tile_and_is_deterministic():
    dem = rough()
    grid = aoi_grid(dem, shapely.box(-25, -25, 25, 25), 1.0)
    rng = np.random.default_rng(1)
    xy = rng.uniform(-25, 25, (40, 2))
    st = np.column_stack([xy, dem.height_at(xy) + H])
    s = CoverageSettings(max_range_m=12.0)
    one = coverage_matrix(dem, st, grid, s, block_m=1e4)
    tiled = coverage_matrix(dem, st, grid, s, block_m=8.0,
                            map_groups=lambda f, items: [f(i) for i in items])
    again = coverage_matrix(dem, st, grid, s, block_m=8.0)
    assert len(one) > 1000 and one.n_rays > 1.1 * len(one)  # some pairs are occluded
    # 28 blocks, each its own tile mesh; on this terrain no ray grazes an edge closely enough
    # to flip with the tile's float32 recentring, so the pairs agree exactly
    for name in ("station", "cell", "distance_m", "incidence_rad", "density_per_m2"):
        np.testing.assert_array_equal(getattr(one, name), getattr(tiled, name))
        np.testing.assert_array_equal(getattr(tiled, name), getattr(again, name))
    key = one.station * len(grid) + one.cell
    assert np.all(np.diff(key) > 0)  # sorted by station, then cell


def test_sight_line_across_nodata_does_not_count():
    """A nodata strip (heights filled flat) between the station and cells beyond it: those
    cells are not covered, though the terrain is flat."""
    valid = np.ones((121, 121), bool)
    x = -30.0 + 0.5 * np.arange(121)
    valid[:, np.abs(x - 5.0) < 0.6] = False
    dem = flat(valid=valid)
    grid = aoi_grid(dem, shapely.box(-10, -2, 3.5, 2), 1.0)
    grid_far = aoi_grid(dem, shapely.box(7, -2, 10, 2), 1.0)
    st = np.array([[0.0, 0.0, H], [12.0, 0.0, H]])
    m = coverage_matrix(dem, st, grid_far, CoverageSettings())
    assert np.all(m.station == 1) and len(m) == len(grid_far)
    measured = coverage_matrix(flat(), st, grid_far, CoverageSettings())
    assert np.count_nonzero(measured.station == 0) == len(grid_far)  # the strip, not range
    near = coverage_matrix(dem, st[:1], grid, CoverageSettings())
    assert len(near) > 0


def test_empty_and_counts():
    dem = flat()
    grid = aoi_grid(dem, shapely.box(-5, -5, 5, 5), 1.0)
    m = coverage_matrix(dem, np.zeros((0, 3)), grid)
    assert len(m) == 0 and m.count().sum() == 0
    st = np.array([[0.0, 0.0, H], [0.5, 0.0, H]])
    m = coverage_matrix(dem, st, grid)
    assert m.count().max() == 2
    np.testing.assert_array_equal(m.count([1]), np.isin(np.arange(len(grid)),
                                                        m.cell[m.station == 1]))
    with pytest.raises(ConfigError, match="`chosen`"):
        m.count([2])


@pytest.mark.parametrize("kwargs, name", [
    ({"cell_m": 0.0}, "cell_m"), ({"max_range_m": 500.0}, "max_range_m"),
    ({"max_incidence_deg": 95.0}, "max_incidence_deg"),
    ({"min_density_per_m2": -1.0}, "min_density_per_m2"),
    ({"min_stations": 0}, "min_stations"), ({"min_stations": 1.5}, "min_stations")])
def test_settings_refused(kwargs, name):
    with pytest.raises(ConfigError, match=f"`{name}`"):
        CoverageSettings(**kwargs)


def test_bad_stations_refused():
    dem = flat()
    grid = aoi_grid(dem, shapely.box(-5, -5, 5, 5), 1.0)
    with pytest.raises(ConfigError, match="`station_position_m`"):
        coverage_matrix(dem, np.zeros((2, 2)), grid)


def _small_case():
    dem = rough(seed=9)
    grid = aoi_grid(dem, shapely.box(-20, -20, 20, 20), 1.0)
    rng = np.random.default_rng(2)
    xy = rng.uniform(-20, 20, (12, 2))
    return dem, grid, np.column_stack([xy, dem.height_at(xy) + H])


def assert_same(a, b):
    for name in ("station", "cell", "distance_m", "incidence_rad", "density_per_m2"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert (a.n_rays, a.n_stations, a.n_cells) == (b.n_rays, b.n_stations, b.n_cells)


def test_groups_survive_pickling_and_the_in_process_executor():
    """What a cluster worker receives (a pickled group) gives the same pairs, and the
    executor's ``map_groups`` form gives the built-in map's matrix."""
    import pickle

    from planner.coverage.sight import group_coverage
    from planner.distributed import executor

    dem, grid, st = _small_case()
    s = CoverageSettings(max_range_m=10.0)
    here = coverage_matrix(dem, st, grid, s, block_m=10.0)
    seen = []

    def spy(fn, items):
        for item in items:
            seen.append(item)
            yield fn(pickle.loads(pickle.dumps(item)))

    assert_same(coverage_matrix(dem, st, grid, s, block_m=10.0, map_groups=spy), here)
    assert len(seen) > 3 and all(g.tile.shape[0] < dem.shape[0] for g in seen)
    assert sum(len(group_coverage(g)) for g in seen) == len(here)
    with executor("none", progress=False) as ex:
        assert_same(coverage_matrix(dem, st, grid, s, block_m=10.0, map_groups=ex), here)


def test_on_a_local_cluster_equals_in_process():
    """Two worker processes (about 2 s) give the in-process matrix."""
    from distributed import Client, LocalCluster

    from planner.distributed import Executor

    dem, grid, st = _small_case()
    s = CoverageSettings(max_range_m=10.0)
    here = coverage_matrix(dem, st, grid, s, block_m=10.0)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=40) as lc, Client(lc) as client:
        there = coverage_matrix(dem, st, grid, s, block_m=10.0,
                                map_groups=Executor(client, progress=False))
    assert_same(there, here)


def test_chunked_pairs_equal_one_chunk_and_too_many_pairs_refused(monkeypatch):
    from planner.coverage import sight

    dem, grid, st = _small_case()
    whole = coverage_matrix(dem, st, grid)
    monkeypatch.setattr(sight, "PAIRS_PER_CHUNK", 700)  # about one station per chunk
    assert_same(coverage_matrix(dem, st, grid), whole)
    monkeypatch.setattr(sight, "MAX_PAIRS", len(whole) // 2)
    with pytest.raises(ConfigError, match="raise `aoi_cell_m`, lower `cover_max_range_m`"):
        coverage_matrix(dem, st, grid)


def test_sight_line_ends_on_the_mesh_not_the_bilinear_height():
    """20 cm bumps on every other DEM node of both axes (0.5 m cells): at the centre of a 1 m
    cell (a DEM quad's centre) the bilinear height is 5 cm, the mesh's 10 cm (its diagonal
    runs through the bump). Every cell near the station is in plain view; a sight line
    ending 2 cm above the bilinear height would end buried."""
    i, j = np.meshgrid(np.arange(121), np.arange(121))
    dem = flat(heights=0.2 * (i % 2) * (j % 2))
    grid = aoi_grid(dem, shapely.box(-4, -4, 4, 4), 1.0)
    np.testing.assert_allclose(grid.ground_z_m, 0.05)
    m = coverage_matrix(dem, np.array([[0.1, 0.2, 1.5]]), grid,
                        CoverageSettings(min_density_per_m2=0.0))
    near = np.hypot(*(grid.centre_xy_m - [0.1, 0.2]).T) < 4.0
    assert np.all(np.isin(np.flatnonzero(near), m.cell))
