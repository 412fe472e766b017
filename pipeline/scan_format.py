"""The station-scan file format, shared by real and simulated scans.

A scan file ``<name>.scan.npz`` is a zip of ``.npy`` arrays, written deterministically
(fixed zip timestamps, sorted members) so the same simulation seed gives byte-identical files.

=====================  ============  =========================================================
member                 shape/dtype   meaning
=====================  ============  =========================================================
``metadata``           () str        JSON object, see below
``turntable_angle_rad``(F,) float64  turntable angle of each frame, radians (NaN = unknown)
``frame_index``        (N,) uint32   frame of each point (points are sorted by frame)
``laser_id``           (N,) uint8    laser channel 0..15 (VLP-16 channel numbering)
``spin_azimuth_rad``   (N,) float32  LiDAR spin azimuth of the firing, radians, [0, 2 pi)
``range_m``            (N,) float32  measured range, metres
``xyz_sensor_m``       (N, 3) float32 point in the sensor frame (:mod:`pipeline.rig`), metres
``intensity``          (N,) uint8    optional reflectivity
=====================  ============  =========================================================

``metadata`` keys: ``format`` (``"markerplan-scan/1"``), ``station_id``, ``source``
(``"simulated"`` or ``"pcap"``), ``sensor`` (``model``, ``rpm``, ``laser_elevation_rad``
list of 16 in channel order, ``firing_order``, ``range_noise_m``, ...), ``rig``
(``lidar_height_m`` nominal height of the LiDAR centre above ground, ``frames_per_turn``),
and ``provenance`` (:func:`markerplan.provenance.provenance`). Mounting offsets are *not*
stored here: the processor must estimate them (simulation truth goes to the truth file).

A simulated scan has a sibling truth file ``<name>.truth.json`` (see :func:`write_truth`).
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from markerplan.errors import DataError, InputFileError

SCAN_FORMAT = "markerplan-scan/1"
TRUTH_FORMAT = "markerplan-truth/1"

_POINT_FIELDS = {
    "frame_index": np.uint32,
    "laser_id": np.uint8,
    "spin_azimuth_rad": np.float32,
    "range_m": np.float32,
}
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)


@dataclass
class StationScan:
    """One station's scan: every frame's returns plus the turntable angle of each frame.

    Attributes
    ----------
    turntable_angle_rad : (F,) float64
        Turntable angle per frame, radians.
    frame_index : (N,) uint32
        Frame of each point.
    laser_id : (N,) uint8
        Laser channel of each point.
    spin_azimuth_rad : (N,) float32
        Spin azimuth of each point, radians.
    range_m : (N,) float32
        Range of each point, metres.
    xyz_sensor_m : (N, 3) float32
        Each point in the sensor frame, metres.
    metadata : dict
        See the module docstring.
    intensity : (N,) uint8 or None
        Optional reflectivity.
    """

    turntable_angle_rad: np.ndarray
    frame_index: np.ndarray
    laser_id: np.ndarray
    spin_azimuth_rad: np.ndarray
    range_m: np.ndarray
    xyz_sensor_m: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)
    intensity: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return int(self.turntable_angle_rad.shape[0])

    @property
    def n_points(self) -> int:
        return int(self.range_m.shape[0])

    @property
    def station_id(self) -> str:
        return str(self.metadata.get("station_id", "station"))

    def validate(self, source: str = "scan") -> StationScan:
        """Check shapes, dtypes and emptiness; return ``self`` (coerced to the file dtypes).

        Raises
        ------
        DataError
            If the scan has no points, no frames, or frames without a turntable angle.
        InputFileError
            If array shapes disagree.
        """
        n = self.range_m.shape[0]
        if self.xyz_sensor_m.shape != (n, 3):
            raise InputFileError(f"{source}: xyz_sensor_m must have shape ({n}, 3), "
                                 f"got {self.xyz_sensor_m.shape}")
        for name in _POINT_FIELDS:
            arr = getattr(self, name)
            if arr.shape != (n,):
                raise InputFileError(f"{source}: {name} must have shape ({n},), got {arr.shape}")
        if self.n_frames == 0:
            raise DataError(f"{source}: scan has no frames; record at least one frame")
        if n == 0:
            raise DataError(f"{source}: scan is empty (0 points); check the capture or the "
                            "simulated station position")
        if not np.all(np.isfinite(self.turntable_angle_rad)):
            bad = int(np.sum(~np.isfinite(self.turntable_angle_rad)))
            raise DataError(f"{source}: {bad} of {self.n_frames} frames have no turntable angle; "
                            "supply the angles (e.g. a turntable CSV) before processing")
        if n and int(self.frame_index.max()) >= self.n_frames:
            raise InputFileError(f"{source}: frame_index refers to frame "
                                 f"{int(self.frame_index.max())} but only {self.n_frames} exist")
        self.turntable_angle_rad = self.turntable_angle_rad.astype(np.float64, copy=False)
        for name, dtype in _POINT_FIELDS.items():
            setattr(self, name, getattr(self, name).astype(dtype, copy=False))
        self.xyz_sensor_m = self.xyz_sensor_m.astype(np.float32, copy=False)
        return self


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(arrays):
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asanyarray(arrays[name]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, member.getvalue(), compresslevel=1)  # 5x faster than 6
    Path(path).write_bytes(buf.getvalue())


def write_scan(path: str | Path, scan: StationScan) -> Path:
    """Write ``scan`` to ``path`` (deterministic bytes for identical input).

    Parameters
    ----------
    path : str or Path
        Destination, conventionally ``<station>.scan.npz``.
    scan : StationScan
        The scan; validated first.

    Returns
    -------
    path : Path
    """
    scan.validate(str(path))
    meta = {"format": SCAN_FORMAT, **scan.metadata}
    arrays = {
        "metadata": np.array(json.dumps(meta, sort_keys=True, default=_json_default)),
        "turntable_angle_rad": scan.turntable_angle_rad,
        "xyz_sensor_m": scan.xyz_sensor_m,
        **{name: getattr(scan, name) for name in _POINT_FIELDS},
    }
    if scan.intensity is not None:
        arrays["intensity"] = np.asarray(scan.intensity, dtype=np.uint8)
    path = Path(path)
    _write_npz(path, arrays)
    return path


def read_scan(path: str | Path) -> StationScan:
    """Read and validate a scan file.

    Raises
    ------
    InputFileError
        Missing, unreadable or malformed file (names the missing member).
    DataError
        Empty scan or frames without turntable angles.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"scan file {path} does not exist; check the path")
    try:
        with np.load(path, allow_pickle=False) as z:
            members = set(z.files)
            required = {"metadata", "turntable_angle_rad", "xyz_sensor_m", *_POINT_FIELDS}
            missing = sorted(required - members)
            if missing:
                raise InputFileError(f"{path} is not a markerplan scan: missing "
                                     f"{', '.join(missing)} (expected format {SCAN_FORMAT})")
            data = {k: z[k] for k in members}
    except InputFileError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputFileError(f"{path} is not a readable scan file ({exc}); expected a "
                             f"{SCAN_FORMAT} .npz written by markerplan") from exc
    try:
        meta = json.loads(str(data["metadata"]))
    except json.JSONDecodeError as exc:
        raise InputFileError(f"{path}: metadata is not valid JSON ({exc})") from exc
    if meta.get("format") != SCAN_FORMAT:
        raise InputFileError(f"{path}: format {meta.get('format')!r} is not {SCAN_FORMAT!r}")
    scan = StationScan(
        turntable_angle_rad=data["turntable_angle_rad"],
        xyz_sensor_m=data["xyz_sensor_m"],
        metadata=meta,
        intensity=data.get("intensity"),
        **{name: data[name] for name in _POINT_FIELDS},
    )
    return scan.validate(str(path))


def write_truth(path: str | Path, truth: dict[str, Any]) -> Path:
    """Write a simulation truth file (JSON, sorted keys).

    ``truth`` keys: ``station_id``; ``station_pose`` {``position_m`` [x, y, z] site frame of
    the station-frame origin, ``heading_rad``, ``roll_rad``, ``pitch_rad``};
    ``mounting_offsets`` (:meth:`pipeline.rig.MountingOffsets.to_dict`); ``marker_radius_m``;
    ``markers`` list of {``id``, ``centre_site_m``, ``centre_station_m``}; ``rocks`` list of
    {``centre_site_m``, ``radius_m``}; ``provenance``.
    """
    body = {"format": TRUTH_FORMAT, **truth}
    path = Path(path)
    path.write_text(json.dumps(body, indent=1, sort_keys=True, default=_json_default) + "\n")
    return path


def read_truth(path: str | Path) -> dict[str, Any]:
    """Read a truth file written by :func:`write_truth`, checking the required keys."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"truth file {path} does not exist; check the path")
    try:
        body = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise InputFileError(f"{path} is not valid JSON ({exc})") from exc
    if body.get("format") != TRUTH_FORMAT:
        raise InputFileError(f"{path}: format {body.get('format')!r} is not {TRUTH_FORMAT!r}")
    missing = [k for k in ("station_id", "station_pose", "markers", "mounting_offsets")
               if k not in body]
    if missing:
        raise InputFileError(f"{path}: truth file lacks {', '.join(missing)}")
    return body


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")
