"""Predicted outer reliability of a network layout (Baarda): what one undetected bias does to
the stations.

Model
-----
The network of :mod:`planner.accuracy.network`: station ``s`` measures the marker at site ``j``
with design ``[H_s | -I3]`` and per-axis weight ``w_s``; the datum is the reference station's
x, y, z and heading (fixed); the pose aids (:mod:`planner.accuracy.aids`: inclinometer, heading
reference, odometry) are pseudo-observations. With the markers eliminated the pose covariance is
``C = J^-1``
(:meth:`~planner.accuracy.network.NetworkModel.covariance`, zero rows for fixed parameters)
and the marker at ``j`` is ``m_j = M_j xi - l_bar_j`` with ``M_j = (1 / W_j) sum_s w_s H_s E_s``
(``E_s`` picks station ``s``'s pose). For the observation ``i = (s, j)``, with
``D_i = H_s E_s - M_j`` (3 x 6 s):

- its cofactor of adjusted observations is ``A_i Q A_i^T = D_i C D_i^T + I / W_j``, so its
  redundancy numbers (per site axis ``c``) are ``r_ic = 1 - w_s (D_i C D_i^T + I / W_j)_cc``;
- the minimal detectable bias of component ``c`` is ``MDB_ic = delta0 / sqrt(w_s r_ic)``
  (``delta0`` from ``alpha0 = 0.1 %``, ``beta0 = 80 %``: 4.13,
  :func:`pipeline.network.reliability.non_centrality`);
- the poses it moves are ``dxi = -C D_i^T w_s e_c MDB_ic`` (``Q A_i^T P e_c MDB``, pose rows);
  its effect on station ``k`` is the shift of that station's position ``(x, y, z)``, 3-D and
  horizontal.

Per component, not per 3-D block: ``markerplan adjust`` tests every component with its own
w-test at ``alpha0`` (:func:`pipeline.network.reliability.data_snooping`), so the bias that test
misses with probability ``1 - beta0`` is the one-component MDB; a 3-D block test (3 dof) is not
what the field software runs.

A marker seen by one station only (``D_i = 0``, ``W_j = w_s``) has ``r = 0``: the observation is
uncontrolled (its MDB is infinite) and the marker absorbs any bias, so no station moves (effect
0). Any other component with ``r ~ 0`` that moves a station has an infinite effect.

Cost: one ``(6 s) x (6 s)`` covariance and one product with the ``3 q`` columns of ``D^T`` (``q``
selected observations), in chunks of ``_CHUNK`` observations: ``O(s^2 q)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from pipeline.network.adjustment import AdjustmentSettings
from pipeline.network.reliability import non_centrality

#: Redundancy below which a component is uncontrolled (as in :mod:`pipeline.network.reliability`).
MIN_REDUNDANCY = 1e-10
#: Shift per unit bias below which an uncontrolled component moves no station (a marker seen
#: once: exactly 0 up to rounding), m/m.
_NO_SHIFT = 1e-9
#: Observations per chunk of ``C D^T`` (memory ``6 s x 3 x _CHUNK`` floats).
_CHUNK = 2000


def default_delta0() -> float:
    """Baarda's ``delta0`` at the adjustment's default ``alpha0`` and ``beta0`` (4.13)."""
    settings = AdjustmentSettings()
    return non_centrality(settings.alpha0, settings.beta0)


@dataclass(frozen=True)
class LayoutReliability:
    """Redundancy, MDB and MDB effects of a layout's observations (``q``) on its stations
    (``s``).

    Attributes
    ----------
    pair : (q,) int
        The observations: indices into the model's pairs (``NetworkModel.pair_station``,
        ``pair_site``), sorted by site then station.
    station, site : (q,) int
        Station and candidate site of each observation.
    redundancy : (q, 3) float
        Redundancy number per site axis, in [0, 1].
    mdb_m : (q, 3) float
        Minimal detectable bias per axis, m (``inf``: uncontrolled).
    effect_m, effect_horizontal_m : (q,) float
        Largest 3-D / horizontal shift of any station's position caused by any one of the
        observation's three MDBs, m (0 for a marker seen once; ``inf`` when an uncontrolled
        component moves a station or a station is undetermined).
    effect_station : (q,) int
        The station of ``effect_m`` (-1 when no station moves).
    station_effect_m, station_effect_horizontal_m : (s,) float
        Per station, the largest 3-D / horizontal shift over all observations, m.
    station_cause, station_cause_horizontal : (s,) int
        Row (into ``pair`` etc.) of the observation causing it (-1 when none moves it, or the
        station is undetermined: its effect is then ``inf``).
    prior_redundancy : (P_prior,) float
        Redundancy numbers of the pose aids' pseudo-observations that bear on the free
        parameters (:meth:`planner.accuracy.aids.PoseAids.redundancy`).
    dof : int
        Degrees of freedom: ``3 q + P_prior - 3 n_markers - P`` (``P`` free pose parameters).
    delta0 : float
    """

    pair: np.ndarray
    station: np.ndarray
    site: np.ndarray
    redundancy: np.ndarray
    mdb_m: np.ndarray
    effect_m: np.ndarray
    effect_horizontal_m: np.ndarray
    effect_station: np.ndarray
    station_effect_m: np.ndarray
    station_effect_horizontal_m: np.ndarray
    station_cause: np.ndarray
    station_cause_horizontal: np.ndarray
    prior_redundancy: np.ndarray
    dof: int
    delta0: float

    @property
    def controlled(self) -> np.ndarray:
        """(q, 3) bool: components whose own bias shows in their residual (``r > 0``)."""
        return np.isfinite(self.mdb_m)


def _difference_design(net, pairs: np.ndarray) -> sp.csr_array:
    """``D`` of the observations ``pairs`` (all pairs of their sites, sorted by site), as a
    sparse ``(3 q, 6 s)`` matrix: row block ``i`` is ``H_a E_{s_a} - sum_b (w_b / T_j) H_b
    E_{s_b}`` over the pairs ``b`` of observation ``a``'s site (``T_j`` its total weight, the
    network's ``site_total_weight``)."""
    q = pairs.size
    row_of = np.full(net.pair_site.size, -1)
    row_of[pairs] = np.arange(q)
    take = np.flatnonzero(row_of[net.tie_a] >= 0)  # ordered pairs (a, b) of selected sites
    a, b = net.tie_a[take], net.tie_b[take]
    coef = np.where(a == b, 1.0, 0.0) - net.weight[b] / net.site_total_weight[net.pair_site[b]]
    blocks = coef[:, None, None] * net.design[b]  # (t, 3, 6)
    rows = 3 * row_of[a][:, None, None] + np.arange(3)[None, :, None]
    cols = 6 * net.pair_station[b][:, None, None] + np.arange(6)[None, None, :]
    rows, cols = np.broadcast_arrays(rows, cols)
    return sp.csr_array((blocks.ravel(), (rows.ravel(), cols.ravel())),
                        shape=(3 * q, 6 * net.problem.n_stations))


def layout_reliability(net, selected, delta0: float | None = None) -> LayoutReliability:
    """Redundancy numbers, MDBs and their effect on every station for a layout.

    Parameters
    ----------
    net : planner.accuracy.network.NetworkModel
    selected : (n,) bool
        The layout (every usable pair of a selected site is an observation).
    delta0 : float, optional
        Non-centrality; default :func:`default_delta0`.

    Returns
    -------
    LayoutReliability
    """
    delta0 = default_delta0() if delta0 is None else float(delta0)
    sel = np.asarray(selected, bool)
    s = net.problem.n_stations
    cov = net.covariance(net.information(sel))
    pairs = np.flatnonzero(sel[net.pair_site])
    q = pairs.size
    w = net.weight[pairs]
    d = _difference_design(net, pairs)
    w_site = net.site_total_weight[net.pair_site[pairs]]
    redundancy = np.empty((q, 3))
    mdb = np.empty((q, 3))
    shift = np.zeros((2, q, 3, s))  # per unit bias: 3-D and horizontal shift of each station
    undetermined = ~cov.determined
    for lo in range(0, q, _CHUNK):
        rows = slice(3 * lo, 3 * min(lo + _CHUNK, q))
        obs = slice(lo, min(lo + _CHUNK, q))
        dc = np.asarray(d[rows] @ cov.full)  # (3 c, 6 s): D_i C
        dcd = np.sum(dc * d[rows].toarray(), axis=1).reshape(-1, 3)
        r = np.clip(1.0 - w[obs, None] * (dcd + 1.0 / w_site[obs, None]), 0.0, 1.0)
        redundancy[obs] = r
        move = dc.reshape(-1, 3, s, 6)[..., :3] * w[obs, None, None, None]  # per unit bias
        shift[0, obs] = np.linalg.norm(move, axis=3)
        shift[1, obs] = np.linalg.norm(move[..., :2], axis=3)
    controlled = redundancy > MIN_REDUNDANCY
    mdb[:] = np.where(controlled, delta0 / np.sqrt(w[:, None] * np.where(controlled, redundancy,
                                                                         1.0)), np.inf)
    scale = np.where(controlled, mdb, 0.0)[None, :, :, None]
    moves = shift > _NO_SHIFT
    effect = np.where(controlled[None, :, :, None], shift * scale,
                      np.where(moves, np.inf, 0.0))  # (2, q, 3, s)
    effect[..., undetermined] = np.inf
    per_obs = effect.max(axis=2)  # (2, q, s): worst component
    effect_station = np.where(per_obs[0].max(axis=1, initial=0.0) > 0,
                              np.argmax(per_obs[0], axis=1) if q else 0, -1)
    station_effect = per_obs.max(axis=1, initial=0.0)  # (2, s)
    cause = np.where(station_effect > 0, np.argmax(per_obs, axis=1) if q else 0, -1)
    cause[:, undetermined] = -1  # no observation is to blame: the layout leaves it loose
    _, prior_r = net.aids.redundancy(cov.full[np.ix_(net.free, net.free)], net.free)
    observed = np.unique(net.pair_site[pairs])
    n_markers = int(observed.size - np.count_nonzero(net.control[observed]))
    return LayoutReliability(
        pair=pairs, station=net.pair_station[pairs], site=net.pair_site[pairs],
        redundancy=redundancy, mdb_m=mdb, effect_m=per_obs[0].max(axis=1, initial=0.0),
        effect_horizontal_m=per_obs[1].max(axis=1, initial=0.0),
        effect_station=effect_station, station_effect_m=station_effect[0],
        station_effect_horizontal_m=station_effect[1], station_cause=cause[0],
        station_cause_horizontal=cause[1], prior_redundancy=prior_r,
        dof=int(3 * q + prior_r.size - 3 * n_markers - net.n_params), delta0=delta0)


#: Columns of a network plan's ``reliability.csv`` (:func:`reliability_rows`), one row per
#: planned observation (station, site).
RELIABILITY_COLUMNS = (
    "station", "site", "redundancy_x", "redundancy_y", "redundancy_z", "controlled",
    "mdb_x_m", "mdb_y_m", "mdb_z_m", "effect_m", "effect_horizontal_m", "effect_station")


def _finite_or_none(value: float) -> float | None:
    return float(value) if np.isfinite(value) else None


def reliability_rows(net, rel: LayoutReliability) -> list[dict]:
    """One row per observation of :data:`RELIABILITY_COLUMNS`: ids, redundancy per axis,
    ``controlled`` (every axis ``r > 0``), MDB per axis (``None``: uncontrolled, infinite), the
    largest station shift (3-D, horizontal; ``None``: infinite) and the station it moves most
    (``None`` when none moves).
    """
    p = net.problem
    out = []
    for i in range(rel.pair.size):
        k = int(rel.effect_station[i])
        out.append({"station": p.station_ids[rel.station[i]], "site": p.site_ids[rel.site[i]],
                    **{f"redundancy_{a}": float(rel.redundancy[i, c])
                       for c, a in enumerate("xyz")},
                    "controlled": bool(rel.controlled[i].all()),
                    **{f"mdb_{a}_m": _finite_or_none(rel.mdb_m[i, c])
                       for c, a in enumerate("xyz")},
                    "effect_m": _finite_or_none(rel.effect_m[i]),
                    "effect_horizontal_m": _finite_or_none(rel.effect_horizontal_m[i]),
                    "effect_station": p.station_ids[k] if k >= 0 else None})
    return out


def station_bias_record(net, rel: LayoutReliability) -> dict[str, dict]:
    """Per station id: its largest MDB effect (``bias_effect_m``, horizontal
    ``bias_effect_horizontal_m``; ``None`` when infinite) and the observation causing each
    (``{"station": id, "site": id}`` or ``None``)."""
    p = net.problem

    def cause(i: int) -> dict | None:
        return None if i < 0 else {"station": p.station_ids[rel.station[i]],
                                   "site": p.site_ids[rel.site[i]]}

    return {p.station_ids[k]: {
        "bias_effect_m": _finite_or_none(rel.station_effect_m[k]),
        "bias_effect_caused_by": cause(int(rel.station_cause[k])),
        "bias_effect_horizontal_m": _finite_or_none(rel.station_effect_horizontal_m[k]),
        "bias_effect_horizontal_caused_by": cause(int(rel.station_cause_horizontal[k]))}
        for k in range(p.n_stations)}
