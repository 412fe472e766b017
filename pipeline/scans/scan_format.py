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
``xyz_sensor_m``       (N, 3) float32 point in the sensor frame (:mod:`pipeline.scans.rig`), metres
``intensity``          (N,) uint8    optional reflectivity
=====================  ============  =========================================================

``metadata`` keys: ``format`` (``"markerplan-scan/1"``), ``station_id``, ``source``
(``"simulated"`` or ``"pcap"``), ``sensor`` (``model``, ``rpm``, ``laser_elevation_rad``
list of 16 in channel order, ``firing_order``, ``range_noise_m``, ...), ``rig``
(``lidar_height_m`` nominal height of the LiDAR centre above ground, ``frames_per_turn``,
``turntable_errors`` the sigmas of the simulated turntable), ``sensor_profile`` (simulated
scans: the name of the sensor profile, or ``null``), ``provenance``
(:func:`markerplan.provenance.provenance`) and, for a scan imported from a packet capture
(:mod:`pipeline.scans.pcap`), ``source_file`` and ``capture`` (``revolution_time_s``: each frame's
time, UNIX seconds on the capturing computer's clock). Mounting offsets are *not* stored here: the
processor must estimate them (simulation truth goes to the truth file).

A simulated scan has a sibling truth file ``<name>.truth.json`` (see :func:`write_truth`).
"""

from __future__ import annotations

import io
import json
import math
import tokenize
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from markerplan.errors import DataError, InputFileError
from markerplan.reading import (
    check_schema_version,
    json_kind,
    json_number,
    json_numbers,
    load_json,
    parse_json,
    require_keys,
    require_type,
    unique_ids,
)
from markerplan.writing import json_default
from pipeline.scans.rig import VLP16_ELEVATION_DEG

#: Version of the scan and truth formats this markerplan writes and reads (the ``/N`` suffix).
FORMAT_VERSION = 1
SCAN_FORMAT = f"markerplan-scan/{FORMAT_VERSION}"
TRUTH_FORMAT = f"markerplan-truth/{FORMAT_VERSION}"
#: Largest range or sensor-frame coordinate accepted, metres. No terrestrial LiDAR measures
#: beyond a few km; a larger value is a corrupt file or a unit mistake.
MAX_RANGE_M = 1e4
#: Largest magnitude accepted for an angle, radians (about 160 turns).
MAX_ABS_ANGLE_RAD = 1e3
#: Laser channels of a VLP-16.
N_LASERS = len(VLP16_ELEVATION_DEG)
#: Sensor model of every scan (metadata ``sensor.model``).
SENSOR_MODEL = "VLP-16"
#: Per-point members other than ``xyz_sensor_m`` (and the optional ``intensity``), with their
#: file dtypes.
POINT_FIELDS = {
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
        """Check shapes, dtypes, values and metadata; return ``self`` (coerced to file dtypes).

        Parameters
        ----------
        source : str
            How messages name the scan (usually its path).

        Raises
        ------
        DataError
            If the scan has no points, no frames, or frames without a turntable angle.
        InputFileError
            If arrays are not numeric, shapes disagree, values are NaN/infinite or absurd
            (ranges or coordinates beyond :data:`MAX_RANGE_M`, angles beyond
            :data:`MAX_ABS_ANGLE_RAD`, laser ids outside 0-15, negative or fractional frame
            indices), or the metadata has the wrong types.
        """
        _scan_arrays_iv(self, source)
        _metadata_iv(self.metadata, source)
        n = self.range_m.shape[0]
        if self.xyz_sensor_m.shape != (n, 3):
            raise InputFileError(f"{source}: xyz_sensor_m must have shape ({n}, 3), "
                                 f"got {self.xyz_sensor_m.shape}")
        for name in POINT_FIELDS:
            arr = getattr(self, name)
            if arr.shape != (n,):
                raise InputFileError(f"{source}: {name} must have shape ({n},), got {arr.shape}")
        if self.intensity is not None and self.intensity.shape != (n,):
            raise InputFileError(f"{source}: intensity must have shape ({n},), "
                                 f"got {self.intensity.shape}")
        if self.n_frames == 0:
            raise DataError(f"{source}: scan has no frames; record at least one frame")
        if n == 0:
            raise DataError(f"{source}: scan is empty (0 points); check the capture or the "
                            "simulated station position")
        if not np.all(np.isfinite(self.turntable_angle_rad)):
            bad = int(np.sum(~np.isfinite(self.turntable_angle_rad)))
            raise DataError(f"{source}: {bad} of {self.n_frames} frames have no turntable angle; "
                            "supply the angles (e.g. a turntable CSV) before processing")
        _values_iv(self, source)
        if n and int(self.frame_index.max()) >= self.n_frames:
            raise InputFileError(f"{source}: frame_index refers to frame "
                                 f"{int(self.frame_index.max())} but only {self.n_frames} exist")
        self.turntable_angle_rad = self.turntable_angle_rad.astype(np.float64, copy=False)
        for name, dtype in POINT_FIELDS.items():
            setattr(self, name, getattr(self, name).astype(dtype, copy=False))
        self.xyz_sensor_m = self.xyz_sensor_m.astype(np.float32, copy=False)
        return self



def sensor_metadata() -> dict[str, Any]:
    """The ``sensor`` metadata every scan carries: ``model`` and ``laser_elevation_rad``.

    Returns
    -------
    sensor : dict
        ``{"model": SENSOR_MODEL, "laser_elevation_rad": [16 floats, channel order]}``.
    """
    return {"model": SENSOR_MODEL,
            "laser_elevation_rad": [float(v) for v in np.radians(VLP16_ELEVATION_DEG)]}

_NUMERIC_KINDS = "iuf"


def _scan_arrays_iv(scan: StationScan, source: str) -> None:
    """Every array numeric (integer or float); the turntable angles one-dimensional."""
    names = ["turntable_angle_rad", "xyz_sensor_m", *POINT_FIELDS]
    if scan.intensity is not None:
        names.append("intensity")
    for name in names:
        arr = np.asarray(getattr(scan, name))
        if arr.dtype.kind not in _NUMERIC_KINDS:
            raise InputFileError(f"{source}: {name} must hold integer or float numbers, got "
                                 f"dtype {arr.dtype}; write the scan with markerplan")
        setattr(scan, name, arr)
    if scan.turntable_angle_rad.ndim != 1:
        raise InputFileError(f"{source}: turntable_angle_rad must have shape (F,), got "
                             f"{scan.turntable_angle_rad.shape}")


def _bad_count(ok: np.ndarray) -> int:
    return int(ok.size - np.count_nonzero(ok))


def _finite_iv(arr: np.ndarray, name: str, limit: float, unit: str, source: str) -> None:
    """Refuse NaN/inf and magnitudes beyond ``limit`` (checked in float64, before any cast)."""
    a = np.asarray(arr, dtype=np.float64)
    finite = np.isfinite(a)
    if not finite.all():
        first = a[~finite].flat[0]
        raise InputFileError(f"{source}: {name} holds {_bad_count(finite)} NaN or infinite "
                             f"value(s) (first {first}); every value must be finite")
    big = np.abs(a) <= limit
    if not big.all():
        first = a[~big].flat[0]
        raise InputFileError(f"{source}: {name} holds {_bad_count(big)} value(s) beyond "
                             f"{limit:g} {unit} (first {first:g}); check the file's units and "
                             "content")


def _integers_iv(arr: np.ndarray, name: str, lo: int, hi: int, source: str,
                 hint: str = "check the file") -> None:
    """Refuse values that are not whole numbers in ``[lo, hi]``."""
    a = np.asarray(arr)
    if a.dtype.kind == "f":
        a64 = a.astype(np.float64)
        ok = np.isfinite(a64) & (a64 == np.round(a64))
        if not ok.all():
            raise InputFileError(f"{source}: {name} must hold whole numbers, got "
                                 f"{a64[~ok].flat[0]!r}; write the scan with markerplan")
    inside = (a >= lo) & (a <= hi)
    if not inside.all():
        raise InputFileError(f"{source}: {name} must lie in {lo}..{hi}, got "
                             f"{a[~inside].flat[0]} ({_bad_count(inside)} value(s)); {hint}")


def _values_iv(scan: StationScan, source: str) -> None:
    """Finite, plausible numbers in every array (shapes already checked)."""
    _finite_iv(scan.turntable_angle_rad, "turntable_angle_rad", MAX_ABS_ANGLE_RAD, "rad",
               source)
    _finite_iv(scan.spin_azimuth_rad, "spin_azimuth_rad", MAX_ABS_ANGLE_RAD, "rad", source)
    _finite_iv(scan.range_m, "range_m", MAX_RANGE_M, "m", source)
    _finite_iv(scan.xyz_sensor_m, "xyz_sensor_m", MAX_RANGE_M, "m", source)
    _integers_iv(scan.laser_id, "laser_id", 0, N_LASERS - 1, source,
                 "VLP-16 channels are 0-15; check the file")
    _integers_iv(scan.frame_index, "frame_index", 0, np.iinfo(np.uint32).max, source)
    if scan.intensity is not None:
        _integers_iv(scan.intensity, "intensity", 0, 255, source)


#: Optional metadata keys and the JSON type each must have when present.
_METADATA_TYPES: dict[str, type | tuple[type, ...]] = {
    "format": str, "station_id": str, "source": str, "source_file": str, "sensor": dict,
    "rig": dict, "provenance": dict,
}


def _metadata_iv(meta: Any, source: str) -> None:
    """The metadata is an object whose known keys have the documented types."""
    if not isinstance(meta, dict):
        raise InputFileError(f"{source}: metadata must be a JSON object, got {json_kind(meta)}")
    for key, kind in _METADATA_TYPES.items():
        if key in meta:
            require_type(meta[key], kind, f"{source}: metadata {key!r}")
    if "station_id" in meta and not meta["station_id"].strip():
        raise InputFileError(f"{source}: metadata 'station_id' is empty; name the station")
    config = meta.get("provenance", {}).get("config")
    if config is not None:
        require_type(config, dict, f"{source}: metadata provenance 'config'")
        if config.get("seed") is not None:
            require_type(config["seed"], int, f"{source}: metadata provenance config 'seed'")


def _format_version(found: Any, family: str, what: str) -> int:
    """The ``N`` of a ``"<family>/N"`` format string, refusing other families and newer N."""
    fix = f"expected {family}/{FORMAT_VERSION} written by markerplan"
    if not isinstance(found, str) or not found.startswith(f"{family}/"):
        raise InputFileError(f"{what}: format {found!r:.60} is not {family}/N; {fix}")
    number = found[len(family) + 1:]
    if not (number.isascii() and number.isdigit()):
        raise InputFileError(f"{what}: format {found!r:.60} has no integer version; {fix}")
    return check_schema_version(int(number), FORMAT_VERSION, what)


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
        "metadata": np.array(json.dumps(meta, sort_keys=True, default=json_default)),
        "turntable_angle_rad": scan.turntable_angle_rad,
        "xyz_sensor_m": scan.xyz_sensor_m,
        **{name: getattr(scan, name) for name in POINT_FIELDS},
    }
    if scan.intensity is not None:
        arrays["intensity"] = np.asarray(scan.intensity, dtype=np.uint8)
    path = Path(path)
    _write_npz(path, arrays)
    return path


def read_scan(path: str | Path) -> StationScan:
    """Read and validate a scan file.

    Parameters
    ----------
    path : str or Path
        A ``.scan.npz`` written by :func:`write_scan`.

    Returns
    -------
    StationScan
        Validated (:meth:`StationScan.validate`), arrays in the file dtypes.

    Raises
    ------
    InputFileError
        Missing, unreadable or malformed file (names the missing member), metadata that is
        not a JSON object with ``format`` and ``station_id``, a format newer than
        :data:`SCAN_FORMAT`, or bad values (see :meth:`StationScan.validate`).
    DataError
        Empty scan or frames without turntable angles.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"scan file {path} does not exist; check the path")
    required = {"metadata", "turntable_angle_rad", "xyz_sensor_m", *POINT_FIELDS}
    data = _read_npz(path, required | {"intensity"})
    missing = sorted(required - set(data))
    if missing:
        raise InputFileError(f"{path} is not a markerplan scan: missing "
                             f"{', '.join(missing)} (expected format {SCAN_FORMAT})")
    meta_arr = data["metadata"]
    if meta_arr.shape != () or meta_arr.dtype.kind != "U":
        raise InputFileError(f"{path}: metadata must be one JSON text, got an array of dtype "
                             f"{meta_arr.dtype} and shape {meta_arr.shape}; write the scan "
                             "with markerplan")
    meta = parse_json(str(meta_arr), f"{path}: metadata")
    require_keys(meta, ("format", "station_id"), f"{path}: metadata",
                 f"expected {SCAN_FORMAT} metadata written by markerplan")
    _format_version(meta["format"], SCAN_FORMAT.split("/")[0], f"{path}: metadata")
    scan = StationScan(
        turntable_angle_rad=data["turntable_angle_rad"],
        xyz_sensor_m=data["xyz_sensor_m"],
        metadata=meta,
        intensity=data.get("intensity"),
        **{name: data[name] for name in POINT_FIELDS},
    )
    return scan.validate(str(path))


def _read_npz(path: Path, names: set[str]) -> dict[str, np.ndarray]:
    """The members ``names`` (those present) of an ``.npz``, each checked before it is read.

    A member whose header declares more data than it holds, or an object array, is refused
    without allocating it, so a corrupt header cannot exhaust memory.
    """
    fix = f"expected a {SCAN_FORMAT} .npz written by markerplan"
    out = {}
    try:
        with zipfile.ZipFile(path) as zf:
            for info in zf.infolist():
                name = info.filename.removesuffix(".npy")
                if name in names and name not in out:
                    out[name] = _read_npy(zf.read(info), f"{path} member {info.filename}", fix)
    except InputFileError:
        raise
    except (OSError, EOFError, ValueError, zipfile.BadZipFile, zlib.error, NotImplementedError,
            RuntimeError) as exc:
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise InputFileError(f"{path} is not a readable scan file ({reason}); {fix}") from exc
    return out


def _read_npy(data: bytes, what: str, fix: str) -> np.ndarray:
    """One ``.npy`` member from its bytes (version 1 or 2 header, no pickles)."""
    fh = io.BytesIO(data)
    version = np.lib.format.read_magic(fh)
    if version not in ((1, 0), (2, 0)):
        raise InputFileError(f"{what}: .npy version {version} is not 1.0 or 2.0; {fix}")
    read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0) else
                   np.lib.format.read_array_header_2_0)
    try:
        shape, _, dtype = read_header(fh)
    except (ValueError, SyntaxError, tokenize.TokenError, TypeError) as exc:
        raise InputFileError(f"{what}: the .npy header is corrupt; {fix}") from exc
    if dtype.hasobject:
        raise InputFileError(f"{what}: holds Python objects, which are never loaded; {fix}")
    expected = math.prod(shape) * dtype.itemsize
    if len(data) - fh.tell() != expected:
        raise InputFileError(f"{what}: header declares {expected} bytes of data but "
                             f"{len(data) - fh.tell()} follow; the file is corrupt or truncated")
    fh.seek(0)
    return np.lib.format.read_array(fh, allow_pickle=False)


def write_truth(path: str | Path, truth: dict[str, Any]) -> Path:
    """Write a simulation truth file (JSON, sorted keys).

    ``truth`` keys: ``station_id``; ``station_pose`` {``position_m`` [x, y, z] site frame of
    the station-frame origin, ``heading_rad``, ``roll_rad``, ``pitch_rad``};
    ``mounting_offsets`` (:meth:`pipeline.scans.rig.MountingOffsets.to_dict`); ``marker_radius_m``;
    ``markers`` list of {``id``, ``centre_site_m``, ``centre_station_m``}; ``rocks`` list of
    {``centre_site_m``, ``radius_m``}; ``turntable_frame_errors`` (``null`` or {``frames``,
    ``angle_error_rad``, ``wobble_rad``}: the true per-frame turntable errors); ``provenance``.
    """
    body = {"format": TRUTH_FORMAT, **truth}
    path = Path(path)
    path.write_text(json.dumps(body, indent=1, sort_keys=True, default=json_default) + "\n")
    return path


def read_truth(path: str | Path) -> dict[str, Any]:
    """Read a truth file written by :func:`write_truth`, checking its keys and values.

    Parameters
    ----------
    path : str or Path
        A ``.truth.json``.

    Returns
    -------
    truth : dict
        The parsed file (see :func:`write_truth` for its keys).

    Raises
    ------
    InputFileError
        Missing file, not UTF-8, not a JSON object, a format other than or newer than
        :data:`TRUTH_FORMAT`, missing keys, or values of the wrong type: ``markers`` must be a
        list of objects with a unique string ``id`` and a ``centre_station_m`` of three
        finite numbers; poses and offsets must be finite numbers.
    """
    path = Path(path)
    what = f"truth file {path}"
    if not path.is_file():
        raise InputFileError(f"{what} does not exist; check the path")
    body = load_json(path, what)
    fix = f"expected a {TRUTH_FORMAT} file written by markerplan simulate"
    require_keys(body, ("format",), what, fix)
    _format_version(body["format"], TRUTH_FORMAT.split("/")[0], what)
    require_keys(body, ("station_id", "station_pose", "markers", "mounting_offsets"), what, fix)
    _truth_iv(body, what)
    return body


def _truth_iv(body: dict[str, Any], what: str) -> None:
    station = require_type(body["station_id"], str, f"{what}: 'station_id'")
    if not station.strip():
        raise InputFileError(f"{what}: 'station_id' is empty; name the station")
    pose = require_type(body["station_pose"], dict, f"{what}: 'station_pose'")
    if "position_m" in pose:
        json_numbers(pose["position_m"], f"{what}: station_pose 'position_m'", length=3)
    for key in ("heading_rad", "roll_rad", "pitch_rad"):
        if key in pose:
            json_number(pose[key], f"{what}: station_pose {key!r}", MAX_ABS_ANGLE_RAD)
    offsets = require_type(body["mounting_offsets"], dict, f"{what}: 'mounting_offsets'")
    for key in ("vertical_axis_error_rad", "lframe_tilt_rad"):
        if key in offsets:
            json_number(offsets[key], f"{what}: mounting_offsets {key!r}", MAX_ABS_ANGLE_RAD)
    if "axis_offset_m" in offsets:
        json_numbers(offsets["axis_offset_m"], f"{what}: mounting_offsets 'axis_offset_m'",
                     length=2)
    if "marker_radius_m" in body:
        radius = json_number(body["marker_radius_m"], f"{what}: 'marker_radius_m'")
        if radius <= 0:
            raise InputFileError(f"{what}: 'marker_radius_m' must be > 0, got {radius:g}")
    markers = require_type(body["markers"], list, f"{what}: 'markers'")
    ids = []
    for k, m in enumerate(markers):
        where = f"{what}: markers[{k}]"
        require_type(m, dict, where)
        require_keys(m, ("id", "centre_station_m"), where, "every marker needs both")
        ids.append(require_type(m["id"], str, f"{where} 'id'"))
        json_numbers(m["centre_station_m"], f"{where} 'centre_station_m'", length=3)
        if "centre_site_m" in m:
            json_numbers(m["centre_site_m"], f"{where} 'centre_site_m'", length=3)
    unique_ids(ids, f"{what}: markers")

