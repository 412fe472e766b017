"""``markerplan plan`` on a GeoTIFF DEM in EPSG:32633: plan.gpkg, the stand-map GeoTIFFs and
markers.geojson come out in the DEM's CRS (GeoJSON in WGS84 lon/lat), and twice the same.

The DEM is a 30 m square of gentle hills near (500 000, 4 649 000) m; its four stations stand
exactly on stand-map cell centres (``--stand-map-cell-m 0.6``: 3 DEM cells), so the stand map at
their cells must repeat what plan.json says of them.
"""

import errno
import hashlib
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from planner.outputs.stand_map import cells_per_stand_cell, stand_grid
from visibility.dem import DEM, read_dem, write_dem

X0, Y0, CELL, N = 500_000.0, 4_649_000.0, 0.2, 151
STAND_CELL = 0.6
#: Stations near these offsets from the DEM's centre, m.
OFFSETS = ((-6.0, -5.0), (6.0, -5.0), (6.0, 6.0), (-6.0, 6.0))


def _utm_wkt():
    from rasterio.crs import CRS

    return CRS.from_epsg(32633).to_wkt()


def _run(root, out):
    from planner.cli import main

    try:
        main(["plan", "--dem", str(root / "dem.tif"), "--stations", str(root / "stations.csv"),
              "--boundary", str(root / "boundary.geojson"), "--stand-map-cell-m", str(STAND_CELL),
              "--out", str(out)])
    except SystemExit as exc:  # pragma: no cover - a failing plan must say so
        raise AssertionError(f"markerplan plan exited {exc.code}") from exc


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """Inputs and two runs of the plan: ``(root, out_a, out_b, dem)``."""
    root = tmp_path_factory.mktemp("gis")
    x = X0 + CELL * np.arange(N)
    y = Y0 + CELL * np.arange(N)
    gx, gy = np.meshgrid(x - x.mean(), y - y.mean())
    heights = 100.0 + 0.4 * np.sin(gx / 4.0) * np.cos(gy / 5.0) + 0.01 * gx
    write_dem(root / "dem.tif", DEM(heights, (X0, Y0), CELL, crs=_utm_wkt()))
    dem = read_dem(root / "dem.tif")
    xy, _ = stand_grid(dem, cells_per_stand_cell(dem, STAND_CELL))
    centre = np.array([x.mean(), y.mean()])
    rows = []
    for k, off in enumerate(OFFSETS):
        d = np.linalg.norm(xy - (centre + off), axis=-1)
        r, c = np.unravel_index(np.argmin(d), d.shape)
        rows.append(f"S{k + 1},{float(xy[r, c, 0])!r},{float(xy[r, c, 1])!r}\n")
    (root / "stations.csv").write_text("id,x_m,y_m\n" + "".join(rows))
    ring = (centre + 12.0 * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [-1, -1]])).tolist()
    (root / "boundary.geojson").write_text(json.dumps({"type": "Polygon", "coordinates": [ring]}))
    _run(root, root / "a")
    _run(root, root / "b")
    return root, root / "a", root / "b", dem


def _plan(out):
    return json.loads((out / "plan.json").read_text())


def test_gpkg_layers_match_plan_json_in_the_dems_crs(planned):
    import pyogrio
    from pyogrio.raw import read
    from rasterio.crs import CRS

    _, out, _, dem = planned
    doc = _plan(out)
    gpkg = out / "plan.gpkg"
    layers = dict(pyogrio.list_layers(gpkg).tolist())
    assert layers == {"markers": "Point Z", "stations": "Point Z",
                      "sight_lines": "LineString Z", "boundary": "Polygon"}
    for name in layers:
        assert CRS.from_user_input(pyogrio.read_info(gpkg, layer=name)["crs"]) \
            == CRS.from_wkt(dem.crs)
    import shapely

    _, _, geom, fields = read(gpkg, layer="markers")
    pts = shapely.get_coordinates(shapely.from_wkb(geom), include_z=True)
    assert [str(v) for v in fields[0]] == [m["id"] for m in doc["markers"]]
    np.testing.assert_array_equal(pts, [[m["x_m"], m["y_m"], m["z_m"]] for m in doc["markers"]])
    assert fields[4].tolist() == [len(m["stations"]) for m in doc["markers"]]
    _, _, geom, fields = read(gpkg, layer="stations")
    assert [str(v) for v in fields[0]] == [s["id"] for s in doc["stations"]]
    np.testing.assert_allclose(fields[1], [s["predicted_error_m"] for s in doc["stations"]],
                               rtol=1e-12)
    assert fields[4].tolist() == [s["n_markers"] for s in doc["stations"]]
    _, _, geom, fields = read(gpkg, layer="sight_lines")
    assert len(geom) == sum(s["n_markers"] for s in doc["stations"])
    used = sorted(zip((str(v) for v in fields[0]), (str(v) for v in fields[1]), strict=True))
    assert used == sorted((s["id"], m) for s in doc["stations"] for m in s["markers"])
    ends = shapely.get_coordinates(shapely.from_wkb(geom), include_z=True).reshape(-1, 2, 3)
    np.testing.assert_allclose(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1), fields[2],
                               rtol=1e-9)


def test_stand_map_repeats_plan_at_the_stations_cells(planned):
    import rasterio

    _, out, _, dem = planned
    doc = _plan(out)
    with rasterio.open(out / "usable_markers.tif") as src:
        usable, t, crs, nodata = src.read(1), src.transform, src.crs, src.nodata
    with rasterio.open(out / "station_error.tif") as src:
        error = src.read(1)
        assert src.transform == t
    assert crs == rasterio.crs.CRS.from_wkt(dem.crs) and np.isnan(nodata)
    # aligned: the DEM's upper-left corner, 3 DEM cells a side
    assert (t.a, -t.e) == pytest.approx((3 * CELL, 3 * CELL), rel=1e-12)
    assert (t.c, t.f) == pytest.approx((X0 - CELL / 2, Y0 + (N - 0.5) * CELL), abs=1e-6)
    for s in doc["stations"]:
        col, row = ~t @ (s["x_m"], s["y_m"])
        r, c = int(row), int(col)
        assert (row - r, col - c) == pytest.approx((0.5, 0.5), abs=1e-6)  # a cell centre
        assert usable[r, c] == s["n_markers"]
        assert error[r, c] == pytest.approx(s["predicted_error_m"], rel=1e-5)  # float32
    # 151 cells = 50 whole stand cells + 1 DEM cell: the last column and (bottom) row are centred
    # off the DEM's cell-centre rectangle, where no station can stand
    assert np.isnan(usable[:, -1]).all() and np.isnan(error[-1]).all()
    assert np.isfinite(usable[1:-1, 1:-1]).all()
    # where fewer than 3 markers are usable there is no error
    assert np.isnan(error[np.isfinite(usable) & (usable < 3)]).all()


def test_geojson_is_wgs84_and_goes_back_to_utm_within_a_millimetre(planned):
    from rasterio.warp import transform

    _, out, _, dem = planned
    doc = _plan(out)
    gj = json.loads((out / "markers.geojson").read_text())
    assert "crs" not in gj and gj["source_crs"] == "WGS 84 / UTM zone 33N (EPSG:32633)"
    pos = np.array([f["geometry"]["coordinates"] for f in gj["features"]])
    assert np.all((pos[:, 0] > 14.0) & (pos[:, 0] < 16.0) & (pos[:, 1] > 41.0)
                  & (pos[:, 1] < 43.0))
    x, y = transform("EPSG:4326", dem.crs, pos[:, 0].tolist(), pos[:, 1].tolist())
    want = np.array([[r["x_m"], r["y_m"]] for r in doc["markers"] + doc["stations"]])
    np.testing.assert_allclose(np.column_stack([x, y]), want, rtol=0, atol=1e-3)
    np.testing.assert_array_equal(pos[:, 2], [r["z_m"] for r in doc["markers"] + doc["stations"]])


def test_report_and_frame_name_the_crs(planned):
    _, out, _, _ = planned
    doc = _plan(out)
    name = "WGS 84 / UTM zone 33N (EPSG:32633)"
    assert doc["site"]["crs"] == name and name in doc["frame"]
    assert name in (out / "report.md").read_text()
    assert (out / "markers.csv").read_text().startswith("id,x_m,y_m,z_m,")
    prj = (out / "markers.prj").read_text()
    assert prj.startswith('PROJCS["WGS_1984_UTM_Zone_33N"') and prj.endswith("]\n")


def test_two_runs_give_byte_identical_files(planned):
    _, a, b, _ = planned

    def digests(folder):
        return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
                for p in sorted(folder.iterdir()) if p.is_file()}

    da, db = digests(a), digests(b)
    assert {"plan.gpkg", "usable_markers.tif", "station_error.tif"} <= set(da)
    assert da == db


def test_network_mode_writes_the_gpkg_relative_to_the_reference_station(planned, tmp_path):
    from pyogrio.raw import read

    from planner.cli import main

    root = planned[0]
    main(["plan", "--dem", str(root / "dem.tif"), "--stations", str(root / "stations.csv"),
          "--network", "--reference-station", "S2", "--stand-map-cell-m", "2",
          "--out", str(tmp_path / "n")])
    doc = _plan(tmp_path / "n")
    _, _, geom, fields = read(tmp_path / "n" / "plan.gpkg", layer="stations")
    assert [str(v) for v in fields[2]] == ["station S2"] * 4
    np.testing.assert_allclose(fields[1], [np.nan if s["predicted_error_m"] is None
                                           else s["predicted_error_m"] for s in doc["stations"]],
                               rtol=1e-12)
    _, _, geom, _ = read(tmp_path / "n" / "plan.gpkg", layer="markers")
    assert len(geom) == doc["n_markers"]


def test_default_site_without_crs_keeps_its_local_frame(valid_inputs):
    """The session's default plan (no CRS): GPKG layers without CRS, GeoJSON in the site
    frame, stand maps written."""
    import pyogrio
    import rasterio

    from planner.outputs.report import FRAME_NOTE

    out = valid_inputs / "plan"
    doc = _plan(out)
    assert doc["frame"] == FRAME_NOTE and doc["site"]["crs"] is None
    assert all(pyogrio.read_info(out / "plan.gpkg", layer=name)["crs"] is None
               for name in ("markers", "stations", "sight_lines"))
    gj = json.loads((out / "markers.geojson").read_text())
    assert gj["coordinate_frame"] == FRAME_NOTE and "crs" not in gj
    assert [f["geometry"]["coordinates"] for f in gj["features"]][:len(doc["markers"])] == \
        [[m["x_m"], m["y_m"], m["z_m"]] for m in doc["markers"]]
    with rasterio.open(out / "usable_markers.tif") as src:
        assert src.crs is None and src.width * src.height <= 40_000
        assert np.nanmax(src.read(1)) == len(doc["markers"])


def test_the_plans_crs_reaches_the_network_geojson(planned):
    """``adjust --plan`` takes the plan's CRS (plan.json ``site.crs_wkt``): its GeoJSON is in
    WGS84 lon/lat like markers.geojson, and names the CRS."""
    from rasterio.crs import CRS

    from pipeline.network.body import Body
    from planner.network.files import network_geojson
    from planner.network.plan_geometry import read_plan_geometry
    from planner.outputs.gis import crs_body

    _, out, _, dem = planned
    geometry = read_plan_geometry(out / "plan.json")
    assert CRS.from_wkt(geometry.crs) == CRS.from_wkt(dem.crs)
    assert crs_body(geometry.crs) == Body.named("earth")  # adjust --body crs
    markers = [{"marker_id": m, "x_m": x, "y_m": y, "z_m": z, "control": False,
                "ellipsoid_major_m": 0.01, "n_stations": 1, "stations": "S1"}
               for m, (x, y, z) in zip(geometry.marker_ids, geometry.marker_xyz_m, strict=True)]
    doc = {"frame": "plan frame", "datum": {"description": "station S1"},
           "provenance": {"markerplan_version": "x", "config_sha256": "y"}}
    gj = network_geojson(doc, [], markers, [], geometry.crs)
    plan_gj = json.loads((out / "markers.geojson").read_text())
    planned_lonlat = {f["properties"]["id"]: f["geometry"]["coordinates"]
                      for f in plan_gj["features"] if f["properties"]["kind"] == "marker"}
    network_lonlat = {f["properties"]["id"]: f["geometry"]["coordinates"] for f in gj["features"]}
    assert network_lonlat.keys() == planned_lonlat.keys() and planned_lonlat
    for marker_id, (lon, lat, z) in network_lonlat.items():
        # 1e-8 deg is about 1 mm; the network rounds its metres to 0.1 mm first
        assert [lon, lat] == pytest.approx(planned_lonlat[marker_id][:2], abs=1e-8)
        assert z == pytest.approx(planned_lonlat[marker_id][2], abs=1e-4)
    assert "WGS84" in gj["coordinate_frame"] and "EPSG:32633" in gj["source_crs"]


def run_with_file_size_limit(code: str, limit_bytes: int, cwd) -> subprocess.CompletedProcess:
    """Run Python ``code`` in a child whose files cannot grow past ``limit_bytes``: every write
    beyond fails with EFBIG (SIGXFSZ ignored), a genuine write failure inside GDAL as a full
    disk's ENOSPC is, without root or a small disk."""
    prelude = textwrap.dedent(f"""
        import resource, signal
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, ({limit_bytes}, {limit_bytes}))
    """)
    return subprocess.run([sys.executable, "-c", prelude + textwrap.dedent(code)], cwd=cwd,
                          capture_output=True, text=True, timeout=120)


def test_a_geopackage_that_cannot_be_written_is_one_line_and_leaves_nothing(tmp_path):
    """plan.gpkg (156 kB for the default site) is the first file over 100 kB: GDAL fails inside
    SQLite with a message that does not say why; the user reads the disk's own reason."""
    done = run_with_file_size_limit("""
        from planner.cli import main
        main(["plan", "--out", "out"])
    """, 100_000, tmp_path)
    assert done.returncode == 1, done.stderr
    assert "Traceback" not in done.stderr
    assert done.stderr.splitlines() == [
        "error: --out out: writing failed (out/plan.gpkg): File too large; "
        "nothing was written; raise the file-size limit (ulimit -f) or choose another folder"], \
        done.stderr
    assert os.listdir(tmp_path) == []


def test_a_stand_map_that_cannot_be_written_raises_the_disks_error(tmp_path):
    """GDAL's GeoTIFF writer on a failing disk: the OSError with the disk's errno, not
    GDAL's "Write failed. See previous exception" and libtiff's lines on stderr."""
    done = run_with_file_size_limit("""
        import numpy as np
        from types import SimpleNamespace
        from planner.outputs.gis import write_stand_map
        band = np.ones((200, 200))
        stand = SimpleNamespace(usable=band, error_m=band, crs=None, transform=(2, 0, 0, 0, -2, 0))
        try:
            write_stand_map(stand, ".")
        except OSError as exc:
            print(type(exc).__name__, exc.errno)
    """, 50_000, tmp_path)
    assert done.stdout.split() == ["OSError", str(errno.EFBIG)], \
        done.stdout + done.stderr
    assert done.stderr == ""
