"""Network mode's tangent (outer-approximation) cuts: the linearisation of every convex
requirement ``g^T J(x)^-1 g <= b`` of :mod:`planner.accuracy.network` at a covariance, as
linear rows over the candidate sites (:class:`NetworkTangents`, mixed into
:class:`~planner.accuracy.network.NetworkModel`)."""

from __future__ import annotations

import numpy as np
import scipy.linalg

from planner.accuracy import known_control
from planner.accuracy.network_covariance import NetworkCovariance


class NetworkTangents:
    """The cuts of a :class:`~planner.accuracy.network.NetworkModel` (which provides the
    problem, pairs, design blocks, weights, prior, figure and allowances these read)."""

    def site_coefficients(self, v: np.ndarray) -> np.ndarray:
        """``v^T J^(j) v`` for every site and every direction ``v``.

        Parameters
        ----------
        v : (m, P) float
            Directions in the free parameters.

        Returns
        -------
        coef : (m, n) float, >= 0
            The weighted spread ``sum_s w_s |a_s - a_bar|^2`` of ``a_s = H_s v_s`` (plus
            ``(lambda_j / (W_j T_j)) |sum_s w_s a_s|^2`` at a control point).
        """
        v = np.atleast_2d(np.asarray(v, dtype=float))
        m = v.shape[0]
        vf = np.zeros((6 * self.problem.n_stations, m))
        vf[self.free] = v.T
        vs = vf.reshape(-1, 6, m)[self.pair_station]  # (p, 6, m)
        a = np.matmul(self.design, vs).reshape(-1, 3 * m)  # (p, 3 m): a_s for every direction
        w = self.weight[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            inv_w = np.where(self.site_weight > 0, 1.0 / self.site_weight, 0.0)
        total = self._site_sum @ (w * a)  # (n, 3 m): sum_s w_s a_s
        mean = total * inv_w[:, None]
        d = a - mean[self.pair_site]
        spread = (w * d * d).reshape(-1, 3, m).sum(axis=1)  # (p, m)
        anchored = inv_w * self.site_prior_weight / self.site_total_weight.clip(min=1e-300)
        return (self._site_sum @ spread
                + anchored[:, None] * (total * total).reshape(-1, 3, m).sum(axis=1)).T

    def station_tangents(self, cov: NetworkCovariance, stations, rim: str = "worst"
                         ) -> list[tuple[int, np.ndarray, float]]:
        """Tangent (outer-approximation) cuts of the station requirement at a covariance.

        Parameters
        ----------
        cov : NetworkCovariance
            ``J0^-1`` (must be determined for ``stations``).
        stations : sequence of int
            Each judged against its own allowance (:attr:`allowed_station_m`).
        rim : {"worst", "spread"}
            Tangent at the worst rim point, or at the station and 8 rim points.

        Returns
        -------
        cuts : list of (station, coef (n,), rhs)
            ``sum_j coef_j x_j >= rhs``; only cuts with ``rhs > 0``.
        """
        gs, owners = self._station_gradients(cov, stations, rim)
        return self.tangents(cov, gs, owners,
                              self.allowed_station_m[owners] ** 2 / self.figure.cut_chi2,
                              np.zeros(len(gs)))

    def scaled_covariances(self, sites_information: np.ndarray, scales, stations):
        """Station blocks of the covariances of ``J(t) = J_prior + t S`` for many ``t``.

        One generalised eigen-decomposition ``S V = (J_prior + S) V diag(mu)`` with ``V^T
        (J_prior + S) V = I`` gives ``J(t)^-1 = V diag(1 / (1 - mu + t mu)) V^T`` for every
        ``t > 0``: ``O(P^3)`` once and ``O(P^2)`` per station instead of ``O(P^3)`` each.

        Parameters
        ----------
        sites_information : (P, P) float
            ``S``, e.g. :meth:`site_information` of every open site; ``J_prior + S`` must be
            positive definite (every station determined).
        scales : (k,) float
            ``t`` per station, > 0.
        stations : (k,) int

        Returns
        -------
        covariances : iterator of (station, NetworkCovariance)
            Per station, in order, a covariance whose ``full`` holds the rows and columns of
            ``station``'s pose parameters only (zero elsewhere): all that
            :meth:`station_tangents` and :meth:`station_errors_from` of that station read.

        Raises
        ------
        numpy.linalg.LinAlgError
            ``J_prior + S`` is not positive definite.
        """
        mu, vec = scipy.linalg.eigh(sites_information, sites_information + self.prior_information)
        return self._scaled_station_rows(mu, vec, scales, stations)

    def _scaled_station_rows(self, mu, vec, scales, stations):
        s = self.problem.n_stations
        position = self.free_position
        for k, t in zip(stations, scales, strict=True):
            params = 6 * int(k) + np.arange(6)
            own = params[position[params] >= 0]
            rows = (vec[position[own]] / (1.0 - mu + t * mu)) @ vec.T  # (q, P)
            full = np.zeros((6 * s, 6 * s))
            full[np.ix_(own, self.free)] = rows
            full[np.ix_(self.free, own)] = rows.T
            yield int(k), NetworkCovariance(full=full, determined=np.ones(s, bool))

    def worst_direction_gain(self, cov: NetworkCovariance, k: int) -> np.ndarray:
        """(n,) ``v^T J^(j) v`` at station ``k``'s worst rim point and direction: the first-order
        reduction of its worst variance that adding each site brings (``v = C g``)."""
        gs, _ = self._station_gradients(cov, [k], "worst", force=True)
        v = (np.asarray(gs) @ cov.full)[:, self.free]
        return self.site_coefficients(v)[0]

    def _station_gradients(self, cov, stations, rim, force=False):
        """``g = G_k(q)^T u`` (in all ``6 s`` parameters) at the chosen rim points of each
        station's worst direction ``u``; undetermined stations are skipped unless ``force``."""
        g_rim = known_control.rim_design_blocks(self.radius)  # (r, 3, 6)
        gs, owners = [], []
        for k in stations:
            if not cov.determined[k] and not force:
                continue
            ck = cov.station(int(k))
            sig = np.einsum("ria,ab,rjb->rij", g_rim, ck, g_rim)
            lam, vec = np.linalg.eigh(sig)
            if rim == "worst":
                points = [int(np.argmax(lam[:, -1]))]
            else:
                points = [0, *range(1, g_rim.shape[0], (g_rim.shape[0] - 1) // 8)]
            for r in points:
                g = np.zeros(6 * self.problem.n_stations)
                g[6 * int(k):6 * int(k) + 6] = g_rim[r].T @ vec[r, :, -1]
                gs.append(g)
                owners.append(int(k))
        return gs, owners

    def marker_tangents(self, cov: NetworkCovariance, sites
                        ) -> list[tuple[int, np.ndarray, float]]:
        """Tangent cuts of the marker requirement (each site's :attr:`allowed_site_m`) for
        markers at ``sites``: ``(site, coef, rhs)`` meaning ``x_site = 1  =>  sum_j coef_j x_j
        >= rhs`` (``rhs > 0`` only)."""
        sites = np.asarray(sites, dtype=np.int64).reshape(-1)
        if sites.size == 0:
            return []
        c = self.marker_covariances(cov, sites)
        gs, owners, const = [], [], []
        for i, j in enumerate(sites):
            if not np.isfinite(c[i]).all():
                continue
            u = np.linalg.eigh(c[i])[1][:, -1]
            lo, hi = self.site_start[j], self.site_start[j + 1]
            g = np.zeros(6 * self.problem.n_stations)
            for p in range(lo, hi):
                s = self.pair_station[p]
                g[6 * s:6 * s + 6] += (self.weight[p] / self.site_total_weight[j]
                                       * self.design[p].T @ u)
            gs.append(g)
            owners.append(int(j))
            const.append(1.0 / self.site_total_weight[j])
        return self.tangents(cov, gs, owners,
                              self.allowed_site_m[owners] ** 2 / self.figure.cut_chi2,
                              np.asarray(const))

    def tangents(self, cov: NetworkCovariance, gs, owners, b, const
                 ) -> list[tuple[int, np.ndarray, float]]:
        """Tangent cuts of requirements ``g^T J^-1 g <= b - const`` at ``cov``.

        Parameters
        ----------
        cov : NetworkCovariance
            ``J0^-1``.
        gs : sequence of (6 s,) float
            Each requirement's gradient over every pose parameter (fixed ones included).
        owners : sequence of int
            What each cut is about (a station or a site), returned with it.
        b, const : (m,) float
            Each requirement's bound and the constant part of its variance, m^2.

        Returns
        -------
        cuts : list of (owner, coef (n,), rhs)
            ``sum_j coef_j x_j >= rhs``; only cuts with ``rhs > 0``.
        """
        if not gs:
            return []
        g = np.asarray(gs)
        v = g @ cov.full  # (m, 6 s); rows of fixed parameters are zero
        h0 = np.einsum("ma,ma->m", v, g)
        vfree = v[:, self.free]
        rhs = 2.0 * h0 - (b - const) - np.einsum("ma,ab,mb->m", vfree, self.prior_information,
                                                   vfree)
        out = []
        keep = np.flatnonzero(rhs > 0)
        for lo in range(0, keep.size, 16):
            sel = keep[lo:lo + 16]
            coef = self.site_coefficients(vfree[sel])
            for i, m in enumerate(sel):
                out.append((owners[m], coef[i], float(rhs[m])))
        return out
