"""Fuzzing the pipeline's readers and the sphere fit: whatever the input, the result is a valid
value or one of our errors (:class:`~markerplan.errors.MarkerPlanError`), never another
exception."""

from __future__ import annotations

import io
import json
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from markerplan.errors import MarkerPlanError
from pipeline.chain.evaluation import read_reference
from pipeline.scans.pointsets import read_points
from pipeline.scans.scan_format import StationScan, _write_npz, read_scan, read_truth, write_scan
from pipeline.sphere_centres.sphere_fit import fit_sphere
from pipeline.tables.marker_table import COLUMNS, read_marker_table

FUZZ = settings(max_examples=40, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


def _scan(n: int = 40) -> StationScan:
    rng = np.random.default_rng(1)
    return StationScan(
        turntable_angle_rad=np.linspace(0, np.pi, 3),
        frame_index=np.sort(rng.integers(0, 3, n)).astype(np.uint32),
        laser_id=rng.integers(0, 16, n).astype(np.uint8),
        spin_azimuth_rad=rng.uniform(0, 6.28, n).astype(np.float32),
        range_m=rng.uniform(1, 5, n).astype(np.float32),
        xyz_sensor_m=rng.normal(size=(n, 3)).astype(np.float32),
        metadata={"station_id": "S01", "source": "test"})


def _scan_bytes() -> bytes:
    with tempfile.TemporaryDirectory() as d:
        return write_scan(Path(d) / "s.scan.npz", _scan()).read_bytes()


SCAN_BYTES = _scan_bytes()


def _arrays() -> dict:
    s = _scan()
    arrays = {k: getattr(s, k) for k in ("turntable_angle_rad", "frame_index", "laser_id",
                                         "spin_azimuth_rad", "range_m", "xyz_sensor_m")}
    arrays["metadata"] = np.array(json.dumps({"format": "markerplan-scan/1", **s.metadata}))
    return arrays


def _ours_or_value(fn, *args):
    try:
        return fn(*args)
    except MarkerPlanError as exc:
        assert "\n" not in str(exc), str(exc)
        return None


def _write(tmp: Path, name: str, data: bytes) -> Path:
    path = tmp / name
    path.write_bytes(data)
    return path


JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-10**20, 10**20) | st.floats(allow_nan=False)
    | st.text(max_size=8),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=6), kids,
                                                              max_size=4),
    max_leaves=12)


# --- read_scan ------------------------------------------------------------------------------

@FUZZ
@given(edits=st.lists(st.tuples(st.integers(0, len(SCAN_BYTES) - 1), st.integers(0, 255)),
                      min_size=1, max_size=6),
       cut=st.none() | st.integers(0, len(SCAN_BYTES)))
def test_read_scan_mutated_bytes(tmp_path, edits, cut):
    data = bytearray(SCAN_BYTES)
    for pos, value in edits:
        data[pos] = value
    scan = _ours_or_value(read_scan, _write(tmp_path, "m.scan.npz", bytes(data[:cut])))
    if scan is not None:
        assert np.all(np.isfinite(scan.xyz_sensor_m)) and scan.n_points > 0


def _stored_npy(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, arr)
    return buf.getvalue()


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(member=st.sampled_from(sorted(_arrays())), pos=st.integers(0, 200),
       value=st.integers(0, 255))
def test_read_scan_mutated_npy_member(tmp_path, member, pos, value):
    """Bytes changed inside one stored (uncompressed) member: header or data."""
    arrays = _arrays()
    path = tmp_path / "m.scan.npz"
    with zipfile.ZipFile(path, "w") as zf:
        for name, arr in arrays.items():
            raw = bytearray(_stored_npy(np.asarray(arr)))
            if name == member:
                raw[pos % len(raw)] = value
            zf.writestr(f"{name}.npy", bytes(raw))
    _ours_or_value(read_scan, path)


FLOAT_VALUES = st.floats(allow_nan=True, allow_infinity=True, width=64) | st.sampled_from(
    [1e300, -1e300, 1e30, 1e4, 0.0, -1.0])


@FUZZ
@given(name=st.sampled_from(["turntable_angle_rad", "frame_index", "laser_id",
                             "spin_azimuth_rad", "range_m", "xyz_sensor_m"]),
       value=FLOAT_VALUES | st.integers(-2**40, 2**40),
       dtype=st.sampled_from([None, np.float64, np.int64, np.float32, np.uint8, np.int8]),
       drop=st.integers(0, 2))
def test_read_scan_mutated_arrays(tmp_path, name, value, dtype, drop):
    arrays = _arrays()
    a = arrays[name].astype(dtype or arrays[name].dtype)
    with np.errstate(all="ignore"):
        try:
            a.flat[0] = value
        except (OverflowError, ValueError):
            pass
    if drop:
        a = a[:-drop]
    arrays[name] = a
    _write_npz(tmp_path / "m.scan.npz", arrays)
    scan = _ours_or_value(read_scan, tmp_path / "m.scan.npz")
    if scan is not None:
        assert int(scan.laser_id.max()) <= 15
        assert np.all(np.abs(scan.range_m) <= 1e4)


@FUZZ
@given(meta=JSON_VALUES, merge=st.booleans())
def test_read_scan_fuzzed_metadata(tmp_path, meta, merge):
    arrays = _arrays()
    if merge and isinstance(meta, dict):
        meta = {"format": "markerplan-scan/1", "station_id": "S1", **meta}
    arrays["metadata"] = np.array(json.dumps(meta))
    _write_npz(tmp_path / "m.scan.npz", arrays)
    _ours_or_value(read_scan, tmp_path / "m.scan.npz")


# --- read_truth / read_reference ------------------------------------------------------------

TRUTH = {"format": "markerplan-truth/1", "station_id": "S1",
         "station_pose": {"position_m": [0, 0, 1], "heading_rad": 0.0},
         "mounting_offsets": {"vertical_axis_error_rad": 0.0, "lframe_tilt_rad": 0.0,
                              "axis_offset_m": [0.0, 0.0]},
         "marker_radius_m": 0.1,
         "markers": [{"id": "M0", "centre_station_m": [1, 2, 3]},
                     {"id": "M1", "centre_station_m": [3, 2, 1]}]}


@FUZZ
@given(key=st.sampled_from(["format", "station_id", "station_pose", "mounting_offsets",
                            "marker_radius_m", "markers", "m0", "m0.id", "m0.centre"]),
       value=JSON_VALUES)
def test_read_truth_and_reference_fuzzed(tmp_path, key, value):
    doc = json.loads(json.dumps(TRUTH))
    if key == "m0":
        doc["markers"][0] = value
    elif key.startswith("m0."):
        doc["markers"][0][{"id": "id", "centre": "centre_station_m"}[key[3:]]] = value
    else:
        doc[key] = value
    path = tmp_path / "t.truth.json"
    path.write_text(json.dumps(doc))
    _ours_or_value(read_truth, path)
    ref = _ours_or_value(read_reference, path)
    if ref is not None:
        assert np.all(np.isfinite(ref.centres_m)) and len(set(ref.ids)) == len(ref.ids)


@FUZZ
@given(data=st.binary(max_size=200) | st.text(max_size=200).map(str.encode))
def test_read_truth_random_bytes(tmp_path, data):
    path = _write(tmp_path, "t.truth.json", data)
    _ours_or_value(read_truth, path)


CSV_CELLS = st.sampled_from(["1", "-2.5", "nan", "inf", "1e300", "", "M1", "x", "1e999", " 3 ",
                             '"q"', "0"])


@FUZZ
@given(header=st.sampled_from(["id,x_m,y_m,z_m", "id,x_m,y_m", "x_m,id,z_m,y_m",
                               "id,x_m,x_m,z_m", ""]),
       rows=st.lists(st.lists(CSV_CELLS, min_size=0, max_size=6), max_size=6),
       raw=st.none() | st.binary(max_size=60))
def test_read_reference_csv_fuzzed(tmp_path, header, rows, raw):
    text = header + "\n" + "".join(",".join(r) + "\n" for r in rows)
    data = text.encode() + (raw or b"")
    ref = _ours_or_value(read_reference, _write(tmp_path, "r.csv", data))
    if ref is not None:
        assert ref.centres_m.shape == (len(ref.ids), 3)
        assert np.all(np.isfinite(ref.centres_m)) and len(set(ref.ids)) == len(ref.ids)


# --- read_points / fit_sphere ---------------------------------------------------------------

POINT_CELLS = st.sampled_from(["1", "2.5", "-3", "nan", "inf", "-inf", "1e300", "1e999", "x",
                               "", "0", "1e-300"])


@FUZZ
@given(lines=st.lists(st.lists(POINT_CELLS, max_size=5).map(" ".join), max_size=8),
       header=st.sampled_from(["", "x,y,z\n", "id,z_m,y_m,x_m\n", "a\n", "# c\n"]),
       raw=st.none() | st.binary(max_size=40))
def test_read_points_fuzzed(tmp_path, lines, header, raw):
    data = (header + "\n".join(lines)).encode() + (raw or b"")
    pts = _ours_or_value(read_points, _write(tmp_path, "p.xyz", data))
    if pts is not None:
        assert pts.ndim == 2 and pts.shape[1] == 3 and pts.shape[0] >= 1
        assert np.all(np.isfinite(pts)) and np.all(np.abs(pts) <= 1e8)


COORD = st.floats(-1e9, 1e9, allow_nan=False) | st.sampled_from(
    [0.0, 1.0, np.nan, np.inf, 1e300, 1e-300])


@FUZZ
@given(points=st.lists(st.tuples(COORD, COORD, COORD), max_size=12)
       | st.integers(1, 30).map(lambda n: [(1.0, 2.0, 3.0)] * n)
       | st.integers(4, 30).map(lambda n: [(0.01 * k, 0.02 * k, 0.0) for k in range(n)]),
       radius=st.sampled_from([0.1, 0.05, 0.0, -1.0, np.nan, np.inf, 1e300, 1e-300]),
       method=st.sampled_from(["fixed-radius", "hemisphere-icp"]))
def test_fit_sphere_fuzzed(points, radius, method):
    pts = np.array(points, dtype=float).reshape(-1, 3)
    with np.errstate(all="ignore"):
        fit = _ours_or_value(fit_sphere, pts, radius, (0.0, 0.0, 0.0), method)
    if fit is not None:
        assert np.all(np.isfinite(fit.centre_m)) and np.isfinite(fit.rms_m)
        assert fit.n_used >= 1


@settings(max_examples=15, deadline=None)
@given(centre=st.tuples(*[st.floats(-20, 20)] * 3), noise=st.floats(0, 0.01),
       n=st.integers(4, 60), method=st.sampled_from(["fixed-radius", "hemisphere-icp"]))
def test_fit_sphere_on_noisy_caps(centre, noise, n, method):
    c = np.array(centre)
    if np.linalg.norm(c) < 0.5:
        c = c + [1.0, 0, 0]
    rng = np.random.default_rng(n)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    u[u @ c > 0] *= -1  # the half facing the sensor at the origin
    pts = c + 0.1 * u + rng.normal(0, noise, (n, 3))
    fit = _ours_or_value(fit_sphere, pts, 0.1, (0.0, 0.0, 0.0), method)
    if fit is not None:
        assert np.all(np.isfinite(fit.centre_m)) and np.isfinite(fit.rms_m)


# --- read_marker_table ----------------------------------------------------------------------

@FUZZ
@given(drop=st.integers(-1, len(COLUMNS) - 1), extra=st.booleans(),
       rows=st.lists(st.integers(len(COLUMNS) - 2, len(COLUMNS) + 1), max_size=4),
       raw=st.none() | st.binary(max_size=40))
def test_read_marker_table_fuzzed(tmp_path, drop, extra, rows, raw):
    cols = [c for k, c in enumerate(COLUMNS) if k != drop] + (["extra"] if extra else [])
    text = ",".join(cols) + "\n" + "".join(",".join(["1"] * n) + "\n" for n in rows)
    table = _ours_or_value(read_marker_table,
                           _write(tmp_path, "m.csv", text.encode() + (raw or b"")))
    if table is not None:
        assert all(tuple(r) == COLUMNS for r in table)


@pytest.mark.parametrize("data", [b"", b"\n\n", b"\xef\xbb\xbf", b"\x00" * 10])
def test_degenerate_files(tmp_path, data):
    for fn, name in ((read_scan, "a.scan.npz"), (read_truth, "a.json"),
                     (read_points, "a.xyz"), (read_reference, "a.csv"),
                     (read_marker_table, "b.csv")):
        path = _write(tmp_path, name, data)
        with pytest.raises(MarkerPlanError):
            fn(path)
