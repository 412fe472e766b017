"""Read a real Velodyne VLP-16 packet capture and a turntable log into the station-scan
structure.

Decoding is done by ``velodyne_decoder`` (model VLP-16): :func:`decode_vlp16_pcap` reads the
pcap itself (checking its structure: link type, whole packets in time order, one return mode,
no packet recorded twice), hands the data packets to the decoder and returns the capture's
spin revolutions (:class:`Capture`), :func:`scan_from_revolutions` turns the ones kept into a
:class:`~pipeline.scans.scan_format.StationScan` (one frame per revolution, or all of them as one
frame at turntable angle 0), and :func:`read_turntable_log` reads the turntable's angles.

Conversions made here:

- ``velodyne_decoder`` returns ROS-convention points (x forward, y left, z up). Our sensor
  frame is the Velodyne manual's (x right, y forward, z up; :mod:`pipeline.scans.rig`), so
  ``x_S = -y_ros``, ``y_S = x_ros``, ``z_S = z_ros``.
- Its ``ring`` is the laser index sorted by elevation; the scan format stores the VLP-16
  *channel* (firing order), recovered with :data:`VLP16_ELEVATION_DEG`.
- ``range_m`` is the point's distance from the sensor origin (the decoder has already
  applied the per-laser vertical offsets of the factory calibration).

Times: the decoder stamps each revolution with the capture computer's clock (``stamp.host``:
the pcap timestamp of the revolution's last packet, UNIX seconds) and gives each point its
firing time relative to that stamp (device clock offsets). A revolution's time
(:attr:`Revolution.time_s`) is the stamp plus the middle of its firing times: the moment the
spin is half done, the best single time for a turntable that turns while the head spins.
A timed turntable log must be on the same clock (UNIX seconds of the capture computer).

Partial revolutions: the decoder (no cut angle) starts the first revolution at the capture's
first packet and cuts one each time the spin azimuth has come round to its start again, so
every revolution but the last is complete; the last is what is left when the file ends
(:attr:`Revolution.complete` is False), unless the capture ends exactly on a cut. Packets lost
inside a revolution do not make it partial: its returns are missing over that azimuth, which
:attr:`Revolution.coverage` measures.
"""

from __future__ import annotations

import mmap
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplan.errors import DataError, InputFileError
from markerplan.reading import finite_number, read_csv
from pipeline.scans.rig import VLP16_ELEVATION_DEG
from pipeline.scans.scan_format import MAX_ABS_ANGLE_RAD, StationScan, sensor_metadata

#: channel of each decoder ring (ring k = k-th lowest elevation)
_CHANNEL_OF_RING = np.argsort(VLP16_ELEVATION_DEG, kind="stable").astype(np.uint8)
#: Largest |time_s| accepted in a timed turntable log, seconds (UNIX time is ~1.7e9 s).
_MAX_ABS_TIME_S = 1e11
# decoder point columns (as_pcl_structs=False)
_X, _Y, _Z, _INTENSITY, _TIME, _RING, _RETURN_TYPE = 0, 1, 2, 3, 4, 6, 7
#: A classic pcap's byte order and timestamp fractions per second, by its first four bytes
_PCAP_FORMAT = {b"\xd4\xc3\xb2\xa1": ("<", 1e6), b"\xa1\xb2\xc3\xd4": (">", 1e6),
                b"\x4d\x3c\xb2\xa1": ("<", 1e9), b"\xa1\xb2\x3c\x4d": (">", 1e9)}
_PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"
_GLOBAL_HEADER_BYTES, _RECORD_HEADER_BYTES = 24, 16
_LINKTYPE_ETHERNET = 1
_LINK_TYPE_NAMES = {0: "BSD loopback", 101: "raw IP", 105: "802.11 Wi-Fi",
                    113: "Linux cooked SLL, what tcpdump -i any records", 127: "802.11 radiotap",
                    276: "Linux cooked SLL2"}
#: VLP-16 data packet (UDP payload), bytes
_DATA_PACKET_BYTES = 1206
_UDP_HEADER_BYTES = 8
#: Factory bytes at the end of a data packet: product id, and the return mode
_PRODUCT_VLP16 = 0x22
_PRODUCT_NAMES = {0x21: "HDL-32E", 0x24: "Puck Hi-Res", 0x28: "VLP-32C", 0x31: "Velarray",
                  0xA1: "VLS-128"}
_RETURN_MODES = {0x37: "strongest", 0x38: "last", 0x39: "dual"}
_DUAL_RETURN = 0x39
#: Data packets within which a repeated device time marks a packet recorded twice
_DUPLICATE_WINDOW = 8


@dataclass(frozen=True, eq=False)
class Revolution:
    """One decoded spin revolution of the VLP-16.

    Attributes
    ----------
    points : (n, 8) float32
        The decoder's rows in firing order: x, y, z (ROS convention, metres), intensity,
        time (seconds from the decoder's stamp of the revolution), column, ring, return type.
    start_s, end_s : float
        Capture-computer times of the first and last firing, UNIX seconds (module docstring).
    complete : bool
        False for the remainder the capture's end cut short (module docstring).
    """

    points: np.ndarray
    start_s: float
    end_s: float
    complete: bool

    @property
    def time_s(self) -> float:
        """The revolution's time: the middle of its firings, UNIX seconds."""
        return 0.5 * (self.start_s + self.end_s)

    @property
    def coverage(self) -> float:
        """Fraction of the spin's 360 one-degree azimuth sectors that hold a return."""
        azimuth_deg = np.degrees(np.arctan2(self.points[:, _Y], self.points[:, _X]))
        sectors = np.floor(np.mod(azimuth_deg, 360.0)).astype(int) % 360
        return np.unique(sectors).size / 360.0


@dataclass(frozen=True, eq=False)
class Capture:
    """A decoded VLP-16 capture.

    Attributes
    ----------
    revolutions : list of Revolution
        Every revolution with at least one return (complete and partial), in capture order.
    return_mode : str
        The data packets' return mode: ``"strongest"``, ``"last"`` or ``"dual"`` (of which
        the last return of each firing is kept, what last-return mode records).
    cut_packet : int or None
        The packet (numbered from 1, as Wireshark does) the file ends inside, left out: the
        file was cut short while recording or copying; ``None`` for a whole file.
    """

    revolutions: list[Revolution]
    return_mode: str
    cut_packet: int | None


def decode_vlp16_pcap(path: str | Path) -> Capture:
    """Decode a VLP-16 ``.pcap`` into its spin revolutions.

    The pcap is read here (memory-mapped: headers and the data packets' bytes only) and its
    VLP-16 data packets are handed to ``velodyne_decoder``'s stream decoder. Refused: another
    file format, a link type other than Ethernet, a file cut inside its first packet, packets
    cut by the snap length or out of time order, data packets of another sensor, in more than
    one return mode, or recorded twice. A file cut inside a later packet is read up to it
    (:attr:`Capture.cut_packet`).

    Parameters
    ----------
    path : str or Path
        Packet capture (classic pcap of Ethernet frames; strongest, last or dual return).
        Packets other than VLP-16 data packets (a 1206-byte UDP payload starting with a firing
        block: position packets, other traffic) are passed over.

    Returns
    -------
    capture : Capture
        Its revolutions, return mode and the packet the file is cut inside.

    Raises
    ------
    InputFileError
        Missing, empty or not a classic pcap file (pcapng named); a link type other than
        Ethernet; cut inside the first packet; packets cut by the snap length or out of time
        order.
    DataError
        No VLP-16 returns; data packets of another sensor, in an unknown or changing return
        mode, or recorded twice.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"pcap file {path} does not exist; check the path")
    if path.stat().st_size == 0:
        raise InputFileError(f"pcap file {path} is empty; give a capture recorded with tcpdump "
                             "or Wireshark (.pcap)")
    with path.open("rb") as file, mmap.mmap(file.fileno(), 0, access=mmap.ACCESS_READ) as buf:
        order, divisor = _pcap_format(buf, path)
        records, cut_packet = _record_headers(buf, order, path)
        _check_records(records, divisor, path)
        data = _data_packets(buf, records)
        mode = _check_data_packets(data, path)
        decoded = _decode(buf, records[data[:, 0] - 1], divisor)
    if mode == _DUAL_RETURN:
        import velodyne_decoder as vd

        strongest = float(vd.ReturnMode.STRONGEST.value)
        decoded = [(stamp, c[c[:, _RETURN_TYPE] != strongest], complete)
                   for stamp, c, complete in decoded]
    revolutions = [Revolution(points=c, start_s=float(stamp.host) + float(c[:, _TIME].min()),
                              end_s=float(stamp.host) + float(c[:, _TIME].max()),
                              complete=complete)
                   for stamp, c, complete in decoded if len(c)]
    if not revolutions:
        raise DataError(f"pcap file {path} holds no VLP-16 returns (no 1206-byte data packets "
                        "with a return); check the capture's port (2368) and sensor model")
    return Capture(revolutions, _RETURN_MODES[mode], cut_packet)


def _pcap_format(buf: mmap.mmap, path: Path) -> tuple[str, float]:
    """A classic pcap's byte order (``"<"`` or ``">"``) and timestamp-fraction divisor (1e6
    or 1e9 per second); refuses pcapng, other files and link types other than Ethernet."""
    magic = buf[:4]
    if magic == _PCAPNG_MAGIC:
        raise InputFileError(f"pcap file {path} is in pcapng format, which import-pcap cannot "
                             f"read; save it as pcap: editcap -F pcap {path.name} capture.pcap")
    order, divisor = _PCAP_FORMAT.get(magic, (None, None))
    if order is None or len(buf) < _GLOBAL_HEADER_BYTES:
        raise InputFileError(f"pcap file {path} is not a readable packet capture (no pcap "
                             "header); give a .pcap recorded with tcpdump or Wireshark")
    link_type = struct.unpack_from(order + "I", buf, 20)[0] & 0xFFFF
    if link_type != _LINKTYPE_ETHERNET:
        name = _LINK_TYPE_NAMES.get(link_type, "not Ethernet")
        raise InputFileError(f"pcap file {path} has link type {link_type} ({name}); import-pcap "
                             "reads Ethernet frames only (link type 1): record on the sensor's "
                             "Ethernet interface (tcpdump -i eth0 -s 0 udp port 2368, not "
                             "-i any), or convert it to Ethernet frames (tcprewrite, DLT "
                             "plugin enet)")
    return order, divisor


def _record_headers(buf: mmap.mmap, order: str, path: Path) -> tuple[np.ndarray, int | None]:
    """The whole records' headers, ``(n, 5)`` int64 columns seconds, fraction, saved length,
    original length (bytes) and the file offset of the header (bytes); and the packet the file
    ends inside (``None``: it ends after a whole record). Refuses a file cut inside its first
    packet. Walks the saved lengths in Python: about 3 s per million records (a few per cent
    of decoding them)."""
    saved_length = struct.Struct(order + "I")
    starts, pos, size = [], _GLOBAL_HEADER_BYTES, len(buf)
    while pos + _RECORD_HEADER_BYTES <= size:
        starts.append(pos)
        pos += _RECORD_HEADER_BYTES + saved_length.unpack_from(buf, pos + 8)[0]
    if pos > size:  # the last header's record is cut
        starts.pop()
    cut_packet = None if pos == size else len(starts) + 1
    if cut_packet == 1:
        raise InputFileError(f"pcap file {path} is truncated: it ends inside its first packet "
                             "(cut short while copying or recording, no packet is whole); copy "
                             "it again from the recording computer")
    starts = np.array(starts, dtype=np.int64)
    raw = np.frombuffer(buf, np.uint8)
    header = raw[starts[:, None] + np.arange(_RECORD_HEADER_BYTES)].view(order + "u4")
    del raw  # no view of the map may outlive it
    return np.column_stack([header.astype(np.int64), starts]), cut_packet


def _check_records(records: np.ndarray, divisor: float, path: Path) -> None:
    """Refuse records cut by the snap length, and records out of time order (``divisor``:
    timestamp fractions per second)."""
    seconds, fraction, saved, original = records[:, :4].T
    cut = np.flatnonzero(saved < original)
    if cut.size:
        k = int(cut[0])
        raise InputFileError(f"pcap file {path}: {cut.size} of its {len(records)} packets were "
                             f"saved cut short (packet {k + 1}: {saved[k]} of {original[k]} "
                             "bytes), the capture's snap length was too small; record again "
                             "with tcpdump -s 0")
    step_s = np.diff(seconds) + np.diff(fraction) / divisor
    earlier = np.flatnonzero(step_s < 0)
    if earlier.size:
        k = int(earlier[0])
        raise InputFileError(f"pcap file {path}: {earlier.size} packet(s) are stamped earlier "
                             f"than the packet before them in the file (first: packet {k + 2}, "
                             f"{-step_s[k]:.6f} s before packet {k + 1}), the packets are out "
                             f"of time order; sort them with reordercap {path.name} "
                             "sorted.pcap")


def _data_packets(buf: mmap.mmap, records: np.ndarray) -> np.ndarray:
    """The VLP-16 data packets: ``(m, 4)`` int64 columns packet number (from 1), device time
    (microseconds past the hour), return mode byte, product id.

    A data packet is a record ending in a 1206-byte UDP payload that starts with a firing
    block's flag ``FF EE``; its last 6 bytes are the device time (little-endian u32), the
    return mode and the product id."""
    saved, start = records[:, 2], records[:, 4]
    end = start + _RECORD_HEADER_BYTES + saved
    maybe = np.flatnonzero(saved >= _DATA_PACKET_BYTES + _UDP_HEADER_BYTES)
    raw = np.frombuffer(buf, np.uint8)
    at = end[maybe] - _DATA_PACKET_BYTES
    udp_length = raw[at - 4].astype(np.int64) * 256 + raw[at - 3]
    rows = maybe[(udp_length == _DATA_PACKET_BYTES + _UDP_HEADER_BYTES)
                 & (raw[at] == 0xFF) & (raw[at + 1] == 0xEE)]
    footer = raw[end[rows, None] + np.arange(-6, 0)].astype(np.int64)
    del raw  # no view of the map may outlive it
    device_time_us = footer[:, :4] @ (256 ** np.arange(4))
    return np.column_stack([rows + 1, device_time_us, footer[:, 4], footer[:, 5]])


def _check_data_packets(data: np.ndarray, path: Path) -> int:
    """Refuse a capture without data packets, data packets of another sensor, in an unknown
    or changing return mode, or recorded twice; return their return-mode byte."""
    if not data.size:
        raise DataError(f"pcap file {path} holds no VLP-16 returns (no 1206-byte data packets); "
                        "check the capture's port (2368) and sensor model")
    number, device_time_us, mode, product = data.T
    other = np.flatnonzero(product != _PRODUCT_VLP16)
    if other.size:
        k = int(other[0])
        name = _PRODUCT_NAMES.get(int(product[k]), "not a VLP-16")
        raise DataError(f"pcap file {path}: data packet {number[k]} has product id "
                        f"0x{product[k]:02X} ({name}), not 0x{_PRODUCT_VLP16:02X} (VLP-16); "
                        "import-pcap reads VLP-16 captures only")
    changed = np.flatnonzero(mode != mode[0])
    if mode[0] not in _RETURN_MODES or changed.size:
        k = int(changed[0]) if changed.size else 0
        after = f" after packets in 0x{mode[0]:02X}" if changed.size else ""
        raise DataError(f"pcap file {path}: data packet {number[k]} has return mode "
                        f"0x{mode[k]:02X} ({_RETURN_MODES.get(int(mode[k]), 'unknown')}){after}; "
                        "import-pcap needs one of 0x37 strongest, 0x38 last, 0x39 dual for the "
                        "whole capture: record in one return mode (the sensor's web page, "
                        "Return Type)")
    repeated = np.zeros(len(number), bool)
    for lag in range(1, _DUPLICATE_WINDOW + 1):
        repeated[lag:] |= device_time_us[lag:] == device_time_us[:-lag]
    if repeated.any():
        k = int(np.argmax(repeated))
        raise DataError(f"pcap file {path}: {repeated.sum()} of its {len(number)} data packets "
                        f"are recorded twice (data packet {number[k]} repeats the device time "
                        f"{device_time_us[k]} us of an earlier one; e.g. captured on two "
                        "interfaces or a mirrored port); drop the copies with editcap -D "
                        f"{_DUPLICATE_WINDOW} {path.name} unique.pcap")
    return int(mode[0])


def _decode(buf: mmap.mmap, records: np.ndarray, divisor: float) -> list[tuple]:
    """``velodyne_decoder.read_pcap``'s loop over the data packets' ``records`` (rows of
    :func:`_record_headers`), telling the revolutions it cut (complete) from the remainder it
    flushes at the end: ``[(stamp, points, complete), ...]``. A packet's host stamp is its pcap
    time, as ``read_pcap`` computes it (seconds + fraction / divisor)."""
    import velodyne_decoder as vd

    decoder = vd.StreamDecoder(vd.Config(model=vd.Model.VLP16, timestamp_first_packet=False))
    decoded = []
    for seconds, fraction, saved, _, start in records.tolist():
        end = start + _RECORD_HEADER_BYTES + saved
        result = decoder.decode(seconds + fraction / divisor, buf[end - _DATA_PACKET_BYTES:end],
                                False)
        if result is not None:
            decoded.append((*result, True))
    rest = decoder.finish(False)
    if rest is not None:
        decoded.append((*rest, False))
    return decoded


def scan_from_revolutions(revolutions: list[Revolution], turntable_angle_rad: np.ndarray | None,
                          station_id: str, source_file: str) -> StationScan:
    """Build the station scan of decoded revolutions.

    Parameters
    ----------
    revolutions : list of Revolution
        The revolutions kept, in capture order (at least one).
    turntable_angle_rad : (F,) float or None
        Turntable angle of each revolution, radians (``F == len(revolutions)``); ``None``: all
        revolutions are one frame at angle 0.
    station_id : str
        The scan's station.
    source_file : str
        The capture's file name, recorded in the metadata.

    Returns
    -------
    scan : StationScan
        Sensor-frame points with channel, spin azimuth and range; metadata ``capture`` holds
        the time of each frame's revolutions (``revolution_time_s``, UNIX seconds).
    """
    clouds = [r.points for r in revolutions]
    if turntable_angle_rad is None:
        clouds = [np.concatenate(clouds)]
        angles = np.zeros(1)
    else:
        angles = np.asarray(turntable_angle_rad, dtype=float).reshape(-1)
        if angles.size != len(clouds):
            raise DataError(f"{source_file}: {len(clouds)} revolutions but {angles.size} "
                            "turntable angles; give one angle per revolution")
    frame_index = np.concatenate([np.full(len(c), i, np.uint32) for i, c in enumerate(clouds)])
    pts = np.concatenate(clouds)
    xyz = np.column_stack([-pts[:, _Y], pts[:, _X], pts[:, _Z]]).astype(np.float32)
    rng = np.linalg.norm(xyz.astype(np.float64), axis=1)
    azimuth = np.mod(np.arctan2(xyz[:, 0], xyz[:, 1]), 2 * np.pi)
    metadata = {
        "station_id": station_id,
        "source": "pcap",
        "source_file": source_file,
        "sensor": sensor_metadata(),
        "rig": {"frames_per_turn": int(angles.size)},
        "capture": {"revolution_time_s": [r.time_s for r in revolutions]},
    }
    return StationScan(
        turntable_angle_rad=angles,
        frame_index=frame_index,
        laser_id=_CHANNEL_OF_RING[pts[:, _RING].astype(int)],
        spin_azimuth_rad=azimuth.astype(np.float32),
        range_m=rng.astype(np.float32),
        xyz_sensor_m=xyz,
        metadata=metadata,
        intensity=np.clip(pts[:, _INTENSITY], 0, 255).astype(np.uint8),
    ).validate(source_file)


@dataclass(frozen=True, eq=False)
class TurntableLog:
    """The turntable's angle log.

    Attributes
    ----------
    angle_rad : (K,) float64
        Logged angles, radians; unwrapped across 360 degrees for a timed log.
    time_s : (K,) float64 or None
        Strictly increasing times of the angles, UNIX seconds on the capture computer's clock;
        ``None`` for a log of one row per frame.
    what : str
        How messages name the log.
    """

    angle_rad: np.ndarray
    time_s: np.ndarray | None
    what: str

    def frame_angles(self, frame_time_s: np.ndarray) -> np.ndarray:
        """The turntable angle of each frame.

        Parameters
        ----------
        frame_time_s : (F,) float
            Each frame's time (:attr:`Revolution.time_s`), UNIX seconds.

        Returns
        -------
        angle_rad : (F,) float64
            A per-frame log's rows in order, or the timed log linearly interpolated (in its
            unwrapped angle) at the frame times.

        Raises
        ------
        DataError
            A per-frame log with fewer or more rows than frames; a frame outside a timed
            log's time span.

        Examples
        --------
        >>> log = TurntableLog(np.radians([350.0, 370.0]), np.array([0.0, 2.0]), "log")
        >>> np.degrees(log.frame_angles(np.array([0.5, 2.0]))).round(9).tolist()
        [355.0, 370.0]
        """
        frame_time_s = np.asarray(frame_time_s, dtype=float)
        n_frames, n_rows = frame_time_s.size, self.angle_rad.size
        if self.time_s is None:
            if n_rows != n_frames:
                fix = ("give one row per frame" if n_rows < n_frames else
                       "drop the extra rows, or log time_s to interpolate")
                raise DataError(f"{self.what} has {n_rows} row(s) but the capture has "
                                f"{n_frames} frame(s) (revolutions kept); {fix}")
            return self.angle_rad.copy()
        outside = np.flatnonzero((frame_time_s < self.time_s[0])
                                 | (frame_time_s > self.time_s[-1]))
        if outside.size:
            shown = ", ".join(f"{k} ({frame_time_s[k]:.3f})" for k in outside[:3])
            raise DataError(f"{self.what} spans {self.time_s[0]:.3f}-{self.time_s[-1]:.3f} s "
                            f"but {outside.size} frame(s) lie outside it: frame {shown}"
                            f"{', ...' if outside.size > 3 else ''}; log time_s over the whole "
                            "capture, in UNIX seconds of the capturing computer's clock")
        return np.interp(frame_time_s, self.time_s, self.angle_rad)


def read_turntable_log(path: str | Path) -> TurntableLog:
    """Read the turntable's angle log, a CSV in one of two forms.

    - one row per frame, in capture order: ``turntable_angle_deg`` (and optionally ``frame``,
      which must count 0, 1, 2, ...);
    - timed: ``time_s,turntable_angle_deg``, times strictly increasing (UNIX seconds on the
      capture computer's clock), at least two rows; angles are unwrapped across 360 degrees.
      Consecutive rows must differ by less than 180 degrees; a step of 180 degrees or more is
      read as the angle wrapping across 0/360, which it must cross by less than 90 degrees
      (a step of 180 to 270 degrees, or of 360 or more, is refused: +270 and -90 look
      alike).

    Parameters
    ----------
    path : str or Path
        The CSV.

    Returns
    -------
    log : TurntableLog
        Angles in radians (and times for a timed log).

    Raises
    ------
    InputFileError
        Missing file or column, a cell that is not a finite number, a bad ``frame`` column,
        times not increasing, a step between rows the unwrapping cannot read.
    """
    what = f"turntable log {path}"
    header, rows = read_csv(path, what, required=["turntable_angle_deg"],
                            fix="give turntable_angle_deg (one row per frame), or time_s and "
                                "turntable_angle_deg (timestamps to interpolate)")
    if not rows:
        raise InputFileError(f"{what} has a header but no rows; give one angle per frame")
    column = {name: [row[k].strip() for row in rows] for k, name in enumerate(header)}
    angle_deg = _numbers(column["turntable_angle_deg"], "turntable_angle_deg", what,
                         float(np.degrees(MAX_ABS_ANGLE_RAD)))
    if "time_s" in column:
        return _timed_log(_numbers(column["time_s"], "time_s", what, _MAX_ABS_TIME_S),
                          angle_deg, what)
    return _per_frame_log(column.get("frame"), angle_deg, what)


def _numbers(cells: list[str], name: str, what: str, max_abs: float) -> np.ndarray:
    """A column's cells as finite floats; messages name the CSV line (header = line 1)."""
    return np.array([finite_number(c, f"{what} line {line}, {name}", max_abs)
                     for line, c in enumerate(cells, start=2)])


def _per_frame_log(frames: list[str] | None, angle_deg: np.ndarray, what: str) -> TurntableLog:
    """A log of one row per frame; an optional ``frame`` column must count 0, 1, 2, ..."""
    if frames is not None:
        for k, cell in enumerate(frames):
            if cell != str(k):
                raise InputFileError(f"{what}: the frame column must count 0, 1, 2, ... in "
                                     f"order, line {k + 2} has {cell!r}; number the rows or "
                                     "drop the column")
    return TurntableLog(np.radians(angle_deg), None, what)


def _timed_log(time_s: np.ndarray, angle_deg: np.ndarray, what: str) -> TurntableLog:
    """A timed log: strictly increasing times, angles unwrapped across 360 degrees (steps as
    :func:`read_turntable_log` says)."""
    if time_s.size < 2:
        raise InputFileError(f"{what}: a timed log needs at least two rows to interpolate, got "
                             f"{time_s.size}; log the angle before and after the capture")
    bad = np.flatnonzero(np.diff(time_s) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise InputFileError(f"{what}: time_s must increase row by row, line {k + 2} has "
                             f"{time_s[k]:g} after {time_s[k - 1]:g}; sort the log by time and "
                             "drop repeated times")
    step_deg = np.diff(angle_deg)
    size_deg = np.abs(step_deg)
    ambiguous = np.flatnonzero(((size_deg >= 180.0) & (size_deg <= 270.0)) | (size_deg >= 360.0))
    if ambiguous.size:
        k = int(ambiguous[0])
        step = step_deg[k]
        other_way = -np.sign(step) * (-abs(step) % 360.0)
        raise InputFileError(f"{what}: turntable_angle_deg steps {step:+g} deg from line {k + 2} "
                             f"({angle_deg[k]:g}) to line {k + 3} ({angle_deg[k + 1]:g}), a "
                             f"turn of {step:+g} deg or of {other_way:+g} deg the other way "
                             "round; log the angle more often (rows under 180 deg apart, under "
                             "90 deg where the angle wraps across 0/360)")
    return TurntableLog(np.unwrap(np.radians(angle_deg)), time_s, what)
