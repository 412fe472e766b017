"""Where the chain lost each marker: the fate of every known marker of one processed station.

Given a station's :class:`~pipeline.chain.process.StationResult` and the true marker centres in its
station frame (the simulator's truth, or a plan's markers projected with the station's pose),
each marker gets the stage of the chain that lost it
(:data:`pipeline.tables.fate_table.FATE_STAGES`, in chain order):

=================  ===========================================================================
stage              the marker ...
=================  ===========================================================================
``not_in_view``    has no return at all (``n_points`` = 0, when known)
``ground``         keeps fewer than the cluster stage's ``min_points`` of the detection
                   subset's points within ``R + shell`` of its centre above the ground stage's
                   ``min_height_m`` (thinned away, cut with the ground, or out of range)
``cluster``        has those points, but most lie in no cluster of ``min_points``
``gate``           lies in a cluster the two-box gate refused (reason: the gate's verdict,
                   ``too_large`` / ``too_small``, and the other markers the cluster holds)
``fit``            lies in a passing cluster, but no fitted candidate lies within ``R`` of it
                   (the re-search found too few points, the fit diverged or ran away)
``quality``        has a candidate within ``R`` that the quality gate rejected (reason: the
                   gate's reason)
``accepted``       has an accepted candidate within ``R``
=================  ===========================================================================

Accepted candidates farther than ``R`` from every known marker are false accepts
(:func:`false_accepts`): rocks, terrain, or a fit that walked off its marker.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

from markerplan.errors import ConfigError
from pipeline.chain.process import StationResult

#: How far outside the sphere a point still counts as the marker's, metres: its range noise
#: (a few millimetres to 3 cm) but not the mixed-return tail behind it (decimetres).
MARKER_SHELL_M = 0.05


@dataclass(frozen=True)
class MarkerFate:
    """One known marker's fate in the chain.

    Attributes
    ----------
    marker_id : str
    stage : str
        One of :data:`pipeline.tables.fate_table.FATE_STAGES`.
    reason : str
        The detail of the stage (the gate's verdict, the quality gate's reason); ``""`` when
        accepted.
    n_above_ground : int
        Detection-subset points within ``R + MARKER_SHELL_M`` of the centre above the ground.
    row_index : int
        Index into ``result.rows`` of the candidate matched to the marker, ``-1`` if none.
    """

    marker_id: str
    stage: str
    reason: str
    n_above_ground: int
    row_index: int

    def to_dict(self) -> dict:
        return asdict(self)


def marker_fates(result: StationResult, centres_station_m: np.ndarray,
                 marker_ids: Sequence[str], radius_m: float, min_points: int,
                 n_points: Sequence[int] | None = None) -> list[MarkerFate]:
    """The fate of each known marker of one processed station.

    Parameters
    ----------
    result : StationResult
        From :func:`pipeline.chain.process.process_station`.
    centres_station_m : (m, 3) float
        The markers' true centres in the station frame, metres.
    marker_ids : sequence of str, length m
    radius_m : float
        Marker radius ``R``, metres (the match distance of a candidate to its marker).
    min_points : int
        The cluster stage's ``min_points``.
    n_points : sequence of int, length m, optional
        Returns on each marker (the simulator's truth); ``0`` makes ``not_in_view``.

    Returns
    -------
    fates : list of MarkerFate, length m
        In the order of ``marker_ids``.
    """
    centres = np.asarray(centres_station_m, dtype=float).reshape(-1, 3)
    ids = list(marker_ids)
    if len(ids) != len(centres) or (n_points is not None and len(n_points) != len(ids)):
        raise ConfigError(f"marker_fates needs one id (got {len(ids)}) and one point count per "
                          f"marker centre (got {len(centres)} centres)")
    if not radius_m > 0:
        raise ConfigError(f"marker_fates needs a marker radius > 0 metres, got {radius_m}")
    det = result.detection
    near = _points_near(det.above_xyz_m, centres, radius_m + MARKER_SHELL_M)
    rows = _nearest_rows(result, centres, radius_m)
    fates = []
    for k, mid in enumerate(ids):
        labels = det.labels[near[k]]
        stage, reason = _stage(k, labels, det.verdicts, near, det.labels, ids, rows[k],
                               result, min_points, n_points)
        fates.append(MarkerFate(mid, stage, reason, len(labels), rows[k]))
    return fates


def false_accepts(result: StationResult, centres_station_m: np.ndarray, radius_m: float
                  ) -> list[int]:
    """Indices into ``result.rows`` of accepted rows farther than ``radius_m`` from every
    known marker centre (station frame, metres)."""
    centres = np.asarray(centres_station_m, dtype=float).reshape(-1, 3)
    accepted = [i for i, r in enumerate(result.rows) if r.accepted]
    if not len(centres):
        return accepted
    tree = cKDTree(centres)
    return [i for i in accepted
            if tree.query(result.rows[i].centre_m)[0] > radius_m]


def _points_near(xyz_m: np.ndarray, centres_m: np.ndarray, reach_m: float
                 ) -> list[np.ndarray]:
    """Indices of ``xyz_m`` within ``reach_m`` of each centre."""
    if not len(xyz_m):
        return [np.zeros(0, dtype=np.int64) for _ in centres_m]
    tree = cKDTree(xyz_m)
    return [np.asarray(sorted(i), dtype=np.int64)
            for i in tree.query_ball_point(centres_m, reach_m)]


def _nearest_rows(result: StationResult, centres_m: np.ndarray, radius_m: float) -> list[int]:
    """Per marker, the row within ``radius_m`` of it (accepted first, then nearest), or -1."""
    out = []
    for c in centres_m:
        best = (True, np.inf, -1)
        for i, r in enumerate(result.rows):
            d = float(np.linalg.norm(r.centre_m - c))
            if d <= radius_m:
                best = min(best, (not r.accepted, d, i))
        out.append(best[2])
    return out


def _stage(k, labels, verdicts, near, all_labels, ids, row, result, min_points, n_points
           ) -> tuple[str, str]:
    """The stage that lost marker ``k`` and its detail (see the module docstring)."""
    if row >= 0:
        r = result.rows[row]
        return ("accepted", "") if r.accepted else ("quality", r.reason)
    if n_points is not None and int(n_points[k]) == 0:
        return "not_in_view", "no return on the marker"
    if len(labels) < min_points:
        return "ground", f"{len(labels)} point(s) above the ground (needs {min_points})"
    clustered = labels[labels >= 0]
    if 2 * len(clustered) < len(labels):
        return "cluster", f"{len(labels) - len(clustered)} of {len(labels)} points in no cluster"
    label = int(np.bincount(clustered).argmax())
    if verdicts[label] != "passed":
        shared = [ids[j] for j in range(len(ids))
                  if j != k and np.any(all_labels[near[j]] == label)]
        with_others = f" (one cluster with {', '.join(shared)})" if shared else ""
        return "gate", f"{verdicts[label]}{with_others}"
    return "fit", "no fitted candidate within a radius of the marker"
