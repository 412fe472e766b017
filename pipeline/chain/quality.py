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
    0.10 m spheres), held in ``[R / 4, 4 R]`` (:data:`RADIUS_BRACKET`): a cap that looks flat
    ends at ``4 R``, a finite mismatch, where the unbounded fit ran away to 0.2-1440 m at
    27-30 m. Without the noise: geometric least squares
    (:func:`~pipeline.sphere_centres.geometric_sphere_fit.fit_free_radius`, biased small by range
    noise); with it: the line-of-sight fit
    (:func:`~pipeline.sphere_centres.line_of_sight_fit.fit_line_of_sight`), unbiased, of the points
    whose beams pass within ``R sin 60 deg`` of the centre
    (:func:`~pipeline.sphere_centres.line_of_sight_fit.beam_cap`; drops the ground an ICP fit may
    have used).
radius_sigma_m
    Standard error that range noise gives ``radius_fit_m`` if the points were a marker of
    radius ``R`` at the fitted centre
    (:func:`~pipeline.sphere_centres.line_of_sight_fit.radius_standard_error`: ``(J^T W J)^-1`` of
    the line-of-sight fit, weights ``1 / sigma_i^2``); 0 when the noise is unknown. It grows as the
    points thin out with range (about 6 mm at 5 m, 12 mm at 14 m, 50 mm at 25 m for ``s = 45 mm``,
    ``R = 0.1 m``; measured spread 5, 16 and diverging).
centre_height_m
    Height of the fitted centre above the ground in front of it: the median height of the
    candidate's points (the re-search, ground included) nearer the sensor than the centre and
    ``1.3 R`` to ``3 R`` from it horizontally (:data:`GROUND_RING_RADII`) and farther than
    ``R + 3 s`` from it, not the sphere's own noisy points (``s``: the range noise's sigma at
    the centre's range, or without the noise the fit RMS). A marker stands on
    the ground, a whole sphere above it: ``~R``. A rock of marker size is baked into the
    terrain, partly buried: the best sphere of radius ``R`` in its top sits near or below the
    ground around it (``<= 0.3 R`` on the default site, markers ``>= 0.68 R`` at 1-30 m).
    NaN when fewer than :data:`MIN_GROUND_POINTS` such points. Assumes the frame's z is up (the
    station frame).
lowest_depth_m
    Depth of the lowest point the fit used below the fitted centre, metres. A marker's lower
    half is seen: ``0.42-0.84 R`` at 19-30 m (about ``0.27 R`` from 1 m at 42 deg elevation,
    the nearest a marker is planned); a marker-size rock baked into the terrain ends near its
    centre (``<= 0.1 R`` for most). The shape check's fallback where no ground is seen in front
    (beyond ~25 m the ground ring is often empty).
range_m
    Distance of the fitted centre from the sensor, metres.
expected_rms_m
    The fit RMS a clean sphere gives under the sensor's noise
    (:func:`~pipeline.sphere_centres.line_of_sight_fit.expected_rms`): the RMS over the points used
    of ``sigma_i cos i_i`` (range noise seen along the surface normal; ``sigma_i`` from
    :class:`~pipeline.scans.sensor_noise.RangeNoise` at the point's range and incidence ``i_i``).
    NaN when the noise is unknown.

Noise-scaled gate (the sensor's noise known): ``high_rms`` when the fit RMS exceeds
``max_rms_sigma * expected_rms_m``; ``radius_mismatch`` when ``|radius_fit_m - R|`` exceeds
``radius_tolerance * R + radius_sigma * radius_sigma_m``. Without the noise, or with
``max_rms_sigma = 0``, the absolute ``max_rms_m`` applies (and ``radius_sigma_m = 0``).

Where the beam footprint (``beam_divergence_rad * range_m``) reaches ``max_footprint_radii * R``
the returns across the cap are mixed over a patch as wide as the marker, the cap looks flatter
and the free radius is biased large (0.22-0.5 m and runaways for true 0.1 m markers at
27-30 m, 3 mrad); there only a radius too *small* is a mismatch, or one pinned at the top of the
bracket (``RADIUS_BRACKET R``: a patch of crater wall 30 m away fitted 0.4 m and was accepted
as a marker). ``partly_buried`` when the
centre stands less than ``min_centre_height * R`` above the ground in front of it, or, with no
ground seen there, when the points used reach less than ``min_lowest_depth * R`` below the
centre.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError
from pipeline.scans.sensor_noise import RangeNoise
from pipeline.sphere_centres.geometric_sphere_fit import fit_free_radius
from pipeline.sphere_centres.line_of_sight_fit import (
    beam_cap,
    expected_rms,
    fit_line_of_sight,
    radius_standard_error,
)
from pipeline.sphere_centres.sphere_fit import SphereFit

_POINTS_PER_CELL = 6
_INNER = 0.8

#: The free radius of the radius check is held in ``[R / RADIUS_BRACKET, RADIUS_BRACKET R]``.
RADIUS_BRACKET = 4.0
#: The ground ring of ``centre_height_m``: horizontal distances from the centre, in radii.
GROUND_RING_RADII = (1.3, 3.0)
#: Fewest ground-ring points that give ``centre_height_m``.
MIN_GROUND_POINTS = 3

#: Checks in the order they are applied (an occluded marker also fails the radius check, but
#: its cause is the missing part, so ``incomplete_cloud`` comes first).
REASONS = ("too_few_points", "incomplete_cloud", "high_rms", "radius_mismatch", "partly_buried")


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
    min_centre_height : float
        Centre less than this many radii above the ground in front of it -> ``partly_buried``
        (0: never).
    min_lowest_depth : float
        No ground seen in front: the points used reaching less than this many radii below the
        centre -> ``partly_buried`` (0: never).
    beam_divergence_rad : float
        Full beam divergence, radians (VLP-16: 3 mrad across the spin); 0: no footprint.
    max_footprint_radii : float
        Footprint ``beam_divergence_rad * range`` beyond this many radii: the radius check
        refuses only radii too small (module docstring).
    """

    min_points: int = 20
    max_rms_sigma: float = 3.0
    max_rms_m: float = 0.03
    radius_tolerance: float = 0.5
    radius_sigma: float = 3.0
    min_visible_fraction: float = 0.6
    min_centre_height: float = 0.5
    min_lowest_depth: float = 0.2
    beam_divergence_rad: float = 0.003
    max_footprint_radii: float = 0.8

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
        for name in ("min_centre_height", "min_lowest_depth"):
            if not 0 <= getattr(self, name) <= 2:
                raise ConfigError(f"quality `{name}` must be in [0, 2] radii, got "
                                  f"{getattr(self, name)}")
        if not 0 <= self.beam_divergence_rad < 0.1:
            raise ConfigError("quality `beam_divergence_rad` must be in [0, 0.1) radians, got "
                              f"{self.beam_divergence_rad}")
        if not self.max_footprint_radii > 0:
            raise ConfigError("quality `max_footprint_radii` must be > 0, got "
                              f"{self.max_footprint_radii}")
        return self


@dataclass(frozen=True)
class MarkerMetrics:
    """Metrics of one fitted candidate (see the module docstring)."""

    point_density_per_m2: float
    visible_fraction: float
    radius_fit_m: float
    radius_sigma_m: float = 0.0
    expected_rms_m: float = float("nan")
    centre_height_m: float = float("nan")
    range_m: float = float("nan")
    lowest_depth_m: float = float("nan")


def marker_metrics(points_m: np.ndarray, fit: SphereFit, sensor_m=(0.0, 0.0, 0.0),
                   noise: RangeNoise | None = None) -> MarkerMetrics:
    """Density, visible fraction, free-fit radius, noise scales and centre height of a fit.

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
    centre_range = float(np.linalg.norm(fit.centre_m - np.asarray(sensor_m, float)))
    scatter = fit.rms_m if noise is None else float(noise.total_sigma_m(centre_range))
    base = {"point_density_per_m2": float(used.shape[0] / (np.pi * radius ** 2)),
            "visible_fraction": visible_fraction(used, fit.centre_m, radius, sensor_m),
            "radius_fit_m": float("nan"),
            "centre_height_m": centre_height(points_m, fit.centre_m, radius, sensor_m,
                                             3 * scatter),
            "range_m": centre_range,
            "lowest_depth_m": float(fit.centre_m[2] - used[:, 2].min()) if used.size else 0.0}
    bracket = (radius / RADIUS_BRACKET, radius * RADIUS_BRACKET)
    if used.shape[0] < 4:
        return MarkerMetrics(**base)
    if noise is None:
        _, r_free, _ = fit_free_radius(used, fit.centre_m, radius, radius_bounds_m=bracket)
        return MarkerMetrics(**{**base, "radius_fit_m": r_free})
    cap = used[beam_cap(used, fit.centre_m, radius, sensor_m)]
    if cap.shape[0] < 4:
        return MarkerMetrics(**base)
    free = fit_line_of_sight(cap, radius, noise, sensor_m, fit.centre_m, free_radius=True,
                             radius_bounds_m=bracket)
    return MarkerMetrics(**{**base, "radius_fit_m": free.radius_m,
                            "radius_sigma_m": radius_standard_error(cap, fit.centre_m, radius,
                                                                    noise, sensor_m),
                            "expected_rms_m": expected_rms(used, fit.centre_m, radius, noise,
                                                           sensor_m)})


def centre_height(points_m: np.ndarray, centre_m: np.ndarray, radius_m: float,
                  sensor_m=(0.0, 0.0, 0.0), clearance_m: float = 0.0) -> float:
    """Height of ``centre_m`` above the ground in front of it, metres (module docstring).

    Parameters
    ----------
    points_m : (n, 3) float
        The candidate's points, ground included, metres, z up.
    centre_m : (3,) float
    radius_m : float
    sensor_m : (3,) float
    clearance_m : float
        Points closer than ``radius_m + clearance_m`` to the centre are the sphere's own, not
        ground (:func:`marker_metrics`: three sigma of the range noise).

    Returns
    -------
    height_m : float
        NaN when fewer than :data:`MIN_GROUND_POINTS` ground-ring points.

    Examples
    --------
    >>> import numpy as np
    >>> g = np.stack(np.meshgrid(np.arange(4.5, 5.5, 0.02), np.arange(-0.5, 0.5, 0.02)), -1)
    >>> ground = np.column_stack([g.reshape(-1, 2), np.full(g.size // 2, -1.0)])
    >>> round(centre_height(ground, np.array([5.0, 0, -0.9]), 0.1), 6)  # a marker on it
    0.1
    >>> round(centre_height(ground, np.array([5.0, 0, -0.98]), 0.1), 6)  # a buried cap's
    0.02
    """
    centre = np.asarray(centre_m, dtype=float)
    sensor = np.asarray(sensor_m, dtype=float)
    horizontal = np.hypot(points_m[:, 0] - centre[0], points_m[:, 1] - centre[1])
    inner, outer = GROUND_RING_RADII
    ring = ((horizontal > inner * radius_m) & (horizontal < outer * radius_m)
            & (np.linalg.norm(points_m - centre, axis=1) > radius_m + clearance_m)
            & (np.linalg.norm(points_m - sensor, axis=1) < np.linalg.norm(centre - sensor)))
    if ring.sum() < MIN_GROUND_POINTS:
        return float("nan")
    return float(centre[2] - np.median(points_m[ring, 2]))


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
    excess = metrics.radius_fit_m - fit.radius_m
    blurred = (config.beam_divergence_rad * metrics.range_m
               > config.max_footprint_radii * fit.radius_m)
    pinned = metrics.radius_fit_m >= RADIUS_BRACKET * fit.radius_m * (1 - 1e-9)
    if not (-excess <= tolerance and (blurred or excess <= tolerance)) or pinned:
        return False, "radius_mismatch"
    if (metrics.centre_height_m < config.min_centre_height * fit.radius_m
            or (np.isnan(metrics.centre_height_m)
                and metrics.lowest_depth_m < config.min_lowest_depth * fit.radius_m)):
        return False, "partly_buried"
    return True, ""
