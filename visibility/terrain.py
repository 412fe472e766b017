"""Seeded synthetic lunar terrain: regional slope, fractal micro-relief, craters and rocks.

Every law and its source:

- **Crater size-frequency** (:func:`sample_crater_diameters`): cumulative number per m^2
  ``N(>D) = C D^-b``. Small lunar craters (D < ~100 m) on the maria are in *equilibrium*,
  ``b = 2`` with ``C ~ 10^-1.1`` per m^2 (D in m) (Trask 1966, Ranger VIII/IX photographs;
  Shoemaker 1970, "Origin of fragmental debris on the lunar surface"); the *production*
  function is steeper, ``b ~ 3`` (Neukum et al. 2001, Space Sci. Rev. 96). ``C`` and ``b`` are
  parameters; presets use a fraction of the equilibrium density (a test field, not a saturated
  mare).
- **Fresh simple crater** (:func:`fresh_crater_profile`): rim-to-floor depth ``0.196 D`` and rim
  height ``0.036 D`` (Pike 1977, "Size-dependence in the shape of fresh impact craters on the
  moon"), parabolic bowl; ejecta thickness falling off as ``(r/R)^-3`` outside the rim
  (McGetchin, Settle & Head 1973, EPSL 20), tapered to zero at ``5 R``.
- **Degraded crater** (:func:`crater_patch`): the fresh profile evolved by topographic
  diffusion ``dh/dt = kappa laplacian(h)`` (Soderblom 1970; Fassett & Thomson 2014, JGR
  Planets 119), whose exact solution on a plane is a Gaussian convolution with
  ``sigma = sqrt(2 kappa t)``. Degradation state ``kappa t / D^2`` in [0.003, 0.03] lowers
  depth/diameter from 0.2 to about 0.15-0.06 and rounds the rim.
- **Rocks** (:func:`sample_rock_diameters`): cumulative fractional area covered by rocks of
  diameter >= D, ``F(D) = k exp(-q(k) D)``, ``q(k) = 1.79 + 0.152 / k`` (Golombek & Rapp 1997,
  JGR 102, fitted to Viking/Pathfinder and consistent with the Surveyor lunar counts of
  Shoemaker & Morris 1970). Rocks are partly buried spheres whose upper surface is baked into
  the height field (a height field has no overhangs; the hidden underside is irrelevant to a
  LiDAR 1 m above ground).
- **Micro-relief** (:func:`fractal_surface`): self-affine (fractional Brownian) surface with
  Hurst exponent ``H ~ 0.85`` (lunar RMS-deviation scaling ``nu(L) ~ L^H``, H = 0.8-0.95,
  Rosenburg et al. 2011, JGR 116, E02001), spectral synthesis with power spectrum
  ``P(k) ~ k^-(2H+2)``, scaled to a chosen RMS deviation at 1 m baseline, wavelengths longer
  than ``rolloff_m`` flattened.
- **Regional slope**: a plane of a few degrees.

Coordinates: site frame (W), metres; heights above an arbitrary datum.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from markerplan.errors import ConfigError
from visibility.dem import DEM

#: Fresh-crater shape ratios (Pike 1977).
FRESH_DEPTH_RATIO = 0.196
FRESH_RIM_RATIO = 0.036
#: Ejecta decay exponent (McGetchin et al. 1973) and the radius (in R) where it is tapered to 0.
EJECTA_EXPONENT = 3.0
EJECTA_EXTENT_R = 5.0


@dataclass(frozen=True)
class Crater:
    """One crater, site frame.

    Attributes
    ----------
    centre_xy_m : tuple of float
        Centre ``(x, y)``, metres.
    diameter_m : float
        Rim-crest diameter, metres.
    depth_m : float
        Rim-crest to floor depth after degradation, metres.
    kind : {"fresh", "degraded"}
    kappa_t_m2 : float
        Diffusive degradation ``kappa t``, m^2 (0 for fresh).
    """

    centre_xy_m: tuple[float, float]
    diameter_m: float
    depth_m: float
    kind: str
    kappa_t_m2: float = 0.0

    def to_dict(self) -> dict:
        return {"centre_xy_m": [float(v) for v in self.centre_xy_m],
                "diameter_m": float(self.diameter_m), "depth_m": float(self.depth_m),
                "kind": self.kind, "kappa_t_m2": float(self.kappa_t_m2)}


@dataclass(frozen=True)
class CraterSpec:
    """A crater placed on purpose (presets): centre, diameter, and degradation state."""

    centre_xy_m: tuple[float, float]
    diameter_m: float
    degradation: float = 0.0  # kappa t / D^2; 0 = fresh


@dataclass(frozen=True)
class RockSpec:
    """A rock placed on purpose (presets): centre xy, diameter, buried fraction of the diameter."""

    centre_xy_m: tuple[float, float]
    diameter_m: float
    burial: float = 0.3


@dataclass(frozen=True)
class TerrainSpec:
    """Parameters of :func:`generate_terrain` (all SI; see the module docstring for the laws).

    Attributes
    ----------
    extent_m : (xmin, xmax, ymin, ymax)
        DEM cell-centre rectangle, site frame, metres.
    cell_size_m : float
        Grid spacing, metres.
    hurst : float
        Hurst exponent of the micro-relief.
    roughness_1m_m : float
        RMS height deviation at 1 m baseline, metres.
    rolloff_m : float
        Wavelengths longer than this are not amplified further, metres.
    slope_deg, slope_azimuth_deg : float
        Regional slope and its down-slope azimuth (from +x towards +y), degrees.
    crater_density : float
        ``C`` in ``N(>D) = C D^-b`` per m^2 (D in metres).
    crater_sfd_exponent : float
        ``b``.
    crater_diameter_range_m : (float, float)
        Random craters drawn in this diameter range.
    fresh_fraction : float
        Probability a random crater is fresh; the rest are degraded.
    rock_abundance : float
        ``k`` of Golombek & Rapp (fraction of area covered by all rocks).
    rock_diameter_range_m : (float, float)
        Random rocks drawn in this diameter range.
    craters, rocks : tuple
        Craters/rocks placed on purpose (:class:`CraterSpec`, :class:`RockSpec`).
    keepout_xyr_m : tuple of (x, y, r)
        Circles in which no random crater centre or rock is placed (stations, markers).
    """

    extent_m: tuple[float, float, float, float] = (-30.0, 30.0, -30.0, 30.0)
    cell_size_m: float = 0.05
    hurst: float = 0.85
    roughness_1m_m: float = 0.02
    rolloff_m: float = 10.0
    slope_deg: float = 1.0
    slope_azimuth_deg: float = 30.0
    crater_density: float = 0.008
    crater_sfd_exponent: float = 2.0
    crater_diameter_range_m: tuple[float, float] = (0.5, 3.0)
    fresh_fraction: float = 0.2
    rock_abundance: float = 0.01
    rock_diameter_range_m: tuple[float, float] = (0.1, 0.6)
    craters: tuple[CraterSpec, ...] = ()
    rocks: tuple[RockSpec, ...] = ()
    keepout_xyr_m: tuple[tuple[float, float, float], ...] = field(default_factory=tuple)


@dataclass
class Terrain:
    """A generated terrain: the DEM (rocks included) and the features placed on it.

    Attributes
    ----------
    dem : DEM
    craters : list of Crater
    rock_centres_m : (k, 3) float
        Rock sphere centres, site frame, metres.
    rock_radii_m : (k,) float
    """

    dem: DEM
    craters: list[Crater]
    rock_centres_m: np.ndarray
    rock_radii_m: np.ndarray


def _terrain_iv(spec: TerrainSpec) -> None:
    xmin, xmax, ymin, ymax = spec.extent_m
    if not (xmax > xmin and ymax > ymin):
        raise ConfigError(f"extent_m must be (xmin, xmax, ymin, ymax) with max > min, "
                          f"got {spec.extent_m}")
    if not spec.cell_size_m > 0:
        raise ConfigError(f"cell_size_m must be > 0, got {spec.cell_size_m}")
    if not 0 < spec.hurst < 1.5:
        raise ConfigError(f"hurst must be in (0, 1.5), got {spec.hurst}")
    lo, hi = spec.crater_diameter_range_m
    if not 0 < lo <= hi:
        raise ConfigError(f"crater_diameter_range_m must satisfy 0 < min <= max, got {(lo, hi)}")
    lo, hi = spec.rock_diameter_range_m
    if not 0 < lo <= hi:
        raise ConfigError(f"rock_diameter_range_m must satisfy 0 < min <= max, got {(lo, hi)}")
    if not 0 <= spec.rock_abundance < 1:
        raise ConfigError(f"rock_abundance must be in [0, 1), got {spec.rock_abundance}")


def generate_terrain(spec: TerrainSpec, rng: np.random.Generator) -> Terrain:
    """Generate a synthetic lunar terrain.

    Parameters
    ----------
    spec : TerrainSpec
        Laws and parameters.
    rng : numpy.random.Generator
        Sole source of randomness (same seed -> identical terrain).

    Returns
    -------
    terrain : Terrain
        DEM in the site frame, craters, rocks.
    """
    _terrain_iv(spec)
    xmin, xmax, ymin, ymax = spec.extent_m
    c = spec.cell_size_m
    nx = int(round((xmax - xmin) / c)) + 1
    ny = int(round((ymax - ymin) / c)) + 1
    x = xmin + c * np.arange(nx)
    y = ymin + c * np.arange(ny)

    heights = fractal_surface((ny, nx), c, spec.hurst, spec.roughness_1m_m, spec.rolloff_m, rng)
    az = np.radians(spec.slope_azimuth_deg)
    g = np.tan(np.radians(spec.slope_deg))
    heights -= g * (np.cos(az) * x[None, :] + np.sin(az) * y[:, None])

    keep = np.array(spec.keepout_xyr_m, dtype=float).reshape(-1, 3)
    crater_specs = list(spec.craters) + _random_craters(spec, keep, rng)
    craters = []
    for cs in crater_specs:
        patch_h, (j0, i0), depth = crater_patch(cs, x, y, c)
        heights[j0:j0 + patch_h.shape[0], i0:i0 + patch_h.shape[1]] += patch_h
        kind = "fresh" if cs.degradation == 0 else "degraded"
        craters.append(Crater(tuple(cs.centre_xy_m), cs.diameter_m, depth, kind,
                              cs.degradation * cs.diameter_m ** 2))

    rock_specs = list(spec.rocks) + _random_rocks(spec, keep, rng)
    centres = np.zeros((len(rock_specs), 3))
    radii = np.zeros(len(rock_specs))
    dem0 = DEM(heights, (xmin, ymin), c)
    for k, rs in enumerate(rock_specs):
        r = rs.diameter_m / 2
        ground = float(dem0.height_at(np.array([rs.centre_xy_m]))[0])
        centres[k] = (*rs.centre_xy_m, ground + r - 2 * r * rs.burial)
        radii[k] = r
        _bake_sphere_cap(heights, x, y, centres[k], r)
    return Terrain(DEM(heights, (xmin, ymin), c), craters, centres, radii)


def fractal_surface(shape: tuple[int, int], cell_size_m: float, hurst: float,
                    roughness_1m_m: float, rolloff_m: float,
                    rng: np.random.Generator) -> np.ndarray:
    """Self-affine random surface by spectral synthesis (Rosenburg et al. 2011 scaling).

    Parameters
    ----------
    shape : (ny, nx)
    cell_size_m : float
    hurst : float
        Hurst exponent H; power spectrum ``~ k^-(2H+2)``.
    roughness_1m_m : float
        Target RMS height difference at 1 m baseline (along x), metres.
    rolloff_m : float
        Longest amplified wavelength, metres.
    rng : numpy.random.Generator

    Returns
    -------
    z : (ny, nx) float64
        Zero-mean heights, metres.
    """
    ny, nx = shape
    if roughness_1m_m == 0:
        return np.zeros(shape)
    kx = np.fft.rfftfreq(nx, cell_size_m)
    ky = np.fft.fftfreq(ny, cell_size_m)
    k = np.hypot(kx[None, :], ky[:, None])
    k = np.maximum(k, 1.0 / rolloff_m)
    amp = k ** (-(hurst + 1.0))
    noise = rng.standard_normal((ny, nx // 2 + 1)) + 1j * rng.standard_normal((ny, nx // 2 + 1))
    z = np.fft.irfftn(amp * noise, s=(ny, nx), axes=(0, 1))
    lag = max(1, int(round(1.0 / cell_size_m)))
    nu = np.sqrt(np.mean((z[:, lag:] - z[:, :-lag]) ** 2))
    z *= roughness_1m_m / nu
    return z - z.mean()


def fresh_crater_profile(r_m: np.ndarray, diameter_m: float) -> np.ndarray:
    """Height change of a fresh simple crater vs radial distance (Pike 1977; McGetchin 1973).

    Parameters
    ----------
    r_m : (n,) float
        Distance from the crater centre, metres.
    diameter_m : float
        Rim-crest diameter D, metres.

    Returns
    -------
    dz : (n,) float
        Height change relative to the pre-impact surface, metres: a parabolic bowl from
        ``h_rim - 0.196 D`` at the centre to ``h_rim = 0.036 D`` at the rim, then ejecta
        ``h_rim (r/R)^-3`` tapered linearly to 0 at ``5 R``.
    """
    R = diameter_m / 2
    h_rim = FRESH_RIM_RATIO * diameter_m
    d = FRESH_DEPTH_RATIO * diameter_m
    s = np.asarray(r_m, dtype=float) / R
    inside = h_rim - d * (1.0 - s ** 2)
    tail_end = EJECTA_EXTENT_R ** -EJECTA_EXPONENT
    ejecta = h_rim * (np.maximum(s, 1.0) ** -EJECTA_EXPONENT - tail_end) / (1 - tail_end)
    return np.where(s <= 1.0, inside, np.where(s < EJECTA_EXTENT_R, ejecta, 0.0))


def crater_patch(cs: CraterSpec, x: np.ndarray, y: np.ndarray, cell_size_m: float
                 ) -> tuple[np.ndarray, tuple[int, int], float]:
    """Height change of one crater on the grid window that it affects.

    Parameters
    ----------
    cs : CraterSpec
        ``degradation = kappa t / D^2``; > 0 diffuses the fresh profile (Fassett & Thomson 2014).
    x : (nx,) float, y : (ny,) float
        Grid cell-centre coordinates, metres.
    cell_size_m : float

    Returns
    -------
    dz : (h, w) float
        Height change on the window.
    corner : (j0, i0)
        Index of the window's first cell in the full grid.
    depth_m : float
        Rim-crest (max over the ring r <= 1.2 R) to floor depth, metres.
    """
    R = cs.diameter_m / 2
    sigma = np.sqrt(2 * cs.degradation) * cs.diameter_m
    n = int(np.ceil((EJECTA_EXTENT_R * R + 4 * sigma) / cell_size_m)) + 1
    ci = int(round((cs.centre_xy_m[0] - x[0]) / cell_size_m))
    cj = int(round((cs.centre_xy_m[1] - y[0]) / cell_size_m))
    # evaluate on the full (unclipped) window so the diffusion sees the whole crater
    gi = np.arange(ci - n, ci + n + 1)
    gj = np.arange(cj - n, cj + n + 1)
    gx = x[0] + cell_size_m * gi - cs.centre_xy_m[0]
    gy = y[0] + cell_size_m * gj - cs.centre_xy_m[1]
    r = np.hypot(gx[None, :], gy[:, None])
    dz = fresh_crater_profile(r, cs.diameter_m)
    if sigma > 0:
        dz = ndimage.gaussian_filter(dz, sigma / cell_size_m, mode="constant")
    ring = r <= 1.2 * R
    depth = float(dz[ring].max() - dz[ring].min())
    i0, i1 = max(0, ci - n), min(len(x), ci + n + 1)
    j0, j1 = max(0, cj - n), min(len(y), cj + n + 1)
    if i1 <= i0 or j1 <= j0:
        return np.zeros((0, 0)), (0, 0), depth
    return dz[j0 - (cj - n):j1 - (cj - n), i0 - (ci - n):i1 - (ci - n)], (j0, i0), depth


def sample_crater_diameters(rng: np.random.Generator, area_m2: float, density: float,
                            exponent: float, d_range_m: tuple[float, float]) -> np.ndarray:
    """Diameters from the power law ``N(>D) = density * D^-exponent`` per m^2 (Trask 1966).

    Returns
    -------
    diameters_m : (n,) float
        A Poisson number of craters with ``d_min <= D <= d_max``.
    """
    lo, hi = d_range_m
    expected = area_m2 * density * (lo ** -exponent - hi ** -exponent)
    n = rng.poisson(expected)
    u = rng.random(n)
    # inverse CDF of the truncated Pareto distribution
    return (lo ** -exponent - u * (lo ** -exponent - hi ** -exponent)) ** (-1.0 / exponent)


def sample_rock_diameters(rng: np.random.Generator, area_m2: float, abundance: float,
                          d_range_m: tuple[float, float]) -> np.ndarray:
    """Rock diameters from Golombek & Rapp (1997): ``F(D) = k exp(-q D)``, ``q = 1.79 + 0.152/k``.

    The number density of rocks per diameter is ``-dF/dD / (pi D^2 / 4)``.

    Returns
    -------
    diameters_m : (n,) float
    """
    if abundance == 0:
        return np.zeros(0)
    lo, hi = d_range_m
    q = 1.79 + 0.152 / abundance
    d = np.linspace(lo, hi, 2001)
    density = abundance * q * np.exp(-q * d) / (np.pi * d ** 2 / 4)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(d))])
    n = rng.poisson(area_m2 * cdf[-1])
    return np.interp(rng.random(n) * cdf[-1], cdf, d)


def _uniform_points_outside(rng: np.random.Generator, n: int, spec: TerrainSpec,
                            keep: np.ndarray, margin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xmin, xmax, ymin, ymax = spec.extent_m
    xy = np.column_stack([rng.uniform(xmin, xmax, n), rng.uniform(ymin, ymax, n)])
    ok = np.ones(n, dtype=bool)
    for kx, ky, kr in keep:
        ok &= np.hypot(xy[:, 0] - kx, xy[:, 1] - ky) > kr + margin
    return xy, ok


def _random_craters(spec: TerrainSpec, keep: np.ndarray, rng: np.random.Generator
                    ) -> list[CraterSpec]:
    xmin, xmax, ymin, ymax = spec.extent_m
    d = sample_crater_diameters(rng, (xmax - xmin) * (ymax - ymin), spec.crater_density,
                                spec.crater_sfd_exponent, spec.crater_diameter_range_m)
    xy, ok = _uniform_points_outside(rng, len(d), spec, keep, 1.5 * d)
    fresh = rng.random(len(d)) < spec.fresh_fraction
    degr = rng.uniform(0.003, 0.03, len(d))
    return [CraterSpec((float(p[0]), float(p[1])), float(di), 0.0 if f else float(g))
            for p, di, f, g, o in zip(xy, d, fresh, degr, ok, strict=True) if o]


def _random_rocks(spec: TerrainSpec, keep: np.ndarray, rng: np.random.Generator
                  ) -> list[RockSpec]:
    xmin, xmax, ymin, ymax = spec.extent_m
    d = sample_rock_diameters(rng, (xmax - xmin) * (ymax - ymin), spec.rock_abundance,
                              spec.rock_diameter_range_m)
    xy, ok = _uniform_points_outside(rng, len(d), spec, keep, d)
    burial = rng.uniform(0.2, 0.5, len(d))
    return [RockSpec((float(p[0]), float(p[1])), float(di), float(b))
            for p, di, b, o in zip(xy, d, burial, ok, strict=True) if o]


def _bake_sphere_cap(heights: np.ndarray, x: np.ndarray, y: np.ndarray, centre: np.ndarray,
                     radius: float) -> None:
    i0, i1 = np.searchsorted(x, [centre[0] - radius, centre[0] + radius])
    j0, j1 = np.searchsorted(y, [centre[1] - radius, centre[1] + radius])
    if i1 <= i0 or j1 <= j0:
        return
    rho2 = (x[None, i0:i1] - centre[0]) ** 2 + (y[j0:j1, None] - centre[1]) ** 2
    cap = centre[2] + np.sqrt(np.maximum(radius ** 2 - rho2, 0.0))
    cap = np.where(rho2 < radius ** 2, cap, -np.inf)
    np.maximum(heights[j0:j1, i0:i1], cap, out=heights[j0:j1, i0:i1])
