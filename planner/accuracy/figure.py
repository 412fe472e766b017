"""The 95 % figure of a station's (or a marker's) error: a computed quantile, or the bound.

What a user sees of a station is the registered cloud over its working disc; its error at a
point ``q`` of the disc is ``e(q) = G(q) d`` for the pose error ``d ~ N(0, C)`` (6 parameters,
:data:`pipeline.network.observations.POSE_PARAMETERS`; :func:`known_control.rim_design_blocks`).
Two 95 % figures of it are offered (``PlanConfig.error_figure``):

- ``"quantile"``: the 95 % quantile of the **worst** error over the disc,
  ``max_q |e(q)|``, computed by spherical-radial integration over :data:`N_DIRECTIONS` fixed
  scrambled-Sobol directions of ``d`` (exact along each direction; the same number on every
  run; :func:`worst_disc_quantile`). The maximum is taken over the station
  and 72 rim points at its height (``|e(q)|^2`` is convex in ``q``, so the disc's maximum lies
  on the rim; between rim points 5 degrees apart it is underestimated by at most
  ``1 - cos(2.5 deg)`` = 0.1 %). This is the quantity a user's Monte-Carlo (or ``verify``)
  measures: the figure is exceeded in 5 % of draws (the ``error_figures`` benchmark and
  ``tests/planner/test_error_figure.py`` check this against adjustments of simulated
  observations; in network mode 4.7-5.1 %).
- ``"ellipsoid"`` (the default for now, see :data:`planner.config.DEFAULT_ERROR_FIGURE`; the
  planner's figure so far): the semi-major axis of the 3-D 95 % error ellipsoid at the worst
  point, ``sqrt(chi2_3(0.95) max_q lambda_max(Sigma(q)))``, ``Sigma(q) = G(q) C G(q)^T``.

Between the two (``B`` the ellipsoid figure, ``X`` the quantile): a single direction at the
worst point gives ``X >= sqrt(chi2_1(0.95) / chi2_3(0.95)) B = 0.70 B``, and ``max_q |G(q) L z|
<= sqrt(max_q lambda_max) |z|`` with ``z ~ N(0, I_6)`` gives ``X <= sqrt(chi2_6(0.95) /
chi2_3(0.95)) B = 1.27 B``. So the ellipsoid figure is not a bound in general (a pose error
whose translation and rotation can align exceeds it): on simulated networks it is 1.18-1.36x
the quantile, for a station fitted to 4 known markers 1.01x (the ``error_figures`` benchmark).

What the integer program relies on
----------------------------------
- **Monotone.** By Anderson's theorem (1955) the probability of the symmetric convex set
  ``{d : max_q |G(q) d| <= r}`` under ``N(0, C)`` does not grow when ``C`` grows in the
  Loewner order, so the quantile never grows when a marker is added. The computed figure
  averages over fixed directions through a square root of ``C``, which follows this to its
  precision, not exactly: adding a marker raised it by at most 3e-4 (relative) in 300 random
  layouts, where plain Monte-Carlo quantiles of 4,096 draws moved by up to 1.2 %.
- **Valid cuts.** Meeting ``r`` at 95 % needs, at every point ``q`` and direction ``u``,
  ``P(|u^T e(q)| <= r) >= 0.95``, i.e. ``chi2_1(0.95) u^T Sigma(q) u <= r^2``: a convex
  requirement whose tangents are valid linear cuts. :attr:`ErrorFigure.cut_chi2` is the
  constant the tangent cuts and the information lower bounds use (``chi2_1(0.95)`` for the
  quantile, ``chi2_3(0.95)`` for the ellipsoid figure, for which the condition is exact).
  Layouts the cuts let through are then judged by the figure itself, and a failing one is cut
  off by a no-good row, as before.
- **Cheap pass/fail.** :meth:`ErrorFigure.station_within` decides most stations from ``B``
  alone, by the bracket above (with a 2 % margin), and computes the quantile only
  for stations inside it.

A marker's own error (a point, no disc) uses the same two figures: the quantile of ``|e|`` for
``e ~ N(0, Sigma)`` (:func:`point_quantile`), or ``sqrt(chi2_3(0.95) lambda_max(Sigma))``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.special import erf
from scipy.stats import chi2, norm, qmc

from markerplan.errors import ConfigError
from planner.accuracy.known_control import (
    CHI2_3_95,
    lambda_max_sym3,
    pose_covariance,
    rim_covariances,
)
from planner.config import DEFAULT_ERROR_FIGURE, ERROR_FIGURES

QUANTILE, ELLIPSOID = ERROR_FIGURES
#: chi-square 95 % quantile with 1 degree of freedom (one direction): 1.96^2.
CHI2_1_95 = float(chi2.ppf(0.95, 1))
#: chi-square 95 % quantile with 6 degrees of freedom (the whole pose).
CHI2_6_95 = float(chi2.ppf(0.95, 6))
#: Scrambled-Sobol directions of the pose error behind the quantile (a power of two): the
#: figure is within 0.3 % of one from 8,192 directions (300 random stations).
N_DIRECTIONS = 2048
#: Seed of the directions' scrambling: the figure is one number, the same on every run.
DRAWS_SEED = 20261203
#: Relative rise of the computed quantile that adding a marker may bring (its precision; the
#: true quantile never rises): three times the largest seen in 300 random layouts.
MONOTONE_TOLERANCE = 1e-3
#: Directions of the quantile in a map of many candidate stations (``station_error.tif``):
#: within 2 % of the planner's figure, 8 times faster.
MAP_DIRECTIONS = 256
#: Relative tolerance of the quantile's squared radius, and most steps to reach it.
_RADIUS_TOLERANCE = 1e-10
_MAX_STEPS = 60
#: Relative margin by which the bracket ``[0.70 B, 1.27 B]`` is widened before it decides a
#: station without computing the quantile (the quantile's own precision is about 3e-3).
SCREEN_MARGIN = 0.02
#: Rim bearings of the quantile's maximum (as the ellipsoid figure's rim).
_N_RIM = 72
_CHUNK_DRAWS = 131072  # station-directions per block of work (a (32, 4096, 73) product)


@lru_cache(maxsize=8)
def directions(n: int = N_DIRECTIONS, dims: int = 6) -> np.ndarray:
    """(n, dims) unit directions: scrambled-Sobol standard normal draws, normalised (fixed
    seed; read-only; ``n`` a power of two; ``dims`` 6 for a pose, 12 for two)."""
    z = norm.ppf(qmc.Sobol(d=dims, scramble=True, seed=DRAWS_SEED).random(n))
    u = z / np.linalg.norm(z, axis=1, keepdims=True)
    u.setflags(write=False)
    return u


@lru_cache(maxsize=8)
def _rim_terms(working_radius_m: float) -> np.ndarray:
    """(6, 73) trigonometric terms of ``|e(q)|^2`` at the station and the 72 rim points."""
    phi = np.linspace(0.0, 2.0 * np.pi, _N_RIM, endpoint=False)
    c, s = np.cos(phi), np.sin(phi)
    r = working_radius_m
    rim = np.vstack([np.ones_like(phi), r * r * c * c, r * r * s * s, 2 * r * r * s * c,
                     2 * r * c, 2 * r * s])
    centre = np.array([[1.0], [0.0], [0.0], [0.0], [0.0], [0.0]])
    return np.hstack([centre, rim])


def square_roots(cov: np.ndarray) -> np.ndarray:
    """(k, d, d) ``L`` with ``L L^T = cov`` for positive semi-definite ``cov`` (k, d, d)."""
    lam, vec = np.linalg.eigh(cov)
    return vec * np.sqrt(np.maximum(lam, 0.0))[:, None, :]


def _chi2_cdf_pdf(x: np.ndarray, dof: int) -> tuple[np.ndarray, np.ndarray]:
    """chi-square distribution and density functions with 3 or an even number of degrees of
    freedom, closed form (even: ``1 - exp(-x/2) sum_{i < dof/2} (x/2)^i / i!``)."""
    half = np.exp(-x / 2)
    if dof == 6:
        return -np.expm1(-x / 2) - half * (x / 2 + x * x / 8), x * x * half / 16
    if dof % 2 == 0:
        term, tail = np.ones_like(x), np.zeros_like(x)
        for i in range(dof // 2):
            tail += term
            term = term * (x / 2) / (i + 1)
        # term is now (x/2)^m / m! (m = dof/2); the density (x/2)^(m-1) exp(-x/2) / (2 (m-1)!)
        return -np.expm1(-x / 2) - half * (tail - 1.0), \
            half * term * (dof / 2) / np.maximum(x, 1e-300)
    root = np.sqrt(x)
    return erf(root / np.sqrt(2)) - np.sqrt(2 / np.pi) * root * half, \
        root * half / np.sqrt(2 * np.pi)


def radial_quantile(extent2: np.ndarray, dof: int, upper: np.ndarray) -> np.ndarray:
    """(k,) ``r`` with ``P(r) = mean_i F_dof(r^2 / extent2[:, i]) = 0.95``: Newton steps in
    ``r^2``, kept inside the bracket ``[0.3 upper, upper]`` (``upper``: a radius where the
    mean is >= 0.95) by bisecting when a step leaves it, to :data:`_RADIUS_TOLERANCE`."""
    inv = 1.0 / np.maximum(extent2, 1e-300)
    lo, hi = (0.3 * upper) ** 2, upper**2
    r2 = 0.5 * (lo + hi)
    for _ in range(_MAX_STEPS):
        cdf, pdf = _chi2_cdf_pdf(r2[:, None] * inv, dof)
        p, slope = cdf.mean(axis=1), (pdf * inv).mean(axis=1)
        lo = np.where(p < 0.95, r2, lo)
        hi = np.where(p < 0.95, hi, r2)
        step = r2 - (p - 0.95) / np.maximum(slope, 1e-300)
        inside = (step > lo) & (step < hi)
        new = np.where(inside, step, 0.5 * (lo + hi))
        done = np.abs(new - r2) <= _RADIUS_TOLERANCE * new
        r2 = new
        if done.all():
            break
    return np.sqrt(r2)


def worst_disc_quantile(cov: np.ndarray, working_radius_m: float,
                        n_directions: int = N_DIRECTIONS) -> np.ndarray:
    """95 % quantile of the worst registered error over the working disc, m.

    Parameters
    ----------
    cov : (k, 6, 6) float
        Pose covariances (x, y, z, heading, roll, pitch), m^2, m rad, rad^2; finite and
        positive semi-definite.
    working_radius_m : float
        Radius of the disc, m (> 0).
    n_directions : int
        Directions of the integration (a power of two; fewer: faster and coarser).

    Returns
    -------
    quantile_m : (k,) float
        ``r`` with ``P(max_q |G(q) d| <= r) = 0.95`` for ``d ~ N(0, C)``.

    Notes
    -----
    Spherical-radial integration (Deak 1980): with ``d = L rho u``, ``u`` uniform on the unit
    sphere and ``rho^2 ~ chi2_6`` independent of it, and ``f(d) = max_q |G(q) d|`` a seminorm,
    ``P(f(d) <= r) = E_u[F_chi2_6(r^2 / f(L u)^2)]``: the radial part is exact, the average
    over ``u`` uses the ``n_directions`` fixed :func:`directions`. At a rim point ``q = R (cos
    phi, sin phi, 0)`` the error is ``e = t + R cos(phi) a + R sin(phi) b`` with ``a = (0,
    heading, -pitch)``, ``b = (-heading, 0, roll)``, so ``|e|^2`` is six per-direction numbers
    times fixed trigonometric terms: one matrix product per block.

    Examples
    --------
    An isotropic translation error (no rotation) of 1 cm per axis: the quantile of
    ``|N(0, 1e-4 I_3)|``, ``0.01 sqrt(chi2_3(0.95))`` = 0.0280 m.

    >>> c = np.zeros((1, 6, 6)); c[0, :3, :3] = np.eye(3) * 1e-4
    >>> round(float(worst_disc_quantile(c, 10.0)[0]), 4)
    0.028
    """
    cov = np.asarray(cov, dtype=float)
    if cov.ndim != 3 or cov.shape[1:] != (6, 6):
        raise ConfigError(f"`cov` must have shape (k, 6, 6), got {cov.shape}")
    u = directions(n_directions)
    terms = _rim_terms(float(working_radius_m)).astype(np.float32)
    out = np.empty(cov.shape[0])
    step = max(1, _CHUNK_DRAWS // u.shape[0])
    for lo in range(0, cov.shape[0], step):
        d = np.einsum("nb,kab->kna", u, square_roots(cov[lo:lo + step]))  # (k, N, 6)
        t, head, roll, pitch = d[..., :3], d[..., 3], d[..., 4], d[..., 5]
        per_direction = np.stack([
            np.einsum("kni,kni->kn", t, t),
            head * head + pitch * pitch,
            head * head + roll * roll,
            -pitch * roll,
            t[..., 1] * head - t[..., 2] * pitch,
            -t[..., 0] * head + t[..., 2] * roll,
        ], axis=-1)  # (k, N, 6)
        # the rim's largest |e|^2 in single precision (7 digits; the product is most of the work)
        worst = (per_direction.reshape(-1, 6).astype(np.float32) @ terms).max(axis=-1)
        extent2 = np.maximum(worst.astype(float), 0.0).reshape(-1, u.shape[0])  # f(L u)^2
        upper = np.sqrt(CHI2_6_95 * extent2.max(axis=1))
        out[lo:lo + step] = np.where(upper > 0, radial_quantile(extent2, 6, upper), 0.0)
    return out


def point_quantile(cov: np.ndarray) -> np.ndarray:
    """(k,) 95 % quantile of ``|e|`` for ``e ~ N(0, cov)``, ``cov`` (k, 3, 3) m^2, m (the
    spherical-radial integration of :func:`worst_disc_quantile` in 3 dimensions, on the first
    3 coordinates of the :func:`directions`, normalised)."""
    cov = np.asarray(cov, dtype=float)
    u = directions(N_DIRECTIONS)[:, :3]
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    out = np.empty(cov.shape[0])
    step = max(1, _CHUNK_DRAWS // u.shape[0])
    for lo in range(0, cov.shape[0], step):
        e = np.einsum("nb,kab->kna", u, square_roots(cov[lo:lo + step]))
        extent2 = np.einsum("kna,kna->kn", e, e)
        upper = np.sqrt(CHI2_3_95 * extent2.max(axis=1))
        out[lo:lo + step] = np.where(upper > 0, radial_quantile(extent2, 3, upper), 0.0)
    return out


def ellipsoid_bound(cov: np.ndarray, working_radius_m: float,
                    inclinometer_sigma_rad: float | None = None) -> np.ndarray:
    """(k,) ``sqrt(chi2_3(0.95) max_q lambda_max(G(q) C G(q)^T))`` over the station and 72 rim
    points, m (:func:`known_control.rim_covariances`), for pose covariances ``cov`` (k, 6, 6),
    or known control's (k, 4, 4) with independent tilts of ``inclinometer_sigma_rad`` (their
    vertical variance ``|q|^2 s^2`` added at each point: the same numbers, fewer products)."""
    _known_control_iv(cov, inclinometer_sigma_rad)
    sig = rim_covariances(np.asarray(cov, dtype=float), working_radius_m)
    if sig.shape[0] and np.shape(cov)[-1] == 4:
        radius = np.full(sig.shape[1], working_radius_m)
        radius[0] = 0.0
        sig[..., 2, 2] += (radius * inclinometer_sigma_rad) ** 2
    return np.sqrt(CHI2_3_95 * np.maximum(lambda_max_sym3(sig).max(axis=1), 0.0))


def _pose(cov: np.ndarray, inclinometer_sigma_rad: float | None) -> np.ndarray:
    """(k, 6, 6) pose covariances: ``cov`` itself, or known control's (k, 4, 4) with its tilts
    (:func:`known_control.pose_covariance`)."""
    _known_control_iv(cov, inclinometer_sigma_rad)
    if cov.shape[-1] == 4:
        return pose_covariance(cov, inclinometer_sigma_rad)
    return cov


def _known_control_iv(cov: np.ndarray, inclinometer_sigma_rad: float | None) -> None:
    if np.ndim(cov) != 3 or np.shape(cov)[1:] not in ((4, 4), (6, 6)):
        raise ConfigError(f"`cov` must have shape (k, 6, 6) or (k, 4, 4), got {np.shape(cov)}")
    if np.shape(cov)[-1] == 4 and inclinometer_sigma_rad is None:
        raise ConfigError("known control's (k, 4, 4) covariances need `inclinometer_sigma_rad`")


@dataclass(frozen=True)
class ErrorFigure:
    """How a station's and a marker's 95 % error is computed (see the module docstring).

    Parameters
    ----------
    kind : {"quantile", "ellipsoid"}
    n_directions : int
        The quantile's integration directions (a power of two, >= 64): the planner's
        :data:`N_DIRECTIONS`; a map of many cells may take fewer (:data:`MAP_DIRECTIONS`).
    """

    kind: str = DEFAULT_ERROR_FIGURE
    n_directions: int = N_DIRECTIONS

    def __post_init__(self) -> None:
        if self.kind not in ERROR_FIGURES:
            raise ConfigError(f"`error_figure` must be one of {', '.join(ERROR_FIGURES)}, got "
                              f"{self.kind!r:.40}")
        n = self.n_directions
        if not (isinstance(n, int) and n >= 64 and n & (n - 1) == 0):
            raise ConfigError(f"`n_directions` must be a power of two >= 64, got {n!r:.40}")

    @property
    def cut_chi2(self) -> float:
        """``k`` such that a passing station has ``k u^T Sigma(q) u <= r^2`` at every point and
        direction: the constant of the tangent cuts and the information lower bounds."""
        return CHI2_1_95 if self.kind == QUANTILE else CHI2_3_95

    def station_errors(self, cov: np.ndarray, working_radius_m: float,
                       inclinometer_sigma_rad: float | None = None) -> np.ndarray:
        """(k,) 95 % figure of each pose covariance over the working disc, m; ``inf`` where
        ``cov`` is not finite.

        Parameters
        ----------
        cov : (k, 6, 6) or (k, 4, 4) float
            Pose covariances; (k, 4, 4): known control's (x, y, z, heading), with roll and
            pitch independent of 1-sigma ``inclinometer_sigma_rad``.
        working_radius_m : float
        inclinometer_sigma_rad : float, optional
            Needed with (k, 4, 4) covariances.
        """
        cov = np.asarray(cov, dtype=float)
        out = np.full(cov.shape[0], np.inf)
        ok = np.isfinite(cov).all(axis=(1, 2))
        if ok.any():
            out[ok] = worst_disc_quantile(_pose(cov[ok], inclinometer_sigma_rad),
                                          working_radius_m, self.n_directions) \
                if self.kind == QUANTILE \
                else ellipsoid_bound(cov[ok], working_radius_m, inclinometer_sigma_rad)
        return out

    def station_within(self, cov: np.ndarray, working_radius_m: float, allowed_m,
                       inclinometer_sigma_rad: float | None = None) -> np.ndarray:
        """(k,) bool: each station's figure is ``<= allowed_m`` (scalar or (k,)), deciding from
        the ellipsoid figure where the bracket ``[0.70, 1.27] x`` it does; ``cov`` as
        :meth:`station_errors`."""
        cov = np.asarray(cov, dtype=float)
        allowed = np.broadcast_to(np.asarray(allowed_m, dtype=float), cov.shape[:1])
        ok = np.isfinite(cov).all(axis=(1, 2))
        out = np.zeros(cov.shape[0], bool)
        if not ok.any():
            return out
        bound = ellipsoid_bound(cov[ok], working_radius_m, inclinometer_sigma_rad)
        if self.kind == ELLIPSOID:
            out[ok] = bound <= allowed[ok]
            return out
        low = np.sqrt(CHI2_1_95 / CHI2_3_95) * (1 - SCREEN_MARGIN) * bound
        high = np.sqrt(CHI2_6_95 / CHI2_3_95) * (1 + SCREEN_MARGIN) * bound
        verdict = high <= allowed[ok]
        unsure = np.flatnonzero((low <= allowed[ok]) & ~verdict)
        if unsure.size:
            rows = np.flatnonzero(ok)[unsure]
            verdict[unsure] = worst_disc_quantile(_pose(cov[rows], inclinometer_sigma_rad),
                                                  working_radius_m,
                                                  self.n_directions) <= allowed[rows]
        out[ok] = verdict
        return out

    def point_within(self, cov: np.ndarray, allowed_m) -> np.ndarray:
        """(k,) bool: each point's figure is ``<= allowed_m`` (scalar or (k,)), deciding from
        ``sqrt(lambda_max)`` where the bracket ``[sqrt(chi2_1), sqrt(chi2_3)] x`` it does (the
        quantile of ``|e|`` is at most the ellipsoid figure: ``|e|^2 <= lambda_max |z|^2``)."""
        cov = np.asarray(cov, dtype=float)
        allowed = np.broadcast_to(np.asarray(allowed_m, dtype=float), cov.shape[:1])
        ok = np.isfinite(cov).all(axis=(1, 2))
        out = np.zeros(cov.shape[0], bool)
        if not ok.any():
            return out
        root = np.sqrt(np.maximum(lambda_max_sym3(cov[ok]), 0.0))
        verdict = np.sqrt(CHI2_3_95) * root <= allowed[ok]
        if self.kind == QUANTILE:
            unsure = np.flatnonzero(~verdict & (np.sqrt(CHI2_1_95) * (1 - SCREEN_MARGIN) * root
                                                <= allowed[ok]))
            if unsure.size:
                rows = np.flatnonzero(ok)[unsure]
                verdict[unsure] = point_quantile(cov[rows]) <= allowed[rows]
        out[ok] = verdict
        return out

    def point_errors(self, cov: np.ndarray) -> np.ndarray:
        """(k,) 95 % figure of 3-D point errors with covariances ``cov`` (k, 3, 3), m; ``inf``
        where ``cov`` is not finite."""
        cov = np.asarray(cov, dtype=float)
        out = np.full(cov.shape[0], np.inf)
        ok = np.isfinite(cov).all(axis=(1, 2))
        if ok.any():
            out[ok] = point_quantile(cov[ok]) if self.kind == QUANTILE \
                else np.sqrt(CHI2_3_95 * np.maximum(lambda_max_sym3(cov[ok]), 0.0))
        return out

    def describe(self) -> str:
        """One line for reports: what the 95 % figure is."""
        if self.kind == QUANTILE:
            return (f"95 % quantile of the worst error over the working disc "
                    f"(spherical-radial integration over {self.n_directions:,} directions of "
                    "the pose error)")
        return ("semi-major axis of the 3-D 95 % error ellipsoid at the worst point of the "
                "working disc (usually above the quantile of the worst error)")


def error_figure(config) -> ErrorFigure:
    """The :class:`ErrorFigure` of a :class:`~planner.config.PlanConfig` (``error_figure``)."""
    return ErrorFigure(config.error_figure)
