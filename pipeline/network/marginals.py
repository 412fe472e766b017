"""Marginal covariances of the network adjustment: the blocks wanted, never the full matrix.

The full covariance of ``u = 6s + 3k`` parameters needs ``u^2`` floats (1.5 GB for 1,000
stations and 2,500 markers). With the markers eliminated
(:func:`pipeline.network.normals.station_schur`: the stations' covariance ``Q_ss``, ``E =
N_sm N_mm^-1`` and the markers' ``N_mm^-1`` blocks) every block is exact and cheap:

    Q_sm = -Q_ss E,    Q_mm = N_mm^-1 + E^T Q_ss E,

with ``E`` as sparse as the observations (a marker's column block is non-zero only at the
stations that saw it). :class:`MarginalCovariance` holds ``Q_ss`` (the stations' size), ``E`` and
``N_mm^-1``; on construction it computes each marker's 3 x 3 block and the 6 x 3 cross block of
every observed station-marker pair (what each observation's 9 x 9 block, and so reliability,
needs), chunk by chunk; any other block, or ``Q y`` for a vector ``y`` (the MDBs' effect), is
computed when asked for. It indexes like the dense array for the patterns the adjustment uses
(``cov[i:j, i:j]``, ``cov[:, idx]``, ``cov[rows, cols]`` with broadcast index arrays of
observed blocks, ``cov.diagonal()``). After data snooping removes an observation it is
downdated like the dense array (:meth:`MarginalCovariance.downdated`: the blocks held updated,
the rank-3 term kept for products).
"""

from __future__ import annotations

import copy

import numpy as np
import scipy.sparse as sp

#: Markers per chunk when the marker and cross blocks are computed (a chunk holds a
#: (3 * chunk, 6s) float array: 37 MB for 1,000 stations).
_CHUNK = 256


class MarginalCovariance:
    """The covariance of the parameters (stations first, 6 each, then markers, 3 each; a-priori,
    sigma0 = 1; rows of parameters the datum fixes zero), m^2 and rad^2, from the markers'
    Schur complement.

    Parameters
    ----------
    q_ss : (6s, 6s) float
        The stations' covariance (:func:`pipeline.network.normals.station_schur`).
    e : (6s, 3k) sparse float
        ``N_sm N_mm^-1``.
    m_inv : (k, 3, 3) float
        The markers' ``N_mm^-1`` blocks, m^2.
    fixed : (u,) bool
        Parameters the datum fixes.
    obs : NetworkObservations
        The observations: their station-marker pairs get their cross blocks ready.

    Attributes
    ----------
    marker_blocks : (k, 3, 3) float
        Each marker's covariance, m^2.
    pairs : (p,) int
        ``station * k + marker`` of each observed pair, ascending.
    cross_blocks : (p, 6, 3) float
        ``Q[station pose, marker xyz]`` of each pair, m^2 and m rad.
    """

    def __init__(self, q_ss: np.ndarray, e: sp.csr_matrix, m_inv: np.ndarray,
                 fixed: np.ndarray, obs) -> None:
        ns, k = q_ss.shape[0], m_inv.shape[0]
        self.ns, self.k = ns, k
        self.shape = (ns + 3 * k, ns + 3 * k)
        station_fixed = np.asarray(fixed[:ns], dtype=bool)
        q_ss = q_ss.copy()
        q_ss[station_fixed, :] = 0.0
        q_ss[:, station_fixed] = 0.0
        self.q_ss = q_ss
        self._q0 = q_ss  # the Schur complement's inverse, before any downdate
        self._low_rank: list[tuple[np.ndarray, np.ndarray]] = []  # downdates: Q += V C V^T
        self.e = sp.csr_matrix(e)
        self.et = sp.csr_matrix(e.T)
        self.m_inv = m_inv
        self._m_inv_matrix = sp.bsr_matrix((m_inv, np.arange(k), np.arange(k + 1)),
                                           shape=(3 * k, 3 * k)).tocsr()
        self.pairs = np.unique(np.asarray(obs.station) * k + np.asarray(obs.marker))
        self.marker_blocks = np.empty((k, 3, 3))
        self.cross_blocks = np.empty((self.pairs.size, 6, 3))
        pair_station, pair_marker = np.divmod(self.pairs, k)
        for first in range(0, k, _CHUNK):
            last = min(first + _CHUNK, k)
            rows = np.arange(3 * first, 3 * last)
            g = np.asarray(self.et[rows] @ q_ss)  # (3c, 6s): E_c^T Q_ss = -Q_ms
            h = np.asarray(self.et[rows] @ g.T)   # (3c, 3c): E_c^T Q_ss E_c
            c = last - first
            diag = h.reshape(c, 3, c, 3)[np.arange(c), :, np.arange(c), :]
            self.marker_blocks[first:last] = m_inv[first:last] + diag
            sel = np.flatnonzero((pair_marker >= first) & (pair_marker < last))
            local = 3 * (pair_marker[sel] - first)
            st = 6 * pair_station[sel]
            self.cross_blocks[sel] = -g[local[:, None, None] + np.arange(3)[None, None, :],
                                        st[:, None, None] + np.arange(6)[None, :, None]]

    # -- products and columns -------------------------------------------------------------
    def matmul(self, y) -> np.ndarray:
        """``Q y`` for ``y`` (u, m), (u, m) float.

        ``z = Q_ss (y_s - E y_m)`` and ``N_mm^-1 y_m - E^T z``. With ``y`` sparse (design
        columns: one station and one marker each) ``y_s - E y_m`` stays sparse (the stations
        that saw the marker), so ``z`` costs ``6s`` per non-zero instead of ``(6s)^2`` per
        column.
        """
        ns = self.ns
        y = sp.csc_matrix(y)
        ys, ym = y[:ns], y[ns:]
        w = sp.csr_matrix((ys - self.e @ ym).T)
        z = np.asarray(w @ self._q0).T  # Q_ss symmetric
        out = np.concatenate([z, np.asarray(self._m_inv_matrix @ ym.toarray())
                              - np.asarray(self.et @ z)])
        for v, c in self._low_rank:
            out += v @ (c @ np.asarray(y.T @ v).T)
        return out

    def downdated(self, blocks: np.ndarray, columns: np.ndarray, weight: np.ndarray
                  ) -> MarginalCovariance:
        """The covariance after removing one point observation (Sherman-Morrison-Woodbury, as
        :func:`pipeline.network.normals.downdated`): ``Q + V C V^T`` with ``V = Q A_i^T``
        (u, 3) and ``C = (W^-1 - A_i Q A_i^T)^-1``; the blocks held are updated, the rank-3
        term kept for :meth:`matmul`.

        Parameters
        ----------
        blocks : (3, 9) float
            The observation's design block.
        columns : (9,) int
        weight : (3,) float
            Its component weights, 1/m^2.
        """
        u_mat = sp.csc_matrix((blocks.T.ravel(), (np.repeat(columns, 3),
                                                  np.tile(np.arange(3), columns.size))),
                              shape=(self.shape[0], 3))
        v = self.matmul(u_mat)
        c = np.linalg.inv(np.diag(1.0 / np.asarray(weight, float)) - blocks @ v[columns])
        new = copy.copy(self)
        ns, k = self.ns, self.k
        vs, vm = v[:ns], v[ns:].reshape(k, 3, 3)
        new.q_ss = self.q_ss + vs @ c @ vs.T
        new.marker_blocks = self.marker_blocks + vm @ c @ np.swapaxes(vm, 1, 2)
        station, marker = np.divmod(self.pairs, k)
        vp = vs.reshape(-1, 6, 3)[station]
        new.cross_blocks = self.cross_blocks + vp @ c @ np.swapaxes(vm[marker], 1, 2)
        new._low_rank = [*self._low_rank, (v, c)]
        return new

    def columns(self, idx) -> np.ndarray:
        """``Q[:, idx]``, (u, len(idx)) float."""
        idx = np.asarray(idx, dtype=int).ravel()
        return self.matmul(sp.csc_matrix((np.ones(idx.size), (idx, np.arange(idx.size))),
                                         shape=(self.shape[0], idx.size)))

    def diagonal(self) -> np.ndarray:
        """(u,) variances, m^2 and rad^2."""
        return np.concatenate([np.diag(self.q_ss),
                               np.diagonal(self.marker_blocks, axis1=1, axis2=2).ravel()])

    # -- indexing -------------------------------------------------------------------------
    def __getitem__(self, key) -> np.ndarray:
        rows, cols = key
        if np.ndim(rows) >= 2 or np.ndim(cols) >= 2:
            return self._entries(*np.broadcast_arrays(np.asarray(rows), np.asarray(cols)))
        rows, cols = self._index(rows), self._index(cols)
        if rows.max(initial=-1) < self.ns and cols.max(initial=-1) < self.ns:
            return self.q_ss[np.ix_(rows, cols)]
        marker = (np.concatenate([rows, cols]) - self.ns) // 3
        if rows.size and cols.size and rows.min() >= self.ns and np.all(marker == marker[0]):
            return self.marker_blocks[marker[0]][np.ix_((rows - self.ns) % 3,
                                                        (cols - self.ns) % 3)]
        return self.columns(cols)[rows]

    def _index(self, key) -> np.ndarray:
        if isinstance(key, slice):
            return np.arange(self.shape[0])[key]
        return np.atleast_1d(np.asarray(key, dtype=int))

    def _entries(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """``Q[i, j]`` elementwise for entries in the blocks held (stations, each marker's own
        block, observed station-marker pairs); ValueError for others."""
        ns, k = self.ns, self.k
        out = np.zeros(i.shape)
        si, sj = i < ns, j < ns
        both = si & sj
        out[both] = self.q_ss[i[both], j[both]]
        mm = ~si & ~sj
        mi, mj = np.divmod(i[mm] - ns, 3), np.divmod(j[mm] - ns, 3)
        if np.any(mi[0] != mj[0]):
            raise ValueError("MarginalCovariance holds no block between two markers")
        out[mm] = self.marker_blocks[mi[0], mi[1], mj[1]]
        for st, flip in ((si & ~sj, False), (~si & sj, True)):
            if not st.any():
                continue
            a, b = (j[st], i[st]) if flip else (i[st], j[st])
            station, pose_axis = np.divmod(a, 6)
            marker, axis = np.divmod(b - ns, 3)
            key = station * k + marker
            where = np.minimum(np.searchsorted(self.pairs, key), self.pairs.size - 1)
            if self.pairs.size == 0 or np.any(self.pairs[where] != key):
                raise ValueError("MarginalCovariance holds station-marker blocks of observed "
                                 "pairs only")
            out[st] = self.cross_blocks[where, pose_axis, axis]
        return out


def design_times(covariance, design: sp.csr_matrix, columns: np.ndarray) -> np.ndarray:
    """``design @ Q[:, columns]`` (rows of ``design``, len(columns)) for a dense covariance or a
    :class:`MarginalCovariance` (``Q`` symmetric: ``(Q design^T)[columns]^T``)."""
    if isinstance(covariance, MarginalCovariance):
        return covariance.matmul(design.T)[columns].T
    return np.asarray(design @ covariance[:, columns])
