"""Initial values of the network adjustment from stations chained outward, or a marker's
position from given poses (:mod:`pipeline.network.adjustment`'s module doc)."""

from __future__ import annotations

import numpy as np

from pipeline.network.design import station_rotations
from pipeline.network.observations import NetworkObservations
from pipeline.scans.rig import fit_heading_shift, rot_z


def chained_initial(obs: NetworkObservations, order: list[int], reference_pose: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Initial poses (s, 6) and markers (k, 3) chained outward from the reference station."""
    s, k = len(obs.station_ids), len(obs.marker_ids)
    pose = np.zeros((s, 6))
    markers = np.full((k, 3), np.nan)
    weight = 1.0 / obs.sigma_m**2
    for position, i in enumerate(order):
        rows = np.flatnonzero(obs.station == i)
        known = rows[~np.isnan(markers[obs.marker[rows], 0])]
        if position == 0:
            pose[i, :4] = reference_pose
        else:
            heading, t, _, _ = fit_heading_shift(obs.xyz_m[known],
                                                 markers[obs.marker[known]], weight[known])
            pose[i, :3], pose[i, 3] = t, heading
        new = rows[np.isnan(markers[obs.marker[rows], 0])]
        markers[obs.marker[new]] = pose[i, :3] + obs.xyz_m[new] @ rot_z(pose[i, 3]).T
    return pose, markers


def markers_from_poses(obs: NetworkObservations, pose: np.ndarray) -> np.ndarray:
    """Each marker's weighted mean position as its stations (at ``pose``) see it, (k, 3)."""
    rz, ry, rx = station_rotations(pose[:, 3:])
    r = rz @ ry @ rx
    site = pose[obs.station, :3] + np.einsum("nij,nj->ni", r[obs.station], obs.xyz_m)
    w = 1.0 / obs.sigma_m**2
    k = len(obs.marker_ids)
    total = np.bincount(obs.marker, weights=w, minlength=k)
    return np.column_stack([np.bincount(obs.marker, weights=w * site[:, a], minlength=k)
                            for a in range(3)]) / total[:, None]
