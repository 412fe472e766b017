"""Network mode: the preflight (sites that can never pass) and valid cuts for the stations and
markers a layout fails."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from markerplan.errors import InfeasiblePlanError
from planner.accuracy.checks import StationInfo, diagnose, station_infos
from planner.accuracy.local import local_accuracy
from planner.accuracy.local_markers import local_marker_accuracy, pair_cut_rows
from planner.accuracy.network import NetworkModel
from planner.accuracy.network_diagnosis import diagnose_network
from planner.problem.usability import PlanProblem
from planner.program.model import Model, RowKind

#: Network mode: grow a failing station's set only when the problem's tie entries are fewer
#: (each growth step evaluates the network exactly).
_GROW_MAX_TIES = 250_000
#: Network mode: exact evaluations a growth may spend.
_GROW_MAX_EVALS = 14
#: Network mode: tangent cuts per round for at most this many failing stations (the worst;
#: their rows are dense over every tying site), and as many failing markers; a quarter of
#: that on large problems.
_MAX_OA_STATIONS = 20
#: Network mode, large problems: most terms of a cut row (see :func:`network_cuts`).
MAX_TERMS = 500
#: Network mode, large problems: a sparse tangent row gives up at most this fraction of its
#: right-hand side (weaker rows, fewer terms: HiGHS slows badly on dense rows).
_SPARSE_SLACK = 0.9
#: Network mode: weight of the every-site information added to an undetermined layout's
#: information before linearising (any positive definite point gives valid tangents).
_REGULARISE = 0.05


def network_preflight(problem: PlanProblem, config, net: NetworkModel,
                      infos: list[StationInfo] | None = None) -> np.ndarray:
    """Network mode: sites whose marker can never meet the requirement, after checking that
    every station can.

    By monotonicity the best any layout can do is every allowed site selected: a marker whose
    error then exceeds the requirement can never be part of a passing layout (it is left out),
    and a station that then fails — or that no chain of shared sites ties to the reference —
    makes the plan infeasible.

    Returns
    -------
    hopeless : (n,) bool
        Sites to leave out.

    Raises
    ------
    InfeasiblePlanError
        Naming each station that cannot be satisfied and why (directions, disconnected,
        heading undetermined or too weak, too far from the datum), or an existing marker
        that cannot meet the requirement.
    """
    forbidden = problem.site_mask(config.forbidden, "forbidden")
    existing = problem.site_mask(config.existing, "existing") | problem.site_existing
    allowed = ~forbidden & (net.n_stations_seeing > 0)
    infos = infos or station_infos(problem, config)
    _raise_network_infeasible(problem, config, net, diagnose(problem, config, infos,
                                                              accuracy_check=False)
                              or diagnose_network(net, allowed))
    cov = net.covariance(net.information(allowed))
    _refuse_failing_pairs(problem, net, config, cov)
    sites = np.flatnonzero(allowed)
    err = net.marker_errors(cov, sites)
    hopeless = np.zeros(problem.n_sites, bool)
    hopeless[sites[err > net.allowed_site_m[sites]]] = True
    bad_existing = np.flatnonzero(hopeless & existing)
    if bad_existing.size:
        names = ", ".join(problem.site_ids[j] for j in bad_existing[:10])
        raise InfeasiblePlanError(f"existing marker(s) {names} cannot meet "
                                  f"{net.requirement.describe()} relative to the datum, "
                                  f"{net.datum_text}, even with "
                                  "every usable site; relax the requirement")
    if hopeless.any():
        extra = tuple(problem.site_ids[j] for j in np.flatnonzero(hopeless & ~forbidden))
        _raise_network_infeasible(problem, config, net, diagnose(
            problem, config.replace(forbidden=config.forbidden + extra), infos,
            accuracy_check=False) or diagnose_network(net, allowed & ~hopeless))
    return hopeless


def _refuse_failing_pairs(problem: PlanProblem, net: NetworkModel, config, cov) -> None:
    """One-line :class:`InfeasiblePlanError` naming the station pairs of the local requirement
    that fail even with every usable site (``cov``: that layout's covariance), with their
    relative error and allowance; nothing when none fails (or there is no local
    requirement)."""
    local = local_accuracy(net, config)
    if local is None:
        return
    bad = local.failing(cov)
    if bad.size == 0:
        return
    err = local.errors(cov, bad[:10])
    what = "; ".join(f"{name}: {e:.3f} m > {a:.4g} m" for name, e, a in
                     zip(local.names(bad[:10]), err, local.pairs.allowed_m[bad[:10]],
                         strict=True))
    raise InfeasiblePlanError(
        f"no layout meets the local requirement ({local.requirement.describe()}) at "
        f"{bad.size} station pair(s), even with every usable site: {what}"
        + (f" (and {bad.size - 10} more)" if bad.size > 10 else "")
        + "; relax local_requirement_m, add candidate sites or a heading prior")


def _raise_network_infeasible(problem: PlanProblem, config, net: NetworkModel,
                              failing: dict[str, str]) -> None:
    """One-line :class:`InfeasiblePlanError` naming each failing station (none: return)."""
    if failing:
        raise InfeasiblePlanError(
            f"no layout meets the requirement in network mode ({net.requirement.describe()} "
            f"relative to the datum, {net.datum_text}; >= {config.min_markers} markers in "
            f">= {config.min_sectors} of {config.n_sectors} sectors) at station(s): "
            + "; ".join(f"{k}: {v}" for k, v in failing.items())
            + "; relax the configuration, add candidate sites or a heading prior")


def sparse_tangent(coef: np.ndarray, rhs: float, upper_bound: int | None,
                    max_terms: int, slack: float = _SPARSE_SLACK
                    ) -> tuple[np.ndarray, np.ndarray, float]:
    """A tangent cut ``sum_j coef_j x_j >= rhs`` with fewer terms, valid for every layout of at
    most ``upper_bound`` sites.

    The terms are kept largest first: at least ``max_terms``, and as many more as it takes
    for the ``upper_bound`` largest dropped coefficients — the most the dropped terms can add
    — to sum to at most ``slack`` of ``rhs``; then
    ``sum_{kept} coef_j x_j >= rhs - (that sum)``.
    Returns ``(sites, coefficients, 1.0)`` normalised to ``>= 1``.
    """
    pos = np.flatnonzero(coef > 0)
    if upper_bound is None or pos.size <= max_terms:
        return pos, coef[pos] / rhs, 1.0
    order = pos[np.argsort(-coef[pos], kind="stable")]
    c = np.r_[coef[order], np.zeros(upper_bound)]
    cum = np.r_[0.0, np.cumsum(c)]
    k = np.arange(max_terms, order.size + 1)
    given_up = cum[k + upper_bound] - cum[k]  # the upper_bound largest after the first k
    k = int(k[np.argmax(given_up <= slack * rhs)])
    given_up = float(cum[k + upper_bound] - cum[k])
    keep = np.sort(order[:k])
    return keep, coef[keep] / (rhs - given_up), 1.0


def network_cuts(problem: PlanProblem, model: Model, selected: np.ndarray, config,
                 net: NetworkModel, j_all: np.ndarray, upper_bound: int | None = None
                 ) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """Valid cuts for every station and selected marker that fails with ``selected`` in
    network mode.

    Per failing station ``k`` (families): ``"cut"`` — the no-good cut: the selected tying
    sites ``T`` (grown to a larger failing ``T'`` on small problems) need one more site,
    ``sum_{j tying, j not in T'} x_j >= 1`` (monotonicity: every subset of ``T'`` fails);
    ``"connect"`` — a station cut off from the reference needs a selected site tying its
    component to the rest; ``"oa"`` — tangents of its convex worst-case variance
    (:meth:`planner.accuracy.network.NetworkModel.station_tangents`), linearised at the
    layout's information (plus ``_REGULARISE`` x the every-site information when the layout
    leaves a station undetermined; any positive definite point gives a valid tangent). Per
    failing selected marker ``m``: ``"cut-marker"`` ``sum_{j tying, not in T} x_j - x_m >= 0``
    and ``"oa-marker"`` ``sum_j c_j x_j - rhs x_m >= 0`` (enforced only when ``x_m = 1``).
    Per failing station pair of a local requirement (:mod:`planner.accuracy.local`):
    ``"cut-pair"`` (the no-good row over the tying sites the layout lacks: every subset of a
    failing layout fails the pair too) and ``"oa-pair"`` (tangents of the pair's convex
    worst-case relative variance). With ``local_markers``, per failing pair of selected
    markers (:mod:`planner.accuracy.local_markers`): ``"cut-marker-pair"`` and
    ``"oa-marker-pair"``, enforced only when both markers are selected. A layout whose
    stations, markers and pairs all pass (and, in redundant mode, every loss) is judged by
    ``max_bias_effect_m`` (:func:`bias_cuts`).

    On large problems (``upper_bound`` given: no layout of interest has more sites, e.g. a
    feasible layout's count) tangent rows keep their ``MAX_TERMS`` largest coefficients and
    lower their right-hand side by the most the dropped terms can add
    (:func:`sparse_tangent`), and combinatorial rows over more than ``MAX_TERMS`` sites are
    left out (valid, merely weak): every row is still valid for those layouts.

    Parameters
    ----------
    j_all : (P, P) float
        Information of every allowed site (the regularisation).
    upper_bound : int, optional
        Most sites a layout of interest selects (enables the sparse rows).

    Returns
    -------
    rows, lower, kinds
        As :func:`~planner.program.cuts_known.accuracy_cuts`; ``rows`` is ``None`` when
        everything passes.
    """
    in_model = model.site_var >= 0
    open_site = in_model.copy()
    open_site[model.var_site[model.ub[:model.var_site.size] == 0]] = False
    tying = net.tying & open_site
    j_sel = net.information(selected)
    cov = net.covariance(j_sel)
    err = net.station_errors_from(cov)
    failing = np.flatnonzero(net.stations_failing(err))
    markers = np.flatnonzero(selected & open_site)
    merr = net.marker_errors(cov, markers)
    marker_fails = merr > net.allowed_site_m[markers]
    bad_markers = markers[marker_fails]
    local = local_accuracy(net, config)
    bad_pairs = np.zeros(0, np.int64) if local is None else local.failing(cov)
    local_markers = local_marker_accuracy(net, config)
    marker_pairs, bad_marker_pairs = (None, np.zeros(0, np.int64)) if local_markers is None \
        else local_markers.failing(cov, selected)
    if failing.size == 0 and bad_markers.size == 0 and bad_pairs.size == 0 \
            and bad_marker_pairs.size == 0:
        if config.redundant:
            loss = _network_loss_cuts(model, selected, j_sel, net, tying, in_model,
                                      upper_bound, local, local_markers)
            if loss[0] is not None:
                return loss
        return bias_cuts(model, selected, config, net, tying & in_model)
    rows, lower, kinds = [], [], []

    def add(row, lo, kind):
        rows.append(row)
        lower.append(lo)
        kinds.append(kind)

    cov0 = cov if cov.determined.all() else net.covariance(j_sel + _REGULARISE * j_all)
    rim = "spread" if failing.size <= 10 else "worst"
    worst_first = failing[np.argsort(-np.nan_to_num(err[failing], posinf=1e300), kind="stable")]
    n_oa = _MAX_OA_STATIONS if upper_bound is None else _MAX_OA_STATIONS // 4
    tangents = net.station_tangents(cov0, worst_first[:n_oa], rim=rim)
    dense_ok = upper_bound is None

    for k, coef, rhs in tangents:
        cut = sparse_tangent(np.where(in_model, coef, 0.0), rhs, upper_bound, MAX_TERMS)
        add(model.site_row(cut[0], cut[1]), cut[2], RowKind("oa", k))
    grow = failing[np.argmax(err[failing])] if failing.size and \
        net.tie_a.size <= _GROW_MAX_TIES and np.isfinite(err[failing]).any() else -1
    linked = net.connected_to_reference(selected)

    def station_rows(stations: np.ndarray, dense: bool) -> None:
        """The "cut" and "connect" rows of failing ``stations`` (the short ones unless
        ``dense``)."""
        done_components = set()
        for k in stations:
            chosen = selected & tying
            if k == grow:
                first = [c for kk, c, _ in tangents if kk == k]
                chosen = _grow_network(net, chosen, int(k), tying & ~selected, j_sel,
                                       first[0] if first else None)
            rest = np.flatnonzero(tying & ~chosen)
            if dense or rest.size <= MAX_TERMS:
                add(model.site_row(rest), 1.0, RowKind("cut", int(k)))
            if not linked[k]:
                comp = _component(net, selected, int(k))
                if comp in done_components:
                    continue
                done_components.add(comp)
                inside = np.zeros(problem.n_stations, bool)
                inside[list(comp)] = True
                a = np.bincount(net.pair_site, inside[net.pair_station],
                                minlength=problem.n_sites)
                b = net.n_stations_seeing - a
                bridge = np.flatnonzero(tying & (a > 0) & (b > 0))
                if dense or bridge.size <= 4 * MAX_TERMS:
                    add(model.site_row(bridge), 1.0, RowKind("connect", int(k)))

    def marker_rows(markers: np.ndarray, dense: bool) -> None:
        """The "cut-marker" rows of failing ``markers`` (left out when long unless ``dense``)."""
        rest = np.flatnonzero(tying & ~selected)
        for m in markers if dense or rest.size <= MAX_TERMS else ():
            add(model.implied_row(m, rest), 0.0, RowKind("cut-marker"))

    def pair_rows(dense: bool) -> None:
        """The "cut-pair" row of the failing pairs (one: it is the same row for each; left
        out when long unless ``dense``)."""
        rest = np.flatnonzero(tying & ~selected)
        if bad_pairs.size and (dense or rest.size <= MAX_TERMS):
            add(model.site_row(rest), 1.0,
                RowKind("cut-pair", int(local.pairs.first[bad_pairs[0]])))

    def marker_pair_rows(dense: bool) -> None:
        """The "cut-marker-pair" and "oa-marker-pair" rows of the failing marker pairs
        (:mod:`planner.accuracy.local_markers`; the no-good rows left out when long unless
        ``dense``)."""
        rest = np.flatnonzero(tying & ~selected)
        worst = bad_marker_pairs[:n_oa]
        tangents = []
        for p, coef, rhs in local_markers.tangents(cov0, marker_pairs, worst):
            cut = sparse_tangent(np.where(in_model, coef, 0.0), rhs, upper_bound, MAX_TERMS)
            tangents.append((p, cut[0], cut[1]))
        nogood = worst if dense or rest.size <= MAX_TERMS else worst[:0]
        for row, lo, kind in zip(*pair_cut_rows(model, marker_pairs, nogood, rest, tangents,
                                                selected), strict=True):
            add(row, lo, RowKind(kind))

    station_rows(failing, dense_ok)
    worst_m = bad_markers[np.argsort(-merr[marker_fails], kind="stable")]
    if bad_markers.size:
        for m, coef, rhs in net.marker_tangents(cov, worst_m[:n_oa]):
            cut = sparse_tangent(np.where(in_model, coef, 0.0), rhs, upper_bound, MAX_TERMS)
            add(model.implied_row(m, cut[0], cut[1]), 0.0, RowKind("oa-marker"))
    marker_rows(bad_markers, dense_ok)
    if bad_pairs.size:
        for k, coef, rhs in local.tangents(cov0, bad_pairs[:n_oa]):
            cut = sparse_tangent(np.where(in_model, coef, 0.0), rhs, upper_bound, MAX_TERMS)
            add(model.site_row(cut[0], cut[1]), cut[2], RowKind("oa-pair", k))
    if failing.size == 0:  # (a failing station's "cut" row is the same row or stronger)
        pair_rows(dense_ok)
    if bad_marker_pairs.size:
        marker_pair_rows(dense_ok)
    if not rows:  # no tangent is violated and every short row was left out: the worst
        # stations' and markers' long rows (valid; merely many terms)
        station_rows(worst_first[:n_oa], True)
        marker_rows(worst_m[:n_oa], True)
        pair_rows(True)
        if bad_marker_pairs.size:
            marker_pair_rows(True)
    if not rows:  # pragma: no cover - a failing station or marker always yields a no-good cut
        raise InfeasiblePlanError("network mode: the layout fails but no cut was found")
    return sp.csr_array(sp.vstack(rows)), lower, kinds


def bias_cuts(model: Model, selected: np.ndarray, config, net: NetworkModel,
              variables: np.ndarray) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """``max_bias_effect_m``: the no-good cut of a layout some station of which an undetected
    bias of MDB size moves too far.

    The effect is a function of the selected tying sites ``T`` alone (a site seen by one
    station changes no pose's information, and its marker absorbs any bias of its observation:
    effect 0), but not a monotone one: a site added raises the redundancy of every
    observation already there, yet brings observations of its own, and even an existing
    observation's effect ``delta0 sqrt(w) |E_k N_0^-1 a| / sqrt(1 + w a^T N_0^-1 a)``
    (``N_0`` the normal matrix without it) can grow or shrink with ``N_0``. So neither the
    subsets nor the supersets of a failing ``T`` are known to fail, and the only valid cut is
    ``T``'s own no-good over the tying variables: ``sum_{j not in T} x_j - sum_{j in T} x_j >=
    1 - |T|`` (family ``"cut-bias"``; weak: it removes the one tying set).

    Parameters
    ----------
    variables : (n,) bool
        The open tying sites that are variables of ``model`` (fixed sites are constants).

    Returns
    -------
    rows, lower, kinds
        As :func:`network_cuts`; ``(None, [], [])`` when the constraint is off or holds.
    """
    if config.max_bias_effect_m is None:
        return None, [], []
    from planner.accuracy.reliability import layout_reliability

    effect = layout_reliability(net, selected).station_effect_m
    worst = int(np.argmax(np.nan_to_num(effect, posinf=1e300)))
    if effect[worst] <= config.max_bias_effect_m:
        return None, [], []
    inside = np.flatnonzero(variables & selected)
    outside = np.flatnonzero(variables & ~selected)
    row = model.site_row(np.r_[inside, outside], np.r_[-np.ones(inside.size),
                                                      np.ones(outside.size)])
    return sp.csr_array(row), [1.0 - inside.size], [RowKind("cut-bias", worst)]


def _network_loss_cuts(model: Model, selected: np.ndarray, j_sel: np.ndarray,
                       net: NetworkModel, tying: np.ndarray, in_model: np.ndarray,
                       upper_bound: int | None, local=None, local_markers=None
                       ) -> tuple[sp.csr_array | None, list[float], list[RowKind]]:
    """Redundant network mode: valid cuts for a layout that passes whole but fails at some
    station, or (with a local requirement) some station pair or pair of the remaining selected
    markers, after losing one tying marker ``m`` (losing a marker one station sees changes no
    covariance and only removes marker pairs).

    ``"cut-loss"``: ``sum_{j tying, not selected} x_j - x_m >= 0`` (with ``m`` the layout needs a
    site outside the selected ones: every subset of the selected sites without ``m`` fails, by
    monotonicity); ``"oa-loss"``: the failing stations' tangents at the information without
    ``m``, enforced only when ``x_m = 1``: ``sum_{j != m} c_j x_j - x_m >= 0`` (normalised).
    A failing station pair (``local``, :class:`~planner.accuracy.local.LocalAccuracy`) gives
    the same two rows, ``"cut-loss-pair"`` and ``"oa-loss-pair"`` (the pair is monotone as a
    station is); a failing marker pair (``local_markers``) the rows of :func:`~planner.accuracy.
    local_markers.pair_cut_rows` with ``lost=m``, enforced only when ``m`` and both markers
    are selected. Arguments as :func:`network_cuts` (``j_sel``: the layout's information,
    ``tying``: open tying sites, ``in_model``: sites that are variables). Returns ``(None,
    [], [])`` when every loss passes.
    """
    markers, errors, covariances = net.loss_station_errors(selected, j_sel)
    rest = np.flatnonzero(tying & ~selected)
    rows, lower, kinds = [], [], []

    def without(m, coef, rhs):
        """A tangent at the information without ``m``, on the model's other sites, sparse:
        ``(sites, coefficients)``."""
        coef = np.where(in_model, coef, 0.0)
        coef[m] = 0.0
        return sparse_tangent(coef, rhs, upper_bound, MAX_TERMS)[:2]

    def implied(m, failing, tangents, cut, oa):
        """The no-good and tangent rows "``x_m`` implies" of one loss."""
        rows.append(model.implied_row(m, rest))
        lower.append(0.0)
        kinds.append(RowKind(cut, failing))
        for k, coef, rhs in tangents:
            rows.append(model.implied_row(m, *without(m, coef, rhs)))
            lower.append(0.0)
            kinds.append(RowKind(oa, k))

    for m, err, cov in zip(markers, errors, covariances, strict=True):
        bad = np.flatnonzero(net.stations_failing(err))
        if bad.size:
            implied(m, int(bad[0]), net.station_tangents(cov, bad), "cut-loss", "oa-loss")
            continue
        bad_pairs = np.zeros(0, np.int64) if local is None else local.failing(cov)
        if bad_pairs.size:
            implied(m, int(local.pairs.first[bad_pairs[0]]),
                    local.tangents(cov, bad_pairs[:_MAX_OA_STATIONS]), "cut-loss-pair",
                    "oa-loss-pair")
        if local_markers is None:
            continue
        left = selected.copy()
        left[m] = False
        pairs, bad_mpairs = local_markers.failing(cov, left)
        if bad_mpairs.size == 0:
            continue
        tangents = [(p, *without(m, coef, rhs)) for p, coef, rhs in
                    local_markers.tangents(cov, pairs, bad_mpairs[:_MAX_OA_STATIONS])]
        for row, lo, kind in zip(*pair_cut_rows(model, pairs, bad_mpairs, rest, tangents,
                                                selected, lost=int(m)), strict=True):
            rows.append(row)
            lower.append(lo)
            kinds.append(RowKind(kind))
    if not rows:
        return None, [], []
    return sp.csr_array(sp.vstack(rows)), lower, kinds


def _component(net: NetworkModel, selected: np.ndarray, k: int) -> frozenset:
    """Stations linked to station ``k`` by shared selected sites."""
    from scipy.sparse.csgraph import connected_components

    _, comp = connected_components(sp.csr_array(net.ties(selected) > 0), directed=False)
    return frozenset(np.flatnonzero(comp == comp[k]).tolist())


def _grow_network(net: NetworkModel, chosen: np.ndarray, k: int, candidates: np.ndarray,
                  j_chosen: np.ndarray, coef) -> np.ndarray:
    """Grow station ``k``'s failing set ``chosen`` by the candidate sites that help its worst
    direction least (``coef`` ascending; by site order without one), as far as it keeps
    failing: by monotonicity "the set plus the first ``m`` candidates fails" is monotone in
    ``m``, so the largest such ``m`` is found by bisection (at most ``_GROW_MAX_EVALS`` exact
    evaluations). Returns the grown (still failing) set, (n,) bool."""
    cand = np.flatnonzero(candidates)
    if cand.size == 0:
        return chosen
    order = cand[np.argsort(coef[cand], kind="stable")] if coef is not None else cand
    def fails(m: int) -> bool:
        x = np.zeros(net.problem.n_sites)
        x[order[:m]] = 1.0
        j = j_chosen + net.site_information(x)
        cov = net.covariance(j)
        if not cov.determined[k]:
            return True
        e = net.station_errors_from(cov)[k]
        return not np.isfinite(e) or bool(e > net.allowed_station_m[k])

    lo, hi = 0, order.size
    for _ in range(_GROW_MAX_EVALS):
        if lo >= hi:
            break
        mid = (lo + hi + 1) // 2
        if fails(mid):
            lo = mid
        else:
            hi = mid - 1
    grown = chosen.copy()
    grown[order[:lo]] = True
    return grown

