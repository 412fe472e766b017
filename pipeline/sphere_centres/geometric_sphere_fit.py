"""Geometric least-squares sphere fits (residuals ``|p - c| - R``), and the constants the
sphere-centre estimators share.

- :func:`lsq_fixed_radius`: the fixed-radius fit of the ASTM E3125 steps
  (:mod:`pipeline.sphere_centres.sphere_fit`) and of the self-calibration;
- :func:`fit_free_radius`: the free-radius fit of the quality gate's radius check when the
  sensor's noise is unknown. Biased small by range noise: 87 mm at ``s = 15 mm``, 62 mm at
  ``s = 45 mm`` for ``R = 0.1 m``; with the noise known,
  :func:`pipeline.sphere_centres.line_of_sight_fit.fit_line_of_sight` with ``free_radius=True`` is
  unbiased;
- :func:`cap_start`: an initial centre from points on the sphere's sensor-facing cap;
- :func:`bounded_radius_step`: the Gauss-Newton step of a free-radius fit whose radius is held
  in a bracket (both free-radius fits): a cap too flat or too few points for its radius ends
  at the bracket, a finite mismatch, instead of running away to hundreds of metres.
"""

from __future__ import annotations

import numpy as np

#: ASTM E3125-17 full cone angle about the scanner line of sight, degrees.
ASTM_CONE_DEG = 120.0
#: Fewest points that fix a sphere.
MIN_POINTS = 4


def lsq_fixed_radius(points_m: np.ndarray, radius_m: float, centre0_m: np.ndarray,
                     max_iter: int = 50, tol_m: float = 1e-10) -> np.ndarray:
    """Geometric least-squares sphere centre with the radius fixed (Gauss-Newton).

    Minimises ``sum (|p_i - c| - R)^2`` over ``c`` from ``centre0_m``, compiled
    (:func:`pipeline.kernels.gauss_newton_fixed_radius`): it runs hundreds of times per station.

    Parameters
    ----------
    points_m : (n, 3) float
    radius_m : float
    centre0_m : (3,) float
        Start; must lie on the correct (far) side of the surface for a cap.

    Returns
    -------
    centre_m : (3,) float
    """
    # imported here: planning imports this module, and numba costs 0.4 s and 90 MB to import
    from pipeline.kernels import gauss_newton_fixed_radius

    return gauss_newton_fixed_radius(np.ascontiguousarray(points_m, dtype=float), float(radius_m),
                                     np.array(centre0_m, dtype=float).reshape(3),
                                     int(max_iter), float(tol_m))


def fit_free_radius(points_m: np.ndarray, centre0_m: np.ndarray, radius0_m: float,
                    max_iter: int = 50, radius_bounds_m: tuple[float, float] | None = None
                    ) -> tuple[np.ndarray, float, float]:
    """Geometric least-squares sphere with a free radius (Levenberg-style Gauss-Newton).

    Parameters
    ----------
    points_m : (n, 3) float
    centre0_m : (3,) float
        Start centre.
    radius0_m : float
        Start radius.
    max_iter : int
    radius_bounds_m : (float, float), optional
        ``(low, high)``, metres, ``0 < low <= radius0_m <= high``: the radius is held in this
        bracket (:func:`bounded_radius_step`); ``None``: unbounded.

    Returns
    -------
    centre_m : (3,) float
    radius_m : float
    rms_m : float

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.linspace(-.02, .02, 5), np.linspace(-.02, .02, 5)), -1)
    >>> flat = np.column_stack([np.full(25, 4.9), g.reshape(-1, 2)])  # a flat patch
    >>> round(fit_free_radius(flat, np.array([5.0, 0, 0]), 0.1, radius_bounds_m=(0.025, 0.4))[1], 3)
    0.4
    """
    x = np.append(np.asarray(centre0_m, dtype=float), float(radius0_m))
    lam = 1e-6
    for _ in range(max_iter):
        d = points_m - x[:3]
        n = np.maximum(np.linalg.norm(d, axis=1), 1e-12)
        r = n - x[3]
        jac = np.column_stack([-d / n[:, None], -np.ones_like(n)])
        a = jac.T @ jac
        try:
            step = bounded_radius_step(a + lam * np.diag(np.diag(a) + 1e-12), jac.T @ r, x[3],
                                       radius_bounds_m)
        except np.linalg.LinAlgError:
            break
        x = x + step
        if np.linalg.norm(step) < 1e-10:
            break
    res = np.linalg.norm(points_m - x[:3], axis=1) - x[3]
    return x[:3], float(abs(x[3])), float(np.sqrt(np.mean(res ** 2)))


def bounded_radius_step(normal: np.ndarray, gradient: np.ndarray, radius_m: float,
                        bounds_m: tuple[float, float] | None) -> np.ndarray:
    """Gauss-Newton step of a free-radius sphere fit with the radius held in a bracket.

    The step ``s`` minimises the quadratic model ``s^T A s / 2 + g^T s`` (``A`` the normal
    matrix, ``g`` the gradient, unknowns ``(c_x, c_y, c_z, R)``). If the radius would leave
    ``bounds_m`` it is set on the bound and the centre takes the model's best step for that
    radius, so a fit whose data want a larger (smaller) sphere ends on the bound.

    Parameters
    ----------
    normal : (4, 4) float
        ``A = J^T W J`` (damping included).
    gradient : (4,) float
        ``g = J^T W r``, residuals ``r`` of sign such that the full step is ``-A^-1 g``.
    radius_m : float
        Current radius, metres (inside the bounds).
    bounds_m : (float, float) or None
        ``(low, high)``, metres; ``None``: the full step.

    Returns
    -------
    step : (4,) float

    Raises
    ------
    numpy.linalg.LinAlgError
        ``A`` (or its centre block) singular.

    Examples
    --------
    >>> import numpy as np
    >>> a = np.eye(4)
    >>> a[0, 3] = a[3, 0] = 0.5  # the radius and c_x coupled
    >>> np.round(bounded_radius_step(a, np.array([0, 0, 0, -1.0]), 0.1, (0.05, 0.4)), 6)[[0, 3]]
    array([-0.15,  0.3 ])
    """
    step = np.linalg.solve(normal, -gradient)
    if bounds_m is None:
        return step
    target = float(np.clip(radius_m + step[3], *bounds_m))
    if target == radius_m + step[3]:
        return step
    dr = target - radius_m
    centre = np.linalg.solve(normal[:3, :3], -(gradient[:3] + normal[:3, 3] * dr))
    return np.append(centre, dr)


def cap_start(points_m: np.ndarray, radius_m: float, sensor_m=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Initial centre from points known to lie on the sphere's sensor-facing cap.

    The centroid is pushed half a radius away from the sensor, then refined by a fixed-radius
    fit of those points.

    Parameters
    ----------
    points_m : (n, 3) float
        Cap points (e.g. the above-ground cluster of a candidate), metres.
    radius_m : float
    sensor_m : (3,) float

    Returns
    -------
    centre_m : (3,) float
    """
    sensor = np.asarray(sensor_m, dtype=float)
    centroid = points_m.mean(axis=0)
    los = (centroid - sensor) / max(np.linalg.norm(centroid - sensor), 1e-12)
    start = centroid + 0.5 * radius_m * los
    if points_m.shape[0] < MIN_POINTS:
        return start
    return lsq_fixed_radius(points_m, radius_m, start)
