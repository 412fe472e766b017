"""``markerplan simulate``: small runs, JSON summary, and one-line errors without partial files."""

import json

import numpy as np
import pytest

from pipeline.scans.scan_format import read_scan, read_truth
from tests.cli.invoke import run_cli


def test_simulate_writes_scans_and_truth(tmp_path, capsys):
    out = tmp_path / "scans"
    code, stdout, _ = run_cli(capsys, [
        "simulate", "--site", "default", "--station-ids", "S1,S3", "--frames", "8", "--seed", "2",
        "--axis-offset-mm", "5,-3", "--vertical-axis-error-deg", "0.2", "--lframe-tilt-deg",
        "-0.1", "--range-noise-mm", "10", "--out", str(out), "--json"])
    assert code == 0
    summary = json.loads(stdout)
    assert [s["station_id"] for s in summary["stations"]] == ["S1", "S3"]
    assert sorted(p.name for p in out.iterdir()) == [
        "provenance.json", "site.json", "station_S1.scan.npz", "station_S1.truth.json",
        "station_S3.scan.npz", "station_S3.truth.json"]
    scan = read_scan(out / "station_S1.scan.npz")
    assert scan.n_frames == 8 and scan.n_points == summary["stations"][0]["n_points"]
    meta = scan.metadata
    assert meta["source"] == "simulated" and meta["station_id"] == "S1"
    assert len(meta["sensor"]["laser_elevation_rad"]) == 16 and meta["sensor"]["rpm"] == 600
    assert meta["sensor"]["range_noise_m"] == pytest.approx(0.01)
    assert meta["rig"]["lidar_height_m"] == 1.0 and meta["rig"]["frames_per_turn"] == 8
    # the default profile (calibrated) drives the sensor; --range-noise-mm overrides it
    assert meta["sensor_profile"] == "calibrated" and meta["sensor"]["beam_divergence"]
    assert summary["sensor_profile"]["name"] == "calibrated"
    assert summary["sensor"]["range_noise_m"] == pytest.approx(0.01)
    assert "mounting_offsets" not in json.dumps(meta)
    truth = read_truth(out / "station_S1.truth.json")
    assert truth["mounting_offsets"]["axis_offset_m"] == pytest.approx([0.005, -0.003])
    assert truth["mounting_offsets"]["vertical_axis_error_rad"] == pytest.approx(
        np.radians(0.2))
    assert len(truth["markers"]) == 11 and len(truth["rocks"]) >= 3
    site = json.loads((out / "site.json").read_text())
    assert len(site["stations"]) == 7


def test_station_count_and_overwrite(tmp_path, capsys):
    out = tmp_path / "o"
    args = ["simulate", "--station-ids", "S1", "--frames", "2", "--out", str(out), "--json"]
    assert run_cli(capsys, args)[0] == 0
    code, _, err = run_cli(capsys, args)
    assert code == 1 and "--overwrite" in err
    assert run_cli(capsys, [*args, "--overwrite"])[0] == 0


def _assert_clean_failure(tmp_path, code, stdout, err, fix):
    assert code not in (0, None)
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert len(lines) == 1 and lines[0].startswith("error:"), err
    assert fix in err
    assert stdout == ""
    leftovers = [p.name for p in tmp_path.rglob("*") if "partial" in p.name or p.name == "out"]
    assert leftovers == []


def test_station_on_nodata_refused_and_nodata_elsewhere_read(tmp_path, capsys):
    h = np.zeros((61, 61))
    h[0, 0] = np.nan  # a corner, away from every station and marker of the default site
    np.savez(tmp_path / "corner.npz", heights_m=h, origin_m=np.array([-30.0, -30.0]),
             cell_size_m=np.array(1.0), crs=np.array(""))
    h[30, 30] = np.nan  # under station S1 at (0, 0)
    np.savez(tmp_path / "s1.npz", heights_m=h, origin_m=np.array([-30.0, -30.0]),
             cell_size_m=np.array(1.0), crs=np.array(""))
    args = ["simulate", "--frames", "2", "--station-ids", "S2", "--json", "--dem"]
    code, stdout, err = run_cli(capsys, [*args, str(tmp_path / "s1.npz"), "--out",
                                         str(tmp_path / "out")])
    _assert_clean_failure(tmp_path, code, stdout, err, "station S1 at (0.00, 0.00) m stands on "
                                                       "DEM nodata")
    code, stdout, _ = run_cli(capsys, [*args, str(tmp_path / "corner.npz"), "--out",
                                       str(tmp_path / "corner")])
    assert code == 0 and json.loads(stdout)["stations"][0]["station_id"] == "S2"
    code, _, _ = run_cli(capsys, [*args, str(tmp_path / "s1.npz"), "--dem-fill", "nearest",
                                  "--out", str(tmp_path / "filled")])
    assert code == 0  # --dem-fill nearest takes the filled cells as terrain


def test_station_outside_dem_refused(tmp_path, capsys):
    np.savez(tmp_path / "small.npz", heights_m=np.zeros((11, 11)),
             origin_m=np.array([-5.0, -5.0]), cell_size_m=np.array(1.0), crs=np.array(""))
    code, stdout, err = run_cli(capsys, ["simulate", "--dem", str(tmp_path / "small.npz"),
                                         "--frames", "2",
                                         "--out", str(tmp_path / "out")])
    _assert_clean_failure(tmp_path, code, stdout, err, "outside the DEM")


def test_unwritable_out_refused(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    code, stdout, err = run_cli(capsys, ["simulate", "--frames", "2", "--station-ids", "S1",
                                         "--out", str(blocker / "out")])
    _assert_clean_failure(tmp_path, code, stdout, err, "writable")


@pytest.mark.parametrize("frames", ["0", "-5", "2000000000"])
def test_frames_out_of_bounds_refused(tmp_path, capsys, frames):
    code, _, err = run_cli(capsys, ["simulate", "--frames", frames, "--out",
                                    str(tmp_path / "out")])
    assert code == 2 and "'--frames'" in err and "1<=x<=20000" in err
    assert list(tmp_path.iterdir()) == []


def test_unknown_preset_refused(tmp_path, capsys):
    code, stdout, err = run_cli(capsys, ["simulate", "--site", "mars", "--out",
                                         str(tmp_path / "out")])
    _assert_clean_failure(tmp_path, code, stdout, err, "default, large")


@pytest.mark.parametrize(("option", "value", "fix"), [
    ("--station-ids", "S9", "valid ids are"),
    ("--rpm", "610", "steps of 60"),
])
def test_bad_options_refused(tmp_path, capsys, option, value, fix):
    code, stdout, err = run_cli(capsys, ["simulate", option, value, "--frames", "2",
                                         "--out", str(tmp_path / "out")])
    _assert_clean_failure(tmp_path, code, stdout, err, fix)


def test_help_has_an_example(capsys):
    code, stdout, _ = run_cli(capsys, ["simulate", "--help"])
    assert code == 0 and "markerplan simulate --site default --out" in stdout


def test_stations_file_and_marker_radius(tmp_path, capsys):
    stations = tmp_path / "stations.csv"
    stations.write_text("id,x_m,y_m,heading_deg\nA,3.0,4.0,90\n")
    out = tmp_path / "o"
    code, _, err = run_cli(capsys, ["simulate", "--stations", str(stations), "--marker-radius-m",
                                    "0.15", "--frames", "2", "--out", str(out)])
    assert code == 0, err
    truth = read_truth(out / "station_A.truth.json")
    assert truth["station_pose"]["position_m"][:2] == pytest.approx([3.0, 4.0])
    assert truth["station_pose"]["heading_rad"] == pytest.approx(np.pi / 2)
    assert truth["marker_radius_m"] == 0.15
    site = json.loads((out / "site.json").read_text())
    assert [s["id"] for s in site["stations"]] == ["A"] and site["marker_radius_m"] == 0.15
    # --station-ids picks among the file's stations
    code, _, err = run_cli(capsys, ["simulate", "--stations", str(stations), "--station-ids",
                                    "B", "--frames", "2", "--out", str(tmp_path / "p")])
    assert code == 1 and "valid ids are A" in err


def test_sparse_dem_too_big_to_read_whole_is_read_by_window(tmp_path, capsys):
    """A 20000 x 20000 GeoTIFF (4e8 cells, more than read_dem reads whole; tiled and sparse on
    disk, data only around the default site) is read only as far as the stations and markers
    are seen (the sensor's maximum range), as ``plan`` reads it."""
    import rasterio
    from rasterio.transform import from_origin
    from rasterio.windows import Window

    from visibility.dem import MAX_DEM_CELLS
    from visibility.sensor import MAX_RANGE_M

    n, data = 20000, 512
    assert n * n > MAX_DEM_CELLS
    with rasterio.open(tmp_path / "big.tif", "w", driver="GTiff", height=n, width=n, count=1,
                       dtype="float32", crs="EPSG:32633",
                       transform=from_origin(-n / 2, n / 2, 1, 1), tiled=True, blockxsize=256,
                       blockysize=256, compress="deflate", sparse_ok=True,
                       nodata=-9999) as dst:  # data over -256..256 m
        dst.write(np.zeros((data, data), "float32"), 1,
                  window=Window((n - data) // 2, (n - data) // 2, data, data))
    out = tmp_path / "o"
    code, _, err = run_cli(capsys, ["simulate", "--dem", str(tmp_path / "big.tif"),
                                    "--station-ids", "S1", "--frames", "2", "--out", str(out)])
    assert code == 0, err
    dem = json.loads((out / "site.json").read_text())["dem"]
    # the site's stations and markers lie within +-18 m; the window adds the range, 5 m
    # and a 2-cell pad
    reach = 2 * (MAX_RANGE_M + 18 + 5 + 2) + 1
    assert dem["shape"][0] < reach and dem["shape"][1] < reach, dem
