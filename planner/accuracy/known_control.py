"""Predicted accuracy of a station registered to its markers by weighted least squares.

Degrees of freedom
------------------
A station's pose in the site frame has six degrees of freedom. Roll and pitch come from the
rover's inclinometer (1-sigma ``inclinometer_sigma_rad``) and are *not* estimated from the
markers; the markers determine the other four: the translation ``t = (x, y, z)`` and the heading
``psi`` (rotation about the vertical). A marker whose centre the station measures at ``p``
(station frame, levelled) maps to the site frame as ``m = t + Rz(psi) p``. Linearised about the
true pose, one marker contributes the 3 x 4 design block ``H = [I3 | (-dy, dx, 0)^T]``, where
``(dx, dy)`` is the marker's horizontal offset from the station (the heading lever arm).
Marker site coordinates are treated as known control.

Each marker centre is observed with the error model's 1-sigma 3D error ``sigma`` for that
station-site pair, i.e. per-axis variance ``sigma**2 / 3`` (isotropic). The information matrix is
``J = sum_i (3 / sigma_i**2) H_i^T H_i`` and the pose covariance ``C = J^-1``.

Predicted station error
-----------------------
A point of the station's cloud at horizontal offset ``q`` (``|q| <= R``, the working radius) is
registered with error ``e = dt + dpsi * (-q_y, q_x, 0)`` plus the inclinometer's vertical error
``q_y droll - q_x dpitch`` — so its covariance is ``Sigma(q) = G(q) C G(q)^T + diag(0, 0,
|q|^2 s_incl^2)``: the 6-parameter pose covariance :func:`pose_covariance` (roll and pitch
independent of the rest). The reported figure over the working disc is the configured
:class:`~planner.accuracy.figure.ErrorFigure`: the ellipsoid figure ``sqrt(chi2_3(0.95) *
lambda_max(Sigma(q)))`` maximised over the disc (default), or the 95 % quantile of the worst
error. Both take their maximum on the rim (convex in ``q``), evaluated at 72 bearings.

Treating the tilt as independent of the fitted pose is optimistic: the fit takes the tilted
station as level, so the tilted markers' displacement leaks into the fitted translation and
heading. Through the real fit, 8 markers: the quantile is exceeded in 4.97 % of level stations
but 6.4 % at 0.01 deg of tilt and 10.0 % at 0.03 deg
(:func:`planner.studies.figure_calibration.known_control_calibration`).

Adding a marker adds a positive semi-definite term to ``J``, so the predicted error never grows
when a marker is added (monotone in the marker set) — the integer program's cuts rely on this.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from markerplan.errors import ConfigError
from pipeline.network.design import pose_design_blocks
from pipeline.scans.rig import rot_z, station_to_site_matrix

#: chi-square 95 % quantile with 3 degrees of freedom (3D position error).
CHI2_3_95 = float(chi2.ppf(0.95, 3))

_N_RIM = 72


def _design_blocks(offset_xy: np.ndarray) -> np.ndarray:
    """(k, 3, 4) design blocks ``[I3 | (-dy, dx, 0)]`` for horizontal offsets (k, 2)."""
    k = offset_xy.shape[0]
    h = np.zeros((k, 3, 4))
    h[:, 0, 0] = h[:, 1, 1] = h[:, 2, 2] = 1.0
    h[:, 0, 3] = -offset_xy[:, 1]
    h[:, 1, 3] = offset_xy[:, 0]
    return h


def _accuracy_iv(station_xy, marker_xy, sigma_m):
    station_xy = np.asarray(station_xy, dtype=float)
    marker_xy = np.asarray(marker_xy, dtype=float)
    sigma_m = np.asarray(sigma_m, dtype=float)
    if station_xy.shape[-1:] != (2,) and station_xy.shape[-1:] != (3,):
        raise ConfigError(f"`station_xy` must have shape (2,) or (3,), got {station_xy.shape}")
    if marker_xy.ndim != 2 or marker_xy.shape[1] not in (2, 3):
        raise ConfigError(f"`marker_xy` must have shape (k, 2) or (k, 3), got {marker_xy.shape}")
    if sigma_m.shape != (marker_xy.shape[0],):
        raise ConfigError(f"`sigma_m` must have shape ({marker_xy.shape[0]},), "
                          f"got {sigma_m.shape}")
    if np.any(~np.isfinite(sigma_m)) or np.any(sigma_m <= 0):
        raise ConfigError("`sigma_m` must be finite and > 0 for every marker")
    return station_xy[:2], marker_xy[:, :2], sigma_m


def _information(offset_xy: np.ndarray, weight: np.ndarray) -> np.ndarray:
    h = _design_blocks(offset_xy)
    return np.einsum("k,kia,kib->ab", weight, h, h)


def _rim_blocks(working_radius_m: float) -> np.ndarray:
    phi = np.linspace(0.0, 2.0 * np.pi, _N_RIM, endpoint=False)
    q = working_radius_m * np.column_stack([np.cos(phi), np.sin(phi)])
    return np.concatenate([_design_blocks(np.zeros((1, 2))), _design_blocks(q)])


def errors_from_information(j: np.ndarray, working_radius_m: float,
                            inclinometer_sigma_rad: float, figure) -> np.ndarray:
    """Predicted 95 % error (see module doc) for a batch of information matrices, m.

    Parameters
    ----------
    j : (k, 4, 4) float
        Information matrices of the 4-DoF pose.
    working_radius_m, inclinometer_sigma_rad : float
    figure : planner.accuracy.figure.ErrorFigure
        Which 95 % figure.

    Returns
    -------
    error_m : (k,) float
        ``inf`` where the pose is not determined (singular information).
    """
    j = np.asarray(j, dtype=float).reshape(-1, 4, 4)
    ok = _determined(j)
    out = np.full(j.shape[0], np.inf)
    if not ok.any():
        return out
    out[ok] = figure.station_errors(np.linalg.inv(j[ok]), working_radius_m,
                                    inclinometer_sigma_rad)
    return out


def within_from_information(j: np.ndarray, working_radius_m: float,
                            inclinometer_sigma_rad: float, figure, allowed_m) -> np.ndarray:
    """(k,) bool: the predicted error of each information matrix ``j`` (k, 4, 4) is at most
    ``allowed_m`` (m; scalar or (k,)), as :func:`errors_from_information` would say, deciding
    most without computing a quantile
    (:meth:`~planner.accuracy.figure.ErrorFigure.station_within`)."""
    j = np.asarray(j, dtype=float).reshape(-1, 4, 4)
    allowed = np.broadcast_to(np.asarray(allowed_m, dtype=float), j.shape[:1])
    ok = _determined(j)
    out = np.zeros(j.shape[0], bool)
    if ok.any():
        out[ok] = figure.station_within(np.linalg.inv(j[ok]), working_radius_m, allowed[ok],
                                        inclinometer_sigma_rad)
    return out


def _determined(j: np.ndarray) -> np.ndarray:
    """(k,) bool: information matrices (k, 4, 4) that determine the pose (not singular)."""
    w = np.linalg.eigvalsh(j)
    return w[:, 0] > 1e-9 * np.maximum(w[:, -1], 1e-300)


def pose_covariance(cov4: np.ndarray, inclinometer_sigma_rad: float) -> np.ndarray:
    """(k, 6, 6) covariance of (x, y, z, heading, roll, pitch): the (k, 4, 4) ``cov4`` of the
    registered parameters with independent roll and pitch of 1-sigma ``inclinometer_sigma_rad``.

    Examples
    --------
    >>> pose_covariance(np.eye(4)[None] * 1e-4, 1e-3)[0].diagonal().tolist()
    [0.0001, 0.0001, 0.0001, 0.0001, 1e-06, 1e-06]
    """
    cov4 = np.asarray(cov4, dtype=float)
    out = np.zeros(cov4.shape[:-2] + (6, 6))
    out[..., :4, :4] = cov4
    out[..., 4, 4] = out[..., 5, 5] = inclinometer_sigma_rad**2
    return out


def rim_covariances(cov: np.ndarray, working_radius_m: float) -> np.ndarray:
    """``G(q) C G(q)^T`` at the station (``q = 0``) and at 72 rim points ``|q| = R``.

    Parameters
    ----------
    cov : (k, 4, 4) or (k, 6, 6) float
        Pose covariances: (x, y, z, heading) or (x, y, z, heading, roll, pitch)
        (:data:`pipeline.network.observations.POSE_PARAMETERS`), m^2, m rad, rad^2.
    working_radius_m : float
        ``R``, m; the rim points lie at the station's height.

    Returns
    -------
    sigma : (k, 73, 3, 3) float
        Covariance of the registered position of each point, m^2. With 6 parameters the
        roll and pitch columns ``(0, 0, q_y)``, ``(0, 0, -q_x)`` of ``G(q)``
        (:func:`rim_design_blocks`) add their terms; the 4-parameter part is the same
        arithmetic either way.

    Examples
    --------
    >>> c = np.zeros((1, 6, 6)); c[0, 4, 4] = 1e-8
    >>> s = rim_covariances(c, 10.0)
    >>> float(s[0, 0, 2, 2]), round(float(s[0, :, 2, 2].max()), 12)
    (0.0, 1e-06)
    """
    g = _rim_blocks(working_radius_m)
    h = g[:, :, 3]  # (r, 3) heading columns (-q_y, q_x, 0)
    c_tt = cov[:, None, :3, :3]
    c = cov[:, None, :3, 3]  # (k, 1, 3)
    cpp = cov[:, None, 3, 3, None, None]
    hh = h[None]
    sig = (c_tt + hh[..., :, None] * c[..., None, :] + c[..., :, None] * hh[..., None, :]
           + cpp * hh[..., :, None] * hh[..., None, :])
    if cov.shape[-1] == 6:
        t = -h[:, :2]  # (r, 2) tilt lever arm (q_y, -q_x) of the vertical component
        m = (np.einsum("kab,rb->kra", cov[:, :3, 4:], t)
             + hh * np.einsum("kb,rb->kr", cov[:, 3, 4:], t)[..., None])
        sig[..., :, 2] += m
        sig[..., 2, :] += m
        sig[..., 2, 2] += np.einsum("ra,kab,rb->kr", t, cov[:, 4:, 4:], t)
    return sig


def rim_design_blocks(working_radius_m: float) -> np.ndarray:
    """(73, 3, 6) network-mode design blocks ``G(q)`` of the station and the 72 rim points of
    :func:`rim_covariances`, in the same order (heading and tilts 0:
    :func:`pipeline.network.design.pose_design_blocks`)."""
    g = _rim_blocks(working_radius_m)
    q = np.column_stack([g[:, 1, 3], -g[:, 0, 3], np.zeros(g.shape[0])])
    return pose_design_blocks(q)[1]


def lambda_max_sym3(a: np.ndarray) -> np.ndarray:
    """Largest eigenvalue of symmetric 3 x 3 matrices (..., 3, 3), closed form (Smith 1961).

    Examples
    --------
    >>> float(lambda_max_sym3(np.diag([1.0, 3.0, 2.0])))
    3.0
    """
    a00, a11, a22 = a[..., 0, 0], a[..., 1, 1], a[..., 2, 2]
    a01, a02, a12 = a[..., 0, 1], a[..., 0, 2], a[..., 1, 2]
    q = (a00 + a11 + a22) / 3.0
    p1 = a01**2 + a02**2 + a12**2
    p2 = (a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * p1
    p = np.sqrt(p2 / 6.0)
    safe = np.where(p > 0, p, 1.0)
    b00, b11, b22 = (a00 - q) / safe, (a11 - q) / safe, (a22 - q) / safe
    b01, b02, b12 = a01 / safe, a02 / safe, a12 / safe
    det = (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
           + b02 * (b01 * b12 - b11 * b02))
    phi = np.arccos(np.clip(det / 2.0, -1.0, 1.0)) / 3.0
    return np.where(p > 0, q + 2.0 * p * np.cos(phi), q)


def linearisation(j: np.ndarray, working_radius_m: float, inclinometer_sigma_rad: float,
                  requirement_m: float, figure,
                  rim: str = "worst") -> list[tuple[np.ndarray, float]]:
    """Outer-approximation cuts of the accuracy requirement at the information matrix ``j``.

    The worst-case variance ``h(J) = max_{u, q} u^T G(q) J^-1 G(q)^T u`` is convex in ``J``
    (a maximum of convex functions, since ``J -> J^-1`` is operator convex), so its tangent at
    ``J0`` (direction ``u``, rim point ``q``, ``v = J0^-1 G(q)^T u``) is a valid lower bound:
    ``h(J) >= 2 h0 - v^T J v``. With ``J = sum_j x_j J_j`` the requirement ``h(J) + c <= b``
    (``b = requirement^2 / chi2_3(0.95)``, ``c`` the inclinometer term at ``q``) therefore
    implies the linear cut ``sum_j (v^T J_j v) x_j >= 2 h0 - (b - c)``. For the quantile
    figure ``b = requirement^2 / chi2_1(0.95)``, a necessary condition
    (:attr:`~planner.accuracy.figure.ErrorFigure.cut_chi2`).

    Parameters
    ----------
    j : (4, 4) float
        Information matrix to linearise at.
    working_radius_m, inclinometer_sigma_rad, requirement_m : float
    figure : planner.accuracy.figure.ErrorFigure
    rim : {"worst", "spread"}
        Tangent at the worst rim point only, or at the station and 8 rim points spread around
        the circle (each with its own worst direction ``u``).

    Returns
    -------
    cuts : list of ((4,) float, float)
        ``(v, rhs)`` pairs; the cut is ``sum_j (v^T J_j v) x_j >= rhs``. Empty when ``j`` is
        singular.
    """
    j = np.asarray(j, dtype=float)
    w = np.linalg.eigvalsh(j)
    if w[0] <= 1e-9 * max(w[-1], 1e-300):
        return []
    cov = np.linalg.inv(j)
    g = _rim_blocks(working_radius_m)
    sig = np.einsum("ria,ab,rjb->rij", g, cov, g)
    radius = np.full(g.shape[0], working_radius_m)
    radius[0] = 0.0
    incl = (radius * inclinometer_sigma_rad) ** 2
    sig_tot = sig.copy()
    sig_tot[:, 2, 2] += incl
    lam, vec = np.linalg.eigh(sig_tot)
    if rim == "worst":
        points = [int(np.argmax(lam[:, -1]))]
    else:
        points = [0, *range(1, g.shape[0], max(1, (g.shape[0] - 1) // 8))]
    b = requirement_m**2 / figure.cut_chi2
    cuts = []
    for r in points:
        u = vec[r, :, -1]
        h0 = float(u @ sig[r] @ u)
        c = float(u[2] ** 2 * incl[r])
        cuts.append((cov @ g[r].T @ u, 2.0 * h0 - (b - c)))
    return cuts


def pair_information(station_xy, marker_xy, sigma_m) -> np.ndarray:
    """Fisher information of the 4-DoF pose (x, y, z, heading) from each marker separately.

    Parameters
    ----------
    station_xy : (2,) or (3,) float
        Station position, site frame, m (only x, y are used).
    marker_xy : (k, 2) or (k, 3) float
        Marker centres, site frame, m.
    sigma_m : (k,) float
        1-sigma 3D centre error of each marker as seen from this station, m.

    Returns
    -------
    J : (k, 4, 4) float
        Information of each marker in units of 1/m^2 (translation) and 1/rad^2 (heading); a
        set of markers has the sum.

    Examples
    --------
    >>> J = pair_information([0, 0], [[10, 0], [0, 10], [-10, 0]], [0.01, 0.01, 0.01])
    >>> round(J.sum(axis=0)[0, 0])
    90000
    """
    station_xy, marker_xy, sigma_m = _accuracy_iv(station_xy, marker_xy, sigma_m)
    h = _design_blocks(marker_xy - station_xy)
    return np.einsum("k,kia,kib->kab", 3.0 / sigma_m**2, h, h)


def station_error(station_xy, marker_xy, sigma_m, working_radius_m: float,
                  inclinometer_sigma_rad: float = 0.0, figure=None) -> float:
    """Predicted 95 % registered-position error of a station over its working radius, m.

    Parameters
    ----------
    station_xy : (2,) or (3,) float
        Station position, site frame, m.
    marker_xy : (k, 2) or (k, 3) float
        Centres of the markers the station uses, site frame, m.
    sigma_m : (k,) float
        Error-model 1-sigma 3D centre error for each (station, marker) pair, m.
    working_radius_m : float
        Radius of the station's working disc, m.
    inclinometer_sigma_rad : float
        1-sigma roll/pitch error, rad.
    figure : planner.accuracy.figure.ErrorFigure, optional
        Which 95 % figure (default: the planner's default).

    Returns
    -------
    error_m : float
        ``inf`` when the markers cannot fix x, y, z and heading (fewer than two distinct
        horizontal positions).

    Examples
    --------
    >>> station_error([0, 0], [[10, 0]], [0.01], 10.0)
    inf
    >>> e = station_error([0, 0], [[10, 0], [0, 10], [-10, 0]], [0.01] * 3, 10.0)
    >>> 0.005 < e < 0.05
    True
    """
    station_xy, marker_xy, sigma_m = _accuracy_iv(station_xy, marker_xy, sigma_m)
    if working_radius_m <= 0 or inclinometer_sigma_rad < 0:
        raise ConfigError(f"`working_radius_m` must be > 0 and `inclinometer_sigma_rad` >= 0, "
                          f"got {working_radius_m!r}, {inclinometer_sigma_rad!r}")
    if marker_xy.shape[0] == 0:
        return float("inf")
    if figure is None:
        from planner.accuracy.figure import ErrorFigure

        figure = ErrorFigure()
    j = _information(marker_xy - station_xy, 3.0 / sigma_m**2)
    return float(errors_from_information(j[None], working_radius_m, inclinometer_sigma_rad,
                                         figure)[0])


def information_lower_bound(requirement_m: float, figure) -> float:
    """Least translation information ``sum_i 3 / sigma_i**2`` any passing station needs, 1/m^2.

    The translation block of ``C`` is at least ``(J_tt)^-1 = I / sum_i (3 / sigma_i**2)`` (Schur
    complement), and a passing station has ``k lambda_max(C_tt) <= requirement_m**2`` at the
    station itself (``k`` = ``figure.cut_chi2``: chi2_3(0.95) for the ellipsoid figure,
    chi2_1(0.95) for the quantile, one direction), so it needs ``sum_i 3 / sigma_i**2 >= k /
    requirement_m**2``. A necessary (valid) linear cut for the integer program.
    """
    return figure.cut_chi2 / requirement_m**2


def heading_information_lower_bound(requirement_m: float, working_radius_m: float,
                                    figure) -> float:
    """Least heading information ``sum_i 3 |d_i|^2 / sigma_i**2`` a passing station needs.

    ``d_i`` is marker ``i``'s horizontal offset from the station (m). For rim points ``q`` and
    ``-q`` the lever-arm term flips sign, so ``Var(u.dt + R dpsi) + Var(u.dt - R dpsi) =
    2 Var(u.dt) + 2 R^2 C_psipsi``: the larger of the two is at least ``R^2 C_psipsi >= R^2 /
    J_psipsi``. Meeting ``requirement_m`` therefore needs
    ``J_psipsi >= k R^2 / requirement_m**2`` (``k`` as in :func:`information_lower_bound`) — a
    second valid linear cut.
    """
    return figure.cut_chi2 * working_radius_m**2 / requirement_m**2


def fit_pose(station_frame_xyz: np.ndarray, site_xyz: np.ndarray, sigma_m: np.ndarray,
             heading0_rad: float = 0.0, iterations: int = 10) -> tuple[np.ndarray, float]:
    """Weighted least-squares 4-DoF pose from marker correspondences (Gauss-Newton).

    Parameters
    ----------
    station_frame_xyz : (k, 3) float
        Marker centres measured in the levelled station frame (roll/pitch already removed), m.
    site_xyz : (k, 3) float
        The same markers' site-frame coordinates (control), m.
    sigma_m : (k,) float
        1-sigma 3D centre error of each measurement, m (weights ``3 / sigma**2``).
    heading0_rad : float
        Starting heading, rad.
    iterations : int
        Gauss-Newton iterations.

    Returns
    -------
    translation_m : (3,) float
        Station origin in the site frame, m.
    heading_rad : float
        Rotation about the vertical from the levelled station frame to the site frame, rad.
    """
    p = np.asarray(station_frame_xyz, dtype=float)
    m = np.asarray(site_xyz, dtype=float)
    w = 3.0 / np.asarray(sigma_m, dtype=float) ** 2
    if p.shape != m.shape or p.ndim != 2 or p.shape[1] != 3 or w.shape != (p.shape[0],):
        raise ConfigError(f"`station_frame_xyz` and `site_xyz` must both be (k, 3) and "
                          f"`sigma_m` (k,), got {p.shape}, {m.shape}, {w.shape}")
    if p.shape[0] < 2:
        raise ConfigError(f"fit_pose needs at least 2 markers, got {p.shape[0]}")
    psi = float(heading0_rad)
    t = np.average(m - p @ rot_z(psi).T, axis=0, weights=w)
    for _ in range(iterations):
        rp = p @ rot_z(psi).T
        r = (m - (t + rp)).reshape(-1)
        h = _design_blocks(rp[:, :2]).reshape(-1, 4)
        ww = np.repeat(w, 3)
        step = np.linalg.solve(h.T @ (h * ww[:, None]), h.T @ (ww * r))
        t = t + step[:3]
        psi += step[3]
        if np.abs(step).max() < 1e-12:
            break
    return t, psi


def registration_error(translation_est_m, heading_est_rad: float, translation_true_m,
                       heading_true_rad: float, working_radius_m: float) -> float:
    """Largest 3D error over the working disc of a station registered with an estimated pose, m.

    The 4-DoF case (roll and pitch known) of :func:`pose_difference_m`: the levelled
    station-frame points ``p`` with ``|p_xy| <= working_radius_m`` at the station's own height map
    to ``t + Rz(psi) p``; the error is the largest difference between the estimated and true
    mapping (a rigid-motion difference, so the maximum lies on the rim).
    """
    return pose_difference_m(np.r_[np.asarray(translation_est_m, float), heading_est_rad, 0, 0],
                             np.r_[np.asarray(translation_true_m, float), heading_true_rad, 0, 0],
                             working_radius_m)


def pose_difference_m(pose_est: np.ndarray, pose_true: np.ndarray,
                      working_radius_m: float) -> float:
    """Largest 3D difference, over a station and its working-radius rim, between two 6-parameter
    mappings of its levelled station frame into the site frame, m.

    A levelled point ``p`` maps to ``t + Rz(heading) Ry(pitch) Rx(roll) p`` (the network
    adjustment's model); ``p`` runs over the station itself and 360 rim points at its height.

    Parameters
    ----------
    pose_est, pose_true : (6,) float
        ``POSE_PARAMETERS``: x, y, z (m), heading, roll, pitch (rad).
    working_radius_m : float
        > 0.

    Returns
    -------
    error_m : float

    Examples
    --------
    A 1 mrad heading error at a 10 m radius, and a 1 cm shift:

    >>> t = np.zeros(6)
    >>> round(pose_difference_m(np.array([0, 0, 0, 1e-3, 0, 0]), t, 10.0), 6)
    0.01
    >>> round(pose_difference_m(np.array([0, 0.01, 0, 0, 0, 0]), t, 10.0), 6)
    0.01
    """
    diff = registration_differences(pose_est, pose_true, working_radius_m, 360)
    return float(np.linalg.norm(diff, axis=1).max())


def registration_differences(pose_est: np.ndarray, pose_true: np.ndarray,
                             working_radius_m: float, n_rim: int) -> np.ndarray:
    """(1 + n_rim, 3) site-frame difference between two 6-parameter mappings of the same
    levelled points (``t + Rz(heading) Ry(pitch) Rx(roll) p``): the station and ``n_rim``
    equally spaced rim points at its height, m.

    Parameters
    ----------
    pose_est, pose_true : (6,) float
        ``POSE_PARAMETERS``: x, y, z (m), heading, roll, pitch (rad).
    working_radius_m : float
    n_rim : int
    """
    phi = np.linspace(0.0, 2.0 * np.pi, n_rim, endpoint=False)
    p = np.vstack([np.zeros((1, 3)), working_radius_m * np.column_stack(
        [np.cos(phi), np.sin(phi), np.zeros_like(phi)])])

    def mapped(pose):
        pose = np.asarray(pose, dtype=float)
        r = station_to_site_matrix(pose[3], pose[4], pose[5])
        return pose[:3] + p @ r.T

    return mapped(pose_est) - mapped(pose_true)
