"""Per-marker quality metrics and the quality gate.

Definitions (all in the station frame; "projected disc" = the disc of radius ``R`` through the
fitted centre, perpendicular to the line of sight from the LiDAR centre):

point_density_per_m2
    Points used by the centre fit divided by ``pi R^2``, the projected area of the
    sensor-facing hemisphere.
visible_fraction
    Fraction of the projected disc's inner part (radius ``0.8 R``) that holds points: the
    points used are projected onto the disc and binned in a square grid whose cell edge is
    ``max(sqrt(k pi R^2 / n), R / 4)`` (``k = 6`` points per cell expected for a fully visible
    marker with ``n`` points); the fraction is occupied cells / cells whose centre lies within
    ``0.8 R``. A clean marker scores ~1 at any density; a marker half hidden by a crater rim or
    a rock scores ~0.5. With fewer than ``4 k`` points the four quadrants of the disc are used
    as the cells.
radius_fit_m
    Radius of a free-radius sphere through the points used (the "radius check": rocks are not
    0.10 m spheres). Without the noise: geometric least squares
    (:func:`~pipeline.geometric_sphere_fit.fit_free_radius`, biased small by range noise); with it:
    the line-of-sight fit (:func:`~pipeline.line_of_sight_fit.fit_line_of_sight`), unbiased, of the
    points whose beams pass within ``R sin 60 deg`` of the centre
    (:func:`~pipeline.line_of_sight_fit.beam_cap`; drops the ground an ICP fit may have used).
radius_sigma_m
    Standard error that range noise gives ``radius_fit_m`` if the points were a marker of
    radius ``R`` at the fitted centre (:func:`~pipeline.line_of_sight_fit.radius_standard_error`:
    ``(J^T W J)^-1`` of the line-of-sight fit, weights ``1 / sigma_i^2``); 0 when the noise is
    unknown. It grows as the points thin out with range (about 6 mm at 5 m, 12 mm at 14 m,
    50 mm at 25 m for ``s = 45 mm``, ``R = 0.1 m``; measured spread 5, 16 and diverging).
expected_rms_m
    The fit RMS a clean sphere gives under the sensor's noise
    (:func:`~pipeline.line_of_sight_fit.expected_rms`): the RMS over the points used of
    ``sigma_i cos i_i`` (range noise seen along the surface normal; ``sigma_i`` from
    :class:`~pipeline.sensor_noise.RangeNoise` at the point's range and incidence ``i_i``).
    NaN when the noise is unknown.

Noise-scaled gate (the sensor's noise known): ``high_rms`` when the fit RMS exceeds
``max_rms_sigma * expected_rms_m``; ``radius_mismatch`` when ``|radius_fit_m - R|`` exceeds
``radius_tolerance * R + radius_sigma * radius_sigma_m``. Without the noise, or with
``max_rms_sigma = 0``, the absolute ``max_rms_m`` applies (and ``radius_sigma_m = 0``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError
from pipeline.geometric_sphere_fit import fit_free_radius
from pipeline.line_of_sight_fit import (
    beam_cap,
    expected_rms,
    fit_line_of_sight,
    radius_standard_error,
)
from pipeline.sensor_noise import RangeNoise
from pipeline.sphere_fit import SphereFit

_POINTS_PER_CELL = 6
_INNER = 0.8

#: Checks in the order they are applied (an occluded marker also fails the radius check, but
#: its cause is the missing part, so ``incomplete_cloud`` comes first).
REASONS = ("too_few_points", "incomplete_cloud", "high_rms", "radius_mismatch")


@dataclass(frozen=True)
class QualityConfig:
    """Thresholds of the quality gate.

    Attributes
    ----------
    min_points : int
        Fewer points used by the fit -> ``too_few_points``.
    max_rms_sigma : float
        Noise known: fit RMS above this multiple of the marker's ``expected_rms_m`` ->
        ``high_rms`` (0: use ``max_rms_m`` instead).
    max_rms_m : float
        Noise unknown, or ``max_rms_sigma = 0``: larger fit RMS -> ``high_rms`` (metres; ~2x
        the VLP-16's 1.5 cm range noise).
    radius_tolerance : float
        ``|radius_fit - R| > radius_tolerance * R + radius_sigma * radius_sigma_m`` ->
        ``radius_mismatch``.
    radius_sigma : float
        Multiple of the free radius's standard error added to the tolerance (noise known).
    min_visible_fraction : float
        Lower visible fraction -> ``incomplete_cloud``.
    """

    min_points: int = 20
    max_rms_sigma: float = 3.0
    max_rms_m: float = 0.03
    radius_tolerance: float = 0.5
    radius_sigma: float = 3.0
    min_visible_fraction: float = 0.6

    def validate(self) -> QualityConfig:
        if int(self.min_points) < 4:
            raise ConfigError(f"quality `min_points` must be >= 4, got {self.min_points}")
        if not self.max_rms_m > 0:
            raise ConfigError(f"quality `max_rms_m` must be > 0 metres, got {self.max_rms_m}")
        for name in ("max_rms_sigma", "radius_sigma"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"quality `{name}` must be >= 0 (a multiple of the noise), "
                                  f"got {getattr(self, name)}")
        if not self.radius_tolerance > 0:
            raise ConfigError(f"quality `radius_tolerance` must be > 0, got "
                              f"{self.radius_tolerance}")
        if not 0 <= self.min_visible_fraction <= 1:
            raise ConfigError("quality `min_visible_fraction` must be in [0, 1], got "
                              f"{self.min_visible_fraction}")
        return self


@dataclass(frozen=True)
class MarkerMetrics:
    """Metrics of one fitted candidate (see the module docstring)."""

    point_density_per_m2: float
    visible_fraction: float
    radius_fit_m: float
    radius_sigma_m: float = 0.0
    expected_rms_m: float = float("nan")


def marker_metrics(points_m: np.ndarray, fit: SphereFit, sensor_m=(0.0, 0.0, 0.0),
                   noise: RangeNoise | None = None) -> MarkerMetrics:
    """Density, visible fraction, free-fit radius and noise scales of the points a fit used.

    Parameters
    ----------
    points_m : (n, 3) float
        The candidate's points given to the fit (``fit.used`` selects from them), metres.
    fit : SphereFit
    sensor_m : (3,) float
        LiDAR centre, same frame.
    noise : RangeNoise, optional
        The sensor's range noise (module docstring); ``None``: unknown.
    """
    used = points_m[fit.used]
    radius = fit.radius_m
    density = used.shape[0] / (np.pi * radius ** 2)
    frac = visible_fraction(used, fit.centre_m, radius, sensor_m)
    if used.shape[0] < 4:
        return MarkerMetrics(float(density), frac, float("nan"))
    if noise is None:
        _, r_free, _ = fit_free_radius(used, fit.centre_m, radius)
        return MarkerMetrics(float(density), frac, r_free)
    cap = used[beam_cap(used, fit.centre_m, radius, sensor_m)]
    if cap.shape[0] < 4:
        return MarkerMetrics(float(density), frac, float("nan"))
    free = fit_line_of_sight(cap, radius, noise, sensor_m, fit.centre_m, free_radius=True)
    return MarkerMetrics(float(density), frac, free.radius_m,
                         radius_standard_error(cap, fit.centre_m, radius, noise, sensor_m),
                         expected_rms(used, fit.centre_m, radius, noise, sensor_m))


def visible_fraction(points_m: np.ndarray, centre_m: np.ndarray, radius_m: float,
                     sensor_m=(0.0, 0.0, 0.0)) -> float:
    """Fraction of the projected disc covered by points (module docstring).

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.linspace(-.1, .1, 21), np.linspace(-.1, .1, 21)), -1)
    >>> g = g.reshape(-1, 2)[np.hypot(*g.reshape(-1, 2).T) < 0.1]
    >>> pts = np.column_stack([np.full(len(g), 4.9), g])
    >>> visible_fraction(pts, np.array([5.0, 0, 0]), 0.1)
    1.0
    >>> round(visible_fraction(pts[pts[:, 2] > 0], np.array([5.0, 0, 0]), 0.1), 1)
    0.5
    """
    n = points_m.shape[0]
    if n == 0:
        return 0.0
    los = np.asarray(centre_m, float) - np.asarray(sensor_m, float)
    los /= np.linalg.norm(los)
    e1 = np.cross([0.0, 0.0, 1.0], los)
    if np.linalg.norm(e1) < 1e-9:
        e1 = np.array([1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(los, e1)
    q = points_m - centre_m
    u, v = q @ e1, q @ e2
    inside = np.hypot(u, v) <= radius_m
    if n < 4 * _POINTS_PER_CELL:
        quadrant = (u[inside] >= 0).astype(int) * 2 + (v[inside] >= 0).astype(int)
        return float(np.unique(quadrant).size / 4)
    cell = max(np.sqrt(_POINTS_PER_CELL * np.pi * radius_m ** 2 / n), radius_m / 4)
    m = int(np.ceil(radius_m / cell))
    centres = (np.arange(-m, m) + 0.5) * cell
    cu, cv = np.meshgrid(centres, centres, indexing="ij")
    expected = np.hypot(cu, cv) <= _INNER * radius_m
    if not expected.any():
        expected = np.hypot(cu, cv) <= np.hypot(cell, cell) / 2 + 1e-12
    iu = np.floor(u[inside] / cell).astype(int) + m
    iv = np.floor(v[inside] / cell).astype(int) + m
    ok = (iu >= 0) & (iu < 2 * m) & (iv >= 0) & (iv < 2 * m)
    occupied = np.zeros_like(expected)
    occupied[iu[ok], iv[ok]] = True
    return float((occupied & expected).sum() / expected.sum())


def quality_gate(fit: SphereFit, metrics: MarkerMetrics, config: QualityConfig
                 ) -> tuple[bool, str]:
    """Accept or reject one candidate.

    Returns
    -------
    accepted : bool
    reason : str
        ``""`` when accepted, else the first failing check of :data:`REASONS`.
    """
    if fit.n_used < config.min_points:
        return False, "too_few_points"
    if metrics.visible_fraction < config.min_visible_fraction:
        return False, "incomplete_cloud"
    scaled = config.max_rms_sigma > 0 and np.isfinite(metrics.expected_rms_m)
    max_rms = config.max_rms_sigma * metrics.expected_rms_m if scaled else config.max_rms_m
    if not fit.rms_m <= max_rms:
        return False, "high_rms"
    tolerance = (config.radius_tolerance * fit.radius_m
                 + config.radius_sigma * metrics.radius_sigma_m)
    if not abs(metrics.radius_fit_m - fit.radius_m) <= tolerance:
        return False, "radius_mismatch"
    return True, ""
