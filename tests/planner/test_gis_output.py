"""planner.outputs.gis and planner.outputs.stand_map: CRS naming, WGS84 GeoJSON, GeoPackage and
GeoTIFF writing in one process, and the stand map against the planner's own station checks."""

from dataclasses import replace

import numpy as np
import pytest
import shapely
from rasterio.crs import CRS

from planner.outputs.gis import (
    crs_name,
    geojson_crs_members,
    geojson_positions,
    is_earth_crs,
    write_gpkg_layers,
    write_stand_map,
)
from planner.outputs.stand_map import StandMap, cells_per_stand_cell, stand_grid, stand_map

UTM = CRS.from_epsg(32633).to_wkt()
MOON = CRS.from_user_input("IAU_2015:30100").to_wkt()
MOON_POLAR = CRS.from_user_input("IAU_2015:30135").to_wkt()


def test_crs_names_and_which_are_on_earth():
    assert crs_name(UTM) == "WGS 84 / UTM zone 33N (EPSG:32633)"
    assert crs_name(MOON_POLAR).startswith("Moon (2015) - Sphere / Ocentric / South Polar")
    assert crs_name(None) is None
    assert [is_earth_crs(c) for c in (UTM, CRS.from_epsg(3857).to_wkt(), MOON, MOON_POLAR,
                                      None)] == [True, True, False, False, False]


def test_geojson_positions_round_trip_and_stay_put_off_earth():
    from rasterio.warp import transform

    xyz = np.array([[500_000.0, 4_649_776.2, 12.5], [512_345.678, 4_700_001.0, -3.0]])
    pos = np.array(geojson_positions(UTM, xyz))
    np.testing.assert_allclose(pos[0, :2], [15.0, 42.0], atol=1e-6)
    x, y = transform("EPSG:4326", UTM, pos[:, 0].tolist(), pos[:, 1].tolist())
    np.testing.assert_allclose(np.column_stack([x, y]), xyz[:, :2], rtol=0, atol=1e-3)
    np.testing.assert_array_equal(pos[:, 2], xyz[:, 2])
    for crs in (MOON_POLAR, None):
        assert geojson_positions(crs, xyz) == xyz.tolist()
    members = geojson_crs_members(MOON_POLAR, "the note")
    assert members["crs"]["properties"]["name"] == crs_name(MOON_POLAR)
    assert members["coordinate_frame"] == "the note"
    assert "crs" not in geojson_crs_members(None, "n") and "crs" not in \
        geojson_crs_members(UTM, "n")


def test_geotiff_and_geopackage_in_one_process(tmp_path):
    """rasterio and pyogrio each bundle a GDAL: both must write and read in one process."""
    import pyogrio
    import rasterio
    from pyogrio.raw import read

    usable = np.array([[1, 2, np.nan], [0, 3, 4]], np.float32)
    stand = StandMap(usable=usable, error_m=usable / 100, transform=(2.0, 0, 500_000.0, 0,
                                                                     -2.0, 4_649_000.0),
                     cell_m=2.0, crs=UTM, elapsed_s=0.0)
    write_stand_map(stand, tmp_path)
    layers = {"pts": ("Point Z", shapely.points([[500_001.0, 4_648_999.0, 7.0]]),
                      {"id": np.array(["A"], object), "n": np.array([3], np.int32)}),
              "area": ("Polygon", shapely.polygons([[[0, 0], [1, 0], [1, 1], [0, 0]]]),
                       {"name": np.array(["b"], object)})}
    for name in ("a.gpkg", "b.gpkg"):
        write_gpkg_layers(tmp_path / name, layers, UTM)
    write_gpkg_layers(tmp_path / "local.gpkg", layers, None)
    assert (tmp_path / "a.gpkg").read_bytes() == (tmp_path / "b.gpkg").read_bytes()
    with rasterio.open(tmp_path / "usable_markers.tif") as src:
        np.testing.assert_array_equal(src.read(1), usable)
        assert src.crs == CRS.from_wkt(UTM) and np.isnan(src.nodata)
        assert tuple(src.transform)[:6] == stand.transform
    with rasterio.open(tmp_path / "station_error.tif") as src:
        np.testing.assert_array_equal(src.read(1), usable / 100)
    meta, _, geom, fields = read(tmp_path / "a.gpkg", layer="pts")
    assert CRS.from_user_input(meta["crs"]) == CRS.from_wkt(UTM)
    assert shapely.get_coordinates(shapely.from_wkb(geom), include_z=True).tolist() == \
        [[500_001.0, 4_648_999.0, 7.0]]
    assert fields[1].tolist() == [3]
    assert pyogrio.read_info(tmp_path / "local.gpkg", layer="area")["crs"] is None


def test_stand_grid_is_aligned_with_the_dem():
    from visibility.dem import DEM

    dem = DEM(np.zeros((7, 5)), (10.0, 20.0), 0.5)
    assert cells_per_stand_cell(dem, max_cells=4) == 4
    assert cells_per_stand_cell(dem, max_cells=35) == 1
    xy, t = stand_grid(dem, 2)
    assert xy.shape == (4, 3, 2)
    assert t == (1.0, 0.0, 9.75, 0.0, -1.0, 23.25)
    np.testing.assert_allclose(xy[0, 0], [10.25, 22.75])  # corner of 4 DEM cells
    np.testing.assert_allclose(xy[-1, -1], [12.25, 19.75])


@pytest.fixture(scope="module")
def holed_plan():
    """The default site's plan on its DEM with a nodata hole west of the stations."""
    from error_model import default_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.run import make_plan
    from visibility.dem import DEM

    inputs = load_inputs("default")
    dem = inputs.dem
    gx, gy = dem.grid_xy()
    valid = ~((gx[None, :] > -26) & (gx[None, :] < -20) & (gy[:, None] > -3) & (gy[:, None] < 3))
    holed = DEM(dem.heights_m, dem.origin_m, dem.cell_size_m, dem.crs, valid=valid)
    model = default_model()
    return make_plan(replace(inputs, dem=holed), PlanConfig(), model, progress=False), model


def test_stand_map_agrees_with_the_planners_station_checks(holed_plan):
    from planner.accuracy.checks import evaluate_layout
    from planner.problem.sight import sight_problem

    outcome, model = holed_plan
    cfg, dem = outcome.config, outcome.inputs.dem
    stand = stand_map(outcome, model, cell_m=1.0)
    xy, t = stand_grid(dem, 10)
    assert stand.transform == t and stand.usable.shape == xy.shape[:2]
    on = dem.valid_at(xy.reshape(-1, 2)).reshape(xy.shape[:2])
    np.testing.assert_array_equal(np.isfinite(stand.usable), on)
    hole = (np.abs(xy[..., 0] + 23) < 2) & (np.abs(xy[..., 1]) < 2)
    assert hole.any() and not on[hole].any()
    # a sample of cells, judged as plan stations by the planner's own checks
    rows, cols = np.nonzero(on)
    pick = np.random.default_rng(3).choice(rows.size, 40, replace=False)
    pick = np.r_[pick, np.flatnonzero(stand.usable[rows, cols] >= 3)[:20]]
    pxy = xy[rows[pick], cols[pick]]
    pxyz = np.column_stack([pxy, dem.height_at(pxy) + outcome.inputs.lidar_height_m])
    sel = np.flatnonzero(outcome.result.selected)
    prob = outcome.problem
    inputs = replace(outcome.inputs, station_ids=[str(k) for k in range(len(pick))],
                     station_xyz=pxyz, station_heading_rad=np.zeros(len(pick)))
    check = evaluate_layout(sight_problem(inputs, [prob.site_ids[j] for j in sel],
                                          prob.site_xyz[sel], cfg, model,
                                          progress=False).problem,
                            np.ones(sel.size, bool), cfg)
    np.testing.assert_array_equal(stand.usable[rows[pick], cols[pick]], check.count)
    registers = (check.count >= cfg.min_markers) & (check.sectors >= cfg.min_sectors) \
        & np.isfinite(check.error_m)
    assert registers.sum() >= 10
    got = stand.error_m[rows[pick], cols[pick]]
    np.testing.assert_allclose(got[registers], check.error_m[registers], rtol=1e-6)
    assert np.isnan(got[~registers]).all()
