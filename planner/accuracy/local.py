"""Local accuracy: the relative error between neighbouring stations, as surveyors state it.

Network accuracy (relative to the datum, :mod:`planner.accuracy.requirement`) grows from the
datum outward; what setting-out needs, and what the published experiment measured with its
all-pairs edge residuals, is the error *between* neighbours. :class:`LocalRequirement` asks
that for every pair of stations at most ``within_m`` apart (horizontally) the 95 % relative
error be at most ``a + b ppm`` of their separation:

``"position"``
    the relative position of any point ``q`` of the first station's working disc and any point
    ``q'`` of the second's, ``e = G(q) d_k - G(q') d_l`` (``d`` the pose errors, jointly
    normal with the 12 x 12 block of the network's covariance): the worst over both discs;
``"distance"``
    the error of their distance (edge length), ``u . e`` with ``u`` the unit vector from the
    first station to the second: the worst over both discs.

The 95 % figure is the plan's (:class:`~planner.accuracy.figure.ErrorFigure`): the ellipsoid
figure, the 3-D 95 % ellipsoid of ``e`` at the worst point pair — its semi-major axis
``sqrt(chi2_3(0.95) max lambda_max(Sigma(q, q')))`` for a position, its extent along the line
``sqrt(chi2_3(0.95) max u^T Sigma(q, q') u)`` for a distance (the one-dimensional
``chi2_1(0.95)`` there would be a pointwise 95 %, which the worst over both discs exceeds: 9.9 %
of pair-draws in :func:`planner.studies.figure_calibration.pair_calibration`), or the computed
95 % quantile
of the worst error over both discs (spherical-radial integration over 12-dimensional
directions, :func:`pair_quantile`). The maximum over the discs lies on their rims (``|e|^2``
is convex in ``(q, q')``), at the stations and 72 rim points each, as for a station.

For the integer program nothing changes in kind: ``g^T J^-1 g`` with ``g = (G(q)^T u, -G(q')^T
u)`` over the two stations' parameters is convex in the information and never grows when a
marker is added, so a failing pair fails for every subset of its layout's tying sites (no-good
rows), and tangents at any point are valid cuts (exact for the ellipsoid figure, the one-
direction necessary condition for the quantile; :meth:`LocalAccuracy.tangents`). In a free network
the pairs are judged in its datum-free covariance, a fixed linear map of the internal one
(:meth:`planner.accuracy.network.NetworkModel.datum_free`), which keeps both properties.

Pairs are screened before the grid of rim points is evaluated: the standard deviation of the
difference of two errors in any direction is at most the sum of theirs, so ``s_k + s_l``
(each station's ``sqrt(max lambda_max)``) bounds every pair's, and a pair whose bound times the
figure's largest factor is within its allowance passes without more work.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from markerplan.errors import ConfigError
from planner.accuracy.figure import (
    CHI2_1_95,
    QUANTILE,
    SCREEN_MARGIN,
    directions,
    ellipsoid_bound,
    radial_quantile,
    square_roots,
)
from planner.accuracy.known_control import CHI2_3_95, lambda_max_sym3, rim_design_blocks
from planner.accuracy.requirement import PPM
from planner.config import LOCAL_KINDS

#: chi-square 95 % quantile with 12 degrees of freedom (two poses).
CHI2_12_95 = float(chi2.ppf(0.95, 12))
#: Pairs per block of the rim grid (each ``73 x 73`` 3 x 3 matrices: 25 MB for 64).
_PAIRS_PER_BLOCK = 64


@dataclass(frozen=True)
class LocalRequirement:
    """The 95 % relative error allowed between two stations at most ``within_m`` apart:
    ``constant_m + ppm * 1e-6 * separation``.

    Parameters
    ----------
    constant_m : float
        m, > 0.
    ppm : float
        Parts per million of the pair's horizontal separation, >= 0.
    within_m : float
        Largest horizontal separation of a judged pair, m, > 0.
    kind : {"position", "distance"}

    Examples
    --------
    >>> LocalRequirement(0.10, within_m=50.0).describe()
    '0.1 m between stations within 50 m (relative position)'
    >>> LocalRequirement(0.05, 100.0, 30.0, "distance").allowed_m(np.array([10.0, 30.0]))
    array([0.051, 0.053])
    """

    constant_m: float
    ppm: float = 0.0
    within_m: float = 50.0
    kind: str = "position"

    def __post_init__(self) -> None:
        for name, positive in (("constant_m", True), ("ppm", False), ("within_m", True)):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v)
                    and (v > 0 if positive else v >= 0)):
                raise ConfigError(f"local requirement `{name}` must be a finite number "
                                  f"{'> 0' if positive else '>= 0'}, got {v!r:.40}")
        if self.kind not in LOCAL_KINDS:
            raise ConfigError(f"local requirement `kind` must be one of "
                              f"{', '.join(LOCAL_KINDS)}, got {self.kind!r:.40}")

    @classmethod
    def of(cls, config) -> LocalRequirement | None:
        """The local requirement of a :class:`~planner.config.PlanConfig` (None when it sets
        no ``local_requirement_m``)."""
        if config.local_requirement_m is None:
            return None
        return cls(float(config.local_requirement_m), float(config.local_requirement_ppm),
                   float(config.local_within_m), config.local_kind)

    def allowed_m(self, separation_m) -> np.ndarray:
        """Allowed 95 % relative error at horizontal separations ``separation_m`` (m), m."""
        return self.constant_m + self.ppm * PPM * np.asarray(separation_m, dtype=float)

    def describe(self) -> str:
        """One line for reports and messages."""
        what = "relative position" if self.kind == "position" else "their distance"
        ppm = f" + {self.ppm:g} ppm" if self.ppm > 0 else ""
        return f"{self.constant_m:g} m{ppm} between stations within {self.within_m:g} m ({what})"


@dataclass(frozen=True)
class PointPairs:
    """The pairs of points (stations, or markers' candidate sites) a :class:`LocalRequirement`
    judges.

    Attributes
    ----------
    first, second : (p,) int
        Station (or site) indices, ``first < second``.
    separation_m : (p,) float
        Horizontal separation, m.
    direction : (p, 3) float
        Unit vector from the first point to the second (site frame).
    allowed_m : (p,) float
        The requirement's allowance for each pair, m.
    """

    first: np.ndarray
    second: np.ndarray
    separation_m: np.ndarray
    direction: np.ndarray
    allowed_m: np.ndarray

    @property
    def size(self) -> int:
        return int(self.first.size)

    def subset(self, which) -> PointPairs:
        """The pairs ``which`` ((q,) int or (p,) bool) of these."""
        return PointPairs(self.first[which], self.second[which], self.separation_m[which],
                          self.direction[which], self.allowed_m[which])


def point_pairs(xyz: np.ndarray, requirement: LocalRequirement) -> PointPairs:
    """Every pair of the points ``xyz`` ((k, 3) m) at most ``requirement.within_m`` apart
    horizontally, in lexicographic order (indices into ``xyz``).

    >>> p = point_pairs(np.array([[0, 0, 0], [30, 0, 0], [90, 0, 0.0]]),
    ...                 LocalRequirement(0.1, within_m=60.0))
    >>> p.first.tolist(), p.second.tolist(), p.separation_m.tolist()
    ([0, 1], [1, 2], [30.0, 60.0])
    """
    xyz = np.asarray(xyz, dtype=float)
    first, second = np.triu_indices(xyz.shape[0], k=1)
    sep = np.linalg.norm(xyz[second, :2] - xyz[first, :2], axis=1)
    keep = sep <= requirement.within_m
    first, second, sep = first[keep], second[keep], sep[keep]
    delta = xyz[second] - xyz[first]
    length = np.linalg.norm(delta, axis=1, keepdims=True)
    direction = np.divide(delta, length, out=np.zeros_like(delta), where=length > 0)
    return PointPairs(first, second, sep, direction, requirement.allowed_m(sep))


def pair_blocks(full: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """(p, 12, 12) joint covariance of two stations' poses (the first's 6 parameters, then the
    second's) from the full pose covariance ``full`` ((6 s, 6 s))."""
    idx = np.hstack([6 * np.asarray(first)[:, None] + np.arange(6),
                     6 * np.asarray(second)[:, None] + np.arange(6)])
    return full[idx[:, :, None], idx[:, None, :]]


def _rim_grid(blocks: np.ndarray, radius_m: float, step: int = 1) -> np.ndarray:
    """(p, m, m, 3, 3) covariance of ``e = G(q_i) d_k - G(q_j) d_l`` at the station and every
    ``step``-th of the 72 rim points of each disc (``m = 1 + 72 / step``)."""
    g = rim_design_blocks(radius_m)
    g = g[np.r_[0, 1 + np.arange(0, g.shape[0] - 1, step)]].reshape(-1, 6)  # rows (point, axis)
    n = g.shape[0] // 3
    kk = g @ blocks[:, :6, :6] @ g.T  # (p, 219, 219)
    ll = g @ blocks[:, 6:, 6:] @ g.T
    kl = (g @ blocks[:, :6, 6:] @ g.T).reshape(-1, n, 3, n, 3)
    pts = np.arange(n)
    sk = kk.reshape(-1, n, 3, n, 3)[:, pts, :, pts, :].swapaxes(0, 1)  # (p, 73, 3, 3)
    sl = ll.reshape(-1, n, 3, n, 3)[:, pts, :, pts, :].swapaxes(0, 1)
    cross = kl.transpose(0, 1, 3, 2, 4)  # (p, i, j, 3, 3): G_i C_kl G_j^T
    return sk[:, :, None] + sl[:, None, :] - cross - np.swapaxes(cross, -1, -2)


#: Rim step of the coarse grid that brackets a pair's worst variance (every 4th of 72: 20
#: degrees) and the factor that makes it an upper bound: ``u^T Sigma(q, q') u`` is a
#: non-negative trigonometric polynomial of degree 2 in each rim angle, so its maximum is at
#: most ``1 / cos(2 pi / N)`` times the largest of ``N`` equally spaced samples (M. Riesz:
#: ``T(x* + t) >= max T cos(2 t)``), once per disc.
COARSE_STEP = 4
COARSE_FACTOR = 1.0 / np.cos(2.0 * np.pi / (72 // COARSE_STEP)) ** 2


def pair_variance_bracket(blocks: np.ndarray, direction: np.ndarray, radius_m: float,
                          kind: str) -> tuple[np.ndarray, np.ndarray]:
    """(p,) lower and upper bounds of :func:`pair_worst`'s variance from the coarse grid
    (:data:`COARSE_STEP`; 361 point pairs instead of 5,329), m^2."""
    low = np.zeros(blocks.shape[0])
    for lo in range(0, blocks.shape[0], 8 * _PAIRS_PER_BLOCK):
        sl = slice(lo, lo + 8 * _PAIRS_PER_BLOCK)
        grid = _rim_grid(blocks[sl], radius_m, COARSE_STEP)
        low[sl] = _grid_variance(grid, direction[sl], kind).max(axis=1)
    low = np.maximum(low, 0.0)
    return low, low * COARSE_FACTOR


def _grid_variance(grid: np.ndarray, direction: np.ndarray, kind: str) -> np.ndarray:
    """(p, m * m) ``lambda_max`` (position) or ``u^T Sigma u`` (distance) over a grid."""
    if kind == "position":
        return lambda_max_sym3(grid).reshape(grid.shape[0], -1)
    return np.einsum("pa,pijab,pb->pij", direction, grid, direction).reshape(grid.shape[0], -1)


def pair_worst(blocks: np.ndarray, direction: np.ndarray, radius_m: float, kind: str
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The worst point pair and direction of each pair's relative error.

    Parameters
    ----------
    blocks : (p, 12, 12) float
        Joint pose covariances (:func:`pair_blocks`), finite.
    direction : (p, 3) float
        Unit vector from the first station to the second (used by ``"distance"``).
    radius_m : float
    kind : {"position", "distance"}

    Returns
    -------
    variance : (p,) float
        ``max lambda_max(Sigma(q, q'))`` (position) or ``max u^T Sigma(q, q') u`` (distance),
        m^2.
    first_point, second_point : (p,) int
        Indices (0: the station, 1..72: rim points) of the worst ``q`` and ``q'``.
    worst_direction : (p, 3) float
        The unit direction of the worst variance.
    """
    p = blocks.shape[0]
    variance = np.zeros(p)
    first_point = np.zeros(p, np.int64)
    second_point = np.zeros(p, np.int64)
    worst_direction = np.zeros((p, 3))
    for lo in range(0, p, _PAIRS_PER_BLOCK):
        sl = slice(lo, lo + _PAIRS_PER_BLOCK)
        grid = _rim_grid(blocks[sl], radius_m)
        n = grid.shape[1]
        lam = _grid_variance(grid, direction[sl], kind)
        best = np.argmax(lam, axis=1)
        variance[sl] = np.maximum(lam[np.arange(best.size), best], 0.0)
        first_point[sl], second_point[sl] = np.divmod(best, n)
        if kind == "position":
            at = grid[np.arange(best.size), first_point[sl], second_point[sl]]
            worst_direction[sl] = np.linalg.eigh(at)[1][:, :, -1]
        else:
            worst_direction[sl] = direction[sl]
    return variance, first_point, second_point, worst_direction


def _rim_basis(radius_m: float) -> tuple[np.ndarray, np.ndarray]:
    """``G(q_i) = sum_a T[i, a] B[a]``: the trigonometric terms ``T`` ((73, 3): 1, R cos,
    R sin of the station and the 72 rim points) and the basis ``B`` ((3, 3, 6)) of
    :func:`~planner.accuracy.known_control.rim_design_blocks`, whose blocks are affine in the
    point."""
    g = rim_design_blocks(radius_m)
    phi = np.linspace(0.0, 2.0 * np.pi, g.shape[0] - 1, endpoint=False)
    t = np.vstack([[1.0, 0.0, 0.0], np.column_stack([np.ones_like(phi), radius_m * np.cos(phi),
                                                     radius_m * np.sin(phi)])])
    basis = np.linalg.lstsq(t, g.reshape(g.shape[0], -1), rcond=None)[0]
    return t, basis.reshape(3, 3, 6)


def pair_quantile(blocks: np.ndarray, direction: np.ndarray, radius_m: float, kind: str,
                  n_directions: int) -> np.ndarray:
    """(p,) 95 % quantile of the worst relative error over both discs, m: ``r`` with
    ``P(max_{q, q'} |e(q, q')| <= r) = 0.95`` (position) or ``|u . e|`` (distance), by
    spherical-radial integration over ``n_directions`` fixed 12-dimensional directions of the
    two poses' error (as :func:`planner.accuracy.figure.worst_disc_quantile`; radial part
    ``chi2_12``).

    Per direction the errors at the rim points are ``e_k(i) = sum_a T[i, a] v_a`` for three
    vectors ``v_a = B[a] d_k`` (:func:`_rim_basis`), so the ``73 x 73`` grid of ``|e_k(i) -
    e_l(j)|^2`` is three Gram matrices of the ``v`` times fixed products of ``T``: one matrix
    product per pair.
    """
    u = directions(n_directions, 12)
    t, basis = _rim_basis(radius_m)
    n = t.shape[0]
    outer_ii = np.einsum("ia,ib->abi", t, t).reshape(9, n)
    outer_ij = np.einsum("ia,jb->abij", t, t).reshape(9, n * n).astype(np.float32)
    out = np.empty(blocks.shape[0])
    roots = square_roots(blocks)
    for p in range(blocks.shape[0]):
        d = u @ roots[p].T  # (N, 12)
        vk = np.einsum("axc,nc->nax", basis, d[:, :6])  # (N, 3, 3): v_a per direction
        vl = np.einsum("axc,nc->nax", basis, d[:, 6:])
        if kind == "position":
            gram_k = np.einsum("nax,nbx->nab", vk, vk).reshape(-1, 9)
            gram_l = np.einsum("nax,nbx->nab", vl, vl).reshape(-1, 9)
            cross = np.einsum("nax,nbx->nab", vk, vl).reshape(-1, 9).astype(np.float32)
            sq = (-2.0 * (cross @ outer_ij)).reshape(-1, n, n)
            sq += (gram_k @ outer_ii).astype(np.float32)[:, :, None]
            sq += (gram_l @ outer_ii).astype(np.float32)[:, None, :]
            extent2 = sq.reshape(sq.shape[0], -1).max(axis=1).astype(float)
        else:
            a = (vk @ direction[p]) @ t.T  # (N, 73): u . e_k(i)
            b = (vl @ direction[p]) @ t.T
            extent2 = np.maximum(a.max(axis=1) - b.min(axis=1),
                                 b.max(axis=1) - a.min(axis=1)) ** 2
        extent2 = np.maximum(extent2, 0.0)[None]
        upper = np.sqrt(CHI2_12_95 * extent2.max(axis=1))
        out[p] = radial_quantile(extent2, 12, upper)[0] if upper[0] > 0 else 0.0
    return out


class LocalAccuracy:
    """A network's station pairs judged by a :class:`LocalRequirement`.

    Parameters
    ----------
    net : planner.accuracy.network.NetworkModel
    requirement : LocalRequirement
    """

    def __init__(self, net, requirement: LocalRequirement) -> None:
        self.net = net
        self.requirement = requirement
        self.kind = requirement.kind
        self.pairs = point_pairs(net.problem.station_xyz, requirement)

    def _blocks(self, cov, which: np.ndarray) -> np.ndarray:
        """The pairs' joint pose covariances (datum-free in a free network:
        :meth:`~planner.accuracy.network.NetworkModel.datum_free`)."""
        return pair_blocks(self.net.datum_free(cov).full, self.pairs.first[which],
                           self.pairs.second[which])

    def _determined(self, cov, which: np.ndarray) -> np.ndarray:
        return cov.determined[self.pairs.first[which]] & cov.determined[self.pairs.second[which]]

    def _station_spread(self, cov) -> np.ndarray:
        """(s,) ``max_q sqrt(lambda_max(Sigma_k(q)))`` of every station, m (the screen)."""
        blocks = self.net.datum_free(cov).station(np.arange(self.net.problem.n_stations))
        return ellipsoid_bound(blocks, self.net.radius) / np.sqrt(CHI2_3_95)

    def errors(self, cov, which=None) -> np.ndarray:
        """(m,) 95 % relative error of the pairs ``which`` (default all), m; ``inf`` where a
        station of the pair is undetermined."""
        which = np.arange(self.pairs.size) if which is None else np.asarray(which, np.int64)
        out = np.full(which.size, np.inf)
        ok = self._determined(cov, which)
        if not ok.any():
            return out
        rows = which[ok]
        blocks = self._blocks(cov, rows)
        direction = self.pairs.direction[rows]
        if self.net.figure.kind == QUANTILE:
            out[ok] = pair_quantile(blocks, direction, self.net.radius, self.kind,
                                    self.net.figure.n_directions)
        else:
            var = pair_worst(blocks, direction, self.net.radius, self.kind)[0]
            out[ok] = np.sqrt(CHI2_3_95 * var)
        return out

    def within(self, cov) -> np.ndarray:
        """(p,) bool: each pair's figure is within its allowance with covariance ``cov``
        (:meth:`all_within` of one covariance, pair by pair)."""
        return self._within([cov])[0]

    def all_within(self, covariances) -> np.ndarray:
        """(k,) bool: every pair passes, for each of ``covariances`` (a sequence of
        :class:`~planner.accuracy.network.NetworkCovariance`), judged in one batch."""
        return self._within(list(covariances)).all(axis=1)

    def _within(self, covariances: list) -> np.ndarray:
        """(k, p) bool: each pair's verdict under each covariance: screened by the stations'
        spreads, then by the ellipsoid bracket, the quantile computed only where they cannot
        decide."""
        pairs = self.pairs
        k, p = len(covariances), pairs.size
        out = np.zeros((k, p), bool)
        if p == 0 or k == 0:
            return out
        every = np.arange(p)
        ok = np.stack([self._determined(c, every) for c in covariances])
        spread = np.stack([self._station_spread(c) for c in covariances])
        bound = spread[:, pairs.first] + spread[:, pairs.second]
        quantile = self.net.figure.kind == QUANTILE
        top = CHI2_12_95 if quantile else CHI2_3_95
        sure = ok & (np.sqrt(top) * (1 + SCREEN_MARGIN) * bound <= pairs.allowed_m)
        out[sure] = True
        row, rest = np.nonzero(ok & ~sure)
        if rest.size == 0:
            return out
        blocks = np.concatenate([self._blocks(covariances[r], rest[row == r])
                                 for r in np.unique(row)])
        allowed = pairs.allowed_m[rest]
        direction = pairs.direction[rest]
        if not quantile:  # the coarse bracket decides most pairs; the rest on the full grid
            chi = CHI2_3_95
            low, high = pair_variance_bracket(blocks, direction, self.net.radius, self.kind)
            verdict = chi * high <= allowed**2
            unsure = np.flatnonzero(~verdict & (chi * low <= allowed**2))
            if unsure.size:
                var = pair_worst(blocks[unsure], direction[unsure], self.net.radius,
                                 self.kind)[0]
                verdict[unsure] = np.sqrt(chi * var) <= allowed[unsure]
            out[row, rest] = verdict
            return out
        low_var, high_var = pair_variance_bracket(blocks, direction, self.net.radius,
                                                  self.kind)
        low = np.sqrt(CHI2_1_95 * low_var) * (1 - SCREEN_MARGIN)
        high = np.sqrt(CHI2_12_95 * high_var) * (1 + SCREEN_MARGIN)
        verdict = high <= allowed
        unsure = np.flatnonzero((low <= allowed) & ~verdict)
        if unsure.size:
            verdict[unsure] = pair_quantile(blocks[unsure], direction[unsure],
                                            self.net.radius, self.kind,
                                            self.net.figure.n_directions) <= allowed[unsure]
        out[row, rest] = verdict
        return out

    def failing(self, cov) -> np.ndarray:
        """(m,) int: the pairs that fail with covariance ``cov``."""
        return np.flatnonzero(~self.within(cov))

    def gradients(self, cov, which) -> np.ndarray:
        """(m, 6 s) ``g = (G(q)^T u, -G(q')^T u)`` at each pair's worst points and direction
        (of the internal covariance in a free network:
        :meth:`~planner.accuracy.network.NetworkModel.datum_free_gradients`)."""
        which = np.asarray(which, np.int64)
        s6 = 6 * self.net.problem.n_stations
        g = np.zeros((which.size, s6))
        if which.size == 0:
            return g
        _, qi, qj, u = pair_worst(self._blocks(cov, which), self.pairs.direction[which],
                                  self.net.radius, self.kind)
        rim = rim_design_blocks(self.net.radius)
        rows = np.arange(which.size)
        first = 6 * self.pairs.first[which][:, None] + np.arange(6)
        second = 6 * self.pairs.second[which][:, None] + np.arange(6)
        g[rows[:, None], first] = np.einsum("mab,ma->mb", rim[qi], u)
        g[rows[:, None], second] = -np.einsum("mab,ma->mb", rim[qj], u)
        return self.net.datum_free_gradients(g)

    def tangents(self, cov, which) -> list[tuple[int, np.ndarray, float]]:
        """Tangent cuts ``(first station, coef (n,), rhs)`` of the pairs ``which`` at ``cov``
        (every pair's stations determined): ``sum_j coef_j x_j >= rhs``, ``rhs > 0`` only."""
        which = np.asarray(which, np.int64)
        which = which[self._determined(cov, which)]
        if which.size == 0:
            return []
        g = self.gradients(cov, which)
        b = self.pairs.allowed_m[which] ** 2 / self.net.figure.cut_chi2
        return self.net.tangents(cov, list(g), [int(k) for k in self.pairs.first[which]], b,
                                 np.zeros(which.size))

    def names(self, which) -> list[str]:
        """``"S1-S2"`` of each pair of ``which``."""
        ids = self.net.problem.station_ids
        return [f"{ids[self.pairs.first[i]]}-{ids[self.pairs.second[i]]}" for i in which]


def local_accuracy(net, config) -> LocalAccuracy | None:
    """The :class:`LocalAccuracy` of a network model under a configuration's local
    requirement (None when it sets none)."""
    requirement = LocalRequirement.of(config)
    return None if requirement is None else LocalAccuracy(net, requirement)
