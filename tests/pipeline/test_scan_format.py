import numpy as np
import pytest

from markerplan.errors import DataError, InputFileError
from pipeline.scans.scan_format import StationScan, read_scan, write_scan


def _scan(n=10, frames=2):
    rng = np.random.default_rng(0)
    return StationScan(
        turntable_angle_rad=np.linspace(0, np.pi, frames),
        frame_index=np.sort(rng.integers(0, frames, n)).astype(np.uint32),
        laser_id=rng.integers(0, 16, n).astype(np.uint8),
        spin_azimuth_rad=rng.uniform(0, 6.28, n).astype(np.float32),
        range_m=rng.uniform(1, 5, n).astype(np.float32),
        xyz_sensor_m=rng.normal(size=(n, 3)).astype(np.float32),
        metadata={"station_id": "S01"},
    )


def test_roundtrip_and_bytes_identical(tmp_path):
    a, b = tmp_path / "a.scan.npz", tmp_path / "b.scan.npz"
    write_scan(a, _scan())
    write_scan(b, _scan())
    assert a.read_bytes() == b.read_bytes()
    back = read_scan(a)
    np.testing.assert_array_equal(back.range_m, _scan().range_m)
    assert back.station_id == "S01"


def test_empty_scan_refused(tmp_path):
    s = _scan(n=0)
    with pytest.raises(DataError, match="empty"):
        write_scan(tmp_path / "e.scan.npz", s)


def test_missing_turntable_angles_refused(tmp_path):
    s = _scan()
    s.turntable_angle_rad[1] = np.nan
    with pytest.raises(DataError, match="turntable angle"):
        s.validate()


def test_malformed_file(tmp_path):
    p = tmp_path / "bad.scan.npz"
    p.write_text("not a zip")
    with pytest.raises(InputFileError, match="not a readable scan"):
        read_scan(p)
    with pytest.raises(InputFileError, match="does not exist"):
        read_scan(tmp_path / "nope.scan.npz")
