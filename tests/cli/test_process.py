import csv
import json

import numpy as np
import pytest

from pipeline.scans.rig import rot_z
from pipeline.scans.scan_format import SCAN_FORMAT, _write_npz
from pipeline.tables.marker_table import COLUMNS, read_marker_table
from tests.cli.bad_input import STATION_MARKERS, write_synthetic_station
from tests.cli.invoke import run_cli


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    d = tmp_path_factory.mktemp("scans")
    write_synthetic_station(d, n_frames=240, azimuth_step_deg=0.4)
    return d


def test_process_with_truth_writes_all_outputs(station, tmp_path, capsys):
    out = tmp_path / "tables"
    code, stdout, _ = run_cli(capsys, ["process", str(station / "station_S1.scan.npz"),
                                       "--reference", str(station),  # folder of *.truth.json
                                       "--no-calibrate", "--out", str(out), "--json"])
    assert code == 0
    summary = json.loads(stdout)
    st = summary["stations"][0]
    assert st["n_accepted"] == 4 and st["n_matched_accepted"] == 4
    assert st["mean_error_m"] < 0.005
    assert summary["provenance"]["config"]["fit"]["method"] == "fixed-radius"
    rows = read_marker_table(out / "markers.csv")
    assert list(rows[0]) == list(COLUMNS)
    assert sorted(r["marker_id"] for r in rows if r["accepted"] == "true") == [
        "M0", "M1", "M2", "M3"]
    stations = list(csv.DictReader((out / "stations.csv").open()))
    assert stations[0]["calibrated"] == "false"
    assert len(list(csv.DictReader((out / "edges.csv").open()))) == 6
    assert json.loads((out / "summary.json").read_text())["provenance"]["inputs"][0]["sha256"]


def test_process_with_total_station_csv_in_another_frame(station, tmp_path, capsys):
    ts = tmp_path / "ts.csv"
    world = STATION_MARKERS @ rot_z(1.1).T + [500.0, -200.0, 30.0]
    ts.write_text("id,x_m,y_m,z_m\n" + "".join(f"T{k},{x},{y},{z}\n"
                                                 for k, (x, y, z) in enumerate(world)))
    out = tmp_path / "o"
    code, stdout, _ = run_cli(capsys, ["process", str(station / "station_S1.scan.npz"),
                                       "--reference", str(ts), "--no-calibrate", "--estimator",
                                       "hemisphere-icp", "--out", str(out), "--json"])
    assert code == 0
    st = json.loads(stdout)["stations"][0]
    assert st["registered"] and st["n_matched_accepted"] == 4
    assert st["mean_abs_edge_residual_m"] < 0.01


def test_unknown_stage_option_refused(station, tmp_path, capsys):
    code, _, err = run_cli(capsys, ["process", str(station / "station_S1.scan.npz"),
                                    "--set", "gate.max_box=0.3", "--out", str(tmp_path / "o")])
    assert code == 1 and "has no option 'max_box'" in err
    assert not (tmp_path / "o").exists()


def _raw_scan(path, n_points, angles):
    meta = {"format": SCAN_FORMAT, "station_id": "S9"}
    _write_npz(path, {
        "metadata": np.array(json.dumps(meta)),
        "turntable_angle_rad": np.asarray(angles, dtype=float),
        "xyz_sensor_m": np.ones((n_points, 3), np.float32),
        "frame_index": np.zeros(n_points, np.uint32), "laser_id": np.zeros(n_points, np.uint8),
        "spin_azimuth_rad": np.zeros(n_points, np.float32),
        "range_m": np.ones(n_points, np.float32)})


@pytest.mark.parametrize("case, needle", [
    ("empty", "empty"), ("no_angles", "turntable angle"), ("garbage", "not a readable scan"),
    ("missing", "does not exist"), ("bad_csv", "lacks column"),
])
def test_bad_input_one_line_no_output(station, tmp_path, capsys, case, needle):
    scan = station / "station_S1.scan.npz"
    args = ["process"]
    if case == "empty":
        p = tmp_path / "e.scan.npz"
        _raw_scan(p, 0, [0.0])
        args += [str(p)]
    elif case == "no_angles":
        p = tmp_path / "n.scan.npz"
        _raw_scan(p, 5, [np.nan])
        args += [str(p)]
    elif case == "garbage":
        p = tmp_path / "g.scan.npz"
        p.write_bytes(b"not a zip file at all")
        args += [str(p)]
    elif case == "missing":
        args += [str(tmp_path / "nope.scan.npz")]
    else:
        ref = tmp_path / "ref.csv"
        ref.write_text("id,x_m,y_m\nA,1,2\n")
        args += [str(scan), "--reference", str(ref)]
    out = tmp_path / "out"
    code, stdout, err = run_cli(capsys, [*args, "--out", str(out)])
    assert code == 1 and stdout == ""
    assert err.startswith("error:") and err.count("\n") == 1 and needle in err
    assert not out.exists()
    assert not any(p.name.startswith(".out.partial") for p in tmp_path.iterdir())


def test_known_offsets_option(station, tmp_path, capsys):
    code, stdout, _ = run_cli(capsys, ["process", str(station / "station_S1.scan.npz"),
                                       "--no-calibrate", "--vertical-axis-error-deg", "0.3",
                                       "--axis-offset-mm", "15,-2", "--out",
                                       str(tmp_path / "k"), "--json"])
    assert code == 0
    cal = json.loads(stdout)["stations"][0]["calibration"]
    assert cal["enabled"] is False
    assert cal["offsets"]["axis_offset_m"] == pytest.approx([0.015, -0.002])
    assert cal["offsets"]["vertical_axis_error_rad"] == pytest.approx(np.radians(0.3))


def _simulate_like_folder(station, tmp_path):
    """The synthetic station as ``simulate`` leaves it: scan, truth, site.json, provenance."""
    folder = tmp_path / "sim"
    folder.mkdir()
    for f in station.iterdir():
        (folder / f.name).write_bytes(f.read_bytes())
    (folder / "site.json").write_text("{}\n")
    (folder / "provenance.json").write_text("{}\n")
    return folder


def test_process_takes_the_folder_simulate_wrote(station, tmp_path, capsys):
    folder = _simulate_like_folder(station, tmp_path)
    code, stdout, err = run_cli(capsys, ["process", str(folder), "--no-calibrate", "--out",
                                         str(tmp_path / "t"), "--json"])
    assert code == 0, err
    assert "passed over" in err and "site.json" in err and "provenance.json" in err
    st = json.loads(stdout)["stations"][0]
    assert st["n_matched_accepted"] == 4 and st["mean_error_m"] < 0.005  # truth found inside
    # the shell's expansion of sim/* gives the same tables
    code, stdout_glob, err = run_cli(capsys, ["process", *map(str, sorted(folder.iterdir())),
                                              "--no-calibrate", "--out", str(tmp_path / "g")])
    assert code == 0, err
    assert (tmp_path / "g" / "markers.csv").read_bytes() == \
        (tmp_path / "t" / "markers.csv").read_bytes()


def test_marker_radius_comes_from_the_truth(station, tmp_path, capsys):
    folder = _simulate_like_folder(station, tmp_path)
    truth = folder / "station_S1.truth.json"
    truth.write_text(truth.read_text().replace('"marker_radius_m": 0.1', '"marker_radius_m": 0.15'))
    code, stdout, err = run_cli(capsys, ["process", str(folder), "--no-calibrate", "--out",
                                         str(tmp_path / "t"), "--json"])
    assert code == 0, err
    assert json.loads(stdout)["provenance"]["config"]["fit"]["radius_m"] == 0.15
    code, stdout, err = run_cli(capsys, ["process", str(folder), "--no-calibrate",
                                         "--marker-radius-m", "0.1", "--out", str(tmp_path / "u"),
                                         "--json"])
    assert code == 0 and json.loads(stdout)["provenance"]["config"]["fit"]["radius_m"] == 0.1


def test_folder_without_scans_refused(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    code, _, err = run_cli(capsys, ["process", str(tmp_path / "empty"), "--out",
                                    str(tmp_path / "o")])
    assert code == 1 and "holds no *.scan.npz" in err and err.count("\n") == 1


def test_truths_with_different_marker_radii_refused(station, tmp_path, capsys):
    folder = _simulate_like_folder(station, tmp_path)
    other = folder / "station_S2.truth.json"
    other.write_text((folder / "station_S1.truth.json").read_text()
                     .replace('"station_id": "S1"', '"station_id": "S2"')
                     .replace('"marker_radius_m": 0.1', '"marker_radius_m": 0.15'))
    code, _, err = run_cli(capsys, ["process", str(folder / "station_S1.scan.npz"),
                                    "--reference", str(folder), "--out", str(tmp_path / "o")])
    assert code == 1 and "different marker radii (0.1, 0.15 m)" in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()
