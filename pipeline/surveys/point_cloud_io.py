"""Point clouds out: a station's synthesised, calibrated cloud as LAS 1.4 and PLY files.

The cloud is the one the chain measured its markers in (:func:`pipeline.chain.synthesis.synthesize`
with the station's self-calibrated mounting offsets), classified by what the chain made of each
point (ASPRS classes):

* :data:`MARKER_CLASS` (64, the first user-definable class): the points the sphere fit of an
  accepted marker used (its inliers);
* :data:`GROUND_CLASS` (2): the rest of the points the chain's ground stage
  (:func:`pipeline.chain.ground.remove_ground`, the ``ground`` cell and minimum height) calls
  ground, here over the whole cloud;
* :data:`UNCLASSIFIED_CLASS` (1): everything else (rejected candidates, rocks, the rig).

Every point also carries its frame index, laser channel and ``marker_index`` (0: none; k: the
k-th row, from 1, of the station's rows in ``markers.csv``). Files are written in the station
frame and, when the station's pose in the site is known, in the site frame. The bytes depend
on the inputs only: the LAS creation date is fixed (:data:`LAS_CREATION_DATE`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import date
from pathlib import Path
from typing import Any

import numpy as np

from markerplan.errors import ConfigError, DataError
from pipeline.chain.ground import remove_ground
from pipeline.chain.process import StationResult
from pipeline.chain.stages import GroundStage
from pipeline.chain.synthesis import synthesize
from pipeline.scans.rig import station_to_site_matrix
from pipeline.scans.scan_format import StationScan

#: ASPRS classes written.
UNCLASSIFIED_CLASS, GROUND_CLASS, MARKER_CLASS = 1, 2, 64
#: LAS coordinate resolution, metres (0.1 mm: a tenth of the finest range noise modelled).
LAS_SCALE_M = 1e-4
#: LAS offsets: the cloud's mid-point rounded to a multiple of this, metres (0 in the station
#: frame; the 32-bit integers reach +-214 km from it).
LAS_OFFSET_STEP_M = 1000.0
#: The LAS header's "creation date": fixed, so that the same inputs give the same bytes (the
#: date the scan archives' members carry).
LAS_CREATION_DATE = date(1980, 1, 1)
#: The file formats :func:`write_station_clouds` writes.
FORMATS = ("las", "ply")
#: The frames a cloud is written in.
FRAMES = ("station", "site")
#: Per-point attributes besides x, y, z and the class: (name, dtype, PLY type, description).
_ATTRIBUTES = (("frame_index", np.uint32, "uint", "turntable frame of the point"),
               ("laser_id", np.uint8, "uchar", "VLP-16 laser channel 0-15"),
               ("marker_index", np.uint16, "ushort", "markers.csv row from 1, 0 none"))


@dataclass(frozen=True)
class StationPose:
    """Where a station stands in the site: ``x_site = rotation @ x_station + position_m``.

    Attributes
    ----------
    rotation : (3, 3) float
        Station -> site rotation (:func:`pipeline.scans.rig.station_to_site_matrix`).
    position_m : (3,) float
        Site coordinates of the station-frame origin, metres.
    """

    rotation: np.ndarray
    position_m: np.ndarray

    @classmethod
    def from_truth(cls, truth: dict[str, Any]) -> StationPose:
        """The pose a simulator truth records (:func:`pipeline.scans.scan_format.read_truth`).

        Raises
        ------
        DataError
            The truth has no ``station_pose.position_m``.
        """
        pose = truth["station_pose"]
        if "position_m" not in pose:
            raise DataError(f"the truth of station {truth['station_id']} has no station_pose "
                            "position_m; without it no site-frame cloud can be written")
        return cls(station_to_site_matrix(pose.get("heading_rad", 0.0), pose.get("roll_rad", 0.0),
                                          pose.get("pitch_rad", 0.0)),
                   np.asarray(pose["position_m"], dtype=float))

    def to_site(self, xyz_m: np.ndarray) -> np.ndarray:
        """Station-frame points (N, 3) -> site-frame points (N, 3), metres."""
        return np.asarray(xyz_m, dtype=float) @ self.rotation.T + self.position_m

    def to_dict(self) -> dict[str, list]:
        return {"rotation": self.rotation.tolist(), "position_m": self.position_m.tolist()}


@dataclass(frozen=True)
class ClassifiedCloud:
    """One station's calibrated cloud with a class per point (station frame).

    Attributes
    ----------
    station_id : str
    xyz_m : (N, 3) float64
        Station frame, metres.
    frame_index : (N,) uint32
    laser_id : (N,) uint8
    classification : (N,) uint8
        :data:`MARKER_CLASS`, :data:`GROUND_CLASS` or :data:`UNCLASSIFIED_CLASS`.
    marker_index : (N,) uint16
        0, or the 1-based row (among the station's rows) of the accepted marker the point
        belongs to.
    markers : list of dict
        Per accepted marker: ``marker_index``, ``marker_id`` (``""`` when unmatched) and
        ``centre_m`` (station frame).
    """

    station_id: str
    xyz_m: np.ndarray
    frame_index: np.ndarray
    laser_id: np.ndarray
    classification: np.ndarray
    marker_index: np.ndarray
    markers: list[dict[str, Any]]


def classify_cloud(scan: StationScan, result: StationResult,
                   ground: GroundStage | None = None) -> ClassifiedCloud:
    """The calibrated cloud of ``scan`` with the classes the chain's ``result`` gives.

    Parameters
    ----------
    scan : StationScan
        The scan ``result`` was computed from.
    result : StationResult
        :func:`pipeline.chain.process.process_station`'s output (offsets and candidates).
    ground : GroundStage, optional
        The ground stage of the configuration the chain ran with (default stage otherwise).

    Returns
    -------
    ClassifiedCloud
    """
    ground = ground or GroundStage()
    cloud = synthesize(scan, result.offsets)
    classes = np.where(remove_ground(cloud.xyz_m, ground.cell_m, ground.min_height_m),
                       UNCLASSIFIED_CLASS, GROUND_CLASS).astype(np.uint8)
    marker_index = np.zeros(scan.n_points, dtype=np.uint16)
    markers = []
    for k, (cand, row) in enumerate(zip(result.candidates, result.rows, strict=True), start=1):
        if cand.accepted:
            marker_index[cand.members[cand.fit.used]] = k
            markers.append({"marker_index": k, "marker_id": row.marker_id,
                            "centre_m": [float(v) for v in cand.fit.centre_m]})
    classes[marker_index > 0] = MARKER_CLASS
    return ClassifiedCloud(scan.station_id, cloud.xyz_m, cloud.frame_index, scan.laser_id,
                           classes, marker_index, markers)


def check_formats(formats: tuple[str, ...]) -> None:
    """Refuse formats other than :data:`FORMATS` (:class:`ConfigError`, naming the choices)."""
    unknown = sorted(set(formats) - set(FORMATS))
    if unknown:
        raise ConfigError(f"unknown point-cloud format(s) {', '.join(unknown)}; choose from "
                          f"{', '.join(FORMATS)}, e.g. `cloud_formats` las,ply")


def write_station_clouds(folder: str | Path, cloud: ClassifiedCloud, formats: tuple[str, ...],
                         pose: StationPose | None = None, crs_wkt: str | None = None
                         ) -> list[str]:
    """Write ``<station>.station.<fmt>`` and, with a pose, ``<station>.site.<fmt>``.

    Parameters
    ----------
    folder : path-like
        Existing output folder.
    cloud : ClassifiedCloud
    formats : tuple of str
        Among :data:`FORMATS`.
    pose : StationPose, optional
        The station's pose in the site; without it no site-frame file is written.
    crs_wkt : str, optional
        The site's CRS (WKT), recorded in the site-frame files.

    Returns
    -------
    names : list of str
        The files written, sorted.
    """
    check_formats(formats)
    encoders = {"las": _write_las, "ply": _write_ply}
    names = []
    for frame in FRAMES[:2 if pose is not None else 1]:
        site = frame == "site"
        xyz, meta = _in_frame(cloud, pose if site else None)  # once for every format
        for fmt in sorted(set(formats)):
            name = f"{cloud.station_id}.{frame}.{fmt}"
            encoders[fmt](Path(folder) / name, cloud, xyz, meta, crs_wkt if site else None)
            names.append(name)
    return sorted(names)


def _in_frame(cloud: ClassifiedCloud, pose: StationPose | None
              ) -> tuple[np.ndarray, dict[str, Any]]:
    """The cloud's points in the frame a file is written in, and what the file holds.

    Parameters
    ----------
    cloud : ClassifiedCloud
    pose : StationPose or None
        The site frame; None: the station frame.

    Returns
    -------
    xyz_m : (N, 3) float
        The points in that frame, metres.
    meta : dict
        Station, frame, classes, the accepted markers' centres (in that frame), the pose.
    """
    meta: dict[str, Any] = {
        "station_id": cloud.station_id, "frame": "station" if pose is None else "site",
        "classes": {str(UNCLASSIFIED_CLASS): "unclassified", str(GROUND_CLASS): "ground",
                    str(MARKER_CLASS): "marker (sphere-fit inliers of an accepted marker)"},
        "markers": cloud.markers}
    if pose is None:
        return cloud.xyz_m, meta
    centres = pose.to_site(np.array([m["centre_m"] for m in cloud.markers]).reshape(-1, 3))
    meta["markers"] = [{**m, "centre_m": c.tolist()}
                       for m, c in zip(cloud.markers, centres, strict=True)]
    meta["station_pose"] = pose.to_dict()
    return pose.to_site(cloud.xyz_m), meta


def write_las(path: str | Path, cloud: ClassifiedCloud, pose: StationPose | None = None,
              crs_wkt: str | None = None) -> Path:
    """Write a LAS 1.4 file, point format 6, 0.1 mm scale, in the station or site frame.

    The header's offsets are the points' mid-point rounded to :data:`LAS_OFFSET_STEP_M`; a
    ``markerplan`` VLR (record 1) holds :func:`_in_frame`'s metadata as JSON; ``crs_wkt`` goes into
    the OGC WKT VLR (global-encoding WKT bit set, as point format 6 requires). Extra bytes:
    ``frame_index``, ``laser_id``, ``marker_index``.

    Parameters
    ----------
    path : path-like
    cloud : ClassifiedCloud
    pose : StationPose, optional
        Write in the site frame (default: the station frame).
    crs_wkt : str, optional
        CRS of the site frame, WKT.

    Raises
    ------
    DataError
        The cloud spans more than the LAS integers hold at 0.1 mm (about 214 km).
    """
    return _write_las(path, cloud, *_in_frame(cloud, pose), crs_wkt)


def _write_las(path: str | Path, cloud: ClassifiedCloud, xyz: np.ndarray, meta: dict[str, Any],
               crs_wkt: str | None) -> Path:
    """:func:`write_las` of the cloud's points already in the file's frame (:func:`_in_frame`
    gives ``xyz``, (N, 3) metres, and ``meta``)."""
    import laspy

    header = laspy.LasHeader(version="1.4", point_format=6)
    header.creation_date = LAS_CREATION_DATE
    header.generating_software = "markerplan process"
    header.system_identifier = f"{cloud.station_id} {meta['frame']} frame"[:32]
    mid = (xyz.min(axis=0) + xyz.max(axis=0)) / 2 if len(xyz) else np.zeros(3)
    offsets = np.round(mid / LAS_OFFSET_STEP_M) * LAS_OFFSET_STEP_M + 0.0  # no -0.0
    if len(xyz) and np.max(np.abs(xyz - offsets)) / LAS_SCALE_M >= 2**31 - 1:
        raise DataError(f"station {cloud.station_id}: the cloud spans more than LAS holds at "
                        f"{LAS_SCALE_M * 1e3:g} mm resolution; crop it before writing")
    header.offsets, header.scales = offsets, np.full(3, LAS_SCALE_M)
    header.add_extra_dims([laspy.ExtraBytesParams(name, dtype, description=desc)
                           for name, dtype, _, desc in _ATTRIBUTES])
    header.global_encoding.wkt = True
    if crs_wkt:
        header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr(crs_wkt))
    header.vlrs.append(laspy.VLR("markerplan", 1, "frame, classes, markers",
                                 json.dumps(meta, sort_keys=True).encode()))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz.T
    las.classification = cloud.classification
    las.return_number = np.ones(len(xyz), np.uint8)
    las.number_of_returns = np.ones(len(xyz), np.uint8)
    for name, _, _, _ in _ATTRIBUTES:
        las[name] = getattr(cloud, name)
    path = Path(path)
    las.write(path)
    return path


def write_ply(path: str | Path, cloud: ClassifiedCloud, pose: StationPose | None = None,
              crs_wkt: str | None = None) -> Path:
    """Write a binary little-endian PLY: double x, y, z, uchar classification, then the
    per-point attributes (``frame_index``, ``laser_id``, ``marker_index``).

    Comments name the station, the frame, the classes, each accepted marker's centre and the
    CRS (WKT on one line). Coordinates are doubles: site coordinates (UTM, hundreds of km)
    keep their sub-millimetre digits.

    Parameters
    ----------
    path : path-like
    cloud : ClassifiedCloud
    pose : StationPose, optional
        Write in the site frame (default: the station frame).
    crs_wkt : str, optional
        CRS of the site frame, WKT.
    """
    return _write_ply(path, cloud, *_in_frame(cloud, pose), crs_wkt)


def _write_ply(path: str | Path, cloud: ClassifiedCloud, xyz: np.ndarray, meta: dict[str, Any],
               crs_wkt: str | None) -> Path:
    """:func:`write_ply` of the cloud's points already in the file's frame (:func:`_in_frame`
    gives ``xyz``, (N, 3) metres, and ``meta``)."""
    fields = [("x", "<f8", "double"), ("y", "<f8", "double"), ("z", "<f8", "double"),
              ("classification", "u1", "uchar"),
              *((name, np.dtype(dtype).newbyteorder("<").str, ply)
                for name, dtype, ply, _ in _ATTRIBUTES)]
    rec = np.empty(len(xyz), dtype=[(name, dt) for name, dt, _ in fields])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["classification"] = cloud.classification
    for name, _, _, _ in _ATTRIBUTES:
        rec[name] = getattr(cloud, name)
    comments = [f"markerplan process: station {cloud.station_id}, {meta['frame']} frame, metres",
                *(f"class {k} {v}" for k, v in meta["classes"].items()),
                *(f"marker_index {m['marker_index']} id {m['marker_id'] or '-'} centre_m "
                  + " ".join(f"{v:.6f}" for v in m["centre_m"]) for m in meta["markers"])]
    if crs_wkt:
        comments.append("crs " + " ".join(crs_wkt.split()))
    head = ["ply", "format binary_little_endian 1.0", *(f"comment {c}" for c in comments),
            f"element vertex {len(xyz)}", *(f"property {ply} {name}" for name, _, ply in fields),
            "end_header"]
    path = Path(path)
    path.write_bytes(("\n".join(head) + "\n").encode("ascii", "replace") + rec.tobytes())
    return path
