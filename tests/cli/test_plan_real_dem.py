"""``markerplan plan`` on a DEM as a survey delivers it: UTM coordinates, nodata around an
irregular measured area (:mod:`tests.planner.utm_dem`); ``reduce`` and ``verify`` of that plan
from another folder; one-line errors for DEMs and stations the planner cannot use."""

import json

import numpy as np
import pytest
import shapely

from planner.problem.candidates import edge_margin_m, valid_area
from planner.problem.sight import crosses_nodata
from tests.cli.bad_input import Case, check_refused
from tests.cli.invoke import run_cli
from tests.planner.utm_dem import ORIGIN, utm_dem, utm_mask, write_stations
from visibility.dem import DEM, read_dem, to_dem_xy, write_dem


@pytest.fixture(scope="module")
def utm_plan(tmp_path_factory):
    """``plan --dem dem.tif --stations st.csv`` run in its own folder: (folder, plan.json)."""
    import contextlib
    import io
    import os

    from planner.cli import main

    cwd = tmp_path_factory.mktemp("utm-plan")
    write_dem(cwd / "dem.tif", utm_dem())
    write_stations(cwd / "st.csv")
    old = os.getcwd()
    os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            main(["plan", "--dem", "dem.tif", "--stations", "st.csv", "--json", "--out", "plan"])
    finally:
        os.chdir(old)
    return cwd, json.loads((cwd / "plan" / "plan.json").read_text())


def test_markers_stand_on_measured_terrain_inside_the_shrunk_outline(utm_plan):
    _, doc = utm_plan
    dem = read_dem(utm_plan[0] / "dem.tif")
    assert np.array_equal(dem.valid_mask(), utm_mask())  # the file kept its nodata
    xy = np.array([[m["x_m"], m["y_m"]] for m in doc["markers"]])
    assert len(xy) >= 3 and doc["meets_requirement"]
    # each marker's cell and its neighbours hold data, checked against the mask itself
    i = np.rint((xy[:, 0] - ORIGIN[0]) / 0.5).astype(int)
    j = np.rint((xy[:, 1] - ORIGIN[1]) / 0.5).astype(int)
    mask = utm_mask()
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            assert mask[j + dj, i + di].all()
    outline = valid_area(dem, edge_margin_m(dem, 0.1))
    assert shapely.contains_xy(outline, xy[:, 0], xy[:, 1]).all()
    boundary = shapely.Polygon(doc["site"]["boundary_xy_m"])
    assert boundary.area > 2000 and boundary.within(shapely.box(*ORIGIN, *(np.add(ORIGIN, 80))))
    assert doc["candidates"]["dropped"]["on nodata"] > 0


def test_no_used_sight_line_crosses_nodata(utm_plan):
    _, doc = utm_plan
    dem = utm_dem()
    markers = {m["id"]: (m["x_m"], m["y_m"]) for m in doc["markers"]}
    starts, ends = [], []
    for s in doc["stations"]:
        for m in s["markers"]:
            starts.append((s["x_m"], s["y_m"]))
            ends.append(markers[m])
    assert len(starts) >= 3 * len(doc["stations"])
    assert not crosses_nodata(dem, np.array(starts), np.array(ends)).any()
    # the gap stands between S4 and the others: some station-marker lines would cross it
    every = [(s["x_m"], s["y_m"], *markers[m]) for s in doc["stations"] for m in markers]
    assert crosses_nodata(dem, np.array(every)[:, :2], np.array(every)[:, 2:]).any()


def test_gis_layers_read_back_in_the_dems_crs_with_markers_on_data(utm_plan):
    """The issue's real-DEM flow: plan.gpkg and the stand-map GeoTIFFs, read back with
    pyogrio and rasterio, keep the DEM's CRS; every marker of the GeoPackage stands on
    measured terrain, and the stand map is nodata wherever the DEM is."""
    import rasterio
    from pyogrio.raw import read
    from rasterio.crs import CRS

    cwd, doc = utm_plan
    dem = read_dem(cwd / "dem.tif")
    utm = CRS.from_epsg(32633)
    meta, _, wkb, fields = read(cwd / "plan" / "plan.gpkg", layer="markers")
    assert CRS.from_user_input(meta["crs"]) == utm
    xy = shapely.get_coordinates(shapely.from_wkb(wkb))
    ids = list(fields[list(meta["fields"]).index("id")])
    assert sorted(ids) == sorted(m["id"] for m in doc["markers"])
    assert dem.valid_at(xy).all()
    for name in ("usable_markers.tif", "station_error.tif"):
        with rasterio.open(cwd / "plan" / name) as src:
            assert src.crs == utm
            band = src.read(1)
            rows, cols = np.indices(band.shape)
            cx, cy = rasterio.transform.xy(src.transform, rows.ravel(), cols.ravel())
        on_data = dem.valid_at(np.column_stack([cx, cy])).reshape(band.shape)
        assert np.isnan(band[~on_data]).all() and (~on_data).any()
        if name == "usable_markers.tif":
            assert np.isfinite(band[on_data]).all() and band[on_data].max() >= 3


def test_site_named_after_the_dem_with_absolute_paths(utm_plan):
    cwd, doc = utm_plan
    assert doc["site"]["name"] == "dem" and doc["site"]["seed"] is None
    assert "site `dem`" in (cwd / "plan" / "report.md").read_text()
    inputs = doc["provenance"]["inputs"]
    assert inputs["dem"] == str((cwd / "dem.tif").resolve())
    assert inputs["stations"] == str((cwd / "st.csv").resolve())


def test_verify_and_reduce_read_the_plan_from_another_folder(utm_plan, tmp_path, capsys,
                                                            monkeypatch):
    from planner.outputs.plan_file import load_plan

    cwd, doc = utm_plan
    monkeypatch.chdir(tmp_path)
    plan = load_plan(cwd / "plan" / "plan.json")  # what verify reads first
    assert np.array_equal(plan.dem.valid_mask(), utm_mask())
    assert plan.dem_path == str(cwd / "dem.tif")
    code, out, err = run_cli(capsys, ["reduce", str(cwd / "plan" / "plan.json"), "--json",
                                      "--out", "red"])
    assert code == 0, err
    summary = json.loads(out)
    assert summary["site"] == "dem" and summary["n_markers"] == doc["n_markers"]


def test_plan_a_dem_in_degrees_with_reproject(tmp_path, capsys, monkeypatch):
    """A DEM and stations in longitude/latitude: ``--reproject`` plans in a local metric CRS;
    the plan records it, and verify's reader reads the DEM the same way."""
    from planner.outputs.plan_file import load_plan

    valid = np.ones((120, 150), bool)
    valid[:, :12] = False  # nodata along the west edge
    x = np.arange(150) * 0.4
    write_dem(tmp_path / "lonlat.tif", DEM(np.tile(0.1 * np.sin(x / 4.0), (120, 1)),
                                           (14.0, 37.0), 5e-6, "EPSG:4326", valid=valid))
    (tmp_path / "st.csv").write_text("id,x_m,y_m\nS1,14.00030,37.00025\n"
                                     "S2,14.00055,37.00035\n")
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, ["plan", "--dem", "lonlat.tif", "--reproject",
                                      "--stations", "st.csv", "--json", "--out", "p"])
    assert code == 0, err
    doc = json.loads((tmp_path / "p" / "plan.json").read_text())
    assert doc["site"]["name"] == "lonlat" and doc["provenance"]["inputs"]["reproject"] is True
    plan = load_plan(tmp_path / "p" / "plan.json")
    assert plan.dem.source_crs is not None
    dem = read_dem(tmp_path / "lonlat.tif", reproject=True)
    assert plan.dem.shape == dem.shape
    xy = plan.marker_xyz_m[:, :2]
    assert dem.valid_at(xy).all() and len(xy) >= 3
    stations = np.array([s.position_m[:2] for s in plan.stations])
    np.testing.assert_allclose(stations, to_dem_xy(dem, [[14.00030, 37.00025],
                                                         [14.00055, 37.00035]]), atol=1e-6)


def _write(name, dem):
    def setup(cwd, inputs):
        write_dem(cwd / name, dem)
    return setup


def _all_nodata(cwd, inputs):
    import rasterio
    from rasterio.transform import Affine

    with rasterio.open(cwd / "bad.tif", "w", driver="GTiff", height=6, width=8, count=1,
                       dtype="float64", crs="EPSG:32633", nodata=-9999.0,
                       transform=Affine(0.5, 0.0, ORIGIN[0], 0.0, -0.5, ORIGIN[1])) as dst:
        dst.write(np.full((1, 6, 8), -9999.0))


def _geographic(cwd, inputs):
    write_dem(cwd / "bad.tif", DEM(np.zeros((20, 20)), (14.0, 37.0), 1e-4, "EPSG:4326"))


PLAN = ["plan", "--dem", "bad.tif", "--stations", "{inputs}/st.csv", "--out", "out"]
CASES = [
    Case("station-on-nodata", PLAN, "station S4 at (500067.00, 4100040.00) m stands on DEM "
         "nodata", setup=_write("bad.tif", DEM(utm_dem().heights_m, ORIGIN, 0.5, utm_dem().crs,
                                               valid=utm_mask() & (np.arange(161) < 120)))),
    Case("all-nodata", PLAN, "every cell is nodata", setup=_all_nodata),
    # the stations' window misses the DEM: the station is named, not the window
    Case("station-off-the-dem", ["plan", "--dem", "dem.tif", "--stations", "far.csv", "--out",
                                 "out"], "station F1 at (400000.00, 4100040.00) m lies outside",
         files={"far.csv": "id,x_m,y_m\nF1,400000,4100040\n"},
         setup=_write("dem.tif", utm_dem())),
    Case("geographic-without-reproject", PLAN, "--reproject", setup=_geographic),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path):
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    write_stations(inputs / "st.csv")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    check_refused(case, capsys, monkeypatch, cwd, inputs)
