"""Read a real Velodyne VLP-16 packet capture and a turntable log into the station-scan
structure.

Decoding is done by ``velodyne_decoder`` (model VLP-16): :func:`decode_vlp16_pcap` returns the
capture's spin revolutions, :func:`scan_from_revolutions` turns the ones kept into a
:class:`~pipeline.scan_format.StationScan` (one frame per revolution, or all of them as one
frame at turntable angle 0), and :func:`read_turntable_log` reads the turntable's angles.

Conversions made here:

- ``velodyne_decoder`` returns ROS-convention points (x forward, y left, z up). Our sensor
  frame is the Velodyne manual's (x right, y forward, z up; :mod:`pipeline.rig`), so
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

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplan.errors import DataError, InputFileError
from markerplan.reading import finite_number, read_csv
from pipeline.rig import VLP16_ELEVATION_DEG
from pipeline.scan_format import MAX_ABS_ANGLE_RAD, StationScan, sensor_metadata

#: channel of each decoder ring (ring k = k-th lowest elevation)
_CHANNEL_OF_RING = np.argsort(VLP16_ELEVATION_DEG, kind="stable").astype(np.uint8)
#: Largest |time_s| accepted in a timed turntable log, seconds (UNIX time is ~1.7e9 s).
_MAX_ABS_TIME_S = 1e11
# decoder point columns (as_pcl_structs=False)
_X, _Y, _Z, _INTENSITY, _TIME, _RING = 0, 1, 2, 3, 4, 6


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


def decode_vlp16_pcap(path: str | Path) -> list[Revolution]:
    """Decode a VLP-16 ``.pcap`` into its spin revolutions, in capture order.

    Parameters
    ----------
    path : str or Path
        Packet capture (single or strongest return). Packets of other sizes (position packets,
        other traffic) are passed over.

    Returns
    -------
    revolutions : list of Revolution
        Every revolution with at least one return (complete and partial).

    Raises
    ------
    InputFileError
        Missing, empty, truncated or not a pcap file.
    DataError
        A readable capture without VLP-16 returns.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"pcap file {path} does not exist; check the path")
    if path.stat().st_size == 0:
        raise InputFileError(f"pcap file {path} is empty; give a capture recorded with tcpdump "
                             "or Wireshark (.pcap)")
    try:
        decoded = _decode(str(path))
    except Exception as exc:  # the decoder raises dpkt's, ValueError and RuntimeError on bad files
        raise InputFileError(f"pcap file {path} is not a readable packet capture, or is truncated "
                             f"(decoder: {exc}); give a .pcap recorded with tcpdump or Wireshark, "
                             "cut with editcap if it ends mid-packet") from exc
    revolutions = [Revolution(points=c, start_s=float(stamp.host) + float(c[:, _TIME].min()),
                              end_s=float(stamp.host) + float(c[:, _TIME].max()),
                              complete=complete)
                   for stamp, c, complete in decoded if len(c)]
    if not revolutions:
        raise DataError(f"pcap file {path} holds no VLP-16 returns (no 1206-byte data packets "
                        "with a return); check the capture's port (2368) and sensor model")
    return revolutions


def _decode(path: str) -> list[tuple]:
    """``velodyne_decoder.read_pcap``'s loop, telling the revolutions it cut (complete) from
    the remainder it flushes at the end of the file: ``[(stamp, points, complete), ...]``."""
    import velodyne_decoder as vd

    decoder = vd.StreamDecoder(vd.Config(model=vd.Model.VLP16, timestamp_first_packet=False))
    decoded = []
    for host_stamp, data in vd.util.iter_pcap(path):
        if len(data) == vd.PACKET_SIZE:  # other sizes: position packets, other traffic
            result = decoder.decode(host_stamp, data, False)
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
      capture computer's clock), at least two rows; angles are unwrapped across 360 degrees
      (consecutive rows must differ by less than 180 degrees).

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
        times not increasing.
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
    """A timed log: strictly increasing times, angles unwrapped across 360 degrees."""
    if time_s.size < 2:
        raise InputFileError(f"{what}: a timed log needs at least two rows to interpolate, got "
                             f"{time_s.size}; log the angle before and after the capture")
    bad = np.flatnonzero(np.diff(time_s) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise InputFileError(f"{what}: time_s must increase row by row, line {k + 2} has "
                             f"{time_s[k]:g} after {time_s[k - 1]:g}; sort the log by time and "
                             "drop repeated times")
    return TurntableLog(np.unwrap(np.radians(angle_deg)), time_s, what)
