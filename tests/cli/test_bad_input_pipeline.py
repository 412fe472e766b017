"""Bad input to ``markerplan process``, ``markerplan fit-sphere`` and ``markerplan
import-pcap``: the pipeline's readers (scan, truth, reference CSV, point set, packet capture,
turntable log) and the sphere fit refuse it in one line.

Packet captures are synthetic VLP-16 captures (:mod:`tests.pcap_builder`), bad in one way each
(link type, file format, snap length, order, sensor, return mode, duplicates, a file cut
inside its first packet); the real capture's cases are in tests/cli/test_import_pcap.py.

Scan files are corrupted in ``setup`` callables: the valid scan is read, one array or the
metadata is changed, and the result is written into the case's working folder with
:func:`pipeline.scans.scan_format._write_npz` (bypassing the writer's own validation).
"""

from __future__ import annotations

import functools
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pipeline.scans.scan_format import SCAN_FORMAT, _write_npz, read_scan
from tests import pcap_builder as pb
from tests.cli.bad_input import Case, check_refused

SCAN = "{inputs}/scan/station_S1.scan.npz"
TRUTH = "{inputs}/scan/station_S1.truth.json"
FIELDS = ("turntable_angle_rad", "xyz_sensor_m", "frame_index", "laser_id", "spin_azimuth_rad",
          "range_m")


@functools.lru_cache(maxsize=2)
def _valid_arrays(inputs: Path) -> dict[str, np.ndarray]:
    scan = read_scan(inputs / "scan" / "station_S1.scan.npz")
    arrays = {name: getattr(scan, name) for name in FIELDS}
    arrays["metadata"] = np.array(json.dumps(scan.metadata))
    return arrays


def _arrays(inputs: Path) -> dict[str, np.ndarray]:
    """Copies of the valid scan's arrays (read once per session)."""
    return {k: v.copy() for k, v in _valid_arrays(inputs).items()}


def scan_with(change):
    """A ``setup`` writing ``bad.scan.npz``: the valid scan's arrays after ``change(arrays)``."""
    def setup(cwd: Path, inputs: Path) -> None:
        arrays = _arrays(inputs)
        change(arrays)
        _write_npz(cwd / "bad.scan.npz", arrays)
    return setup


def set_value(name: str, value, dtype=None):
    def change(arrays):
        a = arrays[name].astype(dtype or arrays[name].dtype)
        a.flat[0] = value
        arrays[name] = a
    return change


def replace(name: str, value):
    def change(arrays):
        if value is None:
            del arrays[name]
        else:
            arrays[name] = value
    return change


def meta(edit):
    def change(arrays):
        doc = json.loads(str(arrays["metadata"]))
        arrays["metadata"] = np.array(edit(doc))
    return change


def _dump(doc, **changes) -> str:
    doc.update(changes)
    return json.dumps(doc)


def _without(doc, key) -> str:
    doc.pop(key)
    return json.dumps(doc)


def truth_with(edit):
    """A ``setup`` writing ``bad.truth.json``: the valid truth after ``edit(doc)``."""
    def setup(cwd: Path, inputs: Path) -> None:
        doc = json.loads((inputs / "scan" / "station_S1.truth.json").read_text())
        out = edit(doc)
        (cwd / "bad.truth.json").write_text(out if isinstance(out, str) else json.dumps(out))
    return setup


def _truth_edit(**changes):
    def edit(doc):
        doc.update(changes)
        return doc
    return edit


def _marker_edit(**changes):
    def edit(doc):
        doc["markers"][0].update(changes)
        return doc
    return edit


def truncated_scan(cwd: Path, inputs: Path) -> None:
    data = (inputs / "scan" / "station_S1.scan.npz").read_bytes()
    (cwd / "bad.scan.npz").write_bytes(data[: len(data) // 2])


def bad_npy_header(cwd: Path, inputs: Path) -> None:
    """A member whose header claims far more data than it holds."""
    arrays = _arrays(inputs)
    _write_npz(cwd / "bad.scan.npz", arrays)
    path = cwd / "bad.scan.npz"
    with zipfile.ZipFile(path) as zf:
        members = {i.filename: zf.read(i) for i in zf.infolist()}
    name = "range_m.npy"
    n = arrays["range_m"].shape[0]
    members[name] = members[name].replace(f"({n},)".encode(), b"(9999999999,)".ljust(
        len(f"({n},)"), b" ")[: max(len(f"({n},)"), 13)], 1)
    with zipfile.ZipFile(path, "w") as zf:
        for k, v in members.items():
            zf.writestr(k, v)


def process(bad: str = "bad.scan.npz", *extra: str) -> list[str]:
    return ["process", bad, *extra, "--out", "out"]


def process_ref(ref: str) -> list[str]:
    return ["process", SCAN, "--reference", ref, "--out", "out"]


REF_HEADER = "id,x_m,y_m,z_m\n"
PTS = "1 2 3\n1 2 4\n1 3 3\n2 2 3\n"

PROCESS_CASES = [
    # --- the scan file itself
    Case("scan-not-zip", process(), "not a readable scan", files={"bad.scan.npz": b"hello"}),
    Case("scan-truncated", process(), "not a readable scan", setup=truncated_scan),
    Case("scan-npy-header-lies", process(), "bad.scan.npz", setup=bad_npy_header),
    Case("scan-missing-member", process(), "missing range_m",
         setup=scan_with(replace("range_m", None))),
    Case("scan-object-array", process(), "dtype",
         setup=scan_with(replace("laser_id", np.array(["a"] * 3)))),
    Case("scan-empty", process(), "empty",
         setup=scan_with(lambda a: a.update({k: a[k][:0] for k in FIELDS[1:]}))),
    Case("scan-no-frames", process(), "no frames",
         setup=scan_with(lambda a: a.update(turntable_angle_rad=np.zeros(0)))),
    Case("scan-ragged-arrays", process(), "must have shape",
         setup=scan_with(lambda a: a.update(range_m=a["range_m"][:-1]))),
    Case("scan-xyz-2d-wrong", process(), "xyz_sensor_m must have shape",
         setup=scan_with(lambda a: a.update(xyz_sensor_m=a["xyz_sensor_m"][:, :2]))),
    Case("scan-turntable-2d", process(), "turntable_angle_rad must have shape",
         setup=scan_with(lambda a: a.update(
             turntable_angle_rad=a["turntable_angle_rad"][:, None]))),
    # --- values
    Case("scan-xyz-nan", process(), "xyz_sensor_m", setup=scan_with(set_value("xyz_sensor_m",
                                                                            np.nan))),
    Case("scan-xyz-inf", process(), "NaN or infinite",
         setup=scan_with(set_value("xyz_sensor_m", np.inf))),
    Case("scan-xyz-1e300", process(), "beyond", setup=scan_with(set_value(
        "xyz_sensor_m", 1e300, np.float64))),
    Case("scan-range-nan", process(), "range_m", setup=scan_with(set_value("range_m", np.nan))),
    Case("scan-range-1e30", process(), "beyond", setup=scan_with(set_value("range_m", 1e30))),
    Case("scan-azimuth-inf", process(), "spin_azimuth_rad",
         setup=scan_with(set_value("spin_azimuth_rad", -np.inf))),
    Case("scan-azimuth-1e300", process(), "spin_azimuth_rad",
         setup=scan_with(set_value("spin_azimuth_rad", 1e300, np.float64))),
    Case("scan-turntable-nan", process(), "turntable angle",
         setup=scan_with(set_value("turntable_angle_rad", np.nan))),
    Case("scan-turntable-1e300", process(), "turntable_angle_rad",
         setup=scan_with(set_value("turntable_angle_rad", 1e300))),
    Case("scan-laser-16", process(), "laser_id", setup=scan_with(set_value("laser_id", 16))),
    Case("scan-laser-negative", process(), "0..15",
         setup=scan_with(set_value("laser_id", -1, np.int16))),
    Case("scan-laser-fraction", process(), "whole numbers",
         setup=scan_with(set_value("laser_id", 1.5, np.float64))),
    Case("scan-frame-beyond", process(), "frame_index",
         setup=scan_with(lambda a: a["frame_index"].__setitem__(-1, 10 ** 6))),
    Case("scan-frame-negative", process(), "frame_index",
         setup=scan_with(set_value("frame_index", -3, np.int64))),
    # --- metadata
    Case("meta-not-json", process(), "metadata", setup=scan_with(replace(
        "metadata", np.array("{not json")))),
    Case("meta-list", process(), "json object", setup=scan_with(replace(
        "metadata", np.array("[1, 2]")))),
    Case("meta-numeric-array", process(), "metadata", setup=scan_with(replace(
        "metadata", np.arange(3)))),
    Case("meta-no-format", process(), "'format'", setup=scan_with(meta(
        lambda d: _without(d, "format")))),
    Case("meta-no-station", process(), "'station_id'", setup=scan_with(meta(
        lambda d: _without(d, "station_id")))),
    Case("meta-future-version", process(), "newer", setup=scan_with(meta(
        lambda d: _dump(d, format="markerplan-scan/2")))),
    Case("meta-other-format", process(), "is not markerplan-scan", setup=scan_with(meta(
        lambda d: _dump(d, format="laz/1")))),
    Case("meta-version-not-int", process(), "no integer version", setup=scan_with(meta(
        lambda d: _dump(d, format="markerplan-scan/x")))),
    Case("meta-station-number", process(), "station_id", setup=scan_with(meta(
        lambda d: _dump(d, station_id=7)))),
    Case("meta-sensor-list", process(), "sensor", setup=scan_with(meta(
        lambda d: _dump(d, sensor=[1])))),
    Case("meta-provenance-string", process(), "provenance", setup=scan_with(meta(
        lambda d: _dump(d, provenance="x")))),
    # --- truth JSON reference
    Case("truth-list", process_ref("bad.truth.json"), "json object",
         setup=truth_with(lambda d: "[1]")),
    Case("truth-not-utf8", process_ref("bad.truth.json"), "utf-8",
         files={"bad.truth.json": b'{"format": "\xff"}'}),
    Case("truth-future", process_ref("bad.truth.json"), "newer",
         setup=truth_with(_truth_edit(format="markerplan-truth/9"))),
    Case("truth-missing-markers", process_ref("bad.truth.json"), "'markers'",
         setup=truth_with(lambda d: {k: v for k, v in d.items() if k != "markers"})),
    Case("truth-markers-object", process_ref("bad.truth.json"), "markers",
         setup=truth_with(_truth_edit(markers={"M0": [1, 2, 3]}))),
    Case("truth-centre-2", process_ref("bad.truth.json"), "centre_station_m",
         setup=truth_with(_marker_edit(centre_station_m=[1, 2]))),
    Case("truth-centre-string", process_ref("bad.truth.json"), "centre_station_m",
         setup=truth_with(_marker_edit(centre_station_m=[1, "2", 3]))),
    Case("truth-centre-huge", process_ref("bad.truth.json"), "beyond",
         setup=truth_with(_marker_edit(centre_station_m=[1, 2, 1e300]))),
    Case("truth-centre-nan", process_ref("bad.truth.json"), "not valid json",
         setup=truth_with(lambda d: json.dumps(d).replace("-0.9", "NaN", 1))),
    Case("truth-marker-no-id", process_ref("bad.truth.json"), "'id'",
         setup=truth_with(lambda d: {**d, "markers": [{"centre_station_m": [1, 2, 3]}]})),
    Case("truth-duplicate-id", process_ref("bad.truth.json"), "more than once",
         setup=truth_with(_marker_edit(id="M1"))),
    Case("truth-pose-string", process_ref("bad.truth.json"), "station_pose",
         setup=truth_with(_truth_edit(station_pose="north"))),
    Case("truth-radius-negative", process_ref("bad.truth.json"), "marker_radius_m",
         setup=truth_with(_truth_edit(marker_radius_m=-0.1))),
    # --- total-station reference CSV
    Case("ref-duplicate-id", process_ref("r.csv"), "more than once",
         files={"r.csv": REF_HEADER + "M0,1,2,3\nM0,2,3,4\nM1,3,3,3\n"}),
    Case("ref-ragged", process_ref("r.csv"), "row 3",
         files={"r.csv": REF_HEADER + "M0,1,2,3\nM1,2,3\n"}),
    Case("ref-nan", process_ref("r.csv"), "finite",
         files={"r.csv": REF_HEADER + "M0,1,nan,3\nM1,2,3,4\nM2,1,1,1\n"}),
    Case("ref-huge", process_ref("r.csv"), "1e300",
         files={"r.csv": REF_HEADER + "M0,1,1e300,3\nM1,2,3,4\nM2,1,1,1\n"}),
    Case("ref-not-utf8", process_ref("r.csv"), "utf-8",
         files={"r.csv": REF_HEADER.encode() + b"M\xe90,1,2,3\n"}),
    Case("ref-missing-column", process_ref("r.csv"), "z_m",
         files={"r.csv": "id,x_m,y_m\nM0,1,2\n"}),
    Case("ref-empty-id", process_ref("r.csv"), "empty",
         files={"r.csv": REF_HEADER + ",1,2,3\n"}),
    Case("ref-empty-file", process_ref("r.csv"), "empty", files={"r.csv": ""}),
    Case("ref-header-only", process_ref("r.csv"), "no markers", files={"r.csv": REF_HEADER}),
]

FIT_CASES = [
    Case("pts-not-utf8", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "utf-8",
         files={"p.xyz": b"1 2 3\n\xff\xfe 2 3\n"}),
    Case("pts-empty", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "no points",
         files={"p.xyz": ""}),
    Case("pts-comments-only", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "no points",
         files={"p.xyz": "# nothing\n\n"}),
    Case("pts-header-only", ["fit-sphere", "p.csv", "--marker-radius-m", "0.1"], "no points",
         files={"p.csv": "x,y,z\n"}),
    Case("pts-short-row", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "line 2",
         files={"p.xyz": "1 2 3\n1 2\n1 3 3\n2 2 3\n"}),
    Case("pts-ragged-csv", ["fit-sphere", "p.csv", "--marker-radius-m", "0.1"], "header has 3",
         files={"p.csv": "x,y,z\n1,2,3\n1,2,4,5\n"}),
    Case("pts-nan", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "finite",
         files={"p.xyz": "1 2 3\n1 nan 4\n1 3 3\n2 2 3\n"}),
    Case("pts-inf", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "finite",
         files={"p.xyz": "1 2 3\n1 2 -inf\n1 3 3\n2 2 3\n"}),
    Case("pts-1e300", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "beyond",
         files={"p.xyz": "1 2 3\n1e300 2 4\n1 3 3\n2 2 3\n"}),
    Case("pts-1e999", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "line 4",
         files={"p.xyz": "1 2 3\n1 2 4\n1 3 3\n2 2 1e999\n"}),
    Case("pts-text", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "three numbers",
         files={"p.xyz": "1 2 3\n1 2 four\n"}),
    Case("pts-too-few", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "at least 4",
         files={"p.xyz": "1 2 3\n1 2 4\n1 3 3\n"}),
    Case("pts-identical", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "same point",
         files={"p.xyz": "1 2 3\n" * 50}),
    Case("pts-two-points", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "one line",
         files={"p.xyz": "1 2 3\n1 2 3.1\n" * 10}),
    Case("pts-collinear", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "one line",
         files={"p.xyz": "".join(f"{1 + k * 0.01} {2 + k * 0.02} 3\n" for k in range(20))}),
    Case("pts-coplanar-line", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1"], "one line",
         files={"p.xyz": "".join(f"{k * 0.01} 0 0\n" for k in range(20))}),
    *[Case(f"radius-{name}", ["fit-sphere", "p.xyz", "--marker-radius-m", value],
           "--marker-radius-m",
           code=2, files={"p.xyz": PTS})
      for name, value in [("zero", "0"), ("negative", "-0.1"), ("nan", "nan"), ("inf", "inf"),
                          ("1e300", "1e300"), ("text", "big")]],
    Case("radius-absent", ["fit-sphere", "p.xyz"], "--marker-radius-m", code=2,
         files={"p.xyz": PTS}),
    Case("estimator-unknown", ["fit-sphere", "p.xyz", "--marker-radius-m", "0.1", "--estimator",
                               "magic"], "--estimator", code=2, files={"p.xyz": PTS}),
]


def import_pcap(*extra: str) -> list[str]:
    """``import-pcap c.pcap``; --keep-partial, so that a small capture would be imported."""
    return ["import-pcap", "c.pcap", "--keep-partial", *extra, "--out", "out"]


FRAMES = pb.vlp16_frames(8)
CAPTURE = pb.pcap_file(FRAMES)


def capture_case(name: str, needle: str, data: bytes) -> Case:
    return Case(name, import_pcap(), needle, files={"c.pcap": data})


def timed_log_case(name: str, needle: str, angles_deg: list[float]) -> Case:
    rows = "".join(f"{pb.START_S + k},{a}\n" for k, a in enumerate(angles_deg))
    return Case(name, import_pcap("--turntable-log", "tt.csv"), needle,
                files={"c.pcap": CAPTURE, "tt.csv": "time_s,turntable_angle_deg\n" + rows})


PCAP_CASES = [
    # --- the file and its link type
    capture_case("pcap-pcapng", "editcap -F pcap", pb.pcapng_header() + bytes(64)),
    capture_case("pcap-link-raw-ip", "link type 101 (raw IP)",
                 pb.pcap_file([(t, pb.raw_ip_frame(f)) for t, f in FRAMES], link_type=101)),
    capture_case("pcap-link-linux-sll", "link type 113 (Linux cooked",
                 pb.pcap_file([(t, pb.linux_sll_frame(f)) for t, f in FRAMES], link_type=113)),
    capture_case("pcap-link-802.11", "link type 105 (802.11",
                 pb.pcap_file(FRAMES, link_type=105)),
    # --- the records
    capture_case("pcap-cut-inside-first-packet", "ends inside its first packet",
                 CAPTURE[:24 + 16 + 500]),
    capture_case("pcap-cut-inside-first-header", "ends inside its first packet",
                 CAPTURE[:24 + 8]),
    capture_case("pcap-snaplen-96", "tcpdump -s 0", pb.pcap_file(FRAMES, snaplen=96)),
    capture_case("pcap-reversed", "reordercap", pb.pcap_file(FRAMES[::-1])),
    capture_case("pcap-two-swapped", "out of time order",
                 pb.pcap_file(FRAMES[:3] + FRAMES[4:5] + FRAMES[3:4] + FRAMES[5:])),
    # --- the data packets
    capture_case("pcap-every-packet-twice", "8 of its 16 data packets are recorded twice",
                 pb.pcap_file([r for r in FRAMES for _ in range(2)])),
    capture_case("pcap-product-hdl32e", "product id 0x21 (HDL-32E)",
                 pb.vlp16_capture(product_id=0x21)),
    capture_case("pcap-return-mode-changes", "data packet 5 has return mode 0x38 (last)",
                 pb.pcap_file(FRAMES[:4] + pb.vlp16_frames(8, return_mode=pb.LAST)[4:])),
    capture_case("pcap-return-mode-unknown", "return mode 0x00 (unknown)",
                 pb.vlp16_capture(return_mode=0)),
    # --- the timed turntable log
    timed_log_case("log-jump-270", "steps +270 deg from line 2 (0) to line 3 (270)", [0, 270]),
    timed_log_case("log-jump-back-200", "steps -200 deg from line 3", [0, 10, -190]),
    timed_log_case("log-jump-over-a-turn", "a turn of +400 deg or of -320 deg", [0, 400]),
]


@pytest.mark.parametrize("case", PROCESS_CASES + FIT_CASES + PCAP_CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)


def test_table_size():
    cases = PROCESS_CASES + FIT_CASES + PCAP_CASES
    assert len(PROCESS_CASES) >= 45 and len(FIT_CASES) >= 20 and len(PCAP_CASES) >= 16
    assert len({c.name for c in cases}) == len(cases)
    assert SCAN_FORMAT.endswith("/1")
