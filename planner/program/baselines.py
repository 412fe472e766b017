"""Baseline layouts the integer program is compared with, on the same problem.

- :func:`greedy_cover`: repeatedly add the site that removes the most unmet requirement
  (missing markers, missing sectors, failing accuracy) over all stations.
- :func:`regular_grid`: markers on a square grid, each grid point moved to the nearest
  candidate site; the widest spacing whose layout meets the requirement at every station
  (in network mode: every station and marker, relative to the reference station).
- :func:`greedy_network`: network mode — the greedy cover's directions, then the sites that
  tie every station to the reference, then the site that most reduces the worst station's
  (or marker's) variance, until all pass.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from markerplan.errors import InfeasiblePlanError
from planner.accuracy.checks import StationInfo, evaluate_layout, station_infos
from planner.accuracy.local import local_accuracy
from planner.accuracy.local_markers import local_marker_accuracy
from planner.accuracy.requirement import NetworkRequirement
from planner.problem.usability import PlanProblem, direction_status, sector_index

#: Grid phases tried at each spacing (fraction of the spacing from the bounds' lower corner).
_PHASES = (0.5, 0.0, 0.25, 0.75)


@dataclass(frozen=True)
class Baseline:
    """A baseline layout.

    Attributes
    ----------
    name : str
    selected : (n,) bool
    meets_requirement : bool
    spacing_m : float or None
        Grid spacing (regular grid only), m.
    note : str or None
        Why the layout falls short, when its method said so (the stuck network greedy's
        :class:`GreedyStuckError` message).
    """

    name: str
    selected: np.ndarray
    meets_requirement: bool
    spacing_m: float | None = None
    note: str | None = None

    @property
    def n_markers(self) -> int:
        return int(self.selected.sum())


class _RememberingInfo(StationInfo):
    """A :class:`~planner.accuracy.checks.StationInfo` that remembers the error of each set of
    its sites it was asked about: the greedy cover checks every station after each added
    site, and only the stations that can use that site see a new set."""

    def __init__(self, problem: PlanProblem, s: int, config) -> None:
        super().__init__(problem, s, config)
        self._errors: dict[bytes, float] = {}

    def error(self, sites) -> float:
        key = np.asarray(sites, np.int64).tobytes()
        if key not in self._errors:
            self._errors[key] = super().error(sites)
        return self._errors[key]


def greedy_cover(problem: PlanProblem, config) -> Baseline:
    """Greedy cover: add one site at a time until every station meets the requirement.

    The score of a site is the sum over stations of what it fixes: one missing marker (1), one
    missing sector (1), and for a station whose directions are met but accuracy fails, the
    relative reduction of its predicted error (1 when it then passes). Ties go to the site with
    more information; existing markers start selected, forbidden sites are never used.

    Raises
    ------
    InfeasiblePlanError
        When no remaining site improves a station that still fails.
    """
    infos = [_RememberingInfo(problem, s, config) for s in range(problem.n_stations)]
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    selected = problem.site_existing | problem.site_mask(config.existing, "existing")
    min_count = config.min_markers + (1 if config.redundant else 0)
    sec = [sector_index(problem.pair_bearing_rad[problem.usable_pairs(s)], config.n_sectors)
           for s in range(problem.n_stations)]
    while True:
        check = evaluate_layout(problem, selected, config, infos)
        if check.all_ok:
            return Baseline("greedy", selected, True)
        score = np.zeros(problem.n_sites)
        for s in np.flatnonzero(~check.ok):
            info = infos[s]
            free = ~selected[info.sites] & ~forbidden[info.sites]
            if not free.any():
                continue
            sites = info.sites[free]
            gain = np.zeros(sites.size)
            if check.count[s] < min_count:
                gain += 1.0
            occupied = np.zeros(config.n_sectors, bool)
            occupied[sec[s][selected[info.sites]]] = True
            if check.sectors[s] < config.min_sectors:
                gain += ~occupied[sec[s][free]]
            elif config.redundant and check.worst_loss_sectors[s] < config.min_sectors:
                per = np.bincount(sec[s][selected[info.sites]], minlength=config.n_sectors)
                gain += per[sec[s][free]] == 1
            if check.count[s] >= min_count and check.sectors[s] >= config.min_sectors:
                base = info.info[selected[info.sites]].sum(axis=0)
                err = info.errors(base[None] + info.info[free])
                before = max(check.error_m[s], check.worst_loss_error_m[s]
                             if config.redundant else 0.0)
                rel = np.where(np.isfinite(before), (before - err) / before, 1.0)
                gain += np.where(err <= config.requirement_m, 1.0, np.clip(rel, 0.0, 1.0))
            # tie-break: information the site brings (small, never outweighs a fix)
            gain += 1e-6 * np.trace(info.info[free][:, :3, :3], axis1=1, axis2=2) \
                / np.trace(info.info[free][:, :3, :3], axis1=1, axis2=2).max()
            np.add.at(score, sites, gain)
        if score.max() <= 0:
            names = [problem.station_ids[s] for s in np.flatnonzero(~check.ok)]
            raise InfeasiblePlanError(f"greedy cover cannot satisfy station(s) "
                                      f"{', '.join(names)}: no remaining site helps")
        selected = selected.copy()
        selected[int(np.argmax(score))] = True


def regular_grid(problem: PlanProblem, config, bounds_xy: tuple[float, float, float, float],
                 spacings_m: np.ndarray | None = None, net=None) -> Baseline:
    """Widest square-grid layout that meets the requirement at every station.

    At each spacing four grid phases per axis are tried (the grid is not favoured or
    penalised by where its corner happens to fall); the passing phase with fewest markers wins.
    In network mode (``config.network``) a grid passes as ``plan --network`` judges a plan:
    directions as always, and every station and every marker within the requirement relative
    to the reference station, from the whole network's covariance (:func:`_grid_passes`).

    Parameters
    ----------
    problem : PlanProblem
    config : PlanConfig
    bounds_xy : (xmin, ymin, xmax, ymax)
        Rectangle the grid covers (site frame, m); grid points start half a spacing inside.
    spacings_m : (k,) float, optional
        Spacings to try, widest first (default: ``max_range_m`` down to ``grid_spacing_m`` in
        0.5 m steps).
    net : planner.accuracy.network.NetworkModel, optional
        Network mode: cache from :func:`planner.accuracy.network.network_model`.

    Returns
    -------
    baseline : Baseline
        ``meets_requirement`` is False (and ``selected`` the densest grid tried) when no
        spacing works.
    """
    infos = station_infos(problem, config)
    if config.network and net is None:
        from planner.accuracy.network import network_model

        net = network_model(problem, config)
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    existing = problem.site_existing | problem.site_mask(config.existing, "existing")
    pool = np.flatnonzero(~forbidden & ~problem.site_existing)
    tree = cKDTree(problem.site_xyz[pool, :2])
    if spacings_m is None:
        spacings_m = np.arange(config.max_range_m, config.grid_spacing_m - 1e-9, -0.5)
    x0, y0, x1, y1 = bounds_xy
    min_count = config.min_markers + (1 if config.redundant else 0)
    selected = existing
    for a in spacings_m:
        best = None
        for fx in _PHASES:
            for fy in _PHASES:
                gx = np.arange(x0 + fx * a, x1 + 1e-9, a)
                gy = np.arange(y0 + fy * a, y1 + 1e-9, a)
                xx, yy = np.meshgrid(gx, gy)
                pts = np.column_stack([xx.ravel(), yy.ravel()])
                d, k = tree.query(pts)
                trial = existing.copy()
                trial[pool[k[d <= a / 2]]] = True
                if best is not None and trial.sum() >= best.sum():
                    continue
                count, sectors = direction_status(problem, trial, config.n_sectors)
                if np.all((count >= min_count) & (sectors >= config.min_sectors)) and \
                        _grid_passes(problem, trial, config, infos, net):
                    best = trial
                selected = trial
        if best is not None:
            return Baseline("regular grid", best, True, float(a))
    return Baseline("regular grid", selected, False, None)


def _grid_passes(problem: PlanProblem, selected: np.ndarray, config, infos, net) -> bool:
    """Whether a grid layout meets the requirement: known control as
    :func:`~planner.accuracy.checks.evaluate_layout` judges it; network mode as ``plan
    --network`` does (every station, and every selected marker the network estimates, within
    its allowance relative to the reference station). A grid marker on a site no station
    can use (occluded from all, out of range) is counted but not judged: it has no position in
    the network, and the integer program never picks such a site."""
    check = evaluate_layout(problem, selected, config, infos, net=net)
    if not config.network:
        return check.all_ok
    judged = selected & (net.n_stations_seeing > 0)
    allowed_site = net.allowances(NetworkRequirement.of(config))[1]
    return bool(check.ok.all()) and bool(np.all(check.marker_error_m[judged]
                                                <= allowed_site[judged]))


def _local_after_loss(net, local, local_markers, selected: np.ndarray, lost: np.ndarray,
                      covariances: list):
    """Redundant mode: the first loss of a selected tying marker (``lost``, with the pose
    covariance without each, ``covariances``) after which a station pair of ``local``, or
    (``local_markers``) a pair of the remaining selected markers, fails. Returns ``(cov,
    bad station pairs (q,) int, marker pairs or None, bad marker pairs (r,) int)``, the
    failing arrays empty (and ``cov`` None) when every loss passes."""
    none = np.zeros(0, np.int64)
    for m, cov in zip(lost, covariances, strict=True):
        bad = none if local is None else local.failing(cov)
        if bad.size:
            return cov, bad, None, none
        if local_markers is not None:
            left = selected.copy()
            left[m] = False
            pairs, bad_m = local_markers.failing(cov, left)
            if bad_m.size:
                return cov, none, pairs, bad_m
    return None, none, None, none


def greedy_network(problem: PlanProblem, config, net=None, max_steps: int = 5000,
                   batch: int = 1, deadline: float | None = None) -> Baseline:
    """Greedy baseline in network mode.

    Starts from the greedy cover of the direction and count rules alone (:func:`greedy_cover`
    with no accuracy requirement). While some station is not tied to the reference (its pose
    moves freely: a null direction of the information), each step first adds the site that
    removes the most free movements, among the sites the first untied station uses (else any
    untied station; :func:`_tying_site`). Once every station is tied it repeatedly adds the
    site with the largest first-order reduction ``v^T J^(j) v`` of the worst variance of the
    worst station relative to the datum
    (:meth:`planner.accuracy.network.NetworkModel.worst_direction_gain`), or of the worst
    selected marker once every station passes, until every station and marker meets the
    requirement; in redundant mode then also of the station that fails worst after losing one
    marker; with a local requirement (:mod:`planner.accuracy.local`) then of the first failing
    station pairs (their worst relative direction), and with ``local_markers`` of the first
    failing marker pairs (:mod:`planner.accuracy.local_markers`), and in redundant mode last
    of the first pairs that fail after the loss of one marker. ``batch > 1`` adds, per
    step, a site for each of the ``batch`` first untied (then worst failing) stations (for
    large networks: fewer exact evaluations). The information and covariance grow with each
    added site (:class:`planner.accuracy.growing.GrowingCovariance`: a low-rank update per
    site, not a fresh inverse).

    ``deadline``: a :func:`time.perf_counter` value after which no further step starts (the
    greedy's share of a plan's time limit; the directions-only cover it starts from is not
    interrupted).

    Raises
    ------
    GreedyStuckError
        When no remaining site ties an untied station, or improves the worst station or
        marker, after ``max_steps`` steps, or at ``deadline``; the message says how many
        stations are untied, or which fail.
    """
    from planner.accuracy.growing import GrowingCovariance
    from planner.accuracy.network import network_model

    net = net or network_model(problem, config)
    allowed, allowed_site = net.allowances(NetworkRequirement.of(config))
    local = local_accuracy(net, config)
    local_markers = local_marker_accuracy(net, config)
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    selected = greedy_cover(problem, config.as_known_control(requirement_m=1e9)).selected
    open_site = ~forbidden & net.tying
    layout = GrowingCovariance(net, net.information(selected))
    j_all = None
    for _ in range(max_steps):
        if deadline is not None and time.perf_counter() > deadline:
            why = "its share of the time limit ran out"
            break
        j, determined = layout.j, layout.determined
        if not determined.all():  # tie first: remove free movements, worst stations first
            added = False
            for k in np.flatnonzero(~determined)[:batch]:
                site = _tying_site(net, layout, open_site & ~selected, int(k))
                if site is not None:
                    selected = selected.copy()
                    selected[site] = True
                    layout.add(site)
                    added = True
            if not added:
                why = "no remaining site removes a free movement"
                break
            continue
        cov = layout.cov
        err = net.station_errors_from(cov)
        markers = np.flatnonzero(selected)
        # markers are judged once every station passes (until then the stations lead)
        stations_pass = not net.stations_failing(err, allowed).any()
        merr = net.marker_errors(cov, markers) if stations_pass else np.zeros(0)
        loss = None
        bad_pairs = bad_mpairs = np.zeros(0, np.int64)
        if stations_pass and np.all(merr <= allowed_site[markers]):
            if config.redundant:
                lost, loss_err, loss_cov = net.loss_station_errors(selected, j)
                if np.any(loss_err > allowed):
                    i, k = np.unravel_index(np.argmax(np.nan_to_num(loss_err / allowed,
                                                                    posinf=1e300)),
                                            loss_err.shape)
                    loss = (loss_cov[i], int(k), int(lost[i]))
            bad_pairs = np.zeros(0, np.int64) if local is None else local.failing(cov)
            if local_markers is not None and loss is None and bad_pairs.size == 0:
                mpairs, bad_mpairs = local_markers.failing(cov, selected)
            if config.redundant and loss is None and bad_pairs.size == 0 \
                    and bad_mpairs.size == 0:  # the local pairs after each loss
                cov, bad_pairs, mpairs, bad_mpairs = _local_after_loss(
                    net, local, local_markers, selected, lost, loss_cov)
            if loss is None and bad_pairs.size == 0 and bad_mpairs.size == 0:
                return Baseline("greedy", selected, True)
        if bad_pairs.size:  # stations and markers pass: the first failing pairs (after a
            # loss in redundant mode: the pose covariance without it)
            v = (local.gradients(cov, bad_pairs[:batch]) @ cov.full)[:, net.free]
            gains = list(net.site_coefficients(v))
        elif bad_mpairs.size:  # then the first failing marker pairs
            g = local_markers.gradients(cov, mpairs, bad_mpairs[:batch])[0]
            gains = list(net.site_coefficients((g @ cov.full)[:, net.free]))
        elif loss is not None:  # redundant: the station that fails worst after a loss
            cov, k, m = loss
            if not cov.determined.all():
                if j_all is None:
                    j_all = net.information(open_site)
                one = np.zeros(problem.n_sites)
                one[m] = 1.0
                cov = net.covariance(j - net.site_information(one) + 0.05 * j_all)
            gains = [net.worst_direction_gain(cov, k)]
        elif not stations_pass:
            worst = np.argsort(-np.nan_to_num(err / allowed, posinf=1e300), kind="stable")
            worst = worst[:min(batch, int(np.sum(err > allowed)))]
            gains = [net.worst_direction_gain(cov, int(k)) for k in worst]
        else:
            m = markers[int(np.argmax(merr / allowed_site[markers]))]
            cuts = net.marker_tangents(cov, [m])
            gains = [cuts[0][1] if cuts else np.zeros(problem.n_sites)]
        added = False
        selected = selected.copy()
        for gain in gains:
            gain = np.where(open_site & ~selected, gain, 0.0)
            if gain.max() > 0:
                site = int(np.argmax(gain))
                selected[site] = True
                layout.add(site)
                added = True
        if not added:
            why = "no remaining site helps"
            break
    else:
        why = f"stopped after {max_steps} steps"
    determined = layout.determined
    if not determined.all():
        untied = [problem.station_ids[s] for s in np.flatnonzero(~determined)]
        raise GreedyStuckError(
            f"greedy (network) got stuck with {len(untied)} station(s) not tied to the "
            f"reference ({_listed(untied)}) after {int(selected.sum())} markers: {why}",
            selected)
    err = net.station_errors_from(layout.cov)
    failing = [problem.station_ids[s] for s in np.flatnonzero(err > allowed)]
    what = f"station(s) {_listed(failing)}" if failing else \
        "every selected marker and station pair"
    raise GreedyStuckError(f"greedy (network) cannot satisfy {what} after "
                           f"{int(selected.sum())} markers: {why}", selected)


def _listed(ids: list[str], shown: int = 10) -> str:
    """The first ``shown`` ids, comma-separated, with a count of the rest."""
    more = f" and {len(ids) - shown} more" if len(ids) > shown else ""
    return ", ".join(ids[:shown]) + more


def _tying_site(net, layout, available: np.ndarray, k: int) -> int | None:
    """The site that removes the most free movements of the layout (null directions of its
    information), first among the sites station ``k`` uses, else among the sites any
    undetermined station uses; ties go to the lowest index. None when no available site
    removes one.

    Parameters
    ----------
    net : planner.accuracy.network.NetworkModel
    layout : planner.accuracy.growing.GrowingCovariance
    available : (n,) bool
        Sites that may be added.
    k : int
        An undetermined station.
    """
    users = [np.array([k]), np.flatnonzero(~layout.determined)]
    for stations in users:
        sites = np.unique(net.pair_site[np.isin(net.pair_station, stations)])
        sites = sites[available[sites]]
        removed = layout.null_reductions(sites)
        if removed.size and removed.max() > 0:
            return int(sites[int(np.argmax(removed))])
    return None


class GreedyStuckError(InfeasiblePlanError):
    """:func:`greedy_network` found no site that helps; ``selected`` (n,) bool is where it
    stopped (a layout that does not meet the requirement)."""

    def __init__(self, message: str, selected: np.ndarray) -> None:
        super().__init__(message)
        self.selected = selected


def network_baseline(problem: PlanProblem, config, net=None,
                     deadline: float | None = None) -> Baseline:
    """:func:`greedy_network` (no step after ``deadline``, a :func:`time.perf_counter` value),
    or the layout where it got stuck (marked as not meeting the requirement, with the error's
    message as its ``note``): a plan stands on its own when the greedy cannot finish."""
    try:
        return greedy_network(problem, config, net, deadline=deadline)
    except GreedyStuckError as exc:
        return Baseline("greedy", exc.selected, False, note=str(exc))
