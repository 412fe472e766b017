"""``markerplan import-pcap`` on the real VLP-16 capture (btlad/ScanParser, CC0): command line
-> scan file -> ``read_scan``, turntable angles from both log forms, refused inputs, and
``markerplan process`` on the imported scan.

my.pcap decodes into a complete revolution (13440 returns) and the partial remainder the end
of the file leaves (2304 returns); the file ends inside its 79th packet (a position packet);
see tests/pipeline/test_pcap.py. Bad synthetic captures are cases of
tests/cli/test_bad_input_pipeline.py.
"""

import json
import shutil

import numpy as np
import pytest

from pipeline.scans.scan_format import read_scan
from tests.cli.bad_input import Case, check_refused
from tests.cli.invoke import run_cli

#: Each revolution's time by hand: the decoder's host stamp (pcap time of the revolution's
#: last packet) plus the middle of its firings' offsets from it (first, last), seconds.
REVOLUTION_TIME_S = [1599213600.072244 + (-0.19983983 + 0.001306368) / 2,
                     1599213600.236023 + (-0.16257 + 0.001306368) / 2]


@pytest.fixture
def capture(real_data, tmp_path, monkeypatch):
    """my.pcap copied into a fresh working folder (the test's cwd)."""
    monkeypatch.chdir(tmp_path)
    return shutil.copy(real_data / "vlp16_pcap" / "my.pcap", tmp_path / "my.pcap")


def _import(capsys, *args):
    code, out, err = run_cli(capsys, ["import-pcap", "my.pcap", "--json", *args])
    assert code == 0, err
    return json.loads(out), err


def test_without_log_one_frame_at_angle_zero(capture, capsys, tmp_path):
    summary, err = _import(capsys, "--out", "a")
    assert "dropped the capture's last revolution (2304 returns)" in err
    assert "the file ends inside packet 79 (cut short while recording or copying)" in err
    assert "no --turntable-log" in err and "--no-calibrate" in err
    assert "revolution 0 has returns over 28% of the spin" in err
    scan = read_scan(tmp_path / "a" / "my.scan.npz")
    assert (scan.n_frames, scan.n_points, scan.station_id) == (1, 13440, "my")
    assert scan.turntable_angle_rad.tolist() == [0.0]
    assert set(np.unique(scan.laser_id)) == set(range(16))
    assert scan.metadata["source"] == "pcap"
    assert scan.metadata["provenance"]["inputs"][0]["file"] == "my.pcap"
    assert summary["revolutions_decoded"] == 2 and summary["partial_dropped"] == 1
    assert (summary["return_mode"], summary["cut_packet"]) == ("strongest", 79)
    assert (summary["n_frames"], summary["n_points"]) == (1, 13440)
    # the same capture gives the same bytes
    _import(capsys, "--out", "b")
    assert (tmp_path / "a" / "my.scan.npz").read_bytes() == \
        (tmp_path / "b" / "my.scan.npz").read_bytes()


def test_per_frame_log(capture, capsys, tmp_path):
    (tmp_path / "tt.csv").write_text("frame,turntable_angle_deg\n0,10\n1,190.5\n")
    summary, _ = _import(capsys, "--turntable-log", "tt.csv", "--keep-partial",
                         "--station-id", "S1", "--out", "scans")
    scan = read_scan(tmp_path / "scans" / "S1.scan.npz")
    assert scan.station_id == "S1" and scan.n_frames == 2
    np.testing.assert_allclose(scan.turntable_angle_rad, np.radians([10, 190.5]))
    assert np.bincount(scan.frame_index).tolist() == [13440, 2304]
    assert summary["partial_dropped"] == 0
    np.testing.assert_allclose(summary["frame_time_s"], REVOLUTION_TIME_S, rtol=0, atol=1e-6)


def test_timed_log_interpolated_and_unwrapped(capture, capsys, tmp_path):
    # 350 deg at t0, 10 deg (370 unwrapped) 2 s later: 10 deg/s through 360
    t0 = 1599213599.0
    (tmp_path / "tt.csv").write_text(f"time_s,turntable_angle_deg\n{t0},350\n{t0 + 2},10\n")
    _import(capsys, "--turntable-log", "tt.csv", "--keep-partial", "--out", "scans")
    scan = read_scan(tmp_path / "scans" / "my.scan.npz")
    expected_deg = [350 + 10 * (t - t0) for t in REVOLUTION_TIME_S]  # 359.7298, 361.5539
    np.testing.assert_allclose(np.degrees(scan.turntable_angle_rad), expected_deg, atol=1e-5)


def test_process_runs_on_the_imported_scan(capture, capsys, tmp_path):
    """An indoor capture holds no marker: process finishes with every candidate rejected."""
    _import(capsys, "--out", "scans")
    code, out, err = run_cli(capsys, ["process", "scans", "--no-calibrate", "--json",
                                      "--out", "tables"])
    assert code == 0, err
    assert "Traceback" not in err
    (station,) = json.loads(out)["stations"]
    assert station["station_id"] == "my" and station["n_accepted"] == 0
    rows = (tmp_path / "tables" / "markers.csv").read_text().splitlines()
    assert len(rows) == 1 + station["n_candidates"]
    assert all(",false," in row for row in rows[1:])


def test_real_capture_to_las_and_ply(capture, capsys, tmp_path):
    """The real capture, imported, processed and written as LAS 1.4 and PLY (station frame:
    a real scan has no pose in a site); read back with laspy and plyfile, every point of the
    scan is there with its sensor-frame range."""
    import laspy
    import plyfile

    _import(capsys, "--out", "scans")
    scan = read_scan(tmp_path / "scans" / "my.scan.npz")
    code, _, err = run_cli(capsys, ["process", "scans", "--no-calibrate", "--cloud", "las,ply",
                                    "--out", "tables"])
    assert code == 0, err
    assert not list((tmp_path / "tables").glob("*.site.*"))
    las = laspy.read(tmp_path / "tables" / "my.station.las")
    ply = plyfile.PlyData.read(tmp_path / "tables" / "my.station.ply")["vertex"]
    assert las.header.version.major == 1 and las.header.version.minor == 4
    assert len(las.points) == ply.count == scan.n_points
    for xyz in (np.column_stack([las.x, las.y, las.z]),
                np.column_stack([ply["x"], ply["y"], ply["z"]])):
        # one frame at angle 0 and no offsets: the station frame's origin is the sensor's, so
        # each point keeps its measured range, in order (to the LAS scale and float32 ranges)
        np.testing.assert_allclose(np.linalg.norm(xyz, axis=1), scan.range_m, atol=2e-4)
    assert set(np.unique(las.classification)) <= {1, 2}  # an indoor capture: no marker


def test_self_calibration_refused_on_a_single_angle(capture, capsys, tmp_path):
    """One frame at one turntable angle cannot calibrate the mounting: a one-line error
    naming --no-calibrate, not meaningless offsets."""
    _import(capsys, "--out", "scans")
    code, out, err = run_cli(capsys, ["process", "scans", "--out", "tables"])
    assert code == 1 and "Traceback" not in err
    assert "360 deg of the turn unscanned" in err and "--no-calibrate" in err
    assert not (tmp_path / "tables").exists()


def test_dual_return_capture_keeps_the_last_returns(capsys, tmp_path, monkeypatch):
    """A synthetic dual-return capture (last returns at 3 m, strongest at 2 m): one point per
    firing, the last return, and a note saying so."""
    from tests import pcap_builder as pb

    monkeypatch.chdir(tmp_path)
    (tmp_path / "my.pcap").write_bytes(pb.vlp16_capture(20, return_mode=pb.DUAL))
    summary, err = _import(capsys, "--keep-partial", "--out", "scans")
    assert "dual-return capture: kept the last return of each firing" in err
    assert summary["return_mode"] == "dual" and summary["n_points"] == 20 * 6 * 32
    scan = read_scan(tmp_path / "scans" / "my.scan.npz")
    np.testing.assert_allclose(scan.range_m, 3.0, atol=5e-3)


def _first_records(n: int):
    """Setup: ``part.pcap``, the capture's global header and first ``n`` records."""
    def setup(cwd, inputs):
        data = (inputs / "my.pcap").read_bytes()
        end = 24
        for _ in range(n):
            end += 16 + int.from_bytes(data[end + 8:end + 12], "little")
        (cwd / "part.pcap").write_bytes(data[:end])
    return setup


def _capture_in_c(cwd, inputs):
    """Setup: ``c/my.pcap``, a copy of the capture."""
    (cwd / "c").mkdir()
    shutil.copy(inputs / "my.pcap", cwd / "c" / "my.pcap")


IMPORT = ["import-pcap", "{inputs}/my.pcap", "--out", "out"]
PARTIAL = IMPORT + ["--keep-partial", "--turntable-log", "tt.csv"]


def log_case(name, text, needle, args=IMPORT + ["--turntable-log", "tt.csv"]):
    return Case(name, args, needle, files={"tt.csv": text})


CASES = [
    log_case("log-fewer-rows-than-frames", "turntable_angle_deg\n0\n",
             "has 1 row(s) but the capture has 2 frame(s)", PARTIAL),
    log_case("log-more-rows-than-frames", "turntable_angle_deg\n0\n90\n180\n",
             "has 3 row(s) but the capture has 1 frame(s)"),
    log_case("log-missing-column", "angle\n0\n", "missing column(s) turntable_angle_deg"),
    log_case("log-nan-angle", "turntable_angle_deg\nnan\n", "must be a finite number"),
    log_case("log-text-angle", "turntable_angle_deg\nten\n", "must be a number"),
    log_case("log-frame-column", "frame,turntable_angle_deg\n1,0\n", "must count 0, 1, 2"),
    log_case("log-times-not-increasing",
             "time_s,turntable_angle_deg\n1599213599,0\n1599213599,5\n", "must increase"),
    log_case("log-frames-outside-span",
             "time_s,turntable_angle_deg\n1599213600.0,0\n1599213601.0,10\n",
             "1 frame(s) lie outside it"),
    Case("log-missing", IMPORT + ["--turntable-log", "nope.csv"], "file not found"),
    Case("pcap-empty", ["import-pcap", "e.pcap", "--out", "out"], "is empty",
         files={"e.pcap": b""}),
    Case("pcap-garbage", ["import-pcap", "g.pcap", "--out", "out"],
         "not a readable packet capture", files={"g.pcap": b"GIF89a" + bytes(range(200))}),
    Case("pcap-cut-mid-file", ["import-pcap", "part.pcap", "--out", "out"],
         "cut short inside packet 5", setup=lambda cwd, inputs: (cwd / "part.pcap").write_bytes(
             (inputs / "my.pcap").read_bytes()[:3000])),
    Case("pcap-no-vlp16-returns", ["import-pcap", "part.pcap", "--out", "out"],
         "no VLP-16 returns", setup=_first_records(0)),
    Case("pcap-only-partial", ["import-pcap", "part.pcap", "--out", "out"],
         "only a partial revolution", setup=_first_records(1)),
    Case("pcap-missing", ["import-pcap", "nope.pcap", "--out", "out"], "does not exist"),
    Case("out-holds-the-capture", ["import-pcap", "c/my.pcap", "--out", "c"], "holds the input",
         setup=_capture_in_c),
    Case("station-id-path", IMPORT + ["--station-id", "../S1"], "--station-id", code=2),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_bad_input_refused(case, capsys, monkeypatch, tmp_path, real_data):
    check_refused(case, capsys, monkeypatch, tmp_path, real_data / "vlp16_pcap")

