"""Noise-aware sphere fits on line-of-sight range residuals: the beam geometry of the points
and its weighted least squares.

A scanner measures range along a beam (the sensor -> point direction). These fits compare each
measured range ``rho_i = |p_i - sensor|`` with the range ``t_i(c, R)`` at which that beam meets
the sphere, weighted by ``1 / sigma_i^2`` from the sensor's noise
(:class:`~pipeline.scans.sensor_noise.RangeNoise`) at the point's range and incidence.

Why: range noise ``n`` along the beam moves a point off the sphere by
``|p - c| - R = -n cos i + n^2 sin^2 i / (2R) + ...``, whose mean ``s^2 sin^2 i / (2R)`` makes
rim points look outside the sphere; the ASTM 60 deg cone about the centre also drops rim points
pushed behind it (large positive ``n``) and keeps those pulled forward. Both pull a geometric
fixed-radius fit toward the sensor: about 2 mm at ``s = 15 mm`` and 24 mm at ``s = 45 mm`` for
``R = 0.1 m``, whatever the number of points (scaling the radius per point by
``R + s^2 sin^2 i / (2R)`` leaves 17 mm). The range residual at the true centre is the noise
itself, independent of the selection, so these fits have no such bias (below 1 mm in the
Monte-Carlo test, ``tests/pipeline/test_noise_aware_fit.py``).

- :func:`fit_line_of_sight`: the weighted least squares, fixed or free radius;
- :func:`astm_beam_steps`: the steps of the ASTM E3125 loop of
  :func:`pipeline.sphere_centres.sphere_fit.fit_sphere` when the noise is given: (2) keeps the beams
  that pass the centre closer than ``R sin 60 deg`` (the ASTM cylinder, tested on the beam, not on
  the noisy point); (3) fits with the radius fixed and trims at 3 standard deviations of
  ``(range - t) / sigma_i``;
- :func:`beam_cap`, :func:`radius_standard_error`, :func:`expected_rms`: the points, the radius
  scale and the RMS scale of the quality gate's checks (:mod:`pipeline.chain.quality`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.scans.sensor_noise import MAX_TAN_INCIDENCE, RangeNoise
from pipeline.sphere_centres.geometric_sphere_fit import (
    ASTM_CONE_DEG,
    bounded_radius_step,
    cap_start,
)

#: Line-of-sight fits: beams are treated as meeting the sphere at no more than this incidence
#: (cos), so a beam that misses the current sphere still has a finite residual and gradient.
_MIN_COS_INCIDENCE = 1.0 / np.hypot(1.0, MAX_TAN_INCIDENCE)


@dataclass(frozen=True)
class LineOfSightFit:
    """Result of :func:`fit_line_of_sight`.

    Attributes
    ----------
    centre_m : (3,) float
        Centre, metres, frame of the input points.
    radius_m : float
        Fitted (``free_radius``) or given radius, metres.
    """

    centre_m: np.ndarray
    radius_m: float


def fit_line_of_sight(points_m: np.ndarray, radius_m: float, noise: RangeNoise,
                      sensor_m=(0.0, 0.0, 0.0), centre0_m: np.ndarray | None = None,
                      free_radius: bool = False,
                      radius_bounds_m: tuple[float, float] | None = None) -> LineOfSightFit:
    """Weighted least-squares sphere on line-of-sight range residuals (Gauss-Newton).

    Minimises ``sum ((rho_i - t_i(c, R)) / sigma_i)^2``: ``rho_i = |p_i - sensor|`` is the
    measured range, ``t_i`` the range at which the beam through ``p_i`` meets the sphere (at
    most 84 deg incidence), ``sigma_i`` the noise's total sigma at ``rho_i`` and the incidence.
    Unbiased under range noise along the beam, unlike the geometric fits
    (:func:`lsq_fixed_radius`, :func:`fit_free_radius`).

    Parameters
    ----------
    points_m : (n, 3) float
        Points on the sphere's sensor-facing side, metres, n >= 4.
    radius_m : float
        Known radius (``free_radius=False``) or start radius, metres.
    noise : RangeNoise
    sensor_m : (3,) float
        Scanner origin, metres.
    centre0_m : (3,) float, optional
        Start centre (default: :func:`cap_start`).
    free_radius : bool
        Fit the radius too.
    radius_bounds_m : (float, float), optional
        ``free_radius`` only: ``(low, high)``, metres, ``0 < low <= radius_m <= high``; the
        radius is held in this bracket
        (:func:`~pipeline.sphere_centres.geometric_sphere_fit.bounded_radius_step`), so a
        flat-looking cap ends on ``high`` instead of running away. ``None``: unbounded.

    Returns
    -------
    LineOfSightFit

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.linspace(-.09, .09, 7), np.linspace(-.09, .09, 7)), -1)
    >>> g = g.reshape(-1, 2)[np.hypot(*g.reshape(-1, 2).T) < 0.1]
    >>> p = np.column_stack([5 - np.sqrt(0.01 - (g ** 2).sum(1)), g])  # exact cap, sensor at 0
    >>> f = fit_line_of_sight(p, 0.12, RangeNoise(0.015), free_radius=True)
    >>> np.round(f.centre_m, 6).tolist() == [5, 0, 0], round(f.radius_m, 6)
    (True, 0.1)
    """
    sensor = np.asarray(sensor_m, dtype=float)
    rng, beam = _beams(np.asarray(points_m, dtype=float), sensor)
    start = cap_start(points_m, radius_m, sensor) if centre0_m is None else centre0_m
    c, r, _ = _los_solve(rng, beam, np.asarray(start, float) - sensor, float(radius_m), noise,
                         free_radius, radius_bounds_m=radius_bounds_m)
    return LineOfSightFit(c + sensor, r)


def radius_standard_error(points_m: np.ndarray, centre_m: np.ndarray, radius_m: float,
                          noise: RangeNoise, sensor_m=(0.0, 0.0, 0.0)) -> float:
    """Standard error of a free-radius :func:`fit_line_of_sight` if the points' beams met the
    sphere ``(centre_m, radius_m)``, metres.

    ``sqrt([(J^T W J)^-1]_RR)`` at that sphere (``W = diag(1 / sigma_i^2)``): the spread that
    range noise alone gives the free radius of a marker seen with these beams, the scale of
    the quality gate's radius check. Evaluated at the marker hypothesis, not at the free fit,
    so a flat patch of a boulder (whose free radius is poorly determined) does not widen it.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.linspace(-.08, .08, 9), np.linspace(-.08, .08, 9)), -1)
    >>> g = g.reshape(-1, 2)[np.hypot(*g.reshape(-1, 2).T) <= 0.08]  # beams up to 53 deg
    >>> p = np.column_stack([np.full(len(g), 4.95), g])  # only the beam directions count
    >>> se = radius_standard_error(p, np.array([5.0, 0, 0]), 0.1, RangeNoise(0.015, 0, 0, 0))
    >>> round(se, 4)  # 49 points of 15 mm noise
    0.0115
    """
    sensor = np.asarray(sensor_m, dtype=float)
    rng, beam = _beams(np.asarray(points_m, dtype=float), sensor)
    jac, w, _ = _los_system(rng, beam, np.append(np.asarray(centre_m, float) - sensor, radius_m),
                            noise, True)
    try:
        return float(np.sqrt(np.linalg.inv(jac.T @ (w[:, None] * jac))[3, 3]))
    except np.linalg.LinAlgError:
        return float("inf")


def expected_rms(points_m: np.ndarray, centre_m: np.ndarray, radius_m: float, noise: RangeNoise,
                 sensor_m=(0.0, 0.0, 0.0)) -> float:
    """RMS of ``|p - c| - R`` that range noise alone gives on a sphere, metres.

    The RMS over the points of ``sigma_i cos i_i``: ``sigma_i`` is the noise's total sigma at
    the point's range and at the incidence ``i_i`` of its beam on the sphere ``(centre_m,
    radius_m)``; ``cos i`` projects the range error onto the surface normal.

    Parameters
    ----------
    points_m : (n, 3) float
    centre_m : (3,) float
    radius_m : float
    noise : RangeNoise
    sensor_m : (3,) float

    Examples
    --------
    >>> import numpy as np
    >>> p = np.array([[4.9, 0, 0], [4.95, 0.0866, 0]])  # incidence 0 and ~61 deg
    >>> round(expected_rms(p, np.array([5.0, 0, 0]), 0.1, RangeNoise(0.02, 0, 0, 0)), 4)
    0.0157
    """
    sensor = np.asarray(sensor_m, dtype=float)
    rng, beam = _beams(np.asarray(points_m, dtype=float), sensor)
    _, h, _ = _los_range(beam, np.asarray(centre_m, dtype=float) - sensor, radius_m)
    return float(np.sqrt(np.mean((_los_sigma(rng, h, radius_m, noise) * h / radius_m) ** 2)))


def beam_cap(points_m: np.ndarray, centre_m: np.ndarray, radius_m: float,
             sensor_m=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Points whose beams pass the centre closer than ``R sin 60 deg`` (the ASTM cylinder tested
    on the beam, independent of the range noise).

    Returns
    -------
    inside : (n,) bool

    Examples
    --------
    >>> import numpy as np
    >>> beam_cap(np.array([[4.9, 0, 0], [4.9, 0.095, 0], [5.2, 0, 0.5]]), np.array([5.0, 0, 0]),
    ...          0.1).tolist()
    [True, False, False]
    """
    sensor = np.asarray(sensor_m, dtype=float)
    _, beam = _beams(np.asarray(points_m, dtype=float), sensor)
    return _beam_cylinder(beam, np.asarray(centre_m, float) - sensor,
                          radius_m * np.sin(np.radians(ASTM_CONE_DEG / 2)))


def astm_beam_steps(p: np.ndarray, radius: float, sensor: np.ndarray, noise: RangeNoise,
                    hold=None):
    """The ASTM steps on the beams: the cylinder tested on each beam, and the line-of-sight fit
    with its normalised range residuals ``(rho - t) / sigma``.

    The noise-aware steps (2) and (3) of the ASTM loop of
    :func:`pipeline.sphere_centres.sphere_fit.fit_sphere` (module docstring).

    Parameters
    ----------
    p : (n, 3) float
        The candidate's points, metres.
    radius : float
        Known radius, metres.
    sensor : (3,) float
        Scanner origin, metres.
    noise : RangeNoise
    hold : callable, optional
        ``hold(centre) -> centre``, applied to each fitted centre (the loop's bound on how far
        the centre may move, :func:`pipeline.sphere_centres.sphere_fit.fit_sphere`); default: none.

    Returns
    -------
    select : callable
        ``select(centre) -> (n,) bool``: the points whose beams pass ``centre`` closer than
        ``R sin 60 deg``.
    solve : callable
        ``solve(sel, start) -> (centre, z)``: the fixed-radius line-of-sight fit of the points
        ``sel`` from ``start`` (through ``hold``), and their normalised range residuals ``z``
        at that centre.
    """
    rng, beam = _beams(p, sensor)
    max_miss = radius * np.sin(np.radians(ASTM_CONE_DEG / 2))

    def select(centre):
        return _beam_cylinder(beam, centre - sensor, max_miss)

    def solve(sel, start):
        c = _los_solve(rng[sel], beam[sel], start - sensor, radius, noise)[0] + sensor
        if hold is not None:
            c = hold(c)
        return c, _los_z(rng[sel], beam[sel], c - sensor, radius, noise)

    return select, solve


def _beams(p: np.ndarray, sensor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Measured range (n,) and unit beam direction (n, 3) of each point from ``sensor``."""
    d = p - sensor
    rng = np.linalg.norm(d, axis=1)
    return rng, d / np.maximum(rng, 1e-12)[:, None]


def _beam_cylinder(beam: np.ndarray, centre: np.ndarray, max_miss_m: float) -> np.ndarray:
    """Beams (sensor at the origin) passing ``centre`` ahead closer than ``max_miss_m``."""
    along = beam @ centre
    return (along > 0) & (centre @ centre - along ** 2 < max_miss_m ** 2)


def _los_range(beam: np.ndarray, centre: np.ndarray, radius: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Range ``t`` (n,) at which each beam meets the sphere (sensor at the origin), ``h = R cos
    i`` (n,) and the point ``t * beam`` (n, 3); incidence capped (:data:`_MIN_COS_INCIDENCE`)."""
    along = beam @ centre
    h = np.sqrt(np.maximum(radius ** 2 - (centre @ centre - along ** 2),
                           (radius * _MIN_COS_INCIDENCE) ** 2))
    t = along - h
    return t, h, t[:, None] * beam


def _los_sigma(rng: np.ndarray, h: np.ndarray, radius: float, noise: RangeNoise) -> np.ndarray:
    """Total range sigma (n,) at each point's range and incidence (``cos i = h / R``)."""
    return noise.total_sigma_m(rng, np.sqrt(np.maximum(radius ** 2 - h ** 2, 0.0)) / h)


def _los_z(rng, beam, centre, radius, noise) -> np.ndarray:
    """Normalised range residuals ``(rho - t) / sigma`` (n,), sensor at the origin."""
    t, h, _ = _los_range(beam, centre, radius)
    return (rng - t) / _los_sigma(rng, h, radius, noise)


def _los_system(rng, beam, x, noise, free_radius
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Jacobian (n, 3 or 4), weights (n,) and residuals ``rho - t`` (n,) of the line-of-sight
    problem at ``x = (centre, R)``, sensor at the origin."""
    t, h, q = _los_range(beam, x[:3], x[3])
    jac = (q - x[:3]) / h[:, None]  # d(rho - t)/dc
    if free_radius:
        jac = np.column_stack([jac, x[3] / h])  # d(rho - t)/dR
    return jac, 1.0 / _los_sigma(rng, h, x[3], noise) ** 2, rng - t


def _los_solve(rng, beam, centre, radius, noise, free_radius=False, max_iter=50, tol_m=1e-10,
               radius_bounds_m=None) -> tuple[np.ndarray, float, np.ndarray]:
    """Gauss-Newton of :func:`fit_line_of_sight`, sensor at the origin.

    A fixed radius runs the compiled loop :func:`pipeline.kernels.los_gauss_newton_fixed` (the
    hundreds of small fits of a station's markers). A free radius runs the problem of
    :func:`_los_system` in numpy with its invariants hoisted out of the iterations (the range
    part of each point's variance) and ``J^T W J`` and ``J^T W r`` from one product
    (``V^T diag(w / h^2) [V, h r]`` with ``V = [t beam - c, R]``); a singular matrix ends the
    iterations. Each step is capped at half the radius; a free radius is held in
    ``radius_bounds_m`` (:func:`~pipeline.sphere_centres.geometric_sphere_fit.bounded_radius_step`).

    Returns the centre (3,), the radius and the covariance ((3, 3) or (4, 4) with the radius)
    of the estimate under the noise model.
    """
    var0 = noise.total_sigma_m(rng) ** 2  # variance at normal incidence, (n,)
    inc2 = noise.incidence_noise_m ** 2
    if not free_radius:
        from pipeline.kernels import los_gauss_newton_fixed  # as in lsq_fixed_radius

        c, cov = los_gauss_newton_fixed(
            np.ascontiguousarray(rng, dtype=float), np.ascontiguousarray(beam, dtype=float),
            np.array(centre, dtype=float), float(radius), np.ascontiguousarray(var0, dtype=float),
            float(inc2), float(_MIN_COS_INCIDENCE), int(max_iter), float(tol_m))
        return c, float(radius), cov
    x = np.array([*np.asarray(centre, dtype=float), radius], dtype=float)
    cov = np.full((4, 4), np.nan)
    v = np.empty((rng.size, 5))  # [rows of the Jacobian times h, h * residual]
    for _ in range(max_iter):
        c, r2 = x[:3], x[3] * x[3]
        along = beam @ c
        h2 = along * along
        h2 += r2 - float(c @ c)
        np.maximum(h2, r2 * _MIN_COS_INCIDENCE ** 2, out=h2)
        h = np.sqrt(h2)
        t = along - h
        var = var0 + inc2 * np.maximum(r2 - h2, 0.0) / h2 if inc2 else var0
        np.multiply(t[:, None], beam, out=v[:, :3])
        v[:, :3] -= c
        v[:, 3] = x[3]
        np.multiply(rng - t, h, out=v[:, 4])
        m = (v[:, :4] * (1.0 / (var * h2))[:, None]).T @ v  # [J^T W J, J^T W r]
        try:
            cov = np.linalg.inv(m[:, :4])
            step = (-cov @ m[:, 4] if radius_bounds_m is None
                    else bounded_radius_step(m[:, :4], m[:, 4], x[3], radius_bounds_m))
        except np.linalg.LinAlgError:
            break
        length = float(np.sqrt(step @ step))
        damp = min(1.0, 0.5 * x[3] / max(length, 1e-300))
        x += step * damp
        if (length if damp == 1.0 else length * damp) < tol_m:
            break
    return x[:3].copy(), float(abs(x[3])), cov
