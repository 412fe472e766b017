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
    # two patches, west (no wall) and east (the wall): their cells, reasons and bounding boxes
    assert u.text.startswith(f"{len(u)} AOI cells ({len(u):g} m^2) in 2 separate patches ")
    assert len(u.patches) == 2 and u.patches[0].n_cells >= u.patches[1].n_cells
    west = u.patch[np.argmin(cx)]
    assert np.all((u.patch == west) == (cx < 500_020))
    for k, p in enumerate(u.patches):
        np.testing.assert_array_equal(p.reason_count,
                                      np.bincount(u.reason[u.patch == k], minlength=4))
        xy = grid.centre_xy_m[u.cell[u.patch == k]]
        assert p.bounds_m == pytest.approx((*(xy.min(axis=0) - 0.5), *(xy.max(axis=0) + 0.5)))
    assert u.patches[west].reason_count[REASONS.index("occluded")] == 0
    # the AOI's cells run from 500001.25 - 0.5 to 500038.25 + 0.5 m, y 4000015.75 +- 5 m
    assert u.patches[west].bounds_m[:2] == pytest.approx((500_000.75, 4_000_015.25))
    assert u.patches[1 - west].bounds_m[1:] == pytest.approx((4_000_015.25, 500_038.75,
                                                              4_000_025.25))


def test_uncovered_summary_min_stations_and_all_covered():
    dem = site()
    grid = aoi_grid(dem, shapely.box(500_018, 4_000_018, 500_022, 4_000_022), 1.0)
    st = np.array([[500_020.0, 4_000_020.0, 1.0]])
    m = coverage_matrix(dem, st, grid)
    assert uncovered_summary(m, grid, st, CoverageSettings()).text == ""
    two = uncovered_summary(m, grid, st, CoverageSettings(min_stations=2))
    assert len(two) == len(grid) and "cannot be covered by 2 candidate stations: " in two.text
    assert np.all(two.reason == 0)


#: A 1.5 m AOI grid on :func:`site`: cell column i spans x from ``X0 + 1.5 i``, row j spans y
#: down from ``Y0 - 1.5 j`` (row 0 north).
X0, Y0, CELL = 499_999.75, 4_000_040.25, 1.5


def cells(c0, c1, r0, r1):
    """The polygon of grid columns c0..c1-1 and rows r0..r1-1 (edges on cell edges)."""
    return shapely.box(X0 + CELL * c0, Y0 - CELL * r1, X0 + CELL * c1, Y0 - CELL * r0)


def nobody_covers(*parts):
    """The uncovered summary of an AOI made of ``parts``, every cell 10 m or more out of reach
    of the only station (near the site's south-west corner, range 2 m)."""
    grid = aoi_grid(site(), shapely.union_all(parts), CELL)
    # the window is cut from the lattice of X0, Y0
    assert ((grid.transform[2] - X0) / CELL) % 1 == 0 and ((Y0 - grid.transform[5]) / CELL) % 1 == 0
    st = np.array([[500_000.5, 4_000_000.5, 1.0]])
    s = CoverageSettings(max_range_m=2.0)
    u = uncovered_summary(coverage_matrix(site(), st, grid, s), grid, st, s)
    assert len(u) == len(grid) and np.all(u.reason == 0)
    return grid, u


def box_text(b):
    return f"in [{b[0]:.1f}, {b[2]:.1f}] x [{b[1]:.1f}, {b[3]:.1f}] m"


def test_separate_patches_are_named_largest_first():
    small, large = cells(2, 4, 1, 3), cells(8, 12, 6, 9)  # 4 cells to the north, 12 south
    grid, u = nobody_covers(small, large)
    assert [p.n_cells for p in u.patches] == [12, 4]
    assert [p.area_m2 for p in u.patches] == [12 * CELL ** 2, 4 * CELL ** 2] == [27.0, 9.0]
    assert u.patches[0].bounds_m == pytest.approx(large.bounds)
    assert u.patches[1].bounds_m == pytest.approx(small.bounds)
    in_large = shapely.contains_xy(large, *grid.centre_xy_m[u.cell].T)
    np.testing.assert_array_equal(u.patch, np.where(in_large, 0, 1))
    assert u.text.startswith("16 AOI cells (36 m^2) in 2 separate patches cannot be covered by "
                             f"any candidate station: patch 1: 12 cells (27 m^2) "
                             f"{box_text(large.bounds)}, 12 out of range; patch 2: 4 cells "
                             f"(9 m^2) {box_text(small.bounds)}, 4 out of range; over all "
                             "patches: 16 out of range (at least ")
    assert "\n" not in u.text and "more patch" not in u.text


def test_cells_touching_at_a_corner_are_one_patch():
    a = cells(2, 4, 2, 4)
    _, u = nobody_covers(a, cells(4, 6, 4, 6))
    assert len(u.patches) == 1 and np.all(u.patch == 0)
    x0, y0, x1, y1 = u.patches[0].bounds_m
    assert (x0, y1, x1, y0) == pytest.approx((*a.bounds[::3], X0 + 6 * CELL, Y0 - 6 * CELL))
    # as one patch the text reads as before: where, centroid, why
    assert u.text.startswith(f"8 AOI cells (18 m^2) {box_text(u.patches[0].bounds_m)} "
                             f"(centroid ({X0 + 4 * CELL:.1f}, {Y0 - 4 * CELL:.1f}) m) cannot "
                             "be covered by any candidate station: 8 out of range (at least ")
    # a cell further apart: two patches
    _, apart = nobody_covers(a, cells(5, 7, 5, 7))
    assert len(apart.patches) == 2 and "in 2 separate patches" in apart.text


def test_more_than_three_patches_name_the_largest_and_sum_the_rest():
    # one-row strips two rows apart, not in size order: 2, 6, 1, 5 and 4 cells
    sizes = [2, 6, 1, 5, 4]
    _, u = nobody_covers(*(cells(3, 3 + n, 2 * k + 1, 2 * k + 2) for k, n in enumerate(sizes)))
    assert [p.n_cells for p in u.patches] == [6, 5, 4, 2, 1]
    np.testing.assert_array_equal(np.bincount(u.patch), [6, 5, 4, 2, 1])
    for k, n in enumerate(sizes):
        rank = sorted(sizes, reverse=True).index(n)
        assert u.patches[rank].bounds_m == pytest.approx(cells(3, 3 + n, 2 * k + 1,
                                                               2 * k + 2).bounds)
    assert "patch 3: 4 cells (9 m^2)" in u.text and "patch 4" not in u.text
    assert "; and 2 more patches (6.75 m^2); over all patches: 18 out of range" in u.text
    assert u.text.startswith("18 AOI cells (40.5 m^2) in 5 separate patches")
    assert "\n" not in u.text and len(u.text) < 700
