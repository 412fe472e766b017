"""Per-station checks of a layout, exact (no integer program): what the planner, the baselines
and the reduction studies all ask of a station.

- :class:`StationInfo`: one station's usable sites, the information each contributes
  (:func:`planner.accuracy.known_control.pair_information`) and the predicted error of any subset
  (:func:`planner.accuracy.known_control.errors_from_information`), with the outer-approximation
  tangents (:func:`planner.accuracy.known_control.linearisation`) and failing-set growth the
  accuracy cuts use;
- :func:`diagnose`: stations no layout can satisfy, and why (:func:`nothing_in_range` for a
  station with no site in range);
- :func:`evaluate_layout`: count, directions (:func:`planner.problem.usability.direction_status`)
and
  predicted error of a layout at every station -> :class:`LayoutCheck`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from planner.accuracy import known_control
from planner.accuracy.figure import error_figure
from planner.problem.usability import (
    OCCLUDED,
    OUT_OF_DOMAIN,
    TOO_INACCURATE,
    PlanProblem,
    direction_status,
    sector_index,
)


class StationInfo:
    """Cached usable sites of one station and the information each contributes.

    Parameters
    ----------
    problem : PlanProblem
    s : int
        Station index.
    config : PlanConfig
        Uses ``working_radius_m``, ``inclinometer_sigma_rad`` and ``error_figure``.

    Attributes
    ----------
    pairs : (u,) int
        The station's usable pairs, ordered by site index.
    sites : (u,) int
        Their candidate-site indices.
    sigma_m : (u,) float
        Error-model 1-sigma 3D centre error of each, m.
    info : (u, 4, 4) float
        Pose information each site contributes
        (:func:`planner.accuracy.known_control.pair_information`), computed on first use (checking a
        layout needs only its markers' information).
    radius : float
        Working radius, m.
    incl : float
        Inclinometer 1-sigma, rad.
    figure : planner.accuracy.figure.ErrorFigure
        The 95 % figure the station is judged by.
    """

    def __init__(self, problem: PlanProblem, s: int, config) -> None:
        idx = problem.usable_pairs(s)
        self.pairs = idx
        self.sites = problem.pair_site[idx]
        self.sigma_m = problem.pair_sigma_m[idx]
        self.station_xyz = problem.station_xyz[s]
        self.site_xyz = problem.site_xyz[self.sites]
        self.radius = config.working_radius_m
        self.incl = config.inclinometer_sigma_rad
        self.figure = error_figure(config)

    @cached_property
    def info(self) -> np.ndarray:
        return self._information(np.arange(self.sites.size))

    def _information(self, k: np.ndarray) -> np.ndarray:
        """(len(k), 4, 4) float: information of the sites in rows ``k`` (per site the same
        numbers as ``info[k]``)."""
        if not k.size:
            return np.zeros((0, 4, 4))
        return known_control.pair_information(self.station_xyz, self.site_xyz[k], self.sigma_m[k])

    def rows(self, sites) -> np.ndarray:
        """Rows in ``sites`` of the usable ones among some candidate-site indices (int)."""
        sites = np.atleast_1d(np.asarray(sites, np.int64))
        k = np.minimum(np.searchsorted(self.sites, sites), max(self.sites.size - 1, 0))
        return k[self.sites[k] == sites] if self.sites.size else k[:0]

    def error(self, sites) -> float:
        """Predicted error using the usable ones among ``sites`` (candidate-site indices), m."""
        k = self.rows(sites)
        if not k.size:
            return float("inf")
        j = self._information(k).sum(axis=0)
        return float(self.errors(j[None])[0])

    def errors(self, j: np.ndarray) -> np.ndarray:
        """(k,) predicted error of the station for pose information matrices ``j`` (k, 4, 4),
        m (:func:`planner.accuracy.known_control.errors_from_information`)."""
        return known_control.errors_from_information(j, self.radius, self.incl, self.figure)

    def within(self, j: np.ndarray, requirement_m: float) -> np.ndarray:
        """(k,) bool: the station meets ``requirement_m`` with each information matrix ``j``
        (k, 4, 4) (:func:`planner.accuracy.known_control.within_from_information`)."""
        return known_control.within_from_information(j, self.radius, self.incl, self.figure,
                                                     requirement_m)

    def oa_cuts(self, sites, requirement_m: float, exclude: int | None = None,
                scale: float = 1.0, rim: str = "worst") -> list:
        """Outer-approximation cuts linearised at ``scale`` x the information of ``sites``
        (:func:`planner.accuracy.known_control.linearisation`), as ``(sites, coefficients, rhs)``
        with the cut ``sum coef * x >= rhs``; only cuts with a positive right-hand side. ``exclude``
        gets no coefficient (the cut then holds for the others alone)."""
        k = self.rows(sites)
        if not k.size:
            return []
        keep = np.ones(self.sites.size, bool)
        if exclude is not None:
            keep[self.rows(exclude)] = False
        out = []
        for v, rhs in known_control.linearisation(scale * self.info[k].sum(axis=0), self.radius,
                                                  self.incl, requirement_m, self.figure, rim):
            if rhs > 0:
                coef = np.einsum("a,kab,b->k", v, self.info[keep], v)
                out.append((self.sites[keep], coef / rhs, 1.0))
        return out

    def grow_failing(self, failing, exclude: int | None, requirement_m: float,
                     max_skips: int = 25) -> np.ndarray:
        """Grow a failing site set, least informative sites first, while it keeps failing.

        Monotonicity makes "the set plus the next ``m`` sites in order still fails" monotone in
        ``m``, so each run of additions is found by bisection; a site whose addition would make
        the station pass is skipped (at most ``max_skips`` times). ``exclude`` is never added.
        Returns candidate-site indices of the grown (still failing) set.
        """
        in_set = np.zeros(self.sites.size, bool)
        in_set[self.rows(failing)] = True
        order = np.argsort(1.0 / self.sigma_m**2, kind="stable")
        skip = in_set.copy()
        if exclude is not None:
            skip[self.rows(exclude)] = True
        order = order[~skip[order]]
        total = self.info[in_set].sum(axis=0)
        cum = np.concatenate([np.zeros((1, 4, 4)), np.cumsum(self.info[order], axis=0)])

        def fails(a: int, b: int) -> bool:
            trial = total + cum[b] - cum[a]
            return not self.within(trial[None], requirement_m)[0]

        pos, skips = 0, 0
        while pos < order.size and skips <= max_skips:
            lo, hi = 0, order.size - pos  # largest m with fails(pos, pos + m)
            while lo < hi:
                mid = (lo + hi + 1) // 2
                if fails(pos, pos + mid):
                    lo = mid
                else:
                    hi = mid - 1
            in_set[order[pos:pos + lo]] = True
            total = total + cum[pos + lo] - cum[pos]
            pos += lo + 1
            skips += 1
        return self.sites[in_set]


def station_infos(problem: PlanProblem, config) -> list[StationInfo]:
    """:class:`StationInfo` of every station (cache it across repeated checks)."""
    return [StationInfo(problem, s, config) for s in range(problem.n_stations)]


def diagnose(problem: PlanProblem, config, infos: list[StationInfo] | None = None,
             accuracy_check: bool = True) -> dict[str, str]:
    """Stations that no layout can satisfy, with the reason (empty dict: none found).

    Checks, per station and with every allowed usable site selected: any site in range, any
    unoccluded, enough usable sites, enough sectors, accuracy reachable (and, in redundant mode,
    reachable after losing any one site). ``accuracy_check=False`` leaves out the two accuracy
    checks (network mode judges accuracy with
    :func:`planner.accuracy.network_diagnosis.diagnose_network`).
    """
    infos = infos or station_infos(problem, config)
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    allowed = ~forbidden
    min_count = config.min_markers + (1 if config.redundant else 0)
    out = {}
    for s in range(problem.n_stations):
        sid = problem.station_ids[s]
        pairs = np.flatnonzero(problem.pair_station == s)
        pairs = pairs[allowed[problem.pair_site[pairs]]]
        if pairs.size == 0:
            out[sid] = nothing_in_range(problem, s, allowed, config.max_range_m)
            continue
        reason = problem.pair_reason[pairs]
        idx = pairs[reason == 0]
        if idx.size == 0:
            if np.all(reason == OCCLUDED):
                out[sid] = f"all {pairs.size} sites in range are occluded"
            else:
                out[sid] = (f"no usable site: {np.sum(reason == OCCLUDED)} occluded, "
                            f"{np.sum(reason == OUT_OF_DOMAIN)} outside the error model's "
                            f"domain, {np.sum(reason == TOO_INACCURATE)} with 95 % centre error "
                            f"above {config.requirement_m:g} m")
            continue
        sites = problem.pair_site[idx]
        sel = np.zeros(problem.n_sites, bool)
        sel[sites] = True
        count, sectors = direction_status(problem, sel, config.n_sectors)
        if count[s] < min_count:
            out[sid] = f"too few usable sites: {count[s]} (needs {min_count})"
            continue
        if sectors[s] < config.min_sectors:
            out[sid] = (f"too few directions: usable sites in {sectors[s]} of "
                        f"{config.n_sectors} sectors (needs {config.min_sectors})")
            continue
        if config.redundant:
            per = np.bincount(sector_index(problem.pair_bearing_rad[idx], config.n_sectors),
                              minlength=config.n_sectors)
            left = int((per > 0).sum()) - int(np.any(per == 1))
            if left < config.min_sectors:
                out[sid] = (f"too few directions after losing one marker: the usable sites "
                            f"leave {left} of {config.n_sectors} sectors (needs "
                            f"{config.min_sectors})")
                continue
        if not accuracy_check:
            continue
        err = infos[s].error(sites)
        if err > config.requirement_m:
            out[sid] = (f"accuracy unreachable: all {sites.size} usable sites give "
                        f"{err:.3f} m > {config.requirement_m:g} m")
            continue
        if config.redundant:
            worst = max(infos[s].error(np.delete(sites, i)) for i in range(sites.size))
            if worst > config.requirement_m:
                out[sid] = (f"accuracy unreachable after losing one marker: {worst:.3f} m > "
                            f"{config.requirement_m:g} m")
    return out


def nothing_in_range(problem: PlanProblem, s: int, allowed: np.ndarray, range_m: float) -> str:
    """Why station ``s`` has no pair with an allowed candidate site: where the nearest lies.

    A station whose every site within ``range_m`` across lies more than ``range_m`` above (or
    below) its LiDAR centre stands in a pit or below the terrain (on a spike or above it).

    Parameters
    ----------
    problem : PlanProblem
    s : int
        Station index.
    allowed : (n,) bool
        Candidate sites a marker may take.
    range_m : float
        LiDAR range, m (3D, as pairs are made).

    Returns
    -------
    reason : str
        One clause, e.g. ``"no candidate site within 30 m: ... the nearest, C00012, is 44.5 m
        away"``.
    """
    head = f"no candidate site within {range_m:g} m"
    sites = np.flatnonzero(allowed)
    if not sites.size:
        return f"{head}: none is allowed"
    offset = problem.site_xyz[sites] - problem.station_xyz[s]
    across = np.hypot(offset[:, 0], offset[:, 1])
    rise = offset[:, 2]
    near = across <= range_m
    z = problem.station_xyz[s, 2]
    if near.any() and np.all(np.abs(rise[near]) > range_m):
        gap = float(np.min(np.abs(rise[near])))
        if np.all(rise[near] > 0):
            return (f"{head}: its LiDAR centre (z {z:.2f} m) lies at least {gap:.1f} m below "
                    f"the {near.sum()} candidate sites within {range_m:g} m across, so it stands "
                    "in a pit of the DEM or below the terrain; check the DEM there and the "
                    "station's height")
        if np.all(rise[near] < 0):
            return (f"{head}: its LiDAR centre (z {z:.2f} m) lies at least {gap:.1f} m above "
                    f"the {near.sum()} candidate sites within {range_m:g} m across, so it stands "
                    "on a spike of the DEM or far above the terrain; check the DEM there and the "
                    "station's height")
    distance = np.hypot(across, rise)
    if np.any(distance <= range_m):  # pairs from a visibility table that lists none for it
        return (f"no pair with any of the {np.sum(distance <= range_m)} candidate sites within "
                f"{range_m:g} m: the visibility lists none for this station; give its pairs")
    k = int(np.argmin(distance))
    return (f"{head}: the nearest, {problem.site_ids[sites[k]]}, is {distance[k]:.1f} m away "
            f"({across[k]:.1f} m across, {rise[k]:+.1f} m up); move the station nearer the "
            "candidate sites or let markers go nearer it")


@dataclass(frozen=True)
class LayoutCheck:
    """Whether a marker layout meets the requirement at every station.

    Attributes
    ----------
    count, sectors : (s,) int
        Usable selected markers and occupied sectors per station.
    error_m : (s,) float
        Predicted error per station, m.
    worst_loss_error_m : (s,) float or None
        Redundant mode: worst predicted error after losing any one of the station's markers.
    worst_loss_sectors : (s,) int or None
        Redundant mode: fewest occupied sectors after losing any one marker.
    ok : (s,) bool
    marker_error_m : (n,) float or None
        Network mode: predicted 95 % error of each selected marker relative to the datum
        (nan where no marker is selected), m.
    markers_ok : bool
        Network mode: every selected marker meets the requirement (always True otherwise).
    bias_effect_m : (s,) float or None
        Network mode with ``max_bias_effect_m``: each station's largest position shift by an
        undetected bias of one observation of minimal detectable size
        (:func:`planner.accuracy.reliability.layout_reliability`), m; ``ok`` requires it
        ``<= max_bias_effect_m``.
    pair_error_m : (p,) float or None
        Network mode with a local requirement: the 95 % relative error of each station pair
        it judges (:class:`planner.accuracy.local.LocalAccuracy`; ``None`` for a verdict
        only), m; in redundant mode the worst with the layout and after each single loss.
    pairs_ok : bool
        Every judged station pair meets the local requirement (always True without one).
    marker_pair_error_m : (q,) float or None
        With ``local_markers``: the 95 % relative error of each judged pair of selected
        markers (:meth:`planner.accuracy.local_markers.LocalMarkerAccuracy.pairs` order), m;
        in redundant mode the worst with the layout and after each single loss of a third
        marker (a pair one of whose markers is lost no longer exists).
    marker_pairs_ok : bool
        Every judged marker pair meets the local requirement (always True without
        ``local_markers``).
    """

    count: np.ndarray
    sectors: np.ndarray
    error_m: np.ndarray
    worst_loss_error_m: np.ndarray | None
    worst_loss_sectors: np.ndarray | None
    ok: np.ndarray
    marker_error_m: np.ndarray | None = None
    markers_ok: bool = True
    bias_effect_m: np.ndarray | None = None
    pair_error_m: np.ndarray | None = None
    pairs_ok: bool = True
    marker_pair_error_m: np.ndarray | None = None
    marker_pairs_ok: bool = True

    @property
    def all_ok(self) -> bool:
        return bool(self.ok.all()) and self.markers_ok and self.pairs_ok \
            and self.marker_pairs_ok


def evaluate_layout(problem: PlanProblem, selected: np.ndarray, config,
                    infos: list[StationInfo] | None = None, net=None,
                    verdict_only: bool = False) -> LayoutCheck:
    """Check directions and predicted accuracy of a layout at every station.

    Parameters
    ----------
    problem : PlanProblem
    selected : (n,) bool
        Candidate sites holding a marker.
    config : PlanConfig
        In redundant mode the layout must also survive the loss of any one marker; in network
        mode (``config.network``) the accuracy of every station and selected marker is the
        network's (:mod:`planner.accuracy.network`), and with ``max_bias_effect_m`` every
        station's largest MDB effect must stay within it.
    infos : list of StationInfo, optional
        Cache from :func:`station_infos`.
    net : planner.accuracy.network.NetworkModel, optional
        Network mode: cache from :func:`planner.accuracy.network.network_model`.
    verdict_only : bool
        Decide ``ok`` without computing the stations' figures where their bracket decides it
        (:meth:`~planner.accuracy.figure.ErrorFigure.station_within`); ``error_m`` (and
        ``marker_error_m``) is then NaN. Not with the redundant rule.
    """
    selected = np.asarray(selected, dtype=bool)
    if verdict_only and config.redundant:
        raise ValueError("verdict_only does not apply to the redundant rule")
    if config.network:
        return _evaluate_network(problem, selected, config, net, verdict_only)
    infos = infos or station_infos(problem, config)
    count, sectors = direction_status(problem, selected, config.n_sectors)
    ok = (count >= config.min_markers) & (sectors >= config.min_sectors)
    if verdict_only:
        err = np.full(problem.n_stations, np.nan)
        for s in np.flatnonzero(ok):
            j = infos[s].info[selected[infos[s].sites]].sum(axis=0)
            ok[s] = infos[s].within(j[None], config.requirement_m)[0]
        return LayoutCheck(count=count, sectors=sectors, error_m=err, worst_loss_error_m=None,
                           worst_loss_sectors=None, ok=ok)
    err = np.array([infos[s].error(infos[s].sites[selected[infos[s].sites]])
                    for s in range(problem.n_stations)])
    ok &= err <= config.requirement_m
    worst_err = worst_sec = None
    if config.redundant:
        worst_err = err.copy()
        for s in range(problem.n_stations):
            info = infos[s]
            chosen = info.sites[selected[info.sites]]
            if chosen.size:
                parts = info.info[selected[info.sites]]
                without = parts.sum(axis=0)[None] - parts  # J after losing each marker
                worst_err[s] = max(worst_err[s], float(info.errors(without).max()))
        worst_sec = _worst_loss_sectors(problem, selected, config, sectors)
        ok &= _survives_loss(count, worst_sec, worst_err, config, config.requirement_m)
    return LayoutCheck(count=count, sectors=sectors, error_m=err, worst_loss_error_m=worst_err,
                       worst_loss_sectors=worst_sec, ok=ok)


def _worst_loss_sectors(problem: PlanProblem, selected: np.ndarray, config,
                        sectors: np.ndarray) -> np.ndarray:
    """(s,) int: fewest occupied sectors of each station after losing any one selected marker
    (``sectors``, the occupied sectors of the whole layout, where a station has none)."""
    worst = sectors.copy()
    for s in range(problem.n_stations):
        sel_pairs = problem.selected_pairs(s, selected)
        if sel_pairs.size:
            sec = sector_index(problem.pair_bearing_rad[sel_pairs], config.n_sectors)
            per = np.bincount(sec, minlength=config.n_sectors)
            worst[s] = int((per > 0).sum()) - int(np.any(per == 1))
    return worst


def _survives_loss(count: np.ndarray, worst_sectors: np.ndarray, worst_error_m: np.ndarray,
                   config, allowed_m) -> np.ndarray:
    """(s,) bool: the redundant-mode rule, given each station's marker count, fewest sectors
    and worst error after losing any one marker, and its allowed error ``allowed_m`` (scalar
    or (s,), m)."""
    return (count >= config.min_markers + 1) & (worst_sectors >= config.min_sectors) \
        & (worst_error_m <= allowed_m)


def _evaluate_network(problem: PlanProblem, selected: np.ndarray, config, net,
                      verdict_only: bool = False) -> LayoutCheck:
    """:func:`evaluate_layout` in network mode (directions as always, accuracy of the whole
    network: every station and every selected marker relative to the datum; redundant mode:
    every station also after losing any one marker; ``max_bias_effect_m``: every station's
    largest MDB effect)."""
    from planner.accuracy.local import local_accuracy
    from planner.accuracy.local_markers import local_marker_accuracy
    from planner.accuracy.network import network_model
    from planner.accuracy.requirement import NetworkRequirement

    net = net or network_model(problem, config)
    allowed, allowed_site = net.allowances(NetworkRequirement.of(config))
    count, sectors = direction_status(problem, selected, config.n_sectors)
    j = net.information(selected)
    cov = net.covariance(j)
    markers = np.flatnonzero(selected)
    merr = np.full(problem.n_sites, np.nan)
    if verdict_only:
        err = np.full(problem.n_stations, np.nan)
        within = net.stations_within(cov, allowed)
        markers_ok = bool(np.all(net.markers_within(cov, markers, allowed_site[markers])))
    else:
        err = net.station_errors_from(cov)
        within = ~net.stations_failing(err, allowed)
        merr[markers] = net.marker_errors(cov, markers)
        markers_ok = bool(np.all(merr[markers] <= allowed_site[markers]))
    ok = (count >= config.min_markers) & (sectors >= config.min_sectors) & within
    worst_err = worst_sec = None
    lost, loss_covs = np.zeros(0, np.int64), []
    if config.redundant:
        lost, loss, loss_covs = net.loss_station_errors(selected, j)
        worst_err = np.max(np.vstack([err[None], loss]), axis=0)
        worst_sec = _worst_loss_sectors(problem, selected, config, sectors)
        ok &= _survives_loss(count, worst_sec, worst_err, config, allowed)
    bias = None
    if config.max_bias_effect_m is not None:
        from planner.accuracy.reliability import layout_reliability

        bias = layout_reliability(net, selected).station_effect_m
        ok &= bias <= config.max_bias_effect_m
    pair_err, pairs_ok = None, True
    local = local_accuracy(net, config)
    if local is not None:
        if verdict_only:
            pairs_ok = bool(local.within(cov).all())
        else:
            pair_err = np.max([local.errors(c) for c in [cov, *loss_covs]], axis=0)
            pairs_ok = bool(np.all(pair_err <= local.pairs.allowed_m))
    marker_pair_err, marker_pairs_ok = None, True
    local_markers = local_marker_accuracy(net, config)
    if local_markers is not None:
        marker_pairs = local_markers.pairs(selected)
        marker_pair_err = local_markers.errors(cov, marker_pairs)
        for m, c in zip(lost, loss_covs, strict=True):  # redundant: pairs the loss leaves
            left = (marker_pairs.first != m) & (marker_pairs.second != m)
            marker_pair_err = np.where(left, np.maximum(
                marker_pair_err, local_markers.errors(c, marker_pairs)), marker_pair_err)
        marker_pairs_ok = bool(np.all(marker_pair_err <= marker_pairs.allowed_m))
    return LayoutCheck(count=count, sectors=sectors, error_m=err, worst_loss_error_m=worst_err,
                       worst_loss_sectors=worst_sec, ok=ok, marker_error_m=merr,
                       markers_ok=markers_ok, bias_effect_m=bias, pair_error_m=pair_err,
                       pairs_ok=pairs_ok, marker_pair_error_m=marker_pair_err,
                       marker_pairs_ok=marker_pairs_ok)
