"""Real VLP-16 capture (btlad/ScanParser, CC0) read into the scan structure, and the turntable
log's two forms.

Figures of my.pcap (from its packet headers): 79 records, 41 VLP-16 data packets; the file ends
inside the 79th (a 554-byte position packet of which 242 bytes are there). The first data
packet is stamped 1599213599.872340 s, the last of the first revolution 1599213600.072244 s and
the capture's last 1599213600.236023 s. The decoder makes two revolutions of it: a complete one
(35 packets x 384 = 13440 returns) and the 6-packet remainder (2304 returns).

The pcap reader's checks and the dual-return reading run on synthetic captures
(:mod:`tests.pcap_builder`); the refused captures are cases of
tests/cli/test_bad_input_pipeline.py.
"""

import numpy as np
import pytest

from markerplan.errors import DataError, InputFileError
from pipeline.scans.pcap import (
    TurntableLog,
    decode_vlp16_pcap,
    read_turntable_log,
    scan_from_revolutions,
)
from pipeline.scans.rig import VLP16_ELEVATION_DEG
from pipeline.scans.scan_format import read_scan, write_scan
from tests import pcap_builder as pb

FIRST_PACKET_S = 1599213599.872340
END_OF_FIRST_REVOLUTION_S = 1599213600.072244
LAST_PACKET_S = 1599213600.236023
#: one data packet's firings last 1.3 ms after its stamp
PACKET_S = 1.33e-3


@pytest.fixture
def capture(real_data):
    return decode_vlp16_pcap(real_data / "vlp16_pcap" / "my.pcap")


@pytest.fixture
def revolutions(capture):
    return capture.revolutions


@pytest.fixture
def scan(revolutions):
    return scan_from_revolutions(revolutions, None, "my", "my.pcap")


def test_revolutions_of_the_capture(revolutions):
    assert [len(r.points) for r in revolutions] == [13440, 2304]
    assert [r.complete for r in revolutions] == [True, False]
    first, last = revolutions
    # the host stamps plus the firings' offsets: the revolution spans its packets
    assert first.start_s == pytest.approx(FIRST_PACKET_S, abs=2e-4)
    assert first.end_s == pytest.approx(END_OF_FIRST_REVOLUTION_S + PACKET_S, abs=5e-5)
    assert last.end_s == pytest.approx(LAST_PACKET_S + PACKET_S, abs=5e-5)
    assert first.time_s == pytest.approx(0.5 * (first.start_s + first.end_s))
    # packets are missing inside the first revolution: returns over ~110 of 360 degrees
    assert 0.2 < first.coverage < 0.35


def test_real_capture_is_cut_inside_its_last_packet(capture):
    """The file ends inside packet 79 (not a data packet): the whole packets are read."""
    assert (capture.cut_packet, capture.return_mode) == (79, "strongest")


def _ranges_m(path) -> np.ndarray:
    capture = decode_vlp16_pcap(path)
    return np.concatenate([np.linalg.norm(r.points[:, :3], axis=1) for r in capture.revolutions])


@pytest.mark.parametrize("mode, name", [(pb.STRONGEST, "strongest"), (pb.LAST, "last")])
def test_synthetic_capture_decodes(tmp_path, mode, name):
    """100 packets of 384 returns at 3 m: one complete revolution (76 packets: 360 deg at
    4.8 deg a packet) and the remainder."""
    path = tmp_path / "c.pcap"
    path.write_bytes(pb.vlp16_capture(100, return_mode=mode))
    capture = decode_vlp16_pcap(path)
    assert [(len(r.points), r.complete) for r in capture.revolutions] == [(76 * 384, True),
                                                                         (24 * 384, False)]
    assert (capture.return_mode, capture.cut_packet) == (name, None)
    np.testing.assert_allclose(_ranges_m(path), 3.0, atol=5e-3)  # + laser offsets
    assert capture.revolutions[0].start_s == pytest.approx(pb.START_S, abs=1e-3)


def test_dual_return_keeps_the_last_return(tmp_path):
    """Each firing of a dual-return packet has its last return (3 m) and its strongest
    (2 m): only the last is kept, one point per firing as in last-return mode."""
    path = tmp_path / "dual.pcap"
    path.write_bytes(pb.vlp16_capture(20, return_mode=pb.DUAL))
    capture = decode_vlp16_pcap(path)
    assert capture.return_mode == "dual"
    ranges = _ranges_m(path)
    assert ranges.size == 20 * 6 * 32  # 6 firing-block pairs of 32 returns a packet
    np.testing.assert_allclose(ranges, 3.0, atol=5e-3)


def test_file_cut_inside_a_later_packet_reads_the_whole_packets(tmp_path):
    data = pb.vlp16_capture(8)
    whole = 24 + 5 * (16 + pb.ETHERNET_FRAME_BYTES)
    for cut_at in (whole + 8, whole + 16 + 500):  # inside packet 6's header, its data
        path = tmp_path / "cut.pcap"
        path.write_bytes(data[:cut_at])
        capture = decode_vlp16_pcap(path)
        assert capture.cut_packet == 6
        assert sum(len(r.points) for r in capture.revolutions) == 5 * 384


def test_packets_other_than_data_packets_are_passed_over(tmp_path):
    """A position packet (512-byte payload) and a 1206-byte UDP payload that is not a data
    packet (no firing-block flag) between the data packets change nothing."""
    frames = pb.vlp16_frames(8)
    t = frames[3][0] + 1e-4
    other = [(t, pb.ethernet_frame(bytes(512), port=8308)),
             (t, pb.ethernet_frame(bytes(pb.DATA_PACKET_BYTES)))]
    path = tmp_path / "mixed.pcap"
    path.write_bytes(pb.pcap_file(frames[:4] + other + frames[4:]))
    capture = decode_vlp16_pcap(path)
    assert sum(len(r.points) for r in capture.revolutions) == 8 * 384


def test_single_frame_without_angles(scan):
    assert scan.n_frames == 1
    assert scan.n_points == 15744
    assert set(np.unique(scan.laser_id)) == set(range(16))
    # indoor capture: ranges up to ~4 m
    assert 0.3 < scan.range_m.min() and scan.range_m.max() < 6.0


def test_channels_have_their_datasheet_elevation(scan):
    xyz = scan.xyz_sensor_m.astype(float)
    elev = np.degrees(np.arcsin(xyz[:, 2] / np.linalg.norm(xyz, axis=1)))
    for ch in range(16):
        median = np.median(elev[scan.laser_id == ch])
        # the factory vertical offsets (a few mm at ~3 m) bend the apparent angle < 0.3 deg
        assert abs(median - VLP16_ELEVATION_DEG[ch]) < 0.3, ch


def test_azimuth_matches_xyz_convention(scan):
    x, y = scan.xyz_sensor_m[:, 0], scan.xyz_sensor_m[:, 1]
    np.testing.assert_allclose(np.sin(scan.spin_azimuth_rad), x / np.hypot(x, y), atol=1e-5)


def test_one_frame_per_revolution(revolutions, tmp_path):
    csv = tmp_path / "tt.csv"
    csv.write_text("frame,turntable_angle_deg\n0,0\n1,180\n")
    angles = read_turntable_log(csv).frame_angles(np.array([r.time_s for r in revolutions]))
    scan = scan_from_revolutions(revolutions, angles, "S1", "my.pcap")
    assert scan.n_frames == 2
    np.testing.assert_allclose(scan.turntable_angle_rad, [0, np.pi])
    assert np.bincount(scan.frame_index).tolist() == [13440, 2304]
    out = write_scan(tmp_path / "real.scan.npz", scan)
    back = read_scan(out)
    assert back.n_points == scan.n_points and back.station_id == "S1"
    assert back.metadata["capture"]["revolution_time_s"] == [r.time_s for r in revolutions]


def test_wrong_angle_count(revolutions):
    with pytest.raises(DataError, match="2 revolutions but 5 turntable angles"):
        scan_from_revolutions(revolutions, np.zeros(5), "S1", "my.pcap")


def test_timed_log_is_unwrapped_and_interpolated(tmp_path):
    csv = tmp_path / "tt.csv"
    csv.write_text("time_s,turntable_angle_deg\n100,350\n102,10\n104,30\n")
    log = read_turntable_log(csv)
    np.testing.assert_allclose(np.degrees(log.angle_rad), [350, 370, 390])
    # wraps across 0/360 either way, by under 90 deg; a continuous log as it is
    for angles, unwrapped in [("10,350,280", [10, -10, -80]), ("0,150,300,450", None),
                              ("100,-60", None)]:
        csv.write_text("time_s,turntable_angle_deg\n" + "".join(
            f"{100 + k},{a}\n" for k, a in enumerate(angles.split(","))))
        expected = unwrapped or [float(a) for a in angles.split(",")]
        np.testing.assert_allclose(np.degrees(read_turntable_log(csv).angle_rad), expected)
    # 350 + 10 deg/s x 0.5 s; 370 + 10 deg/s x 1.5 s; the ends themselves
    np.testing.assert_allclose(np.degrees(log.frame_angles(np.array([100.5, 103.5, 100, 104]))),
                               [355, 385, 350, 390])


def test_timed_log_refuses_frames_outside_its_span():
    log = TurntableLog(np.zeros(2), np.array([10.0, 20.0]), "turntable log t.csv")
    with pytest.raises(DataError, match=r"spans 10.000-20.000 s but 2 frame\(s\) lie outside"):
        log.frame_angles(np.array([9.0, 15.0, 21.0]))


@pytest.mark.parametrize("n_rows, fix", [(1, "give one row per frame"),
                                         (3, "drop the extra rows")])
def test_per_frame_log_needs_one_row_per_frame(n_rows, fix):
    log = TurntableLog(np.zeros(n_rows), None, "turntable log t.csv")
    with pytest.raises(DataError, match=f"has {n_rows} row\\(s\\) but the capture has 2 frame"
                                        f"\\(s\\).*{fix}"):
        log.frame_angles(np.array([1.0, 2.0]))


@pytest.mark.parametrize("text, match", [
    ("angle\n1\n", "missing column.*turntable_angle_deg"),
    ("turntable_angle_deg\n", "no rows"),
    ("turntable_angle_deg\nnan\n", "line 2, turntable_angle_deg: must be a finite number"),
    ("turntable_angle_deg\n1\nabc\n", "line 3, turntable_angle_deg: must be a number"),
    ("frame,turntable_angle_deg\n0,1\n2,3\n", "line 3 has '2'"),
    ("time_s,turntable_angle_deg\n5,1\n", "at least two rows"),
    ("time_s,turntable_angle_deg\n5,1\n6,2\n6,3\n", "line 4 has 6 after 6"),
    ("time_s,turntable_angle_deg\n5,1\ninf,2\n", "line 3, time_s: must be a finite"),
    ("time_s,turntable_angle_deg\n5,0\n6,270\n", r"steps \+270 deg from line 2 \(0\) to line 3"),
    ("time_s,turntable_angle_deg\n5,0\n6,180\n", r"\+180 deg or of -180 deg the other way"),
    ("time_s,turntable_angle_deg\n5,0\n6,10\n7,-350\n", "steps -360 deg from line 3"),
])
def test_bad_logs(tmp_path, text, match):
    bad = tmp_path / "tt.csv"
    bad.write_text(text)
    with pytest.raises(InputFileError, match=match):
        read_turntable_log(bad)


def test_missing_files(tmp_path):
    with pytest.raises(InputFileError, match="file not found"):
        read_turntable_log(tmp_path / "none.csv")
    with pytest.raises(InputFileError, match="does not exist"):
        decode_vlp16_pcap(tmp_path / "none.pcap")


def test_bad_captures(tmp_path):
    empty, garbage, header = tmp_path / "e.pcap", tmp_path / "g.pcap", tmp_path / "h.pcap"
    empty.write_bytes(b"")
    garbage.write_bytes(b"not a capture at all, but long enough to hold a header")
    header.write_bytes(bytes.fromhex("d4c3b2a1020004000000000000000000ffff000001000000"))
    with pytest.raises(InputFileError, match="is empty"):
        decode_vlp16_pcap(empty)
    with pytest.raises(InputFileError, match="not a readable packet capture"):
        decode_vlp16_pcap(garbage)
    with pytest.raises(DataError, match="no VLP-16 returns"):
        decode_vlp16_pcap(header)
