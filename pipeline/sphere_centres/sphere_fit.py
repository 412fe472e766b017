"""Sphere-centre estimation from a point cloud of known radius: two estimators, one interface.

Both estimators take the points of one candidate (any frame, e.g. station frame) and the
position of the scanner in that same frame, and return a :class:`SphereFit`.

``fixed-radius`` (default)
    The line-of-sight procedure of ASTM E3125-17 as published by NIST (DMG_SphereFitting,
    ``coneCylAlgoE57``): (1) *closest-point* initial estimate: the median range of the
    ``min(500, 5 %)`` points nearest the scanner marks the front of the sphere; points within
    half a radius behind it are fitted with the radius fixed; (2) keep the points inside the
    cone of half-angle 60 deg about the centre->scanner line (apex at the centre) that also lie
    within the cylinder of radius ``R sin 60 deg`` about the scanner->centre line; (3) fit with
    the radius fixed (:func:`~pipeline.sphere_centres.geometric_sphere_fit.lsq_fixed_radius`), drop
    points whose residual exceeds 3 standard deviations, fit again; repeat (2)-(3) from the new
    centre until the centre moves less than ``tol_m`` (or ``max_iter`` times: a loop that does not
    converge cycles through a few point sets, and is stopped where ``max_iter`` would leave it
    once the cycle has been seen twice). The centre is held within ``max_shift_m`` (default one
    diameter) of the initial estimate: a fit of a handful of trimmed points can otherwise jump
    metres (4.7 m from a start 2 cm off, 8 points at 24 m), and a fit held on that bound is
    reported not converged.

    *With the sensor's range noise given* (``noise``, a
    :class:`~pipeline.scans.sensor_noise.RangeNoise`) the same procedure runs on line-of-sight
    residuals instead (:func:`pipeline.sphere_centres.line_of_sight_fit.astm_beam_steps`): (2) tests
    the cylinder on each beam, (3) fits the measured ranges by weighted least squares and trims on
    the normalised range residuals. This removes the pull toward the sensor that range noise gives
    the fit of ``|p - c| - R`` (the docstring of :mod:`pipeline.sphere_centres.line_of_sight_fit`).
``hemisphere-icp``
    The published marker method: point-to-point ICP of a known-radius hemisphere model (a
    dense point cloud of the sphere's half that faces the scanner) to the points, solving a
    translation only. Correspondences farther than ``max_correspondence_m`` are ignored. It is
    run as published, with or without ``noise``.

The free-radius fits of the quality gate's radius check are
:func:`pipeline.sphere_centres.geometric_sphere_fit.fit_free_radius` and, with the noise known,
:func:`pipeline.sphere_centres.line_of_sight_fit.fit_line_of_sight`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from markerplan.constants import GOLDEN_ANGLE_RAD
from markerplan.errors import ConfigError, DataError
from markerplan.reading import MAX_ABS_COORDINATE_M
from pipeline.scans.sensor_noise import RangeNoise
from pipeline.sphere_centres.geometric_sphere_fit import ASTM_CONE_DEG, MIN_POINTS, lsq_fixed_radius
from pipeline.sphere_centres.line_of_sight_fit import astm_beam_steps

METHODS = ("fixed-radius", "hemisphere-icp")
DEFAULT_METHOD = "fixed-radius"


@dataclass(frozen=True)
class SphereFit:
    """Result of one sphere-centre estimate.

    Attributes
    ----------
    centre_m : (3,) float
        Estimated centre, metres, in the frame of the input points.
    radius_m : float
        The (fixed) radius used, metres.
    rms_m : float
        RMS of ``|p - centre| - radius`` over the points used, metres.
    n_points : int
        Points given.
    n_used : int
        Points used by the final fit (after trimming / correspondence rejection).
    used : (n_points,) bool
        Which input points the final fit used.
    method : str
        ``"fixed-radius"`` or ``"hemisphere-icp"``.
    iterations : int
        Outer iterations run (a fit whose iterations cycle stops early and reports those the
        loop would have run, ``max_iter``; see ``_astm_e3125``).
    converged : bool
        Whether the centre moved less than the tolerance before the iteration cap.
    """

    centre_m: np.ndarray
    radius_m: float
    rms_m: float
    n_points: int
    n_used: int
    used: np.ndarray
    method: str
    iterations: int
    converged: bool

    def to_dict(self) -> dict:
        return {"centre_m": [float(v) for v in self.centre_m], "radius_m": self.radius_m,
                "rms_m": self.rms_m, "n_points": self.n_points, "n_used": self.n_used,
                "method": self.method, "iterations": self.iterations,
                "converged": self.converged}


def fit_sphere(points_m: np.ndarray, radius_m: float, sensor_m=(0.0, 0.0, 0.0),
               method: str = DEFAULT_METHOD, *, tol_m: float = 1e-7, max_iter: int = 100,
               max_correspondence_m: float | None = None,
               centre0_m: np.ndarray | None = None,
               noise: RangeNoise | None = None, max_shift_m: float | None = None) -> SphereFit:
    """Estimate the centre of a sphere of known radius seen from ``sensor_m``.

    Parameters
    ----------
    points_m : (n, 3) float
        Points on (and near) the sphere, metres, any frame.
    radius_m : float
        Known sphere radius, metres, > 0.
    sensor_m : (3,) float
        Scanner origin in the same frame, metres.
    method : {"fixed-radius", "hemisphere-icp"}
        Estimator (see the module docstring).
    tol_m : float
        Convergence: stop when the centre moves less than this, metres.
    max_iter : int
        Iteration cap.
    max_correspondence_m : float, optional
        ``hemisphere-icp`` only: ignore pairs farther apart than this (default ``radius_m / 2``).
    centre0_m : (3,) float, optional
        Initial centre. Default: the ASTM closest-point estimate, which assumes the sphere is
        the closest surface; give a start when ground in front of the sphere is included.
    noise : RangeNoise, optional
        The scanner's range noise. ``fixed-radius`` then fits line-of-sight residuals, which
        removes the noise bias (:mod:`pipeline.sphere_centres.line_of_sight_fit`); ``None``
        (default): the ASTM fit of ``|p - c| - R``. ``hemisphere-icp`` does not use it.
    max_shift_m : float, optional
        ``fixed-radius`` only: the centre stays within this distance of the initial centre
        (the start or the closest-point estimate), metres; default ``2 radius_m`` (the
        closest-point estimate can be a radius off when a mount stands in front).

    Returns
    -------
    SphereFit
        Centre and RMS always finite; at least one point used.

    Raises
    ------
    DataError
        Fewer than 4 points, NaN/infinite or absurd coordinates (beyond
        :data:`markerplan.reading.MAX_ABS_COORDINATE_M`), all points identical or on one line,
        or no sphere of the radius fits (no point used, or the fit diverged).
    ConfigError
        ``radius_m`` not a positive finite number, bad ``sensor_m``, ``method``, ``tol_m``,
        ``max_iter``, ``max_correspondence_m``, ``centre0_m`` or ``max_shift_m``.

    Examples
    --------
    >>> import numpy as np
    >>> u = np.array([[-1, 0, 0], [-0.8, 0.6, 0], [-0.8, 0, 0.6], [-0.8, -0.6, 0],
    ...               [-0.8, 0, -0.6], [-0.6, 0.8, 0], [-0.6, 0, -0.8]])
    >>> fit = fit_sphere(np.array([5.0, 0, 0]) + 0.1 * u, 0.1)
    >>> bool(np.allclose(fit.centre_m, [5, 0, 0])), fit.n_used
    (True, 7)
    """
    p, sensor = _fit_sphere_iv(points_m, radius_m, sensor_m, method, tol_m, max_iter,
                               max_correspondence_m)
    if centre0_m is None:
        centre0, _ = _closest_point_start(p, float(radius_m), sensor)
    else:
        centre0 = np.asarray(centre0_m, dtype=float).reshape(-1)
        if centre0.shape != (3,) or not np.all(np.isfinite(centre0)):
            raise ConfigError(f"`centre0_m` must be three finite numbers, got {centre0_m!r}")
    if noise is not None and not isinstance(noise, RangeNoise):
        raise ConfigError(f"`noise` must be a RangeNoise or None, got {type(noise).__name__}")
    shift = 2.0 * float(radius_m) if max_shift_m is None else _number(max_shift_m, "max_shift_m")
    if not (shift > 0 and np.isfinite(shift)):
        raise ConfigError(f"`max_shift_m` must be a positive number of metres, got "
                          f"{max_shift_m!r}")
    if method == "fixed-radius":
        return _result_iv(_astm_e3125(p, float(radius_m), sensor, centre0, tol_m,
                                      int(max_iter), noise, shift))
    corr = radius_m / 2 if max_correspondence_m is None else float(max_correspondence_m)
    return _result_iv(_hemisphere_icp(p, float(radius_m), sensor, centre0, corr, tol_m,
                                      int(max_iter)))


def _fit_sphere_iv(points_m, radius_m, sensor_m, method, tol_m, max_iter, max_corr):
    try:
        p = np.asarray(points_m, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataError(f"`points_m` must be an (n, 3) array of numbers ({exc})") from exc
    if p.ndim != 2 or p.shape[1] != 3:
        raise DataError(f"`points_m` must have shape (n, 3), got {p.shape}")
    if p.shape[0] < MIN_POINTS:
        raise DataError(f"`points_m` needs at least {MIN_POINTS} points to fit a sphere, "
                        f"got {p.shape[0]}")
    if not np.all(np.isfinite(p)):
        raise DataError("`points_m` contains NaN or infinite coordinates; drop them first")
    biggest = float(np.max(np.abs(p)))
    if biggest > MAX_ABS_COORDINATE_M:
        raise DataError(f"`points_m` has a coordinate of {biggest:g}, beyond the accepted "
                        f"magnitude {MAX_ABS_COORDINATE_M:g}; check the units")
    radius = _number(radius_m, "radius_m")
    if not (np.isfinite(radius) and 0 < radius <= MAX_ABS_COORDINATE_M):
        raise ConfigError(f"`radius_m` must be a positive number of metres, got {radius_m!r}")
    try:
        sensor = np.asarray(sensor_m, dtype=float).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"`sensor_m` must be three finite numbers, got {sensor_m!r}") from exc
    if (sensor.shape != (3,) or not np.all(np.isfinite(sensor))
            or np.max(np.abs(sensor)) > MAX_ABS_COORDINATE_M):
        raise ConfigError(f"`sensor_m` must be three finite numbers, got {sensor_m!r}")
    if method not in METHODS:
        raise ConfigError(f"`method` must be one of {', '.join(METHODS)}; got {method!r}")
    tol, iters = _number(tol_m, "tol_m"), _number(max_iter, "max_iter")
    if not (tol > 0 and np.isfinite(tol)) or not (iters >= 1 and np.isfinite(iters)):
        raise ConfigError(f"`tol_m` must be > 0 and `max_iter` >= 1, got {tol_m}, {max_iter}")
    if max_corr is not None:
        corr = _number(max_corr, "max_correspondence_m")
        if not (corr > 0 and np.isfinite(corr)):
            raise ConfigError(f"`max_correspondence_m` must be > 0, got {max_corr!r}")
    _spread_iv(p, radius)
    return p, sensor


def _number(value, name: str) -> float:
    """``value`` as a float, or a ConfigError naming ``name``."""
    if isinstance(value, bool | np.bool_):
        raise ConfigError(f"`{name}` must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ConfigError(f"`{name}` must be a number, got {value!r:.40}") from exc


def _spread_iv(p: np.ndarray, radius: float) -> None:
    """Refuse point sets that cannot fix a centre: all identical, or all on one line.

    The spread along the second principal axis must exceed ``1e-6 radius`` (plus the
    float64 resolution of the coordinates): far below the noise of any scan, far above the
    rounding of a synthetic line.
    """
    centred = p - p.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False) / np.sqrt(p.shape[0])
    tol = 1e-6 * radius + 1e-12 * float(np.max(np.abs(p)))
    if s[0] <= tol:
        raise DataError(f"`points_m`: all {p.shape[0]} points are the same point (spread "
                        f"{s[0]:.3g} m); a sphere needs points spread over its surface")
    if s[1] <= tol:
        raise DataError(f"`points_m`: all {p.shape[0]} points lie on one line (spread across "
                        f"it {s[1]:.3g} m); a sphere needs points spread over its surface")


def _result_iv(fit: SphereFit) -> SphereFit:
    """Refuse a fit that used no points or diverged (never report NaN or infinity)."""
    if fit.n_used == 0 or not (np.all(np.isfinite(fit.centre_m)) and np.isfinite(fit.rms_m)):
        raise DataError(f"no sphere of radius {fit.radius_m:g} m fits the {fit.n_points} points "
                        f"({fit.method}: {fit.n_used} points used, centre "
                        f"{np.round(fit.centre_m, 6).tolist()}); check the radius, the sensor "
                        "position and that the points are one sphere")
    return fit


def _closest_point_start(p: np.ndarray, radius: float, sensor: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray]:
    """ASTM/NIST closest-point initial estimate; returns (centre, mask of points used)."""
    rng = np.linalg.norm(p - sensor, axis=1)
    n = p.shape[0]
    k = int(np.floor(min(500, 0.05 * n)))
    if k < 4:
        k = max(4, int(np.ceil(0.1 * n)))
    front = float(np.median(np.partition(rng, k - 1)[:k]))
    near = rng < front + 0.5 * radius
    if near.sum() < 3:
        near = np.ones(n, dtype=bool)
    centroid = p[near].mean(axis=0)
    los = (centroid - sensor) / max(np.linalg.norm(centroid - sensor), 1e-12)
    start = sensor + los * (front + radius)
    return lsq_fixed_radius(p[near], radius, start), near


def _cone_cylinder(p: np.ndarray, radius: float, sensor: np.ndarray, centre: np.ndarray,
                   half_angle_rad: float) -> np.ndarray:
    """Points inside the ASTM cone (apex at the centre, about centre->scanner) and cylinder."""
    co = sensor - centre
    axis = co / np.linalg.norm(co)
    cp = p - centre
    cos_angle = (cp @ axis) / np.maximum(np.linalg.norm(cp, axis=1), 1e-12)
    in_cone = cos_angle > np.cos(half_angle_rad)
    op = p - sensor
    along = op @ -axis
    perp2 = np.maximum(np.einsum("ij,ij->i", op, op) - along ** 2, 0.0)
    in_cyl = perp2 < (radius * np.sin(half_angle_rad)) ** 2
    return in_cone & in_cyl


def _residuals(p: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    return np.linalg.norm(p - centre, axis=1) - radius


def _astm_e3125(p, radius, sensor, centre, tol_m, max_iter, noise=None,
                max_shift_m=np.inf) -> SphereFit:
    """The ASTM E3125 loop; with ``noise`` on line-of-sight residuals (module docstring).

    Every fitted centre is held within ``max_shift_m`` of the initial ``centre``
    (:func:`_held_near`); a fit that ends on that bound is not converged.

    A loop that does not converge falls into a cycle: the points selected and kept repeat with
    a short period (2 to 12 iterations on the simulated stations) while the centre alternates
    between as many positions, up to millimetres apart. Once the last ``q`` iterations' point
    sets have repeated the ``q`` before them, the loop stops and reports the iteration of the
    cycle that iteration ``max_iter`` would reach (:func:`_cycle_period`): the same sets and,
    up to the Gauss-Newton stopping tolerance, the same centre, at a fraction of the cost.
    """
    start = centre

    def hold(c):
        return _held_near(c, start, max_shift_m)

    select, solve = (_geometric_steps(p, radius, sensor, hold) if noise is None
                     else astm_beam_steps(p, radius, sensor, noise, hold))
    used = np.ones(p.shape[0], dtype=bool)
    converged = False
    it = 0
    states, history = [], []  # point sets selected and kept; (centre, used) after each iteration
    for it in range(1, max_iter + 1):  # noqa: B007 - `it` is reported
        sel = select(centre)
        if sel.sum() < MIN_POINTS:
            break
        c1, res = solve(sel, centre)
        keep = np.zeros_like(sel)
        keep[np.flatnonzero(sel)[np.abs(res) < 3 * np.std(res)]] = True
        if keep.sum() < MIN_POINTS:
            keep = sel
        new, _ = solve(keep, c1)
        moved = float(np.linalg.norm(new - centre))
        centre, used = new, keep
        if moved < tol_m:
            converged = True
            break
        states.append((np.packbits(sel).tobytes(), np.packbits(keep).tobytes()))
        history.append((centre, used))
        period = _cycle_period(states)
        if period and it < max_iter:  # skip whole cycles: where iteration max_iter would be
            centre, used = history[-1 - (period - (max_iter - it) % period) % period]
            it = max_iter
            break
    res = _residuals(p[used], centre, radius)
    held = np.linalg.norm(centre - start) >= max_shift_m * (1 - 1e-9)
    return SphereFit(centre, radius, float(np.sqrt(np.mean(res ** 2))), p.shape[0],
                     int(used.sum()), used, "fixed-radius", it, converged and not held)


def _held_near(centre: np.ndarray, start: np.ndarray, max_shift_m: float) -> np.ndarray:
    """``centre``, or its projection onto the ball of radius ``max_shift_m`` about ``start``.

    Examples
    --------
    >>> _held_near(np.array([3.0, 4.0, 0.0]), np.zeros(3), 1.0).tolist()
    [0.6000000000000001, 0.8, 0.0]
    """
    shift = centre - start
    length = float(np.linalg.norm(shift))
    return centre if length <= max_shift_m else start + shift * (max_shift_m / length)


def _cycle_period(states: list) -> int:
    """Smallest ``q`` such that the last ``q`` states equal the ``q`` before them (0: none).

    Examples
    --------
    >>> _cycle_period(list("abcbc")), _cycle_period(list("abcb")), _cycle_period(list("aa"))
    (2, 0, 1)
    """
    for q in range(1, len(states) // 2 + 1):
        if states[-1] == states[-1 - q] and states[-q:] == states[-2 * q:-q]:
            return q
    return 0


def _geometric_steps(p, radius, sensor, hold):
    """The ASTM steps on the points: the 60 deg cone/cylinder about the centre, and the
    geometric fixed-radius fit, its centre passed through ``hold``, with its ``|p - c| - R``
    residuals."""
    half = np.radians(ASTM_CONE_DEG / 2)

    def select(centre):
        return _cone_cylinder(p, radius, sensor, centre, half)

    def solve(sel, start):
        c = hold(lsq_fixed_radius(p[sel], radius, start))
        return c, _residuals(p[sel], c, radius)

    return select, solve


def hemisphere_model(radius_m: float, spacing_m: float | None = None) -> np.ndarray:
    """Unit-centred hemisphere point model facing -x (Fibonacci lattice).

    Parameters
    ----------
    radius_m : float
    spacing_m : float, optional
        Approximate point spacing (default ``radius_m / 40``).

    Returns
    -------
    model : (m, 3) float
        Points ``radius_m * u`` with ``u_x <= 0``, relative to the centre.
    """
    spacing = radius_m / 40 if spacing_m is None else spacing_m
    n_full = int(np.ceil(4 * np.pi * radius_m ** 2 / spacing ** 2))
    i = np.arange(n_full) + 0.5
    x = 1 - 2 * i / n_full
    phi = -GOLDEN_ANGLE_RAD * i  # a Fibonacci sphere
    s = np.sqrt(1 - x ** 2)
    u = np.column_stack([x, s * np.cos(phi), s * np.sin(phi)])
    return radius_m * u[u[:, 0] <= 0]


def _facing_rotation(los: np.ndarray) -> np.ndarray:
    """Rotation taking +x to ``los`` (so the model's -x half faces the scanner)."""
    a = np.array([1.0, 0.0, 0.0])
    v = np.cross(a, los)
    c = float(a @ los)
    if 1 + c < 1e-9:  # los within ~5e-5 rad of -x: the half turn about z (1 / (1 + c) blows up)
        return np.diag([-1.0, -1.0, 1.0])
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def _hemisphere_icp(p, radius, sensor, centre, max_corr, tol_m, max_iter) -> SphereFit:
    model_local = hemisphere_model(radius)
    converged = False
    used = np.ones(p.shape[0], dtype=bool)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - `it` is reported
        los = (centre - sensor) / np.linalg.norm(centre - sensor)
        model = model_local @ _facing_rotation(los).T + centre
        dist, idx = cKDTree(model).query(p, k=1)
        used = dist < max_corr
        if used.sum() < MIN_POINTS:
            break
        step = (p[used] - model[idx[used]]).mean(axis=0)
        centre = centre + step
        if np.linalg.norm(step) < tol_m:
            converged = True
            break
    res = _residuals(p[used], centre, radius)
    rms = float(np.sqrt(np.mean(res ** 2))) if used.any() else float("nan")
    return SphereFit(centre, radius, rms, p.shape[0], int(used.sum()), used, "hemisphere-icp",
                     it, converged)
