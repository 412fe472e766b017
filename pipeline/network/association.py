"""Marker identity across stations: which detections of different stations are one marker.

Network mode needs to know which detections of different stations are the same marker. The
identity comes from one of two sources, never from a simulator's truth:

With a plan (:func:`associate_with_plan`)
    The plan gives every marker's nominal site position. The station's nominal pose (rover
    odometry) predicts each one in the station's levelled frame. The prediction's covariance
    combines the detection noise (``sigma^2 / 3`` per axis) and the odometry error. The
    heading error goes through the lever arm, so it spreads far markers across the line of
    sight and leaves them tight along it. A detection may take a marker whose squared
    Mahalanobis distance is inside the chi-square(3) gate. One-to-one assignment minimises
    the summed squared distance (Hungarian). A match is only made when it is clearly better
    than every alternative (see :func:`associate_with_plan`).
Without a plan (:func:`associate_by_geometry`)
    Levelled station frames differ by a 4-DoF transform (translation and heading).
    Between two detections, the horizontal distance and the height difference do not depend
    on that transform. For each pair of stations, pairs of detections whose two invariants
    agree (within their sigmas) give candidate transforms. The best-supported transform is
    refined by weighted 2-D Procrustes on its gated one-to-one correspondences. A rival
    transform with other correspondences, at least half as many as the best's, makes the
    pair ambiguous (a symmetric layout such as a regular grid), and the pair is left
    unmatched.
    Correspondences of all pairs are merged with union-find. A merge that would put two
    detections of one station into one marker is refused. Markers are named ``M001``,
    ``M002``, ... by their first detection (station order, then detection order).

Frames: a *levelled station frame* has its origin at the LiDAR centre, z up and x along the
station's nominal heading (the ``x_m, y_m, z_m`` of a station's ``markers.csv``). A site
point ``m`` is seen at ``Rz(heading)^T (m - position)``. The residual tilt of a levelled
frame (inclinometer, about 0.01 deg: 5 mm at 30 m) is far below the plan gate and is ignored
there. The geometry gates are centimetres wide, so it is added to their variance.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from markerplan.errors import ConfigError
from pipeline.scans.rig import fit_heading_shift, rot_z

#: Squared-distance margin of "clearly better": a match is kept only if no alternative is
#: within ``2 ln(ambiguity_odds)``, i.e. the Gaussian likelihood of the best assignment beats
#: every alternative by at least these odds.
AMBIGUITY_ODDS = 100.0

#: A rival transform makes a station pair ambiguous when its correspondences outside the
#: best transform's number at least this fraction of the best's (and ``min_correspondences``).
#: On a regular grid the transforms shifted by one spacing keep most of the best's support.
RIVAL_FRACTION = 0.5

#: Detection pairs closer than this horizontally do not seed a transform (heading undefined).
MIN_SEED_BASELINE_M = 1.0

#: Refinement passes (gated assignment, then Procrustes) of one transform hypothesis.
_REFINE_PASSES = 6

#: Largest block of seed x detection x detection tests evaluated at once.
_CHUNK_ELEMENTS = 1_000_000

#: Most seed x detection x detection tests per station pair: beyond it (only a highly
#: repetitive layout has that many seeds) an even, deterministic subset of seeds is examined.
_MAX_SEED_ELEMENTS = 100_000_000


@dataclass(frozen=True)
class PlanAssociation:
    """Result of :func:`associate_with_plan` for one station.

    Attributes
    ----------
    ids : list of (str or None)
        ``(n,)`` planned marker id of each detection, None when unassigned.
    status : tuple of str
        ``(n,)`` one of ``"assigned"``, ``"outside_gate"`` (no planned marker in its gate),
        ``"ambiguous"`` (an alternative assignment is within the odds margin) or ``"taken"``
        (its gated markers are clearly other detections').
    mahalanobis_sq : (n,) float
        Squared Mahalanobis distance to the assigned marker. When unassigned, it is the
        distance to the nearest planned marker (``inf`` with an empty plan).
    gate : float
        The gate: chi-square(3) quantile of ``gate_probability``.
    """

    ids: list[str | None]
    status: tuple[str, ...]
    mahalanobis_sq: np.ndarray
    gate: float


def associate_with_plan(detections_xyz: np.ndarray, nominal_position_m: np.ndarray,
                        nominal_heading_rad: float, plan_xyz: np.ndarray,
                        plan_ids: Sequence[str], detection_sigma_m: np.ndarray,
                        odometry_sigma_m: float | np.ndarray, odometry_heading_sigma_rad: float,
                        gate_probability: float = 0.999,
                        ambiguity_odds: float = AMBIGUITY_ODDS) -> PlanAssociation:
    """Give one station's detections their planned marker ids by gated association.

    Each planned marker ``m`` is predicted at ``p = Rz(h)^T (m - t)``, where ``t`` and ``h``
    are the nominal position and heading. Its covariance for detection ``i`` is
    ``sigma_i^2/3 I + Rz(h)^T diag(odometry_sigma_m^2) Rz(h)
    + odometry_heading_sigma_rad^2 g g^T`` with ``g = (p_y, -p_x, 0)``. The heading term is
    linearised, which is good for heading sigmas of a few degrees.

    Decision rule. ``c_ij`` is the squared Mahalanobis distance, and pairs with
    ``c_ij > gate`` are forbidden. The best one-to-one assignment minimises the summed
    ``c_ij`` plus ``gate`` for each unassigned detection. Let ``B`` be its cost and
    ``B(i, j)`` the best cost with the pair ``(i, j)`` forced. Detection ``i`` keeps its
    marker ``j`` only if every alternative costs at least ``2 ln(ambiguity_odds)`` more
    than ``B``. The alternatives are ``i`` on another gated marker, ``B(i, j')``, and ``j``
    on another detection, ``B(i', j)``. Otherwise detection ``i`` is ``"ambiguous"`` and
    stays None. An unassigned detection is ``"ambiguous"`` when some ``B(i, j)`` is within
    the margin, else ``"taken"``.

    Parameters
    ----------
    detections_xyz : (n, 3) float
        Marker centres in the station's levelled frame, metres.
    nominal_position_m : (3,) float
        Nominal site position of the LiDAR centre (odometry), metres.
    nominal_heading_rad : float
        Nominal heading (angle of the station's x axis from the site x axis), radians.
    plan_xyz : (k, 3) float
        Planned marker centres, site frame, metres.
    plan_ids : sequence of str
        ``(k,)`` unique ids of the planned markers.
    detection_sigma_m : (n,) float
        1-sigma 3D centre error of each detection, metres, > 0.
    odometry_sigma_m : float or (3,) float
        1-sigma per-axis error of the nominal position (site x, y, z), metres. A
        marker-placement error (isotropic) can be added to it in quadrature.
    odometry_heading_sigma_rad : float
        1-sigma error of the nominal heading, radians.
    gate_probability : float
        Probability that a detection's own marker lies inside its gate, in (0, 1).
    ambiguity_odds : float
        Smallest likelihood ratio (> 1) between the best assignment and any alternative.

    Returns
    -------
    PlanAssociation

    Raises
    ------
    ConfigError
        Wrong shapes, non-finite values, a sigma that is negative (or not > 0 for a
        detection), repeated or empty ids, or a probability or odds out of range.

    Examples
    --------
    >>> import numpy as np
    >>> plan = np.array([[10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [10.3, 0.2, 0.0]])
    >>> det = np.array([[10.02, 0.0, 0.0], [0.0, -10.1, 0.0], [0.0, 20.0, 0.0]])
    >>> res = associate_with_plan(det, [0.0, 0.0, 0.0], np.pi / 2, plan, ["A", "B", "C"],
    ...                           np.full(3, 0.01), 0.3, np.radians(1.0))
    >>> res.ids
    ['B', None, None]
    >>> res.status
    ('assigned', 'ambiguous', 'outside_gate')
    >>> associate_with_plan(np.zeros((0, 3)), [0, 0, 0], 0.0, plan, ["A", "B", "C"],
    ...                     np.zeros(0), 0.3, 0.01).ids
    []
    """
    det, sigma, position, plan, ids, odo = _plan_iv(
        detections_xyz, detection_sigma_m, nominal_position_m, nominal_heading_rad, plan_xyz,
        plan_ids, odometry_sigma_m, odometry_heading_sigma_rad, gate_probability,
        ambiguity_odds)
    gate = float(chi2.ppf(gate_probability, 3))
    cost = _plan_mahalanobis_sq(det, sigma, position, float(nominal_heading_rad), plan, odo,
                                float(odometry_heading_sigma_rad))
    n = det.shape[0]
    best = cost.min(axis=1) if cost.shape[1] else np.full(n, np.inf)
    gated = np.where(cost <= gate, cost, np.inf)
    cols = np.flatnonzero(np.isfinite(gated).any(axis=0))  # markers inside some gate
    total, assigned = _gated_assignment(gated[:, cols], gate)
    forced = np.full((n, cols.size), np.inf)  # B(i, j) for gated pairs
    for i, j in np.argwhere(np.isfinite(gated[:, cols])):
        rest = np.delete(np.delete(gated[:, cols], i, axis=0), j, axis=1)
        forced[i, j] = gated[i, cols[j]] + _gated_assignment(rest, gate)[0]
    close = forced - total < 2.0 * math.log(ambiguity_odds)
    out_ids: list[str | None] = [None] * n
    status, d2 = [], best.copy()
    for i in range(n):
        j = assigned[i]
        if j < 0:
            status.append("outside_gate" if not np.isfinite(forced[i]).any()
                          else "ambiguous" if close[i].any() else "taken")
            continue
        rivals = np.delete(close[i], j).any() or np.delete(close[:, j], i).any()
        status.append("ambiguous" if rivals else "assigned")
        if not rivals:
            out_ids[i] = ids[cols[j]]
            d2[i] = gated[i, cols[j]]
    return PlanAssociation(out_ids, tuple(status), d2, gate)


def _plan_mahalanobis_sq(det: np.ndarray, sigma: np.ndarray, position: np.ndarray,
                         heading: float, plan: np.ndarray, odometry_sigma: np.ndarray,
                         heading_sigma: float) -> np.ndarray:
    """``(n, k)`` squared Mahalanobis distance of each detection to each predicted marker."""
    rz = rot_z(heading)
    predicted = (plan - position) @ rz  # rows: Rz^T (m - t)
    lever = np.stack([predicted[:, 1], -predicted[:, 0], np.zeros(len(plan))], axis=1)
    pose = rz.T @ np.diag(odometry_sigma**2) @ rz + heading_sigma**2 * (
        lever[:, :, None] * lever[:, None, :])  # (k, 3, 3)
    cov = pose[None] + (sigma**2 / 3.0)[:, None, None, None] * np.eye(3)  # (n, k, 3, 3)
    r = det[:, None, :] - predicted[None]
    return np.einsum("nki,nki->nk", r, np.linalg.solve(cov, r[..., None])[..., 0])


def _gated_assignment(cost: np.ndarray, gate: float) -> tuple[float, np.ndarray]:
    """Best one-to-one assignment when leaving a row unassigned costs ``gate``.

    Parameters
    ----------
    cost : (n, c) float
        ``inf`` where a pair is forbidden.
    gate : float

    Returns
    -------
    total : float
        Summed cost, ``gate`` per unassigned row.
    column : (n,) int
        Assigned column of each row, -1 when unassigned.
    """
    n, c = cost.shape
    aug = np.full((n, c + n), np.inf)
    aug[:, :c] = cost
    aug[np.arange(n), c + np.arange(n)] = gate
    rows, cols = linear_sum_assignment(aug)
    column = np.full(n, -1, dtype=np.int64)
    column[rows] = np.where(cols < c, cols, -1)
    return float(aug[rows, cols].sum()), column


def _plan_iv(det, sigma, position, heading, plan, ids, odo, heading_sigma, probability, odds):
    det = _points(det, "detections_xyz")
    plan = _points(plan, "plan_xyz")
    sigma = _sigmas(sigma, det.shape[0], "detection_sigma_m")
    position = np.asarray(position, dtype=float)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise ConfigError(f"`nominal_position_m` must be 3 finite numbers, got {position!r}")
    ids = [str(i) for i in ids]
    if len(ids) != plan.shape[0]:
        raise ConfigError(f"`plan_ids` must give one id per row of `plan_xyz` "
                          f"({plan.shape[0]}), got {len(ids)}")
    if len(set(ids)) != len(ids) or "" in ids:
        raise ConfigError("`plan_ids` must be unique and non-empty, got repeated or empty ids")
    odo = np.broadcast_to(np.asarray(odo, dtype=float), (3,)) if np.ndim(odo) == 0 else \
        np.asarray(odo, dtype=float)
    if odo.shape != (3,) or not np.all(np.isfinite(odo) & (odo >= 0)):
        raise ConfigError("`odometry_sigma_m` must be one or 3 finite numbers >= 0 metres, "
                          f"got {np.asarray(odo).tolist()}")
    for name, value in (("nominal_heading_rad", heading),
                        ("odometry_heading_sigma_rad", heading_sigma)):
        if not np.isfinite(value):
            raise ConfigError(f"`{name}` must be a finite number, got {value}")
    if heading_sigma < 0:
        raise ConfigError(f"`odometry_heading_sigma_rad` must be >= 0, got {heading_sigma}")
    if not 0 < probability < 1:
        raise ConfigError(f"`gate_probability` must be in (0, 1), got {probability}")
    if not odds > 1:
        raise ConfigError(f"`ambiguity_odds` must be > 1, got {odds}")
    return det, sigma, position, plan, ids, odo


def _points(xyz, name: str) -> np.ndarray:
    xyz = np.asarray(xyz, dtype=float)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise ConfigError(f"`{name}` must have shape (n, 3), got {xyz.shape}")
    if not np.all(np.isfinite(xyz)):
        raise ConfigError(f"`{name}` must be finite, got {int((~np.isfinite(xyz)).sum())} "
                          "NaN or infinite value(s)")
    return xyz


def _sigmas(sigma, n: int, name: str) -> np.ndarray:
    sigma = np.asarray(sigma, dtype=float)
    if sigma.shape != (n,):
        raise ConfigError(f"`{name}` must have shape ({n},), got {sigma.shape}")
    if not np.all(sigma > 0) or not np.all(np.isfinite(sigma)):
        raise ConfigError(f"`{name}` must be finite and > 0 metres, got "
                          f"{sigma[~(np.isfinite(sigma) & (sigma > 0))][:3].tolist()}")
    return sigma


@dataclass(frozen=True)
class StationPairMatch:
    """How two stations' detections were matched by :func:`associate_by_geometry`.

    Attributes
    ----------
    station_a, station_b : str
    status : str
        ``"matched"``. Or ``"no_overlap"``: the best transform has fewer than
        ``min_correspondences`` correspondences. Or ``"ambiguous"``: a rival transform
        explains at least ``min_correspondences`` other correspondences, and at least
        :data:`RIVAL_FRACTION` of the best's.
    correspondences : (m, 2) int
        Detection indices ``(a, b)`` of the best transform's one-to-one correspondences.
        Used only when matched.
    heading_rad : float
        Rotation about z from a's levelled frame to b's, radians.
    translation_m : (3,) float
        ``x_b = Rz(heading_rad) x_a + translation_m``, metres.
    rival_support : int
        Correspondences outside the best set of the strongest rival transform found.
    """

    station_a: str
    station_b: str
    status: str
    correspondences: np.ndarray
    heading_rad: float
    translation_m: np.ndarray
    rival_support: int


@dataclass(frozen=True)
class GeometryAssociation:
    """Result of :func:`associate_by_geometry`.

    Attributes
    ----------
    ids : list of list of str
        Marker id of every detection, per station in input order. A marker seen by one
        station only has its own id.
    pairs : tuple of StationPairMatch
        One per examined station pair.
    refused_merges : int
        Correspondences not merged because their two markers hold detections of a common
        station.
    """

    ids: list[list[str]]
    pairs: tuple[StationPairMatch, ...]
    refused_merges: int


def associate_by_geometry(stations: Sequence[tuple[str, np.ndarray]],
                          detection_sigma_m: float | Sequence[np.ndarray] = 0.02,
                          station_pairs: Sequence[tuple[str, str]] | None = None,
                          min_correspondences: int = 4, gate_probability: float = 0.999,
                          inclinometer_sigma_rad: float = math.radians(0.01)
                          ) -> GeometryAssociation:
    """Name markers across stations from consistent inter-marker geometry alone (no plan).

    For each station pair, candidate transforms come from seeds. A seed is two detections
    in each station, at least :data:`MIN_SEED_BASELINE_M` apart horizontally, whose
    horizontal distances and height differences agree within
    ``sqrt(chi2_1(gate_probability))`` sigmas. A seed's support counts the other detections
    whose distances and height differences to both of its ends agree too; no transform is
    needed for that. Seeds are refined in order of support: gated one-to-one assignment
    (chi-square(3) gate on the per-axis variance of both detections plus the transform's
    own) and weighted Procrustes (heading, 3-D translation), repeated until the
    correspondences stop changing. The first to reach ``min_correspondences`` is the best.
    Every later seed not made of two of the best's correspondences is a rival. If a rival
    keeps at least ``min_correspondences`` correspondences outside the best's, and at least
    :data:`RIVAL_FRACTION` of the best's count, the pair is ambiguous and left unmatched.

    Parameters
    ----------
    stations : sequence of (str, (n_i, 3) float)
        Station id and its detections (marker centres, levelled station frame, metres).
    detection_sigma_m : float or sequence of (n_i,) float
        1-sigma 3D centre error, metres, > 0: one value for all, or one array per station.
    station_pairs : sequence of (str, str) or None
        Station pairs that may share markers. None means all pairs; the cost grows with
        their number.
    min_correspondences : int
        Correspondences (>= 3) a transform needs to be accepted, and the fewest a rival needs
        to make it ambiguous. 4 guards against chance congruent triangles on flat ground
        (see Notes).
    gate_probability : float
        Probability of the gates, in (0, 1).
    inclinometer_sigma_rad : float
        1-sigma residual tilt of a levelled frame, radians. A detection at distance ``r``
        gains ``(inclinometer_sigma_rad r)^2`` per-axis variance (5 mm at 30 m for the
        default 0.01 deg, comparable to the centre error).

    Returns
    -------
    GeometryAssociation

    Raises
    ------
    ConfigError
        Repeated or empty station ids, wrong shapes, non-finite coordinates, sigmas not
        > 0, unknown stations in ``station_pairs``, ``min_correspondences < 3``.

    Notes
    -----
    Limitations. A layout that repeats itself under a horizontal shift or rotation (a
    regular grid, markers on a circle) gives rival transforms with nearly equal support.
    Such pairs stay unmatched, so their markers get separate ids. On a grid, the
    transforms one spacing away from the best lose only one row of the overlap. That keeps
    them above :data:`RIVAL_FRACTION` of the best's support whenever the overlap is at
    least two rows deep. On flat ground the height difference carries no information.
    Three detections then match three others whenever their three distances agree, which
    happens by chance in large layouts, hence the default of 4 correspondences. The cost
    grows with the fourth power of the detections per station: about 10 ms per station
    pair at 10 detections, about 1 s at 50 (flat ground), more for a repetitive layout.

    Examples
    --------
    >>> import numpy as np
    >>> from pipeline.scans.rig import rot_z
    >>> a = np.array([[0.0, 0, 0], [7, 1, 0.3], [2, 9, -0.2], [-6, 4, 0.1], [-3, -8, 0.4]])
    >>> b = a[[3, 0, 4, 1]] @ rot_z(0.8).T + [5.0, -2.0, 0.1]
    >>> res = associate_by_geometry([("S1", a), ("S2", b)], 0.01)
    >>> res.ids
    [['M001', 'M002', 'M003', 'M004', 'M005'], ['M004', 'M001', 'M005', 'M002']]
    >>> res.pairs[0].status, round(res.pairs[0].heading_rad, 3)
    ('matched', 0.8)
    >>> associate_by_geometry([("S1", np.zeros((0, 3)))]).ids
    [[]]
    """
    names, points, sigmas, pairs = _geometry_iv(stations, detection_sigma_m, station_pairs,
                                                min_correspondences, gate_probability,
                                                inclinometer_sigma_rad)
    gate = float(chi2.ppf(gate_probability, 3))
    tol1 = float(chi2.ppf(gate_probability, 1))
    variance = [s**2 / 3.0 + inclinometer_sigma_rad**2 * np.sum(p**2, axis=1)
                for p, s in zip(points, sigmas, strict=True)]  # per axis, m^2
    matches = [_match_stations(names[i], points[i], variance[i], names[j], points[j],
                               variance[j], gate, tol1, min_correspondences) for i, j in pairs]
    offset = np.cumsum([0] + [len(p) for p in points])
    parent = list(range(int(offset[-1])))
    members = [{s} for s in range(len(names)) for _ in range(len(points[s]))]

    def find(u: int) -> int:
        while parent[u] != u:
            parent[u] = parent[parent[u]]
            u = parent[u]
        return u

    refused = 0
    order = sorted(range(len(pairs)), key=lambda p: (-len(matches[p].correspondences), p))
    for p in order:
        if matches[p].status != "matched":
            continue
        i, j = pairs[p]
        for a, b in matches[p].correspondences:
            ra, rb = find(int(offset[i] + a)), find(int(offset[j] + b))
            if ra == rb:
                continue
            if members[ra] & members[rb]:
                refused += 1
                continue
            keep, drop = min(ra, rb), max(ra, rb)
            parent[drop] = keep
            members[keep] |= members[drop]
    names_of: dict[int, str] = {}
    ids = [[names_of.setdefault(find(int(offset[s] + d)), f"M{len(names_of) + 1:03d}")
            for d in range(len(points[s]))] for s in range(len(names))]
    return GeometryAssociation(ids, tuple(matches), refused)


def _match_stations(name_a: str, a: np.ndarray, va: np.ndarray, name_b: str, b: np.ndarray,
                    vb: np.ndarray, gate: float, tol1: float, min_support: int
                    ) -> StationPairMatch:
    """Best 4-DoF transform of a's detections onto b's (``va``, ``vb``: per-axis variances)."""
    var = va[:, None] + vb[None, :]  # (na, nb) per-axis variance of a - b
    seeds = _seeds(a, va, b, vb, tol1, min_support)
    best, explained, rival_support = None, None, 0
    for h in range(len(seeds[0])):
        i, j, k, m = seeds[4][h]
        if best is not None and explained[i, k] and explained[j, m]:
            continue  # seeded by two pairs of a transform already refined
        pairs, heading, shift = _refine(a, b, var, seeds, h, gate)
        if len(pairs) < min_support:
            continue
        if best is None:
            best = (pairs, heading, shift)
            rival_needed = max(min_support, math.ceil(RIVAL_FRACTION * len(pairs)))
            in_best = np.zeros(var.shape, dtype=bool)
            in_best[pairs[:, 0], pairs[:, 1]] = True
            explained = in_best.copy()  # pairs of the best transform or of rivals equal to it
            continue
        rival_support = max(rival_support, int((~in_best[pairs[:, 0], pairs[:, 1]]).sum()))
        if rival_support >= rival_needed:
            break
        explained[pairs[:, 0], pairs[:, 1]] = True
    if best is None:
        return StationPairMatch(name_a, name_b, "no_overlap", np.zeros((0, 2), dtype=np.int64),
                                math.nan, np.full(3, math.nan), 0)
    status = "ambiguous" if rival_support >= rival_needed else "matched"
    return StationPairMatch(name_a, name_b, status, *best, rival_support)


def _seeds(a, pva, b, pvb, tol1, min_support):
    """Transform hypotheses from pairs of detections, most supported first.

    A seed maps detections ``(i, j)`` of a onto ``(k, m)`` of b when their horizontal
    distances and height differences agree. Its support counts the other detections ``c`` of
    a that have a partner ``d`` in b at consistent distance and height difference from both
    ends (no transform needed). Seeds with support below ``min_support - 2`` are dropped.

    Returns
    -------
    heading : (H,) float
    shift : (H, 3) float
        ``x_b = Rz(heading) x_a + shift``.
    spread : (H, 2) float
        Variance of the heading (rad^2) and per-axis variance of the centre (m^2).
    centre : (H, 3) float
        Centre in a's frame, where the lever arm of the heading error starts.
    ends : (H, 4) int
        ``i, j, k, m``.
    """
    ha, hb = (np.hypot(*(p[None, :, :2] - p[:, None, :2]).T).T for p in (a, b))
    za, zb = a[None, :, 2] - a[:, None, 2], b[None, :, 2] - b[:, None, 2]
    ia, ja = np.nonzero(np.triu(ha >= MIN_SEED_BASELINE_M, 1))
    kb, mb = np.nonzero(hb >= MIN_SEED_BASELINE_M)
    v = (pva[ia] + pva[ja])[:, None] + (pvb[kb] + pvb[mb])[None, :]
    p, q = np.nonzero(((ha[ia, ja][:, None] - hb[kb, mb][None]) ** 2 <= tol1 * v)
                      & ((za[ia, ja][:, None] - zb[kb, mb][None]) ** 2 <= tol1 * v))
    ends = np.stack([ia[p], ja[p], kb[q], mb[q]], axis=1)
    most = max(1, _MAX_SEED_ELEMENTS // max(1, len(a) * len(b)))
    if len(ends) > most:
        ends = ends[np.linspace(0, len(ends) - 1, most).astype(np.int64)]
    support = np.zeros(len(ends), dtype=np.int64)
    step = max(1, _CHUNK_ELEMENTS // max(1, len(a) * len(b)))
    for first in range(0, len(ends), step):
        e = ends[first:first + step]
        ok = np.ones((len(e), len(a), len(b)), dtype=bool)
        for end_a, end_b in ((e[:, 0], e[:, 2]), (e[:, 1], e[:, 3])):
            tol = tol1 * (pva[end_a, None, None] + pva[None, :, None]
                          + pvb[end_b, None, None] + pvb[None, None, :])
            ok &= (ha[end_a][:, :, None] - hb[end_b][:, None, :]) ** 2 <= tol
            ok &= (za[end_a][:, :, None] - zb[end_b][:, None, :]) ** 2 <= tol
        rows = np.arange(len(e))
        ok[rows, e[:, 0]] = ok[rows, e[:, 1]] = False
        ok[rows, :, e[:, 2]] = ok[rows, :, e[:, 3]] = False
        support[first:first + step] = ok.any(axis=2).sum(axis=1)
    keep = np.flatnonzero(support >= min_support - 2)
    ends = ends[keep[np.argsort(-support[keep], kind="stable")]]
    i, j, k, m = ends.T
    da, db = a[j] - a[i], b[m] - b[k]
    heading = np.arctan2(db[:, 1], db[:, 0]) - np.arctan2(da[:, 1], da[:, 0])
    centre = (a[i] + a[j]) / 2.0
    shift = (b[k] + b[m]) / 2.0 - np.einsum("hij,hj->hi", rot_z(heading), centre)
    var = pva[i] + pva[j] + pvb[k] + pvb[m]
    spread = np.stack([var / ha[i, j] ** 2, var / 4.0], axis=1)
    return heading, shift, spread, centre, ends


def _normalised_d2(a, b, var, heading, shift, spread, centre) -> np.ndarray:
    """``(na, nb)`` squared distances of moved a to b over their per-axis variance.

    The variance is that of the detections plus the transform's own: ``spread[0]`` times
    the squared horizontal lever arm from ``centre``, plus ``spread[1]``.
    """
    moved = a @ rot_z(heading).T + shift
    extra = spread[0] * np.sum((a[:, :2] - centre[:2]) ** 2, axis=1) + spread[1]
    return np.sum((moved[:, None] - b[None]) ** 2, axis=2) / (var + extra[:, None])


def _refine(a, b, var, hypotheses, h, gate):
    """Gated one-to-one correspondences and weighted Procrustes, until they stop changing.

    Parameters
    ----------
    a : (na, 3) float
    b : (nb, 3) float
    var : (na, nb) float
        Per-axis variance of ``a - b`` from the detections, m^2.
    hypotheses : tuple of arrays
        ``heading, shift, spread, centre, ...`` as returned by :func:`_seeds`.
    h : int
        The hypothesis to start from.
    gate : float

    Returns
    -------
    pairs : (m, 2) int
    heading : float
    shift : (3,) float
    """
    heading, shift, spread, centre = (x[h] for x in hypotheses[:4])
    pairs = np.zeros((0, 2), dtype=np.int64)
    for _ in range(_REFINE_PASSES):
        d2 = _normalised_d2(a, b, var, heading, shift, spread, centre)
        column = _gated_assignment(np.where(d2 <= gate, d2, np.inf), gate)[1]
        rows = np.flatnonzero(column >= 0)
        new = np.stack([rows, column[rows]], axis=1)
        if len(new) < 2:
            return new, float(heading), shift
        if np.array_equal(new, pairs):
            break
        pairs = new
        heading, shift, spread, centre = fit_heading_shift(
            a[pairs[:, 0]], b[pairs[:, 1]], 1.0 / var[pairs[:, 0], pairs[:, 1]])
    return pairs, float(heading), shift


def _geometry_iv(stations, sigma, station_pairs, min_support, probability, inclinometer):
    names, points = [], []
    for item in stations:
        if not isinstance(item, tuple | list) or len(item) != 2:
            raise ConfigError("`stations` must be a sequence of (station_id, detections) "
                              f"pairs, got {type(item).__name__} {str(item)[:40]!r}")
        names.append(str(item[0]))
        points.append(_points(item[1], f"detections of station {names[-1]!r}"))
    if len(set(names)) != len(names) or "" in names:
        raise ConfigError(f"station ids must be unique and non-empty, got {names}")
    if isinstance(sigma, numbers.Real):
        if not (np.isfinite(sigma) and sigma > 0):
            raise ConfigError(f"`detection_sigma_m` must be finite and > 0 metres, got {sigma}")
        sigmas = [np.full(len(p), float(sigma)) for p in points]
    else:
        if len(sigma) != len(points):
            raise ConfigError(f"`detection_sigma_m` must be one number or one array per "
                              f"station ({len(points)}), got {len(sigma)} arrays")
        sigmas = [_sigmas(s, len(p), f"detection_sigma_m of station {n!r}")
                  for n, p, s in zip(names, points, sigma, strict=True)]
    index = {n: i for i, n in enumerate(names)}
    if station_pairs is None:
        pairs = [(i, j) for i in range(len(names)) for j in range(i + 1, len(names))]
    else:
        unknown = sorted({str(s) for pair in station_pairs for s in pair} - set(index))
        if unknown:
            raise ConfigError(f"`station_pairs` names unknown station(s) {', '.join(unknown)}; "
                              f"stations are {', '.join(names)}")
        pairs = sorted({tuple(sorted((index[str(x)], index[str(y)])))
                        for x, y in station_pairs if str(x) != str(y)})
    if not (isinstance(min_support, int | np.integer) and min_support >= 3):
        raise ConfigError(f"`min_correspondences` must be an integer >= 3, got {min_support}")
    if not 0 < probability < 1:
        raise ConfigError(f"`gate_probability` must be in (0, 1), got {probability}")
    if not (np.isfinite(inclinometer) and inclinometer >= 0):
        raise ConfigError(f"`inclinometer_sigma_rad` must be finite and >= 0, got {inclinometer}")
    return names, points, sigmas, pairs
