"""Which station-site pairs a plan may count on, and the direction (sector) check.

:class:`PlanProblem` is the plain-data input of the integer program: stations, candidate sites,
and the sparse list of station-site pairs with bearing, error-model sigma and a usability verdict.
It looks site ids up (:meth:`PlanProblem.site_mask`) and gives the sub-problem of some sites
(:meth:`PlanProblem.restrict`). :func:`problem_from_visibility` judges every pair of a visibility
matrix with an error model; :func:`direction_status` counts a layout's markers and sectors.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from markerplan.errors import ConfigError

#: Reason codes of ``PlanProblem.pair_reason`` (index -> text).
REASONS = ("usable", "occluded", "outside the error model's domain",
           "error-model 95 % error above the requirement")
USABLE, OCCLUDED, OUT_OF_DOMAIN, TOO_INACCURATE = range(4)


@dataclass(frozen=True)
class PlanProblem:
    """Stations, candidate sites and the sparse station x site pairs (site frame, metres).

    Attributes
    ----------
    station_ids : tuple of str, (s,)
    station_xyz : (s, 3) float
        LiDAR centres, site frame, m.
    site_ids : tuple of str, (n,)
    site_xyz : (n, 3) float
        Marker centres at each candidate site, site frame, m.
    site_existing : (n,) bool
        Markers already in the field (fixed to 1 in the plan).
    site_cost : (n,) float
        Objective weight of each site (1 = count markers; existing markers cost 0).
    pair_station, pair_site : (p,) int
        Indices of each pair.
    pair_distance_m, pair_bearing_rad, pair_sigma_m : (p,) float
        3D distance, bearing of the site from the station (site frame, counter-clockwise from
        +x), error-model 1-sigma 3D centre error.
    pair_reason : (p,) int
        Index into :data:`REASONS`; 0 means usable.
    pair_detection_p : (p,) float or None
        Probability that each pair's marker is detected and accepted when it is there (the
        detection model's, times the chance that the terrain lets the station see it); ``None``:
        not known, every planned marker counted as detected (:attr:`detection_p` gives ones).
    site_control_sigma_m : (n,) float or None
        Network mode's control points (a lander's fiducials, sites with known coordinates,
        always in the layout: existing in a plan, kept in a reduction study): the 1-sigma of
        each coordinate, m; 0 for every other site. ``None``: no control point
        (:attr:`site_control` gives all False).
    """

    station_ids: tuple[str, ...]
    station_xyz: np.ndarray
    site_ids: tuple[str, ...]
    site_xyz: np.ndarray
    site_existing: np.ndarray
    site_cost: np.ndarray
    pair_station: np.ndarray
    pair_site: np.ndarray
    pair_distance_m: np.ndarray
    pair_bearing_rad: np.ndarray
    pair_sigma_m: np.ndarray
    pair_reason: np.ndarray
    pair_detection_p: np.ndarray | None = None
    site_control_sigma_m: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        _problem_iv(self)

    @property
    def n_stations(self) -> int:
        return len(self.station_ids)

    @property
    def n_sites(self) -> int:
        return len(self.site_ids)

    @property
    def site_control(self) -> np.ndarray:
        """(n,) bool: the control points among the sites."""
        if self.site_control_sigma_m is None:
            return np.zeros(self.n_sites, bool)
        return self.site_control_sigma_m > 0

    @property
    def pair_usable(self) -> np.ndarray:
        return self.pair_reason == USABLE

    @property
    def detection_p(self) -> np.ndarray:
        """(p,) float: :attr:`pair_detection_p`, or ones when it is not known."""
        if self.pair_detection_p is None:
            return np.ones(len(self.pair_station))
        return self.pair_detection_p

    def usable_pairs(self, station: int) -> np.ndarray:
        """Indices of the usable pairs of station ``station`` (ordered by site index)."""
        idx, start = self._usable_by_station
        return idx[start[station]:start[station + 1]].copy()

    @cached_property
    def _usable_by_station(self) -> tuple[np.ndarray, np.ndarray]:
        """Usable pairs sorted by station, then site (sorted once: planners ask per station),
        and where each station's run starts ((s + 1,) int)."""
        idx = np.flatnonzero(self.pair_usable)
        idx = idx[np.lexsort((self.pair_site[idx], self.pair_station[idx]))]
        return idx, np.searchsorted(self.pair_station[idx], np.arange(self.n_stations + 1))

    def selected_pairs(self, station: int, selected: np.ndarray) -> np.ndarray:
        """Indices of the usable pairs of ``station`` whose site is ``selected`` ((n_sites,)
        bool), ordered by site index: the markers of a layout the station uses."""
        idx = self.usable_pairs(station)
        return idx[selected[self.pair_site[idx]]]

    def site_mask(self, ids, name: str) -> np.ndarray:
        """(n,) bool: the candidate sites named by ``ids``.

        Parameters
        ----------
        ids : iterable of str
            Site ids (e.g. ``config.existing``).
        name : str
            How error messages name the list (``"existing"``, ``"forbidden"``).

        Raises
        ------
        ConfigError
            An id that names no candidate site.
        """
        ids = list(ids)
        mask = np.zeros(self.n_sites, dtype=bool)
        if not ids:
            return mask
        pos = {sid: i for i, sid in enumerate(self.site_ids)}
        unknown = [i for i in ids if i not in pos]
        if unknown:
            raise ConfigError(f"`{name}` names unknown site id(s) {', '.join(unknown[:5])}; "
                              "use ids from the candidate sites or the marker layout")
        mask[[pos[i] for i in ids]] = True
        return mask

    def restrict(self, sites: np.ndarray) -> PlanProblem:
        """The problem with only the candidate sites in ``sites`` (their pairs kept, re-indexed).

        Parameters
        ----------
        sites : (n,) bool
            Candidate sites to keep.

        Returns
        -------
        sub : PlanProblem
            Same stations; the kept sites in their original order.
        """
        keep = np.asarray(sites, dtype=bool)
        if keep.shape != (self.n_sites,):
            raise ConfigError(f"`sites` must have shape ({self.n_sites},), got {keep.shape}")
        idx = np.flatnonzero(keep)
        new = np.full(self.n_sites, -1, dtype=np.int64)
        new[idx] = np.arange(idx.size)
        pairs = keep[self.pair_site]
        return replace(self, site_ids=tuple(self.site_ids[j] for j in idx),
                       site_xyz=self.site_xyz[idx], site_existing=self.site_existing[idx],
                       site_cost=self.site_cost[idx], pair_station=self.pair_station[pairs],
                       pair_site=new[self.pair_site[pairs]],
                       pair_distance_m=self.pair_distance_m[pairs],
                       pair_bearing_rad=self.pair_bearing_rad[pairs],
                       pair_sigma_m=self.pair_sigma_m[pairs],
                       pair_reason=self.pair_reason[pairs],
                       pair_detection_p=None if self.pair_detection_p is None
                       else self.pair_detection_p[pairs],
                       site_control_sigma_m=None if self.site_control_sigma_m is None
                       else self.site_control_sigma_m[idx])

    def restrict_stations(self, stations) -> PlanProblem:
        """The problem with only some of its stations (their pairs kept, re-indexed).

        Parameters
        ----------
        stations : (k,) int
            Indices of the stations to keep, in the order the sub-problem lists them.

        Returns
        -------
        sub : PlanProblem
            The kept stations in the given order; every site kept.
        """
        order = np.asarray(stations, dtype=np.int64).ravel()
        if order.size and (order.min() < 0 or order.max() >= self.n_stations
                           or np.unique(order).size != order.size):
            raise ConfigError(f"`stations` must be distinct indices below {self.n_stations}")
        new = np.full(self.n_stations, -1, dtype=np.int64)
        new[order] = np.arange(order.size)
        pairs = np.flatnonzero(new[self.pair_station] >= 0)
        pairs = pairs[np.argsort(new[self.pair_station[pairs]], kind="stable")]
        return replace(self, station_ids=tuple(self.station_ids[s] for s in order),
                       station_xyz=self.station_xyz[order],
                       pair_station=new[self.pair_station[pairs]],
                       pair_site=self.pair_site[pairs],
                       pair_distance_m=self.pair_distance_m[pairs],
                       pair_bearing_rad=self.pair_bearing_rad[pairs],
                       pair_sigma_m=self.pair_sigma_m[pairs],
                       pair_reason=self.pair_reason[pairs],
                       pair_detection_p=None if self.pair_detection_p is None
                       else self.pair_detection_p[pairs])


def _problem_iv(p: PlanProblem) -> None:
    s, n = len(p.station_ids), len(p.site_ids)
    checks = [("station_xyz", p.station_xyz, (s, 3)), ("site_xyz", p.site_xyz, (n, 3)),
              ("site_existing", p.site_existing, (n,)), ("site_cost", p.site_cost, (n,))]
    npair = np.shape(p.pair_station)
    for name in ("pair_site", "pair_distance_m", "pair_bearing_rad", "pair_sigma_m",
                 "pair_reason"):
        checks.append((name, getattr(p, name), npair))
    if p.pair_detection_p is not None:
        checks.append(("pair_detection_p", p.pair_detection_p, npair))
    if p.site_control_sigma_m is not None:
        checks.append(("site_control_sigma_m", p.site_control_sigma_m, (n,)))
    for name, arr, shape in checks:
        if np.shape(arr) != shape:
            raise ConfigError(f"PlanProblem `{name}` must have shape {shape}, got {np.shape(arr)}")
    if p.pair_detection_p is not None and not np.all((p.pair_detection_p >= 0)
                                                     & (p.pair_detection_p <= 1)):
        raise ConfigError("PlanProblem `pair_detection_p` must hold probabilities in [0, 1]")
    if p.site_control_sigma_m is not None and not np.all(
            np.isfinite(p.site_control_sigma_m) & (p.site_control_sigma_m >= 0)):
        raise ConfigError("PlanProblem `site_control_sigma_m` must be finite and >= 0")
    if len(set(p.station_ids)) != s:
        raise ConfigError("PlanProblem `station_ids` must be unique")
    if len(set(p.site_ids)) != n:
        raise ConfigError("PlanProblem `site_ids` must be unique")
    if npair[0] and (p.pair_station.min() < 0 or p.pair_station.max() >= s
                     or p.pair_site.min() < 0 or p.pair_site.max() >= n):
        raise ConfigError("PlanProblem pair indices out of range")


def sector_index(bearing_rad, n_sectors: int) -> np.ndarray:
    """Sector (0 .. n_sectors-1) of bearings: sector k spans [k, k+1) * 2 pi / n_sectors.

    Examples
    --------
    >>> sector_index([0.0, 1.1, -0.1], 6).tolist()
    [0, 1, 5]
    """
    b = np.mod(np.asarray(bearing_rad, dtype=float), 2.0 * np.pi)
    return np.minimum((b / (2.0 * np.pi / n_sectors)).astype(np.int64), n_sectors - 1)


def problem_from_visibility(vis, model, config, station_ids, station_xyz, site_ids, site_xyz,
                            site_existing=None, site_cost=None) -> PlanProblem:
    """Judge every pair of a visibility matrix and return the integer program's input.

    A pair is usable when its visible fraction is at least ``config.min_visible_fraction``, it
    lies inside the error model's domain (unless ``config.allow_out_of_domain``) and the model's
    95 % centre error is within ``config.requirement_m``.

    Parameters
    ----------
    vis : visibility.visibility_matrix.VisibilityMatrix
        Sparse pairs with distance, elevation, bearing, visible fraction, expected points.
    model : error_model ErrorModel
        ``model.predict(distance_m, elevation_rad, **extra)`` -> ``sigma_m, q95_m, in_domain``.
    config : PlanConfig
    station_ids, station_xyz, site_ids, site_xyz
        As in :class:`PlanProblem`.
    site_existing : (n,) bool, optional
    site_cost : (n,) float, optional
        Default 1 for new sites, 0 for existing ones.
    """
    n = len(site_ids)
    existing = np.zeros(n, bool) if site_existing is None else np.asarray(site_existing, bool)
    cost = np.where(existing, 0.0, 1.0) if site_cost is None else np.asarray(site_cost, float)
    pred = model.predict(vis.distance_m, vis.elevation_rad, **_model_extras(model, vis))
    sigma = np.asarray(pred.sigma_m, dtype=float)
    q95 = np.asarray(pred.q95_m, dtype=float)
    in_domain = np.asarray(pred.in_domain, dtype=bool)
    reason = np.full(len(vis.station), USABLE, dtype=np.int8)
    reason[q95 > config.requirement_m] = TOO_INACCURATE
    if not config.allow_out_of_domain:
        reason[~in_domain] = OUT_OF_DOMAIN
    reason[vis.visible_fraction < config.min_visible_fraction] = OCCLUDED
    reason[~np.isfinite(sigma) | (sigma <= 0)] = OUT_OF_DOMAIN
    sigma = np.where(np.isfinite(sigma) & (sigma > 0), sigma, np.inf)
    return PlanProblem(
        station_ids=tuple(station_ids), station_xyz=np.asarray(station_xyz, float),
        site_ids=tuple(site_ids), site_xyz=np.asarray(site_xyz, float),
        site_existing=existing, site_cost=cost,
        pair_station=np.asarray(vis.station, np.int64), pair_site=np.asarray(vis.site, np.int64),
        pair_distance_m=np.asarray(vis.distance_m, float),
        pair_bearing_rad=np.asarray(vis.bearing_rad, float), pair_sigma_m=sigma,
        pair_reason=reason)


def _model_extras(model, vis) -> dict[str, np.ndarray]:
    """Extra predictors the model asks for that the visibility matrix provides."""
    available = {"expected_points": vis.expected_points, "n_points": vis.expected_points,
                 "point_count": vis.expected_points, "visible_fraction": vis.visible_fraction}
    extras = {}
    for name in getattr(model, "predictors", ()):
        if name in ("distance_m", "elevation_rad"):
            continue
        if name not in available:
            raise ConfigError(f"error model predictor {name!r} is not provided by the visibility "
                              f"matrix (it provides distance_m, elevation_rad, "
                              f"{', '.join(sorted(available))}); use a model fitted on those")
        extras[name] = np.asarray(available[name], float)
    return extras


def direction_status(problem: PlanProblem, selected: np.ndarray, n_sectors: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Per station: number of selected usable markers and number of occupied sectors.

    Parameters
    ----------
    problem : PlanProblem
    selected : (n,) bool
        Which candidate sites hold a marker.
    n_sectors : int

    Returns
    -------
    count : (s,) int
    sectors : (s,) int
    """
    selected = np.asarray(selected, dtype=bool)
    if selected.shape != (problem.n_sites,):
        raise ConfigError(f"`selected` must have shape ({problem.n_sites},), got {selected.shape}")
    use = problem.pair_usable & selected[problem.pair_site]
    st = problem.pair_station[use]
    count = np.bincount(st, minlength=problem.n_stations)
    sec = sector_index(problem.pair_bearing_rad[use], n_sectors)
    occupied = np.zeros((problem.n_stations, n_sectors), dtype=bool)
    occupied[st, sec] = True
    return count, occupied.sum(axis=1)


def directions_ok(problem: PlanProblem, selected: np.ndarray, config) -> np.ndarray:
    """(s,) bool: each station has >= ``min_markers`` usable selected markers in
    >= ``min_sectors`` distinct sectors."""
    count, sectors = direction_status(problem, selected, config.n_sectors)
    return (count >= config.min_markers) & (sectors >= config.min_sectors)
