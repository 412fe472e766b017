"""Turntable synthesis: merge a station's frames into one cloud in the station frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.scans.rig import MountingOffsets, sensor_to_station_with_range
from pipeline.scans.scan_format import StationScan


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
    xyz, range_m = sensor_to_station_with_range(scan.xyz_sensor_m, scan.frame_index,
                                                scan.turntable_angle_rad, offsets)
    return StationCloud(xyz, scan.frame_index, range_m, offsets)

