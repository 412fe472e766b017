"""Turntable synthesis: merge a station's frames into one cloud in the station frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.rig import MountingOffsets, frame_poses
from pipeline.scan_format import StationScan


@dataclass(frozen=True)
class StationCloud:
    """One station's merged cloud.

    Attributes
    ----------
    xyz_m : (N, 3) float64
        Points in the station frame (origin at the nominal LiDAR centre, z up), metres.
    frame_index : (N,) uint32
        Frame of each point.
    range_m : (N,) float64
        Distance of each point from the station origin, metres.
    offsets : MountingOffsets
        The mounting offsets applied.
    """

    xyz_m: np.ndarray
    frame_index: np.ndarray
    range_m: np.ndarray
    offsets: MountingOffsets

    @property
    def n_points(self) -> int:
        return int(self.xyz_m.shape[0])


def synthesize(scan: StationScan, offsets: MountingOffsets | None = None) -> StationCloud:
    """Rotate every frame by its turntable angle (with the mounting offsets) into one cloud.

    Parameters
    ----------
    scan : StationScan
        A validated scan (every frame has a turntable angle).
    offsets : MountingOffsets, optional
        Mounting offsets to correct for (default: none).

    Returns
    -------
    StationCloud
    """
    offsets = MountingOffsets() if offsets is None else offsets
    xyz = frames_to_station(scan.xyz_sensor_m, scan.frame_index, scan.turntable_angle_rad,
                            offsets)
    return StationCloud(xyz, scan.frame_index, np.sqrt(np.einsum("ij,ij->i", xyz, xyz)),
                        offsets)


def frames_to_station(xyz_sensor_m: np.ndarray, frame_index: np.ndarray,
                      turntable_angle_rad: np.ndarray, offsets: MountingOffsets) -> np.ndarray:
    """Sensor-frame points to the station frame, one matrix product per run of equal frames.

    Same result as :func:`pipeline.rig.sensor_to_station` without its (N, 3, 3) temporary, so
    it scales to the ~10 million points of an 800-frame station.

    Parameters
    ----------
    xyz_sensor_m : (N, 3) float
        Points in the sensor frame, metres.
    frame_index : (N,) int
        Frame of each point (runs of equal values are transformed together; sorted is fastest).
    turntable_angle_rad : (F,) float
        Turntable angle per frame, radians.
    offsets : MountingOffsets

    Returns
    -------
    xyz_station_m : (N, 3) float64
    """
    rotation, translation = frame_poses(turntable_angle_rad, offsets)
    fi = np.asarray(frame_index)
    out = np.empty((fi.size, 3))
    if fi.size == 0:
        return out
    starts = np.flatnonzero(np.r_[True, fi[1:] != fi[:-1]])
    ends = np.r_[starts[1:], fi.size]
    p = np.asarray(xyz_sensor_m)
    for a, b in zip(starts, ends, strict=True):
        f = fi[a]
        out[a:b] = p[a:b] @ rotation[f].T + translation[f]
    return out
