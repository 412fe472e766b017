"""Terrain known only from orbit: an orbital-grade planning DEM made from a fine truth DEM.

On the Moon a planner has no 0.1 m terrain: it has an orbital product — LOLA site DEMs at
~5 m/px with a median height error of 0.3-0.5 m, LROC NAC stereo DTMs at ~2 m/px — with rocks
and small craters below its resolution missing. :func:`orbital_dem` makes such a product from a
simulated truth terrain:

1. **Block average** the truth onto cells of ``cell_m`` (an integer multiple of the truth's
   cell): each coarse cell holds the mean of the ``f x f`` fine cells it covers (``f = cell_m /
   truth cell``; a ragged last row/column of fine cells is dropped), its centre at their
   centre. Rocks and craters much smaller than ``cell_m`` vanish into the mean.
2. **Add a height-error field** (:func:`height_error_field`): a stationary zero-mean Gaussian
   random field with covariance

   ``C(r) = rms_m**2 * exp(-(r / correlation_m)**2)``

   (``correlation_m`` is the 1/e distance of the correlation), made by filtering white noise on
   the coarse grid with a Gaussian kernel of standard deviation ``correlation_m / 2`` (two such
   Gaussians convolved give the covariance above) and scaled by the kernel's exact discrete
   norm, so every cell's variance is exactly ``rms_m**2``. The grid is padded by three
   correlation lengths before filtering, so the field does not wrap around. When
   ``correlation_m`` is below a cell the field is white (independent cells); when it spans
   more than eight cells the field is drawn on a coarser grid (kernel four cells wide) and
   interpolated onto the DEM's by cubic spline, which keeps its RMS and correlation within a
   few per cent (tested).

:class:`HeightError` (what a DEM's height error is declared as) is what the planner's terrain
handling (:mod:`planner.problem.terrain_uncertainty`) draws realisations from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from markerplan.errors import ConfigError
from visibility.dem import DEM

#: Largest height-error RMS accepted, m: LOLA site products have 0.3-0.5 m median error; a DEM
#: 50 m wrong everywhere is not a planning DEM.
MAX_HEIGHT_ERROR_RMS_M = 50.0
#: Largest correlation length accepted, m (10 km: beyond it the error is a plain offset).
MAX_CORRELATION_M = 10_000.0
#: Correlation length when a ``--dem-height-error`` gives only the RMS, m (LROC NAC DTM errors
#: are correlated over a few of its 2 m posts, its stereo-matching kernel).
DEFAULT_CORRELATION_M = 10.0
#: Largest orbital cell accepted, m (LOLA's coarsest site products are 20 m/px; 100 m leaves
#: nothing of a site).
MAX_ORBITAL_CELL_M = 100.0


@dataclass(frozen=True)
class HeightError:
    """A DEM's declared height error: a Gaussian field (module docstring), metres.

    Attributes
    ----------
    rms_m : float
        Standard deviation of the error at any point, m (0 .. :data:`MAX_HEIGHT_ERROR_RMS_M`).
    correlation_m : float
        1/e distance of its correlation, m (> 0 .. :data:`MAX_CORRELATION_M`).

    Raises
    ------
    ConfigError
        A value that is not a finite number in range (one line naming the fix).

    Examples
    --------
    >>> HeightError(0.3, 10.0)
    HeightError(rms_m=0.3, correlation_m=10.0)
    """

    rms_m: float
    correlation_m: float = DEFAULT_CORRELATION_M

    def __post_init__(self) -> None:
        rms = _number(self.rms_m, "height error RMS")
        corr = _number(self.correlation_m, "height error correlation length")
        if not 0.0 <= rms <= MAX_HEIGHT_ERROR_RMS_M:
            raise ConfigError(f"height error RMS {rms:g} m is outside [0, "
                              f"{MAX_HEIGHT_ERROR_RMS_M:g}] m; give the DEM's 1-sigma vertical "
                              "error in metres (LOLA site products: 0.3-0.5)")
        if not 0.0 < corr <= MAX_CORRELATION_M:
            raise ConfigError(f"height error correlation length {corr:g} m is outside (0, "
                              f"{MAX_CORRELATION_M:g}] m; give the distance over which the "
                              "DEM's error stays alike, in metres (e.g. 10)")
        object.__setattr__(self, "rms_m", rms)
        object.__setattr__(self, "correlation_m", corr)

    @classmethod
    def parse(cls, text: str) -> HeightError:
        """``"RMS_M[,CORRELATION_M]"`` -> HeightError (correlation default
        :data:`DEFAULT_CORRELATION_M`).

        >>> HeightError.parse("0.5,20")
        HeightError(rms_m=0.5, correlation_m=20.0)
        """
        parts = [p.strip() for p in str(text).split(",")]
        if len(parts) not in (1, 2) or not all(parts):
            raise ConfigError(f"height error {text!r}: give RMS_M or RMS_M,CORRELATION_M in "
                              "metres, e.g. 0.3,10")
        names = ("height error RMS", "height error correlation length")
        return cls(*(_number(p, name) for p, name in zip(parts, names, strict=False)))

    def record(self) -> dict:
        """``{"rms_m", "correlation_m"}`` for provenance."""
        return {"rms_m": self.rms_m, "correlation_m": self.correlation_m}


def _number(value, name: str) -> float:
    """``value`` as a finite float, else a one-line :class:`ConfigError`."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise ConfigError(f"{name} {value!r} is not a finite number; give metres, e.g. 0.3 "
                          "(height error RMS), 10 (correlation length), 2 (orbital cell)")
    return number


def block_average(truth: DEM, cell_m: float) -> DEM:
    """The truth DEM averaged onto cells of ``cell_m`` (step 1 of the module docstring).

    Parameters
    ----------
    truth : DEM
        Fine terrain, site frame.
    cell_m : float
        Coarse cell, m: an integer multiple (>= 1) of ``truth.cell_size_m``.

    Returns
    -------
    coarse : DEM
        Cell ``[J, I]`` = mean of fine cells ``[fJ:fJ+f, fI:fI+f]``, centred on them; valid
        where all of them are.

    Raises
    ------
    ConfigError
        ``cell_m`` not a multiple of the truth's cell, or above :data:`MAX_ORBITAL_CELL_M`.
    """
    f = _block_factor(truth.cell_size_m, cell_m)
    ny, nx = (n // f for n in truth.shape)
    if min(ny, nx) < 2:
        raise ConfigError(f"orbital cell {cell_m:g} m leaves fewer than 2 x 2 cells of this "
                          f"{truth.shape[1]} x {truth.shape[0]}-cell DEM; give a smaller cell")

    def mean(a):
        return a[:ny * f, :nx * f].reshape(ny, f, nx, f).mean(axis=(1, 3))

    valid = None if truth.valid is None else mean(truth.valid.astype(float)) == 1.0
    half = 0.5 * (f - 1) * truth.cell_size_m
    return DEM(mean(truth.heights_m), (truth.origin_m[0] + half, truth.origin_m[1] + half),
               f * truth.cell_size_m, crs=truth.crs, valid=valid)


def _block_factor(fine_m: float, cell_m: float) -> int:
    cell = _number(cell_m, "orbital cell")
    if not 0.0 < cell <= MAX_ORBITAL_CELL_M:
        raise ConfigError(f"orbital cell {cell:g} m is outside (0, {MAX_ORBITAL_CELL_M:g}] m; "
                          "give the orbital product's post spacing (NAC DTM 2, LOLA 5)")
    f = round(cell / fine_m)
    if f < 1 or abs(f * fine_m - cell) > 1e-6 * cell:
        raise ConfigError(f"orbital cell {cell:g} m is not a whole multiple of the truth DEM's "
                          f"{fine_m:g} m cell; give a multiple of it")
    return int(f)


def height_error_field(shape: tuple[int, int], cell_m: float, error: HeightError,
                       rng: np.random.Generator) -> np.ndarray:
    """One draw of the height-error field on a grid (module docstring, step 2).

    Parameters
    ----------
    shape : (ny, nx)
        Grid cells.
    cell_m : float
        Grid spacing, m.
    error : HeightError
    rng : numpy.random.Generator

    Returns
    -------
    field : (ny, nx) float
        Heights to add, m; zero mean, variance ``error.rms_m**2`` per cell, covariance
        ``rms**2 exp(-(r / correlation)**2)`` between cells ``r`` apart.
    """
    ny, nx = shape
    if error.rms_m == 0.0:
        return np.zeros(shape)
    sigma = 0.5 * error.correlation_m / cell_m  # kernel std, cells
    if sigma < 0.5:  # correlation below a cell: white
        return error.rms_m * rng.standard_normal(shape)
    step = max(1, int(sigma // COARSE_SIGMA_CELLS))
    if step == 1:
        return error.rms_m * _unit_field((ny, nx), sigma, rng)
    coarse = _unit_field((ny // step + 3, nx // step + 3), sigma / step, rng)
    j, i = np.meshgrid(np.arange(ny) / step + 1.0, np.arange(nx) / step + 1.0, indexing="ij")
    return error.rms_m * ndimage.map_coordinates(coarse, [j, i], order=3, mode="nearest")


#: Kernel width (cells) at which a smooth field is drawn on a coarser grid and interpolated
#: (cubic spline) onto the DEM's: a 10 m correlation on 0.1 m cells is drawn on 1 m cells, so a
#: draw costs the same on any grid.
COARSE_SIGMA_CELLS = 4.0


def _unit_field(shape: tuple[int, int], sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Unit-variance white noise filtered by a Gaussian kernel of ``sigma`` cells (>= 0.5) on a
    grid padded by ``6 sigma`` (so it does not wrap), divided by the kernel's exact discrete
    norm (the variance of the separable filter is the square of its 1-D kernel's sum of
    squares)."""
    ny, nx = shape
    pad = int(math.ceil(6.0 * sigma))
    noise = rng.standard_normal((ny + 2 * pad, nx + 2 * pad))
    smooth = ndimage.gaussian_filter(noise, sigma, mode="wrap", truncate=4.0)
    delta = np.zeros(2 * pad + 1)
    delta[pad] = 1.0
    kernel = ndimage.gaussian_filter1d(delta, sigma, mode="constant", truncate=4.0)
    return smooth[pad:pad + ny, pad:pad + nx] / float(np.sum(kernel**2))


def with_height_error(dem: DEM, error: HeightError, rng: np.random.Generator) -> DEM:
    """``dem`` plus one draw of the height-error field on its own grid (m)."""
    return DEM(dem.heights_m + height_error_field(dem.shape, dem.cell_size_m, error, rng),
               dem.origin_m, dem.cell_size_m, crs=dem.crs, valid=dem.valid)


def reseated(xyz: np.ndarray, from_dem: DEM, to_dem: DEM) -> np.ndarray:
    """Points at the same x, y and the same height above ``to_dem``'s ground as they stand
    above ``from_dem``'s: a station (its LiDAR centre) or a marker (its centre) moved onto
    other terrain.

    Parameters
    ----------
    xyz : (k, 3) float
        Site frame, m.
    from_dem, to_dem : DEM
        Both covering the points.

    Returns
    -------
    moved : (k, 3) float
    """
    xyz = np.asarray(xyz, float)
    xy = xyz[:, :2]
    return np.column_stack([xy, xyz[:, 2] - from_dem.height_at(xy) + to_dem.height_at(xy)])


def orbital_dem(truth: DEM, cell_m: float, height_error: HeightError, seed: int = 0) -> DEM:
    """An orbital-grade DEM of ``truth``: block-averaged onto ``cell_m`` cells plus a seeded
    draw of the height-error field (module docstring).

    Parameters
    ----------
    truth : DEM
        Fine terrain (rocks baked in), site frame.
    cell_m : float
        Orbital post spacing, m (a multiple of the truth's cell; NAC DTM 2, LOLA 5).
    height_error : HeightError
    seed : int
        Seed of the error field (the same seed gives the same DEM).

    Returns
    -------
    dem : DEM
    """
    rng = np.random.default_rng([int(seed), 0x0EB17])
    return with_height_error(block_average(truth, cell_m), height_error, rng)
