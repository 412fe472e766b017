"""The linearised observation model of network mode: a station measuring a marker's centre.

Station ``s`` with the pose ``(x, y, z, heading, roll, pitch)`` (site frame, see
:data:`pipeline.network.observations.POSE_PARAMETERS`) measures marker ``j``'s centre at ``p``
in its levelled station frame. The observation equation and its weight are

    f = t_s + Rz(heading_s) Ry(pitch_s) Rx(roll_s) p - m_j,   per-axis weight 3 / sigma^2

(``sigma`` the error model's isotropic 1-sigma 3D centre error). Its design block, the
derivative of ``f`` with respect to the station's 6 pose parameters and the marker's 3
coordinates, is ``[H | -I3]`` with ``H`` (3 x 6) from :func:`pose_design_blocks`; the marker's
part is the constant ``-I3``.

Both the network adjustment (:mod:`pipeline.network.adjustment`, linearised at each
Gauss-Newton iterate) and the planner's predicted network accuracy
(:mod:`planner.accuracy.network`, linearised at the nominal layout: tilts 0 and the levelled
frame along the site axes) use these two functions, so the planner predicts the covariance the
adjustment will report (on a curved body too: the tilt prior's centre, the local vertical's
deflection of :mod:`pipeline.network.body`, changes no covariance).
"""

from __future__ import annotations

import numpy as np

from pipeline.scans.rig import rot_x, rot_y, rot_z


def axis_weight(sigma_m):
    """Per-axis weight of a marker-centre measurement with isotropic 3D 1-sigma ``sigma_m``.

    Parameters
    ----------
    sigma_m : float or (...) float
        1-sigma 3D centre error, m (> 0); the per-axis variance is ``sigma**2 / 3``.

    Returns
    -------
    weight : float or (...) float
        ``3 / sigma**2``, 1/m^2, the shape of ``sigma_m``.

    Examples
    --------
    >>> axis_weight(np.array([0.01, 0.02])).round(1).tolist()
    [30000.0, 7500.0]
    """
    return 3.0 / sigma_m**2


def station_rotations(angles_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The factors of the levelled-station-to-site rotation ``R = Rz(heading) Ry(pitch) Rx(roll)``.

    Parameters
    ----------
    angles_rad : (n, 3) float
        ``(heading, roll, pitch)`` of each station (the angles of ``POSE_PARAMETERS``), rad.

    Returns
    -------
    rz, ry, rx : (n, 3, 3) float
        ``Rz(heading)``, ``Ry(pitch)``, ``Rx(roll)``.
    """
    return rot_z(angles_rad[:, 0]), rot_y(angles_rad[:, 2]), rot_x(angles_rad[:, 1])


def pose_design_blocks(offset_m: np.ndarray, angles_rad: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Site-frame offsets and pose design blocks of marker centres measured by stations.

    Parameters
    ----------
    offset_m : (n, 3) float
        Marker centre ``p`` in the observing station's levelled frame, m.
    angles_rad : (n, 3) float or None
        ``(heading, roll, pitch)`` of the observing station to linearise at, rad; None for all
        zero (the levelled frame along the site axes: ``p`` is the site-frame offset), which
        skips the rotations.

    Returns
    -------
    rotated_m : (n, 3) float
        ``q = R p``: the marker's offset from the station along the site axes, m.
    blocks : (n, 3, 6) float
        ``H = d(t + R p) / d(x, y, z, heading, roll, pitch)``: ``I3`` (dimensionless), the
        heading column ``(-q_y, q_x, 0)``, the roll column ``Rz Ry (e_x x Rx p)`` and the pitch
        column ``Rz (e_y x Ry Rx p)`` (m/rad). The marker centre's block is ``-I3``.

    Examples
    --------
    >>> q, h = pose_design_blocks(np.array([[1.0, 2.0, 3.0]]))
    >>> h[0]
    array([[ 1.,  0.,  0., -2.,  0.,  3.],
           [ 0.,  1.,  0.,  1., -3.,  0.],
           [ 0.,  0.,  1.,  0.,  2., -1.]])

    A heading of 90 degrees turns the offset and the tilt axes:

    >>> q, h = pose_design_blocks(np.array([[1.0, 2.0, 3.0]]), np.array([[np.pi / 2, 0, 0]]))
    >>> np.round(q, 12).tolist(), (np.round(h[0, :, 3:], 12) + 0.0).tolist()
    ([[-2.0, 1.0, 3.0]], [[-1.0, 3.0, 0.0], [-2.0, 0.0, 3.0], [0.0, 2.0, -1.0]])
    """
    p = np.asarray(offset_m, dtype=float)
    n = p.shape[0]
    if angles_rad is None:
        a = b = q = p
    else:
        rz, ry, rx = station_rotations(angles_rad)
        a = np.einsum("nij,nj->ni", rx, p)
        b = np.einsum("nij,nj->ni", ry, a)
        q = np.einsum("nij,nj->ni", rz, b)
    block = np.zeros((n, 3, 6))
    block[:, [0, 1, 2], [0, 1, 2]] = 1.0
    block[:, 0, 3], block[:, 1, 3] = -q[:, 1], q[:, 0]
    zero = np.zeros(n)
    d_roll = np.column_stack([zero, -a[:, 2], a[:, 1]])   # e_x x (Rx p)
    d_pitch = np.column_stack([b[:, 2], zero, -b[:, 0]])  # e_y x (Ry Rx p)
    if angles_rad is None:
        block[:, :, 4], block[:, :, 5] = d_roll, d_pitch
    else:
        block[:, :, 4] = np.einsum("nij,nj->ni", rz @ ry, d_roll)
        block[:, :, 5] = np.einsum("nij,nj->ni", rz, d_pitch)
    return q, block
