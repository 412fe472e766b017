"""The information and covariance of a network-mode layout that grows one site at a time.

The network greedy (:mod:`planner.program.baselines`) adds candidate sites to a layout one by
one; :class:`GrowingCovariance` keeps the layout's covariance
(:class:`~planner.accuracy.network.NetworkModel`) up to date by low-rank updates instead of
inverting afresh after every site.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.sparse import csr_array
from scipy.sparse.csgraph import connected_components

from markerplan.errors import ConfigError
from planner.accuracy.network import NetworkCovariance, NetworkModel

#: Candidate sites whose low-rank factors are held at once (`GrowingCovariance.null_reductions`).
_SITES_CHUNK = 512


class GrowingCovariance:
    """The information and covariance of a layout that grows one site at a time.

    Adding site ``j`` adds ``J^(j) = U U^T`` (:meth:`NetworkModel.site_factor`, rank
    ``r <= 3 (m - 1)`` for a site ``m`` stations use) to the information. While every station
    is determined the covariance follows by the Woodbury identity ``C' = C - C U (I + U^T C
    U)^-1 U^T C`` in ``O(P^2 r)`` instead of a fresh ``O(P^3)`` inverse; it is recomputed by
    :meth:`NetworkModel.covariance` every ``refresh`` updates (round-off does not accumulate).
    While some station is undetermined, the null space of the information is tracked instead
    (adding ``U U^T`` leaves the null vectors ``n`` with ``U^T n = 0``), and the covariance is
    only computed when asked for. Equal to :meth:`NetworkModel.covariance` of the grown
    information up to round-off.

    Parameters
    ----------
    net : NetworkModel
    j : (P, P) float
        Information of the starting layout (copied), e.g. ``net.information(selected)``.
    refresh : int
        Updates between recomputations (>= 1).

    Attributes
    ----------
    j : (P, P) float
        The current information.
    """

    #: ``|U^T n|`` below this fraction of ``|U|`` leaves ``n`` in the null space.
    NULL_TOLERANCE = 1e-8

    def __init__(self, net: NetworkModel, j: np.ndarray, refresh: int = 50) -> None:
        if refresh < 1:
            raise ConfigError(f"`refresh` must be >= 1, got {refresh!r}")
        self.net = net
        self.j = np.array(j, dtype=float)
        self.refresh = int(refresh)
        self._recompute()
        self._null = np.zeros((net.free.size, 0))
        if not self._cov.determined.all():
            self._null = self._null_space()

    def _recompute(self) -> None:
        self._cov = self.net.covariance(self.j)
        self._updates = 0

    def _null_space(self) -> np.ndarray:
        """(P, d) orthonormal basis of the null space of ``j``, each vector within one
        connected block of ``j``, by :meth:`NetworkModel.covariance`'s criterion (eigenvalues
        of the diagonally scaled ``j`` below ``1e-10`` of the largest)."""
        _, block = connected_components(csr_array(self.j != 0), directed=False)
        scale = np.sqrt(np.maximum(np.diag(self.j), 1e-300))
        parts = []
        for b in np.unique(block):
            idx = np.flatnonzero(block == b)
            lam, vec = np.linalg.eigh(self.j[np.ix_(idx, idx)] / scale[idx, None]
                                      / scale[None, idx])
            parts.append((idx, lam, vec))
        top = max(max(lam[-1] for _, lam, _ in parts), 1e-300)
        null = np.zeros((self.j.shape[0], 0))
        for idx, lam, vec in parts:
            v = vec[:, lam <= 1e-10 * top] / scale[idx, None]
            if v.shape[1]:
                part = np.zeros((self.j.shape[0], v.shape[1]))
                part[idx] = np.linalg.qr(v)[0]  # orthonormal in the unscaled parameters
                null = np.column_stack([null, part])
        return null

    @property
    def determined(self) -> np.ndarray:
        """(s,) bool: stations whose pose the layout determines (no null vector moves them)."""
        if not self._null.shape[1]:
            return self._cov.determined
        return self.net.determined_by(self._null)

    @property
    def cov(self) -> NetworkCovariance:
        """The covariance of ``j`` (updated in place by :meth:`add`: do not keep it across)."""
        if self._cov is None:
            self._recompute()
        return self._cov

    def add(self, site: int) -> None:
        """Add candidate site ``site`` to the layout."""
        index, u = self.net.site_factor(site)
        if u.shape[1] == 0:
            return  # a site one station uses adds no information
        pos = self.net.free_position[index]
        free = pos >= 0
        uf = u[free]
        self.j[np.ix_(pos[free], pos[free])] += uf @ uf.T
        if self._null.shape[1]:
            self._shrink_null(pos[free], uf)
        if self._cov is None or not self._cov.determined.all() \
                or self._updates + 1 >= self.refresh:
            # stale until asked for while undetermined; recomputed once determined
            self._cov = None
            if not self._null.shape[1]:
                self._recompute()
            return
        full = self._cov.full
        cu = full[:, index] @ u  # (6 s, r); rows and columns of fixed parameters are zero
        inner = np.eye(u.shape[1]) + u.T @ cu[index]
        z = scipy.linalg.solve_triangular(np.linalg.cholesky(inner), cu.T, lower=True)
        full -= z.T @ z
        self._updates += 1

    def null_reductions(self, sites: np.ndarray) -> np.ndarray:
        """(k,) int: how many free movements (null directions of ``j``) adding each of
        ``sites`` ((k,) int, distinct) alone would remove: the rank of ``U^T N`` (``N`` the
        null basis), counting singular values above ``NULL_TOLERANCE`` times ``|U|``, as
        :meth:`add` does."""
        sites = np.asarray(sites, dtype=np.int64)
        removed = np.zeros(sites.size, dtype=np.int64)
        if not self._null.shape[1]:
            return removed
        n_free = self._null.shape[0]
        null = np.vstack([self._null, np.zeros((1, self._null.shape[1]))])  # row n_free: 0
        where = {int(j): i for i, j in enumerate(sites)}
        for lo in range(0, sites.size, _SITES_CHUNK):  # bounded memory: factors of a chunk
            for group, index, u in self.net.site_factors(sites[lo:lo + _SITES_CHUNK]):
                pos = self.net.free_position[index]  # (g, 6 m)
                fixed = pos < 0
                u = np.where(fixed[:, :, None], 0.0, u)
                m = np.einsum("gpr,gpd->grd", u, null[np.where(fixed, n_free, pos)])
                sig = np.linalg.svd(m, compute_uv=False)
                tol = self.NULL_TOLERANCE * np.linalg.norm(u, 2, axis=(1, 2))
                removed[[where[int(j)] for j in group]] = np.sum(sig > tol[:, None], axis=1)
        return removed

    def _null_split(self, pos: np.ndarray, uf: np.ndarray) -> tuple[np.ndarray, int, np.ndarray]:
        """The null vectors an added ``U U^T`` (rows ``pos``) touches (column indices), how
        many of their directions it removes, and the right singular vectors of ``U^T N``
        (rows past that count span what stays null)."""
        touched = np.flatnonzero(np.any(self._null[pos] != 0, axis=0))
        if not touched.size:
            return touched, 0, np.zeros((0, 0))
        m = uf.T @ self._null[np.ix_(pos, touched)]  # (r, t)
        _, sig, vt = np.linalg.svd(m)
        tol = self.NULL_TOLERANCE * np.linalg.norm(uf, 2)
        return touched, int(np.sum(sig > tol)), vt

    def _shrink_null(self, pos: np.ndarray, uf: np.ndarray) -> None:
        """Keep the null vectors the added ``U U^T`` (rows ``pos``) leaves null."""
        touched, rank, vt = self._null_split(pos, uf)
        if not touched.size:
            return
        kept = self._null[:, touched] @ vt[rank:].T
        rest = np.delete(self._null, touched, axis=1)
        self._null = np.column_stack([rest, kept])
