"""Planning on a DEM with nodata: candidate sites, sight lines, stations and the default
boundary (:mod:`planner.problem.candidates`, :mod:`planner.problem.sight`, :mod:`planner.run`)."""

from types import SimpleNamespace

import numpy as np
import pytest
import shapely
import shapely.affinity

from error_model import default_model
from markerplan.errors import DataError
from planner.config import PlanConfig
from planner.problem.candidates import (
    candidate_sites,
    edge_margin_m,
    on_terrain,
    valid_area,
)
from planner.problem.inputs import default_boundary, read_stations
from planner.problem.sight import crosses_nodata, sight_problem
from planner.problem.usability import OCCLUDED, USABLE
from tests.planner.utm_dem import ORIGIN, local_grid, utm_dem, utm_mask
from visibility.dem import DEM


def test_valid_area_keeps_the_margin_from_nodata_and_the_edge():
    dem = utm_dem()
    margin = edge_margin_m(dem, 0.1)
    area = valid_area(dem, margin)
    # every cell centre within the margin of a nodata cell (or off the grid) lies outside
    x, y = local_grid()
    valid = utm_mask()
    nodata_xy = np.column_stack([x[~valid], y[~valid]]) + ORIGIN
    inside = shapely.contains_xy(area, x.ravel() + ORIGIN[0], y.ravel() + ORIGIN[1])
    pts = np.column_stack([x.ravel(), y.ravel()])[inside] + ORIGIN
    from scipy.spatial import cKDTree

    # nodata footprints reach half a cell towards the point
    d, _ = cKDTree(nodata_xy).query(pts)
    assert d.min() >= margin + 0.5 * dem.cell_size_m - 1e-9
    # ... and it is not much smaller than that: cells 2 margins in are kept
    deep = cKDTree(nodata_xy).query(np.column_stack([x.ravel(), y.ravel()]) + ORIGIN)[0]
    deep_inside = deep.reshape(x.shape) >= margin + 3 * dem.cell_size_m
    assert inside.reshape(x.shape)[deep_inside & valid].all()


def test_no_candidate_site_on_nodata_or_its_edge():
    dem = utm_dem()
    cfg = PlanConfig(grid_spacing_m=1.0)
    c = candidate_sites(dem, cfg, marker_radius_m=0.1)
    xy = c.centre_m[:, :2]
    assert on_terrain(dem, xy).all()
    assert shapely.contains_xy(valid_area(dem, edge_margin_m(dem, 0.1)), xy[:, 0],
                               xy[:, 1]).all()
    # the grid covered the whole rectangle: most nodata points went as "on nodata"
    n_grid = 80 * 80
    assert c.dropped["on nodata"] > 0.2 * n_grid and c.dropped["near nodata"] > 0
    assert sum(c.dropped.values()) + len(c) == n_grid
    # the same heights without a mask: sites on (formerly) nodata come back
    whole = candidate_sites(DEM(dem.heights_m, dem.origin_m, dem.cell_size_m), cfg)
    assert len(whole) > len(c) + c.dropped["on nodata"] // 2
    assert "on nodata" not in whole.dropped


def test_on_terrain_checks_the_slope_stencil():
    valid = np.ones((21, 21), bool)
    valid[:, 15:] = False  # nodata from x = 7.25 m (cell footprints) on
    dem = DEM(np.zeros((21, 21)), (0.0, 0.0), 0.5, valid=valid)
    # (6.9, 5): its own cells are valid, its +x stencil point (7.15) reaches column 15
    assert dem.valid_at(np.array([[6.9, 5.0]])).all()
    assert on_terrain(dem, np.array([[6.9, 5.0], [6.0, 5.0]])).tolist() == [False, True]


def test_crosses_nodata_ground_truth():
    valid = np.ones((41, 61), bool)
    valid[:, 28:33] = False  # x from 14 to 16 m at 0.5 m cells
    dem = DEM(np.zeros((41, 61)), (0.0, 0.0), 0.5, valid=valid)
    start = np.array([[5.0, 10.0], [5.0, 10.0], [5.0, 10.0], [20.0, 0.0], [29.0, 19.0]])
    end = np.array([[25.0, 10.0], [13.0, 19.0], [5.0, 10.0], [20.0, 20.0], [17.0, 1.0]])
    assert crosses_nodata(dem, start, end).tolist() == [True, False, False, False, False]
    # a diagonal that just reaches the strip's first cell (x = 14 m)
    assert crosses_nodata(dem, [[0.0, 0.0]], [[14.0, 14.0]]).tolist() == [True]
    assert crosses_nodata(dem, np.zeros((0, 2)), np.zeros((0, 2))).shape == (0,)


def test_sight_line_across_a_nodata_gap_is_not_used():
    """Sites beyond a nodata strip are occluded for the station; the same sites on a DEM
    without the mask are usable (same heights: the mask alone makes the difference)."""
    valid = np.ones((41, 61), bool)
    valid[:, 28:33] = False
    heights = np.zeros((41, 61))
    station = np.array([[5.0, 10.0, 1.0]])
    sites = np.array([[x, y, 0.1] for x in (9.0, 11.0, 22.0, 24.0) for y in (6.0, 10.0, 14.0)])
    beyond = sites[:, 0] > 16
    cfg = PlanConfig()

    def reasons(mask):
        inputs = SimpleNamespace(dem=DEM(heights, (0.0, 0.0), 0.5, valid=mask),
                                 station_ids=["S1"], station_xyz=station, marker_radius_m=0.1)
        ids = [f"C{k}" for k in range(len(sites))]
        p = sight_problem(inputs, ids, sites, cfg, default_model(), progress=False).problem
        out = np.full(len(sites), -1)
        out[p.pair_site] = p.pair_reason
        return out

    assert (reasons(None) == USABLE).all()
    masked = reasons(valid)
    assert (masked[beyond] == OCCLUDED).all() and (masked[~beyond] == USABLE).all()


def test_a_station_on_nodata_is_a_one_line_error(tmp_path):
    dem = utm_dem()
    path = tmp_path / "st.csv"
    path.write_text(f"id,x_m,y_m\nS1,{ORIGIN[0] + 40:.1f},{ORIGIN[1] + 40:.1f}\n"
                    f"S9,{ORIGIN[0] + 59:.1f},{ORIGIN[1] + 30:.1f}\n")
    with pytest.raises(DataError, match="S9 at .*nodata") as exc:
        read_stations(path, dem, 1.0)
    assert "\n" not in str(exc.value) and "move it" in str(exc.value)
    assert "500059.00" in str(exc.value)


def test_default_boundary_is_the_largest_valid_piece():
    dem = utm_dem()
    corners = default_boundary(dem, 0.1)
    poly = shapely.Polygon(corners)
    # ground truth built independently: the ellipse of valid cell centres minus the notch,
    # shrunk by the margin and half a cell (the gap is a hole, not part of the outline)
    ellipse = shapely.affinity.scale(shapely.Point(40, 40).buffer(1.0, quad_segs=64), 36, 30)
    truth = ellipse.difference(shapely.box(36, 52, 44, 80)).buffer(
        -edge_margin_m(dem, 0.1) - 0.5 * dem.cell_size_m)
    truth = shapely.affinity.translate(truth, *ORIGIN)
    assert poly.is_valid and poly.area == pytest.approx(truth.area, rel=0.02)
    assert poly.symmetric_difference(truth).area < 0.04 * truth.area
    # the notch is outside it, the gap (a hole) inside its outline
    assert not poly.contains(shapely.Point(ORIGIN[0] + 40, ORIGIN[1] + 60))
    assert poly.contains(shapely.Point(ORIGIN[0] + 59, ORIGIN[1] + 35))
    assert default_boundary(DEM(np.zeros((5, 5)), (0.0, 0.0), 1.0), 0.1) is None


def test_too_little_measured_terrain_is_a_one_line_error():
    valid = np.zeros((20, 20), bool)
    valid[5:8, 5:15] = True  # 1.5 m wide at 0.5 m cells: nothing is 2 x 1 m wide
    dem = DEM(np.zeros((20, 20)), (0.0, 0.0), 0.5, valid=valid)
    with pytest.raises(DataError, match="nowhere wider") as exc:
        valid_area(dem, edge_margin_m(dem, 0.1))
    assert "\n" not in str(exc.value)


def test_dem_read_only_as_far_as_the_stations_see(tmp_path):
    """A 400 m DEM with two stations in one corner: load_inputs reads the stations' window
    (their box grown by the sight radius and the margin), records it, and the default boundary
    keeps the edge margin from the window's edge."""
    from planner.problem.inputs import WINDOW_MARGIN_M, load_inputs, sight_window
    from visibility.dem import write_dem

    x = np.arange(401.0)
    valid = np.ones((401, 401), bool)
    valid[:, :5] = False  # nodata along the west edge: the DEM has a mask
    write_dem(tmp_path / "big.tif", DEM(0.01 * np.add.outer(x, x), (1000.0, 2000.0), 1.0,
                                        "EPSG:32633", valid=valid))
    (tmp_path / "st.csv").write_text("id,x_m,y_m\nA,1040,2050\nB,1060,2040\n")
    inputs = load_inputs(dem_path=tmp_path / "big.tif", stations_path=tmp_path / "st.csv",
                         sight_radius_m=30.0)
    window = sight_window([[1040, 2050], [1060, 2040]], 30.0)
    assert window == (1040 - 30 - WINDOW_MARGIN_M, 1060 + 30 + WINDOW_MARGIN_M,
                      2040 - 30 - WINDOW_MARGIN_M, 2050 + 30 + WINDOW_MARGIN_M)
    assert inputs.sources["dem_window"] == list(window)
    xmin, xmax, ymin, ymax = inputs.dem.extent()
    pad = 2 + 1  # read_dem's pad of 2 cells, and the cell the window's edge falls in
    assert window[0] - pad <= xmin <= window[0] and window[1] <= xmax <= window[1] + pad
    assert window[2] - pad <= ymin <= window[2] and window[3] <= ymax <= window[3] + pad
    assert inputs.dem.shape[0] * inputs.dem.shape[1] < 0.1 * 401 * 401
    b = np.asarray(inputs.boundary_xy)
    margin = edge_margin_m(inputs.dem, inputs.marker_radius_m)
    assert b[:, 0].min() >= 1005 + margin - 0.5 and b[:, 0].max() <= xmax - margin
    assert b[:, 1].min() >= ymin + margin and b[:, 1].max() <= ymax - margin
    # the same inputs read whole: the window is the only difference
    whole = load_inputs(dem_path=tmp_path / "big.tif", stations_path=tmp_path / "st.csv")
    assert whole.dem.shape == (401, 401) and "dem_window" not in whole.sources
    np.testing.assert_array_equal(inputs.station_xyz, whole.station_xyz)


def test_reproject_maps_every_input_file_into_the_dem(tmp_path):
    """A DEM in degrees (EPSG:4326) with stations, a boundary and an exclusion in degrees:
    --reproject reads it in a local metric CRS and maps each file with to_dem_xy."""
    import json

    from markerplan.errors import InputFileError
    from planner.problem.inputs import load_inputs
    from visibility.dem import read_dem, to_dem_xy, write_dem

    cell = 5e-6  # degrees: about 0.55 m north-south, 0.44 m east-west at 37 N
    h = np.zeros((160, 200))
    write_dem(tmp_path / "geo.tif", DEM(h, (14.0, 37.0), cell, "EPSG:4326"))
    lonlat = np.array([[14.0002, 37.0003], [14.0007, 37.0004]])
    (tmp_path / "st.csv").write_text("id,x_m,y_m\n" + "".join(
        f"S{k},{lon:.7f},{lat:.7f}\n" for k, (lon, lat) in enumerate(lonlat)))
    ring = [[14.0001, 37.0001], [14.0009, 37.0001], [14.0009, 37.0007], [14.0001, 37.0007],
            [14.0001, 37.0001]]
    (tmp_path / "b.geojson").write_text(json.dumps(
        {"type": "Polygon", "coordinates": [ring]}))
    with pytest.raises(InputFileError, match="`reproject`"):
        load_inputs(dem_path=tmp_path / "geo.tif", stations_path=tmp_path / "st.csv")
    inputs = load_inputs(dem_path=tmp_path / "geo.tif", stations_path=tmp_path / "st.csv",
                         boundary_path=tmp_path / "b.geojson", reproject=True,
                         sight_radius_m=30.0)
    dem = read_dem(tmp_path / "geo.tif", reproject=True)
    np.testing.assert_allclose(inputs.station_xyz[:, :2], to_dem_xy(dem, lonlat), atol=1e-6)
    # 0.0005 degrees of longitude apart at 37 N: about 44 m east, 11 m north (metres now)
    d = np.diff(inputs.station_xyz[:, :2], axis=0)[0]
    assert d[0] == pytest.approx(0.0005 * 111_320 * np.cos(np.radians(37)), rel=0.01)
    assert d[1] == pytest.approx(0.0001 * 110_950, rel=0.01)
    np.testing.assert_allclose(inputs.boundary_xy, to_dem_xy(dem, np.array(ring)), atol=1e-6)
    assert inputs.sources["reproject"] is True and "dem_window" not in inputs.sources
