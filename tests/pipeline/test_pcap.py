"""Real VLP-16 capture (btlad/ScanParser, CC0) read into the scan structure."""

import numpy as np
import pytest

from markerplan.errors import DataError, InputFileError
from pipeline.pcap import read_turntable_csv, read_vlp16_pcap
from pipeline.rig import VLP16_ELEVATION_DEG
from pipeline.scan_format import read_scan, write_scan


@pytest.fixture
def pcap(real_data):
    return real_data / "vlp16_pcap" / "my.pcap"


def test_single_frame_without_angles(pcap):
    scan = read_vlp16_pcap(pcap)
    assert scan.n_frames == 1
    assert scan.n_points > 10_000
    assert set(np.unique(scan.laser_id)) == set(range(16))
    # indoor capture: ranges up to ~4 m
    assert 0.3 < scan.range_m.min() and scan.range_m.max() < 6.0


def test_channels_have_their_datasheet_elevation(pcap):
    scan = read_vlp16_pcap(pcap)
    xyz = scan.xyz_sensor_m.astype(float)
    elev = np.degrees(np.arcsin(xyz[:, 2] / np.linalg.norm(xyz, axis=1)))
    for ch in range(16):
        median = np.median(elev[scan.laser_id == ch])
        # the factory vertical offsets (a few mm at ~3 m) bend the apparent angle < 0.3 deg
        assert abs(median - VLP16_ELEVATION_DEG[ch]) < 0.3, ch


def test_azimuth_matches_xyz_convention(pcap):
    scan = read_vlp16_pcap(pcap)
    x, y = scan.xyz_sensor_m[:, 0], scan.xyz_sensor_m[:, 1]
    np.testing.assert_allclose(np.sin(scan.spin_azimuth_rad), x / np.hypot(x, y), atol=1e-5)


def test_turntable_angles_per_revolution(pcap, tmp_path):
    csv = tmp_path / "tt.csv"
    csv.write_text("frame,turntable_angle_deg\n0,0\n1,180\n")
    scan = read_vlp16_pcap(pcap, read_turntable_csv(csv))
    assert scan.n_frames == 2
    np.testing.assert_allclose(scan.turntable_angle_rad, [0, np.pi])
    out = write_scan(tmp_path / "real.scan.npz", scan)
    assert read_scan(out).n_points == scan.n_points


def test_wrong_angle_count(pcap):
    with pytest.raises(DataError, match="revolutions"):
        read_vlp16_pcap(pcap, np.zeros(5))


def test_bad_csv_and_missing_file(tmp_path):
    bad = tmp_path / "tt.csv"
    bad.write_text("angle\n1\n")
    with pytest.raises(InputFileError, match="turntable_angle_deg"):
        read_turntable_csv(bad)
    with pytest.raises(InputFileError, match="does not exist"):
        read_vlp16_pcap(tmp_path / "none.pcap")
