"""``markerplan plan --aoi``: the stations chosen over an area of interest, written like any
plan plus the route (stations.csv in route order, the route layer, coverage.tif), the same
bytes from the same inputs; and the bad inputs of the AOI plan, each refused in one line with
nothing written (:func:`tests.cli.bad_input.check_refused`)."""

import json

import numpy as np
import pandas as pd
import pytest

from tests.cli.bad_input import Case, check_refused
from tests.cli.invoke import run_cli
from tests.cli.test_bad_input_model_dem import _tif

AOI = ('{"type": "Polygon", "coordinates": [[[-6, -6], [6, -6], [6, 6], [-6, 6], '
       '[-6, -6]]]}')
RUN = ["plan", "--aoi", "aoi.geojson", "--route-start", "0,-3", "--chance-epsilon", "none"]


def _plan(capsys, monkeypatch, folder, out="out"):
    folder.mkdir(exist_ok=True)
    (folder / "aoi.geojson").write_text(AOI)
    monkeypatch.chdir(folder)
    code, _, err = run_cli(capsys, RUN + ["--out", out, "--scheduler", "none"])
    assert code == 0, err
    return folder / out


@pytest.fixture(scope="module")
def aoi_plan(tmp_path_factory):
    mp = pytest.MonkeyPatch()
    capsys = _Capture()
    out = _plan(capsys, mp, tmp_path_factory.mktemp("aoi"))
    mp.undo()
    return out


class _Capture:
    """``capsys`` for a module fixture: the CLI's output is not asserted on there."""

    def readouterr(self):
        return "", ""


def test_aoi_plan_writes_the_route_and_coverage(aoi_plan):
    doc = json.loads((aoi_plan / "plan.json").read_text())
    design = doc["design"]
    n = len(doc["stations"])
    assert design["options"]["plan"]["n_stations"] == n
    assert design["joint_program"]["proven_optimal"]
    assert design["route"]["start_xy_m"] == [0.0, -3.0]
    stations = pd.read_csv(aoi_plan / "stations.csv")
    assert stations["route_order"].tolist() == list(range(1, n + 1))
    assert stations["id"].tolist() == [f"S{k}" for k in range(1, n + 1)]
    assert stations["drive_m"].iloc[-1] + design["route"]["legs_m"][-1] == \
        pytest.approx(design["route"]["length_m"], abs=2e-3)


def test_coverage_raster_matches_the_plan(aoi_plan):
    import rasterio

    doc = json.loads((aoi_plan / "plan.json").read_text())
    with rasterio.open(aoi_plan / "coverage.tif") as src:
        count, density = src.read(1), src.read(2)
        assert src.count == 2
    inside = np.isfinite(count)
    assert inside.sum() == doc["design"]["aoi"]["n_cells"]
    covered = (count[inside] >= 1).mean()
    assert covered == pytest.approx(doc["design"]["options"]["plan"]["covered_fraction"])
    assert np.all(density[inside][count[inside] >= 1] >= 100.0)  # the density limit


def test_route_layer_in_the_geopackage(aoi_plan):
    import pyogrio
    import shapely
    from pyogrio.raw import read

    gpkg = aoi_plan / "plan.gpkg"
    layers = {name for name, _ in pyogrio.list_layers(gpkg)}
    assert {"route", "aoi", "candidate_stations", "stations", "markers"} <= layers
    doc = json.loads((aoi_plan / "plan.json").read_text())
    _, _, geom, fields = read(gpkg, layer="route")
    line = shapely.from_wkb(geom)[0]
    # the line's 2D length is the route's (the route counts height change too: a little more)
    assert line.length == pytest.approx(doc["design"]["route"]["length_m"], rel=0.02)
    assert fields[0][0] == pytest.approx(doc["design"]["route"]["length_m"], abs=1e-3)
    start = doc["design"]["route"]["start_xy_m"]
    assert line.coords[0][:2] == pytest.approx(start, abs=0.5)
    assert line.coords[-1][:2] == pytest.approx(start, abs=0.5)


def test_reduce_takes_the_aoi_plan_unchanged(aoi_plan, capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(capsys, ["reduce", str(aoi_plan / "plan.json"), "--out", "r"])
    assert code == 0, err
    doc = json.loads((aoi_plan / "plan.json").read_text())
    per_station = pd.read_csv(tmp_path / "r" / "per_station.csv")
    assert set(per_station["station"]) == {s["id"] for s in doc["stations"]}


@pytest.mark.slow
def test_same_inputs_same_bytes(aoi_plan, capsys, monkeypatch):
    again = _plan(capsys, monkeypatch, aoi_plan.parent, out="again")
    for name in ("plan.json", "stations.csv", "coverage.tif", "plan.gpkg", "report.md",
                 "markers.csv"):
        assert (again / name).read_bytes() == (aoi_plan / name).read_bytes(), name


def _nodata_block() -> np.ndarray:
    """Flat 61 x 61 heights (1 m cells, -30..30 m) with nodata over -5..5 m."""
    h = np.zeros((61, 61))
    h[25:36, 25:36] = np.nan
    return h


def _cases():
    files = {"aoi.geojson": AOI}
    off = ('{"type": "Polygon", "coordinates": [[[20, 20], [45, 20], [45, 45], [20, 45], '
           '[20, 20]]]}')
    return [
        Case("aoi-with-stations", RUN + ["--stations", "{inputs}/stations.csv", "--out", "out"],
             "--aoi chooses the stations", files=files),
        Case("route-start-without-aoi", ["plan", "--route-start", "0,0", "--out", "out"],
             "add --aoi"),
        Case("aoi-off-the-dem", ["plan", "--aoi", "off.geojson", "--out", "out"], "off.geojson",
             files={"off.geojson": off}),
        Case("route-start-in-a-crater", ["plan", "--aoi", "aoi.geojson", "--route-start",
                                         "13.75,10", "--out", "out"],
             "--route-start (13.75, 10.00) m is not on trafficable ground (crater interior)",
             files=files),
        Case("aoi-nobody-can-cover", ["plan", "--aoi", "aoi.geojson", "--keep-out", "ko.geojson",
                                      "--route-start", "-10,-3", "--out", "out"],
             "covers part of the AOI",
             files={"aoi.geojson": ('{"type": "Polygon", "coordinates": [[[-12, -6], [12, -6],'
                                    ' [12, 6], [-12, 6], [-12, -6]]]}'),
                    "ko.geojson": ('{"type": "Polygon", "coordinates": [[[-4, -30], [30, -30],'
                                   ' [30, 30], [-4, 30], [-4, -30]]]}')}),
        Case("aoi-on-nodata", ["plan", "--dem", "nd.tif", "--aoi", "aoi.geojson", "--out",
                               "out"], "nodata", files=files, setup=_tif("nd.tif",
                                                                         heights=_nodata_block(),
                                                                         west_north=(-30.5,
                                                                                     30.5))),
        Case("aoi-not-a-polygon", ["plan", "--aoi", "pt.geojson", "--out", "out"], "pt.geojson",
             files={"pt.geojson": '{"type": "Point", "coordinates": [0, 0]}'}),
        Case("aoi-loop-given", RUN + ["--config", "loop.toml", "--out", "out"],
             "`odometry_loop_m` (25 m) of a plan over an area of interest",
             files={**files, "loop.toml": ("network = true\nodometry_percent = 2.0\n"
                                           "odometry_loop_m = 25.0\n")}),
    ]


@pytest.mark.parametrize("case", _cases(), ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)


@pytest.mark.slow
def test_a_network_aoi_plan_closes_its_route(capsys, monkeypatch, tmp_path):
    """In network mode with odometry the route's last and first legs are the odometry's
    closing legs: ``plan.json`` records them in its configuration and its aids (about 30 s)."""
    (tmp_path / "aoi.geojson").write_text(
        '{"type": "Polygon", "coordinates": [[[-14, -4], [14, -4], [14, 4], [-14, 4], '
        '[-14, -4]]]}')
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(capsys, RUN + ["--network", "--odometry-percent", "2", "--out", "out",
                                          "--scheduler", "none", "--time-limit", "15"])
    assert code == 0, err
    doc = json.loads((tmp_path / "out" / "plan.json").read_text())
    legs = doc["design"]["route"]["legs_m"]
    assert len(doc["stations"]) >= 2
    loop = doc["provenance"]["config"]["odometry_loop_m"]
    assert loop == pytest.approx(legs[-1] + legs[0], abs=2e-3)
    assert doc["network"]["datum"]["odometry_loop_m"] == loop
