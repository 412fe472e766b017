"""Read a real Velodyne VLP-16 packet capture into the station-scan structure.

Decoding is done by ``velodyne_decoder`` (model VLP-16). Each decoded revolution becomes one
frame; turntable angles come from a CSV the user supplies (one row per frame, in capture
order). Without a CSV the whole capture is one frame at turntable angle 0.

Conversions made here:

- ``velodyne_decoder`` returns ROS-convention points (x forward, y left, z up). Our sensor
  frame is the Velodyne manual's (x right, y forward, z up; :mod:`pipeline.rig`), so
  ``x_S = -y_ros``, ``y_S = x_ros``, ``z_S = z_ros``.
- Its ``ring`` is the laser index sorted by elevation; the scan format stores the VLP-16
  *channel* (firing order), recovered with :data:`VLP16_ELEVATION_DEG`.
- ``range_m`` is the point's distance from the sensor origin (the decoder has already
  applied the per-laser vertical offsets of the factory calibration).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from markerplan.errors import DataError, InputFileError
from pipeline.rig import VLP16_ELEVATION_DEG
from pipeline.scan_format import StationScan, sensor_metadata

#: channel of each decoder ring (ring k = k-th lowest elevation)
_CHANNEL_OF_RING = np.argsort(VLP16_ELEVATION_DEG, kind="stable").astype(np.uint8)


def read_turntable_csv(path: str | Path) -> np.ndarray:
    """Read turntable angles from a CSV with a ``turntable_angle_deg`` column.

    Parameters
    ----------
    path : str or Path
        CSV with a header; one row per frame in capture order. A ``frame`` column, if
        present, must count 0, 1, 2, ...

    Returns
    -------
    angles_rad : (F,) float64
        Turntable angle per frame, radians.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"turntable CSV {path} does not exist; check the path")
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        if reader.fieldnames is None or "turntable_angle_deg" not in reader.fieldnames:
            raise InputFileError(f"{path}: needs a 'turntable_angle_deg' column, got columns "
                                 f"{reader.fieldnames}")
        rows = list(reader)
    try:
        angles = np.array([float(r["turntable_angle_deg"]) for r in rows])
    except ValueError as exc:
        raise InputFileError(f"{path}: turntable_angle_deg must be numbers ({exc})") from exc
    if rows and "frame" in rows[0]:
        frames = [int(r["frame"]) for r in rows]
        if frames != list(range(len(rows))):
            raise InputFileError(f"{path}: 'frame' column must count 0, 1, 2, ... in order")
    if angles.size == 0 or not np.all(np.isfinite(angles)):
        raise DataError(f"{path}: every frame needs a finite turntable_angle_deg")
    return np.radians(angles)


def read_vlp16_pcap(path: str | Path, turntable_angle_rad: np.ndarray | None = None,
                    station_id: str | None = None) -> StationScan:
    """Decode a VLP-16 ``.pcap`` into a :class:`StationScan`.

    Parameters
    ----------
    path : str or Path
        Packet capture (single or strongest return).
    turntable_angle_rad : (F,) float, optional
        Turntable angle of each decoded revolution, radians; ``F`` must equal the number of
        revolutions in the capture. ``None``: the whole capture is one frame at angle 0.
    station_id : str, optional
        Defaults to the file stem.

    Returns
    -------
    scan : StationScan
        Sensor-frame points with channel, spin azimuth and range.
    """
    import velodyne_decoder as vd

    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"pcap file {path} does not exist; check the path")
    config = vd.Config(model=vd.Model.VLP16)
    try:
        clouds = [c for _, c in vd.read_pcap(str(path), config, as_pcl_structs=False)]
    except Exception as exc:  # the decoder raises plain RuntimeError/ValueError on bad input
        raise InputFileError(f"{path}: not a readable VLP-16 pcap ({exc})") from exc
    clouds = [c for c in clouds if len(c)]
    if not clouds:
        raise DataError(f"{path}: capture holds no VLP-16 returns; check the capture port/model")
    if turntable_angle_rad is None:
        clouds = [np.concatenate(clouds)]
        angles = np.zeros(1)
    else:
        angles = np.asarray(turntable_angle_rad, dtype=float).reshape(-1)
        if angles.size != len(clouds):
            raise DataError(f"{path}: capture holds {len(clouds)} revolutions but "
                            f"{angles.size} turntable angles were given; give one per revolution")
    frame_index = np.concatenate([np.full(len(c), i, np.uint32) for i, c in enumerate(clouds)])
    pts = np.concatenate(clouds)
    xyz = np.column_stack([-pts[:, 1], pts[:, 0], pts[:, 2]]).astype(np.float32)
    rng = np.linalg.norm(xyz.astype(np.float64), axis=1)
    azimuth = np.mod(np.arctan2(xyz[:, 0], xyz[:, 1]), 2 * np.pi)
    channel = _CHANNEL_OF_RING[pts[:, 6].astype(int)]
    metadata = {
        "station_id": station_id or path.name.split(".")[0],
        "source": "pcap",
        "source_file": path.name,
        "sensor": sensor_metadata(),
        "rig": {"frames_per_turn": int(angles.size)},
    }
    return StationScan(
        turntable_angle_rad=angles,
        frame_index=frame_index,
        laser_id=channel,
        spin_azimuth_rad=azimuth.astype(np.float32),
        range_m=rng.astype(np.float32),
        xyz_sensor_m=xyz,
        metadata=metadata,
        intensity=np.clip(pts[:, 3], 0, 255).astype(np.uint8),
    ).validate(str(path))
