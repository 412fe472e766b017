"""Geometry of the tilted-VLP-16-on-a-turntable rig: sensor frame -> turntable -> station.

This module is part of the scan-format contract (the simulator in ``visibility`` uses it to
cast rays; the pipeline uses it to synthesise and calibrate), so both sides agree on every
convention.

Frames
------
sensor (S)
    The VLP-16's own frame: origin at the optical centre, z along the spin axis. A return
    of laser elevation ``omega`` at spin azimuth ``alpha`` (clockwise from +y) and range
    ``r`` lies at ``(r cos(omega) sin(alpha), r cos(omega) cos(alpha), r sin(omega))``
    (Velodyne VLP-16 user manual, section 9).
turntable (T)
    Rotates with the turntable. z is the turntable axis (up); origin on that axis at the
    nominal LiDAR-centre height. The LiDAR is tilted 90 deg on an L-bracket: nominally
    S.x -> T.y, S.y -> T.z, S.z -> T.x, so the spin sweeps the vertical T y-z plane and the
    16 beams fan out horizontally (+-15 deg about T.x's normal plane).
station (P)
    Fixed to the rover: ``p_P = Rz(theta) p_T`` for a frame taken at turntable angle
    ``theta``. Same origin as T, z up, x along T.x at ``theta = 0``.
site (W)
    Local metres of the survey site; ``p_W = position + Rz(heading) Ry(pitch) Rx(roll) p_P``.

Mounting offsets (the three errors the pipeline self-calibrates)
---------------------------------------------------------------
vertical_axis_error_rad
    Rotation of the LiDAR about its own spin axis (S.z): its optical zero direction is off
    the true vertical. A frame and the frame 180 deg later see it with opposite signs.
lframe_tilt_rad
    Tilt of the L-bracket: rotation about T.y, so the spin axis leaves the horizontal and the
    spin plane leans off vertical.
axis_offset_m
    ``(dx, dy)``: the LiDAR centre's offset from the turntable axis in T's horizontal plane.
    Translation along the turntable axis is unobservable and not modelled.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from markerplan.errors import DataError

#: VLP-16 laser elevation angles in channel (firing) order, degrees (VLP-16 user manual).
VLP16_ELEVATION_DEG = (-15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0,
                       -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0)

#: Nominal rotation sensor -> turntable (columns are S.x, S.y, S.z in T coordinates).
NOMINAL_SENSOR_TO_TURNTABLE = np.array(
    [[0.0, 0.0, 1.0],
     [1.0, 0.0, 0.0],
     [0.0, 1.0, 0.0]]
)


@dataclass(frozen=True)
class MountingOffsets:
    """The three mounting errors of the rig (true values in simulation, estimates in processing).

    Attributes
    ----------
    vertical_axis_error_rad : float
        Rotation about the spin axis S.z, radians.
    lframe_tilt_rad : float
        Rotation of the bracket about T.y, radians.
    axis_offset_m : tuple of float
        ``(dx, dy)`` offset of the LiDAR centre from the turntable axis, metres, turntable frame.
    """

    vertical_axis_error_rad: float = 0.0
    lframe_tilt_rad: float = 0.0
    axis_offset_m: tuple[float, float] = (0.0, 0.0)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["axis_offset_m"] = [float(v) for v in self.axis_offset_m]
        return d


def rot_x(a: float | np.ndarray) -> np.ndarray:
    """Rotation matrices about x. ``a`` scalar -> (3, 3); ``a`` (n,) -> (n, 3, 3)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1),
                     np.stack([z, s, c], -1)], -2)


def rot_y(a: float | np.ndarray) -> np.ndarray:
    """Rotation matrices about y. ``a`` scalar -> (3, 3); ``a`` (n,) -> (n, 3, 3)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)


def rot_z(a: float | np.ndarray) -> np.ndarray:
    """Rotation matrices about z. ``a`` scalar -> (3, 3); ``a`` (n,) -> (n, 3, 3)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], -2)


def sensor_to_turntable_rotation(offsets: MountingOffsets) -> np.ndarray:
    """Rotation S -> T including the vertical-axis error and the L-frame tilt.

    Returns
    -------
    R : (3, 3) float
        ``p_T = R @ p_S + [dx, dy, 0]``.
    """
    return (rot_y(offsets.lframe_tilt_rad) @ NOMINAL_SENSOR_TO_TURNTABLE
            @ rot_z(offsets.vertical_axis_error_rad))


def frame_poses(turntable_angle_rad: np.ndarray, offsets: MountingOffsets
                ) -> tuple[np.ndarray, np.ndarray]:
    """Pose of the sensor in the station frame for each frame.

    Parameters
    ----------
    turntable_angle_rad : (F,) float
        Turntable angle of each frame, radians.
    offsets : MountingOffsets
        Mounting errors.

    Returns
    -------
    rotation : (F, 3, 3) float
        ``R_f`` with ``p_P = R_f @ p_S + t_f``.
    translation : (F, 3) float
        ``t_f``, the LiDAR centre in the station frame, metres.
    """
    theta = np.asarray(turntable_angle_rad, dtype=float).reshape(-1)
    rz = rot_z(theta)
    rotation = rz @ sensor_to_turntable_rotation(offsets)
    d = np.array([offsets.axis_offset_m[0], offsets.axis_offset_m[1], 0.0])
    translation = rz @ d
    return rotation, translation


def sensor_to_station(xyz_sensor_m: np.ndarray, frame_index: np.ndarray,
                      turntable_angle_rad: np.ndarray, offsets: MountingOffsets) -> np.ndarray:
    """Merge sensor-frame points of many frames into the station frame.

    Each point is rotated and shifted by its frame's pose (:func:`frame_poses`) in one compiled
    pass (:func:`pipeline.kernels.transform_frames`): no temporaries over the ~10 million
    points of an 800-frame station, and no per-frame overhead for subsamples of a few points
    per frame.

    Parameters
    ----------
    xyz_sensor_m : (N, 3) float
        Points in the sensor frame, metres.
    frame_index : (N,) int
        Frame of each point, indexing ``turntable_angle_rad`` (any order).
    turntable_angle_rad : (F,) float
        Turntable angle per frame, radians.
    offsets : MountingOffsets
        Mounting errors to apply.

    Returns
    -------
    xyz_station_m : (N, 3) float64
        Points in the station frame, metres.

    Raises
    ------
    DataError
        If a frame index has no turntable angle.
    """
    return _to_station(xyz_sensor_m, frame_index, turntable_angle_rad, offsets, False)[0]


def sensor_to_station_with_range(xyz_sensor_m: np.ndarray, frame_index: np.ndarray,
                                 turntable_angle_rad: np.ndarray, offsets: MountingOffsets
                                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sensor_to_station`, and each point's distance from the station origin (N,),
    metres, from the same pass."""
    return _to_station(xyz_sensor_m, frame_index, turntable_angle_rad, offsets, True)


def _to_station(xyz_sensor_m, frame_index, turntable_angle_rad, offsets, with_range: bool
                ) -> tuple[np.ndarray, np.ndarray]:
    # imported here: planning imports this module for the poses, and numba costs 0.4 s and
    # 90 MB to import
    from pipeline.kernels import transform_frames

    p = np.asarray(xyz_sensor_m)
    if p.dtype not in (np.float32, np.float64):
        p = p.astype(np.float64)
    fi = np.asarray(frame_index)
    rotation, translation = frame_poses(turntable_angle_rad, offsets)
    if fi.size and not 0 <= int(fi.min()) <= int(fi.max()) < rotation.shape[0]:
        raise DataError(f"frame indices run from {int(fi.min())} to {int(fi.max())} but there "
                        f"are {rotation.shape[0]} turntable angles: give one angle per frame")
    out = np.empty((fi.size, 3))
    range_m = np.empty(fi.size if with_range else 0)
    transform_frames(np.ascontiguousarray(p), np.ascontiguousarray(fi),
                     np.ascontiguousarray(rotation), np.ascontiguousarray(translation), out,
                     range_m)
    return out, range_m


def station_to_site_matrix(heading_rad: float, roll_rad: float = 0.0,
                           pitch_rad: float = 0.0) -> np.ndarray:
    """Rotation P -> W: ``Rz(heading) @ Ry(pitch) @ Rx(roll)``, shape (3, 3)."""
    return rot_z(heading_rad) @ rot_y(pitch_rad) @ rot_x(roll_rad)


def fit_heading_shift(src: np.ndarray, dst: np.ndarray, weight: np.ndarray
                      ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Weighted least-squares 4-DoF fit ``dst ~ Rz(heading) src + shift`` (closed form).

    The rotation is about the vertical only (levelled frames); z enters the shift alone.

    Parameters
    ----------
    src, dst : (n, 3) float
        Corresponding points in the two frames, m.
    weight : (n,) float
        Weights, 1 / per-axis variance (1/m^2).

    Returns
    -------
    heading : float
        Rotation about z from ``src`` to ``dst``, rad.
    shift : (3,) float
        Translation, m.
    spread : (2,) float
        Heading variance (rad^2) and per-axis variance of the weighted centre (m^2).
    centre : (3,) float
        Weighted centre of ``src``, m.

    Examples
    --------
    >>> src = np.array([[1.0, 0, 0], [0, 1, 0], [-1, 0, 0]])
    >>> h, t, _, _ = fit_heading_shift(src, src @ rot_z(0.5).T + [1, 2, 3], np.ones(3))
    >>> round(h, 6), [round(float(v), 6) for v in t]
    (0.5, [1.0, 2.0, 3.0])
    """
    total = weight.sum()
    cs, cd = weight @ src / total, weight @ dst / total
    s, d = src - cs, dst - cd
    heading = float(np.arctan2(weight @ (s[:, 0] * d[:, 1] - s[:, 1] * d[:, 0]),
                               weight @ (s[:, 0] * d[:, 0] + s[:, 1] * d[:, 1])))
    lever = float(weight @ (s[:, 0] ** 2 + s[:, 1] ** 2))
    return heading, cd - rot_z(heading) @ cs, np.array([1.0 / max(lever, 1e-12), 1.0 / total]), cs
