"""Coverage raster of chosen stations, its GeoTIFF, and the uncovered summary."""

import numpy as np
import pytest
import rasterio
import shapely
from rasterio.crs import CRS

from markerplan.output_folder import output_folder
from planner.coverage.grid import aoi_grid
from planner.coverage.raster import (
    COVERAGE_BANDS,
    COVERAGE_FILE,
    REASONS,
    coverage_raster,
    uncovered_summary,
    write_coverage_raster,
)
from planner.coverage.sight import CoverageSettings, coverage_matrix
from visibility.dem import DEM

UTM = CRS.from_epsg(32633).to_wkt()


def site(crs=None, heights=None):
    return DEM(np.zeros((81, 81)) if heights is None else heights, (500_000.0, 4_000_000.0),
               0.5, crs=crs)


def test_raster_counts_and_density():
    dem = site()
    grid = aoi_grid(dem, shapely.box(500_005, 4_000_005, 500_035, 4_000_035), 1.0)
    st = np.array([[500_010.0, 4_000_020.0, 1.0], [500_018.0, 4_000_020.0, 1.0],
                   [500_030.0, 4_000_030.0, 1.0]])
    m = coverage_matrix(dem, st, grid)
    r = coverage_raster(m, grid, chosen=[0, 1])
    assert np.isnan(r.count[~grid.inside]).all() and np.isnan(r.density_per_m2[~grid.inside]).all()
    count = r.count.flat[grid.cell_index]
    dens = r.density_per_m2.flat[grid.cell_index]
    # a cell 4 m from both chosen stations (on flat ground both cover it; the third is 14 m off)
    k = int(np.argmin(np.hypot(*(grid.centre_xy_m - [500_014.0, 4_000_020.5]).T)))
    assert count[k] == 2
    d = [np.hypot(np.linalg.norm(grid.centre_xy_m[k] - s[:2]), 1.0) for s in st[:2]]
    best = max(m.density_per_m2[(m.cell == k) & (m.station == j)][0] for j in (0, 1))
    assert dens[k] == pytest.approx(best, rel=1e-6) and d[0] != d[1]
    assert np.all((count == 0) == (dens == 0))
    far = np.hypot(*(grid.centre_xy_m - [500_010.0, 4_000_020.0]).T) > 12
    far &= np.hypot(*(grid.centre_xy_m - [500_018.0, 4_000_020.0]).T) > 12
    assert np.all(count[far] == 0)
    assert coverage_raster(m, grid).count.flat[grid.cell_index].sum() == len(m)


def test_geotiff_round_trip(tmp_path):
    dem = site(crs=UTM)
    grid = aoi_grid(dem, shapely.Polygon([(500_002, 4_000_002), (500_038, 4_000_010),
                                          (500_020, 4_000_037)]), 1.5)
    st = np.array([[500_015.0, 4_000_015.0, 1.0], [500_025.0, 4_000_020.0, 1.0]])
    r = coverage_raster(coverage_matrix(dem, st, grid), grid)
    with output_folder(tmp_path / "out", False, "test") as stage:
        path = write_coverage_raster(r, stage)
        assert path.name == COVERAGE_FILE
    with rasterio.open(tmp_path / "out" / COVERAGE_FILE) as src:
        assert src.count == 2 and src.dtypes == ("float32", "float32")
        assert CRS.from_wkt(src.crs.to_wkt()) == CRS.from_epsg(32633)
        assert tuple(src.transform)[:6] == pytest.approx(
            (grid.transform[0], 0, grid.transform[2], 0, grid.transform[4], grid.transform[5]))
        assert src.descriptions == COVERAGE_BANDS
        assert np.isnan(src.nodata)
        np.testing.assert_array_equal(src.read(1), r.count)
        np.testing.assert_array_equal(src.read(2), r.density_per_m2)
        # the raster's cell (row, col) centre is the grid's cell centre
        k = grid.cell_index[7]
        row, col = divmod(int(k), grid.shape[1])
        assert src.xy(row, col) == pytest.approx(tuple(grid.centre_xy_m[7]))
    # the same inputs give the same bytes
    with output_folder(tmp_path / "again", False, "test") as stage:
        write_coverage_raster(r, stage)
    assert ((tmp_path / "out" / COVERAGE_FILE).read_bytes()
            == (tmp_path / "again" / COVERAGE_FILE).read_bytes())


def test_uncovered_summary_reasons():
    """One station at (20, 20) m on a 40 m site with a 2 m wall 4 m east of it: cells beyond
    15 m are out of range, cells 11.5..15 m away on flat ground exceed the incidence limit,
    cells behind the wall within 11 m are occluded."""
    x = 500_000.0 + 0.5 * np.arange(81)
    h = np.zeros((81, 81))
    h[:, np.abs(x - 500_024.0) < 0.3] = 2.0
    dem = site(heights=h)
    grid = aoi_grid(dem, shapely.box(500_001, 4_000_015, 500_039, 4_000_025), 1.0)
    st = np.array([[500_020.0, 4_000_020.0, 1.0]])
    s = CoverageSettings(max_range_m=15.0)
    m = coverage_matrix(dem, st, grid, s)
    u = uncovered_summary(m, grid, st, s)
    assert len(u) == len(grid) - len(m)
    cx = grid.centre_xy_m[u.cell, 0]
    r = np.hypot(*(grid.centre_xy_m[u.cell] - st[0, :2]).T)
    assert np.all(u.reason[np.hypot(r, 1.0) > 15.0] == 0)
    assert np.all(u.reason[(r < 11.0) & (cx > 500_024.5)] == REASONS.index("occluded"))
    assert np.all(u.reason[(r > 11.5) & (np.hypot(r, 1.0) < 15) & (cx < 500_020)] == 1)
    assert "\n" not in u.text
    assert "86 out of range (at least 15.0 m across from every candidate station" in u.text
    assert "`cover_max_range_m` 15 m" in u.text and "`cover_max_incidence_deg` 85" in u.text
    assert "occluded (the terrain, or nodata on the way, hides it" in u.text
    # cell edges: the AOI's cells run from 500001.25 - 0.5 to 500038.25 + 0.5 m
    assert (f"{len(u)} AOI cells ({len(u):g} m^2) in [500000.8, 500038.8] x [4000015.2, "
            "4000025.2] m") in u.text


def test_uncovered_summary_min_stations_and_all_covered():
    dem = site()
    grid = aoi_grid(dem, shapely.box(500_018, 4_000_018, 500_022, 4_000_022), 1.0)
    st = np.array([[500_020.0, 4_000_020.0, 1.0]])
    m = coverage_matrix(dem, st, grid)
    assert uncovered_summary(m, grid, st, CoverageSettings()).text == ""
    two = uncovered_summary(m, grid, st, CoverageSettings(min_stations=2))
    assert len(two) == len(grid) and "cannot be covered by 2 candidate stations: " in two.text
    assert np.all(two.reason == 0)
