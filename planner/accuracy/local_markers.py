"""Local accuracy between markers: the relative error of every pair of selected markers within
``within_m`` of each other (horizontally), judged by the plan's :class:`~planner.accuracy.local.
LocalRequirement` (``local_markers``). A selected marker no station uses (an existing one out of
sight) is not estimated by the network and is not judged.

Cross-covariance
----------------
A selected marker at site ``j`` is estimated as the weighted mean of its stations' registered
measurements (:mod:`planner.accuracy.network`): its error is ``e_j = e_j0 + M_j d`` with ``d``
the pose errors (covariance ``C``), ``M_j = (1 / W_j) sum_s w_s H_s`` (3 x 6 s) and ``e_j0`` the
measurement noise's own mean (covariance ``I / W_j``, independent between markers and of
``d``). Hence ``cov(e_j, e_k) = delta_jk I / W_j + M_j C M_k^T``, and the relative position
``e_k - e_j`` of two markers has covariance

    Sigma_jk = I / W_j + I / W_k + (M_k - M_j) C (M_k - M_j)^T.

(At a control point ``W_j`` is the network's total weight ``T_j``, its coordinate prior
included; control points are in the cross-covariance but not judged, their accuracy being
given.)

Figures
-------
Markers are points (no working disc): the ``"position"`` figure is the plan's point figure of
``Sigma_jk`` (:meth:`~planner.accuracy.figure.ErrorFigure.point_errors`: the ellipsoid's
semi-major axis, or the 95 % quantile of ``|e|``); the ``"distance"`` figure is
``sqrt(k u^T Sigma_jk u)`` with ``u`` the unit vector from ``j`` to ``k`` and ``k`` the
figure's :attr:`~planner.accuracy.figure.ErrorFigure.cut_chi2` (the 3-D ellipsoid's extent
along the line, ``chi2_3(0.95)``; the exact 95 % of the 1-D distance error, ``chi2_1(0.95)``,
for the quantile figure).

The integer program
-------------------
A pair applies only when both markers are selected, so the rule is not monotone in the
selection: a site added shrinks ``C`` (every existing pair's ``Sigma_jk`` shrinks, since
``M_j`` and ``W_j`` are the site's, not the layout's) but may bring new pairs. It is checked
lazily on each candidate layout, and a failing pair ``(j, k)`` gives two valid cuts:

``"cut-marker-pair"``
    ``sum_{i tying, not selected} x_i >= x_j + x_k - 1``: a layout holding both markers and no
    tying site outside the failing layout's has a subset ``T'`` of its tying sites, so its
    information is no larger (a site seen by one station adds none), ``C`` no smaller and
    ``Sigma_jk`` no smaller: it fails the pair too;
``"oa-marker-pair"``
    the tangent of ``g^T J^-1 g`` (``g = (M_k - M_j)^T u`` at the worst direction ``u``),
    enforced only when both are selected: ``sum_i c_i x_i >= rhs (x_j + x_k - 1)``.

Both rows leave every layout that holds one of the two markers or neither untouched.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from planner.accuracy.local import LocalRequirement, PointPairs, point_pairs


def marker_pairs(site_xyz: np.ndarray, sites, requirement: LocalRequirement) -> PointPairs:
    """Every pair of the markers at ``sites`` ((m,) int into ``site_xyz``, (n, 3) m) at most
    ``requirement.within_m`` apart horizontally, in lexicographic order of site.

    >>> p = marker_pairs(np.array([[0, 0, 0], [30, 0, 0], [90, 0, 0.0]]), [2, 0, 1],
    ...                  LocalRequirement(0.1, within_m=60.0))
    >>> p.first.tolist(), p.second.tolist(), p.separation_m.tolist()
    ([0, 1], [1, 2], [30.0, 60.0])
    """
    sites = np.sort(np.asarray(sites, dtype=np.int64).reshape(-1))
    pairs = point_pairs(np.asarray(site_xyz, dtype=float)[sites], requirement)
    return replace(pairs, first=sites[pairs.first], second=sites[pairs.second])


def marker_maps(net, sites, weight: np.ndarray | None = None) -> sp.csr_array:
    """``M_j = (1 / W_j) sum_s w_s H_s`` of the markers at ``sites`` ((m,) int), stacked:
    (3 m, 6 s) sparse, rows ``3 i .. 3 i + 2`` the marker ``sites[i]``'s (zero for a site no
    station uses).

    Parameters
    ----------
    net : planner.accuracy.network.NetworkModel
        Its :meth:`~planner.accuracy.network.NetworkModel.pairs_of`, ``pair_station``,
        ``weight``, ``design`` and ``site_total_weight`` are used.
    sites : (m,) int
    weight : (P,) float, optional
        Each pair's weight when not ``net.weight`` (0 for a lost pair: the marker is the mean
        of the measurements that were detected).
    """
    sites = np.asarray(sites, dtype=np.int64).reshape(-1)
    weight = net.weight if weight is None else weight
    pairs, pos = net.pairs_of(sites)
    w = total_weight(net, weight)[sites]
    f = weight[pairs] / np.where(w > 0, w, 1.0)[pos]  # (q,)
    blocks = f[:, None, None] * net.design[pairs]  # (q, 3, 6)
    rows = 3 * pos[:, None, None] + np.arange(3)[None, :, None] + np.zeros((1, 1, 6), np.int64)
    cols = 6 * net.pair_station[pairs][:, None, None] + np.arange(6)[None, None, :] \
        + np.zeros((1, 3, 1), np.int64)
    return sp.csr_array((blocks.ravel(), (rows.ravel(), cols.ravel())),
                        shape=(3 * sites.size, 6 * net.problem.n_stations))


def total_weight(net, weight: np.ndarray) -> np.ndarray:
    """(n,) every site's total weight ``T_j`` (its pairs' ``weight``, (P,), plus its
    coordinate prior)."""
    return np.bincount(net.pair_site, weight, minlength=net.problem.n_sites) \
        + net.site_prior_weight


def marker_cross_covariance(net, cov, sites, weight: np.ndarray | None = None) -> np.ndarray:
    """(m, m, 3, 3) joint covariance of the markers at ``sites``, m^2: block ``(a, b)`` is
    ``cov(e_a, e_b) = delta_ab I / W_a + M_a C M_b^T`` (see the module doc); ``inf`` in the
    rows and columns of a marker no station uses or seen from an undetermined station.

    Parameters
    ----------
    net : planner.accuracy.network.NetworkModel
    cov : planner.accuracy.network_covariance.NetworkCovariance
    sites : (m,) int
    weight : (P,) float, optional
        As :func:`marker_maps`.
    """
    sites = np.asarray(sites, dtype=np.int64).reshape(-1)
    weight = net.weight if weight is None else weight
    m = marker_maps(net, sites, weight)
    mc = np.asarray(m @ cov.full)  # (3m, 6s)
    out = np.asarray(m @ mc.T).reshape(sites.size, 3, sites.size, 3).transpose(0, 2, 1, 3)
    w = total_weight(net, weight)[sites]
    idx = np.arange(sites.size)
    out[idx, idx] += (1.0 / np.where(w > 0, w, 1.0))[:, None, None] * np.eye(3)
    bad = (w <= 0) | net.undetermined_markers(cov, sites)
    out[bad] = np.inf
    out[:, bad] = np.inf
    return out


class LocalMarkerAccuracy:
    """The selected markers' pairs of a layout judged by a local requirement.

    Parameters
    ----------
    net : planner.accuracy.network.NetworkModel
    requirement : LocalRequirement
    weight : (P,) float, optional
        Each pair's weight when some were lost (0; :class:`~planner.accuracy.network_chance.
        NetworkOdds`): a marker is then the mean of its detected measurements, and one with
        none detected is not estimated, so its pairs no longer exist (not judged). Default
        ``net.weight`` (every usable pair detected).
    """

    def __init__(self, net, requirement: LocalRequirement,
                 weight: np.ndarray | None = None) -> None:
        self.net = net
        self.requirement = requirement
        self.kind = requirement.kind
        self.weight = net.weight if weight is None else np.asarray(weight, float)

    def pairs(self, selected) -> PointPairs:
        """The judged pairs of the layout ``selected`` ((n,) bool): its markers some station
        uses (a marker no station sees, or whose every measurement was lost, is not estimated
        by the network, and not judged), but the control points (their accuracy is given, as
        for the network requirement)."""
        seen = np.asarray(selected, bool) & (total_weight(self.net, self.weight) > 0) \
            & ~self.net.control
        return marker_pairs(self.net.problem.site_xyz, np.flatnonzero(seen), self.requirement)

    def difference_covariances(self, cov, pairs: PointPairs) -> np.ndarray:
        """(p, 3, 3) covariance ``Sigma_jk`` of each pair's relative position, m^2 (``inf``
        where a marker is undetermined)."""
        if pairs.size == 0:
            return np.zeros((0, 3, 3))
        sites, inv = np.unique(np.r_[pairs.first, pairs.second], return_inverse=True)
        a, b = inv[:pairs.size], inv[pairs.size:]
        full = marker_cross_covariance(self.net, cov, sites, self.weight)
        finite = np.isfinite(full[np.arange(sites.size), np.arange(sites.size)]).all(axis=(1, 2))
        full[~finite] = 0.0
        full[:, ~finite] = 0.0
        cross = full[a, b]
        out = full[a, a] + full[b, b] - cross - np.swapaxes(cross, 1, 2)
        out[~(finite[a] & finite[b])] = np.inf
        return out

    def errors(self, cov, pairs: PointPairs) -> np.ndarray:
        """(p,) 95 % relative error of each pair (module doc), m; ``inf`` where undetermined."""
        sigma = self.difference_covariances(cov, pairs)
        if self.kind == "position":
            return self.net.figure.point_errors(sigma)
        out = np.full(pairs.size, np.inf)
        ok = np.isfinite(sigma).all(axis=(1, 2))
        var = np.einsum("pa,pab,pb->p", pairs.direction[ok], sigma[ok], pairs.direction[ok])
        out[ok] = np.sqrt(self.net.figure.cut_chi2 * np.maximum(var, 0.0))
        return out

    def failing(self, cov, selected) -> tuple[PointPairs, np.ndarray]:
        """The layout's judged pairs and the indices (into them) of those that fail."""
        pairs = self.pairs(selected)
        if pairs.size == 0:
            return pairs, np.zeros(0, np.int64)
        if self.kind == "position":
            ok = self.net.figure.point_within(self.difference_covariances(cov, pairs),
                                              pairs.allowed_m)
        else:
            ok = self.errors(cov, pairs) <= pairs.allowed_m
        return pairs, np.flatnonzero(~ok)

    def gradients(self, cov, pairs: PointPairs, which) -> np.ndarray:
        """(q, 6 s) ``g = (M_k - M_j)^T u`` of the pairs ``which`` at their worst direction
        ``u`` (the top eigenvector of ``Sigma_jk``, or the line for ``"distance"``)."""
        which = np.asarray(which, np.int64)
        first, second = pairs.first[which], pairs.second[which]
        m1 = marker_maps(self.net, first, self.weight).toarray().reshape(which.size, 3, -1)
        m2 = marker_maps(self.net, second, self.weight).toarray().reshape(which.size, 3, -1)
        if self.kind == "position":
            sigma = self.difference_covariances(cov, pairs.subset(which))
            u = np.linalg.eigh(sigma)[1][:, :, -1]
        else:
            u = pairs.direction[which]
        return np.einsum("qa,qab->qb", u, m2 - m1), u

    def tangents(self, cov, pairs: PointPairs, which) -> list[tuple[int, np.ndarray, float]]:
        """Tangent cuts ``(pair index, coef (n,), rhs)`` of the pairs ``which`` at ``cov`` (both
        markers determined): a layout holding both markers passes only if ``sum_i coef_i x_i
        >= rhs``; ``rhs > 0`` only."""
        which = np.asarray(which, np.int64)
        determined = ~self.net.undetermined_markers(cov, pairs.first[which]) \
            & ~self.net.undetermined_markers(cov, pairs.second[which])
        which = which[determined]
        if which.size == 0:
            return []
        g, u = self.gradients(cov, pairs, which)
        total = total_weight(self.net, self.weight)
        w1, w2 = total[pairs.first[which]], total[pairs.second[which]]
        const = np.einsum("qa,qa->q", u, u) * (1.0 / w1 + 1.0 / w2)
        b = pairs.allowed_m[which] ** 2 / self.net.figure.cut_chi2
        return self.net.tangents(cov, list(g), [int(i) for i in which], b, const)


def local_marker_accuracy(net, config) -> LocalMarkerAccuracy | None:
    """The :class:`LocalMarkerAccuracy` of a network model under a configuration (None unless
    it sets ``local_requirement_m`` and ``local_markers``)."""
    requirement = LocalRequirement.of(config)
    if requirement is None or not getattr(config, "local_markers", False):
        return None
    return LocalMarkerAccuracy(net, requirement)


def pair_cut_rows(model, pairs: PointPairs, bad, tying_rest: np.ndarray, tangents,
                  selected: np.ndarray, lost: int | None = None
                  ) -> tuple[list, list[float], list[str]]:
    """The ``"cut-marker-pair"`` and ``"oa-marker-pair"`` rows (module doc) of the failing
    pairs ``bad``; with ``lost``, the redundant rows ``"cut-loss-marker-pair"`` and
    ``"oa-loss-marker-pair"`` of pairs that fail once the marker ``lost`` is lost (enforced
    only when all three markers are selected: ``sum_{i tying, not selected} x_i >= x_lost +
    x_j + x_k - 2``, valid as the plain row is, the information without ``lost`` being the
    layout's with it, and the tangents at the covariance without it).

    Parameters
    ----------
    model : planner.program.model.Model
    pairs : PointPairs
    bad : (q,) int
        Failing pairs (indices into ``pairs``).
    tying_rest : (r,) int
        The open tying sites the layout does not select (model variables).
    tangents : list of (pair index, sites (t,) int, coef (t,) float)
        Sparse tangents normalised to ``sum coef x >= 1`` (:func:`~planner.program.
        cuts_network.sparse_tangent`).
    selected : (n,) bool
    lost : int, optional
        The lost marker's site (redundant mode).

    Returns
    -------
    rows : list of (1, n_vars) sparse
    lower : list of float
    kinds : list of str
        Each row is ``row @ vars >= lower``.
    """
    rows, lower, kinds = [], [], []
    extra = [] if lost is None else [lost]
    cut, oa = ("cut-marker-pair", "oa-marker-pair") if lost is None \
        else ("cut-loss-marker-pair", "oa-loss-marker-pair")
    for p in np.asarray(bad, np.int64):
        implied, shift = _all_of(model, [pairs.first[p], pairs.second[p], *extra])
        rows.append(model.site_row(np.r_[tying_rest, implied],
                                   np.r_[np.ones(tying_rest.size), -np.ones(implied.size)]))
        lower.append(shift)
        kinds.append(cut)
    for p, sites, coef in tangents:
        implied, shift = _all_of(model, [pairs.first[p], pairs.second[p], *extra])
        rows.append(model.site_row(np.r_[sites, implied], np.r_[coef, -np.ones(implied.size)]))
        lower.append(shift)
        kinds.append(oa)
    return rows, lower, kinds


def _all_of(model, sites) -> tuple[np.ndarray, float]:
    """``sum_{i in sites} x_i - (|sites| - 1)`` as the variables among ``sites`` and the lower
    bound of a row ``(...) - sum x_i >= 1 - |sites|`` once a fixed site's ``x = 1`` is moved
    to it."""
    sites = np.asarray(sites, np.int64)
    var = model.site_var[sites] >= 0
    return sites[var], 1.0 - sites.size + float(np.sum(~var))
