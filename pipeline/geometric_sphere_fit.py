"""Geometric least-squares sphere fits (residuals ``|p - c| - R``), and the constants the
sphere-centre estimators share.

- :func:`lsq_fixed_radius`: the fixed-radius fit of the ASTM E3125 steps
  (:mod:`pipeline.sphere_fit`) and of the self-calibration;
- :func:`fit_free_radius`: the free-radius fit of the quality gate's radius check when the
  sensor's noise is unknown. Biased small by range noise: 87 mm at ``s = 15 mm``, 62 mm at
  ``s = 45 mm`` for ``R = 0.1 m``; with the noise known,
  :func:`pipeline.line_of_sight_fit.fit_line_of_sight` with ``free_radius=True`` is unbiased;
- :func:`cap_start`: an initial centre from points on the sphere's sensor-facing cap.
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
                    max_iter: int = 50) -> tuple[np.ndarray, float, float]:
    """Geometric least-squares sphere with a free radius (Levenberg-style Gauss-Newton).

    Parameters
    ----------
    points_m : (n, 3) float
    centre0_m : (3,) float
        Start centre.
    radius0_m : float
        Start radius.

    Returns
    -------
    centre_m : (3,) float
    radius_m : float
    rms_m : float
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
            step = np.linalg.solve(a + lam * np.diag(np.diag(a) + 1e-12), -jac.T @ r)
        except np.linalg.LinAlgError:
            break
        x = x + step
        if np.linalg.norm(step) < 1e-10:
            break
    res = np.linalg.norm(points_m - x[:3], axis=1) - x[3]
    return x[:3], float(abs(x[3])), float(np.sqrt(np.mean(res ** 2)))



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
