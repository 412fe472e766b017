"""Evaluation against reference marker coordinates.

A reference is either simulation truth (marker centres already in each station's frame) or a
total-station CSV ``id,x_m,y_m,z_m`` in some other frame. Station-frame references are matched
to detections by nearest centre (one-to-one, gated); an external CSV is first aligned by a
best-fit rigid registration found from edge-length-consistent marker triplets (RANSAC-like),
then matched the same way. Errors are estimate minus (registered) reference, station frame.
Edge residuals (|estimated edge| - |reference edge| for every pair of matched, accepted
markers) need no common frame at all. :func:`evaluate_rows` does all of this for one station's
marker rows; :func:`pick_reference` and :func:`check_references` pair references with stations.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from markerplan.errors import ConfigError, DataError, InputFileError
from markerplan.reading import MAX_ABS_COORDINATE_M, finite_number, read_csv, unique_ids
from pipeline.chain.stages import EvaluateStage
from pipeline.scans.scan_format import read_truth
from pipeline.tables.marker_table import MarkerRow

REFERENCE_CSV_COLUMNS = ("id", "x_m", "y_m", "z_m")


@dataclass(frozen=True)
class Reference:
    """Reference marker centres.

    Attributes
    ----------
    ids : tuple of str
    centres_m : (M, 3) float
        Metres; station frame when ``station_id`` is set, else an external frame.
    station_id : str or None
        The station whose frame ``centres_m`` is in (simulation truth), None for a CSV.
    source : str
        File it came from.
    marker_radius_m : float or None
        Radius of the markers, metres, when the reference records it (simulation truth).
    """

    ids: tuple[str, ...]
    centres_m: np.ndarray
    station_id: str | None
    source: str
    marker_radius_m: float | None = None


def read_reference(path: str | Path) -> Reference:
    """Read a truth JSON (``*.json``) or a total-station CSV ``id,x_m,y_m,z_m``.

    Raises
    ------
    InputFileError
        Missing/unreadable/non-UTF-8 file, missing columns or keys, ragged rows, empty or
        repeated ids, coordinates that are not finite numbers (or beyond
        :data:`markerplan.reading.MAX_ABS_COORDINATE_M`); a truth JSON as in
        :func:`pipeline.scans.scan_format.read_truth`.
    DataError
        No markers in the file.
    """
    path = Path(path)
    if path.suffix.lower() == ".json":
        ref = reference_from_truth(read_truth(path), str(path))
    else:
        ref = _read_reference_csv(path)
    if not ref.ids:
        raise DataError(f"reference {path} lists no markers")
    return ref


def reference_from_truth(truth: dict, source: str = "simulator truth") -> Reference:
    """The reference of a simulated station: its truth's marker ids and station-frame centres.

    Parameters
    ----------
    truth : dict
        A truth record (``read_truth`` / the simulator's second return value).
    source : str
        Where it came from, for messages and outputs.

    Raises
    ------
    InputFileError
        A marker without ``id`` or a ``centre_station_m`` of 3 finite numbers, or a repeated
        id.
    """
    try:
        ids = tuple(str(m["id"]) for m in truth["markers"])
        centres = np.array([m["centre_station_m"] for m in truth["markers"]],
                           dtype=float).reshape(-1, 3)
        station = str(truth["station_id"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputFileError(f"{source}: every marker needs 'id' and a 3-element "
                             f"'centre_station_m' ({exc})") from exc
    if centres.shape[0] != len(ids) or not np.all(np.isfinite(centres)):
        raise InputFileError(f"{source}: every marker needs a 'centre_station_m' of 3 finite "
                             "numbers")
    unique_ids(ids, f"{source}: markers")
    return Reference(ids, centres, station, source, truth.get("marker_radius_m"))


def _read_reference_csv(path: Path) -> Reference:
    what = f"reference CSV {path}"
    if not path.is_file():
        raise InputFileError(f"reference file {path} does not exist; check the path")
    header, rows = read_csv(path, what)
    missing = [c for c in REFERENCE_CSV_COLUMNS if c not in header]
    if missing:
        raise InputFileError(f"{what} lacks column(s) {', '.join(missing)}; got "
                             f"{','.join(header)[:80]!r}; expected a header "
                             f"{','.join(REFERENCE_CSV_COLUMNS)}")
    col = {c: header.index(c) for c in REFERENCE_CSV_COLUMNS}
    ids = unique_ids([r[col["id"]].strip() for r in rows], what)
    centres = np.array([[_coordinate(r[col[c]], c, i, what) for c in ("x_m", "y_m", "z_m")]
                        for i, r in zip(ids, rows, strict=True)], dtype=float).reshape(-1, 3)
    return Reference(tuple(ids), centres, None, str(path))


def _coordinate(cell: str, column: str, marker: str, what: str) -> float:
    """One coordinate cell as a finite float, or one line naming the marker and the rule."""
    try:
        return finite_number(cell.strip(), f"{what}: {column} of {marker!r}")
    except InputFileError as exc:
        raise InputFileError(f"{what}: x_m, y_m, z_m must be finite numbers of magnitude at "
                             f"most {MAX_ABS_COORDINATE_M:g} m; {column} of {marker!r} is "
                             f"{cell.strip()!r:.40}") from exc


def match_nearest(centres_m: np.ndarray, reference_m: np.ndarray, max_distance_m: float = 0.5
                  ) -> np.ndarray:
    """One-to-one matching of detections to references by distance (Hungarian, gated).

    Parameters
    ----------
    centres_m : (K, 3) float
    reference_m : (M, 3) float
        Same frame, metres.
    max_distance_m : float
        Pairs farther apart never match.

    Returns
    -------
    match : (K,) int
        Reference index of each detection, -1 if unmatched.
    """
    k = centres_m.shape[0]
    match = np.full(k, -1, dtype=np.int64)
    if k == 0 or reference_m.shape[0] == 0:
        return match
    d = np.linalg.norm(centres_m[:, None, :] - reference_m[None, :, :], axis=2)
    cost = np.where(d <= max_distance_m, d, 1e6)
    rows, cols = linear_sum_assignment(cost)
    ok = cost[rows, cols] < 1e6
    match[rows[ok]] = cols[ok]
    return match


def kabsch(src_m: np.ndarray, dst_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transform minimising ``sum |R src + t - dst|^2``; returns ``(R (3,3), t (3,))``."""
    cs, cd = src_m.mean(axis=0), dst_m.mean(axis=0)
    h = (src_m - cs).T @ (dst_m - cd)
    u, _, vt = np.linalg.svd(h)
    s = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    rot = vt.T @ s @ u.T
    return rot, cd - rot @ cs


def register_reference(centres_m: np.ndarray, reference_m: np.ndarray, tol_m: float = 0.15
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Find the rigid transform of an external reference into the station frame.

    Hypotheses come from triplets whose three edge lengths agree within ``tol_m``; the one
    that brings most detections within ``tol_m`` of a reference wins, then it is refined on
    all its matches.

    Parameters
    ----------
    centres_m : (K, 3) float
        Accepted detections, station frame.
    reference_m : (M, 3) float
        Reference centres, external frame.
    tol_m : float
        Edge-length and match tolerance, metres.

    Returns
    -------
    match : (K,) int
        Reference index per detection, -1 unmatched.
    rotation : (3, 3) float
    translation : (3,) float
        ``station = rotation @ reference + translation``.

    Raises
    ------
    DataError
        Fewer than three detections or references, or no consistent triplet.
    """
    k, m = centres_m.shape[0], reference_m.shape[0]
    if k < 3 or m < 3:
        raise DataError(f"registering a reference CSV needs >= 3 accepted markers and >= 3 "
                        f"reference points, got {k} and {m}")
    dd = np.linalg.norm(centres_m[:, None] - centres_m[None], axis=2)
    dm = np.linalg.norm(reference_m[:, None] - reference_m[None], axis=2)
    best = (0, np.inf, None)
    for i, j in itertools.combinations(range(k), 2):
        ab = np.argwhere(np.abs(dm - dd[i, j]) < tol_m)
        for a, b in ab:
            if a == b:
                continue
            for c_det in range(k):
                if c_det in (i, j):
                    continue
                cs = np.flatnonzero((np.abs(dm[a] - dd[i, c_det]) < tol_m)
                                    & (np.abs(dm[b] - dd[j, c_det]) < tol_m))
                for c in cs:
                    if c in (a, b):
                        continue
                    src = reference_m[[a, b, c]]
                    if np.linalg.norm(np.cross(src[1] - src[0], src[2] - src[0])) < 1e-3:
                        continue
                    rot, t = kabsch(src, centres_m[[i, j, c_det]])
                    match = match_nearest(centres_m, reference_m @ rot.T + t, tol_m)
                    n = int((match >= 0).sum())
                    if n < 3:
                        continue
                    ok = match >= 0
                    err = np.linalg.norm(centres_m[ok] - (reference_m[match[ok]] @ rot.T + t),
                                         axis=1)
                    score = (n, float(np.mean(err ** 2)))
                    if score[0] > best[0] or (score[0] == best[0] and score[1] < best[1]):
                        best = (n, score[1], (rot, t))
            if best[0] == min(k, m):
                break
        if best[0] == min(k, m):
            break
    if best[2] is None:
        raise DataError("no three detected markers match the reference CSV's edge lengths "
                        f"within {tol_m} m; check the reference or the marker ids")
    rot, t = best[2]
    for _ in range(3):
        match = match_nearest(centres_m, reference_m @ rot.T + t, tol_m)
        ok = match >= 0
        rot, t = kabsch(reference_m[match[ok]], centres_m[ok])
    return match_nearest(centres_m, reference_m @ rot.T + t, tol_m), rot, t


def edge_residuals(ids: list[str], estimated_m: np.ndarray, reference_m: np.ndarray
                   ) -> list[dict]:
    """Length residual of every marker-to-marker edge.

    Parameters
    ----------
    ids : list of str
        Marker ids, one per row of the two arrays.
    estimated_m, reference_m : (K, 3) float
        Estimated and reference centres (each in its own frame), metres.

    Returns
    -------
    edges : list of dict
        ``{"marker_a", "marker_b", "reference_length_m", "estimated_length_m", "residual_m"}``.
    """
    out = []
    for a, b in itertools.combinations(range(len(ids)), 2):
        le = float(np.linalg.norm(estimated_m[a] - estimated_m[b]))
        lr = float(np.linalg.norm(reference_m[a] - reference_m[b]))
        out.append({"marker_a": ids[a], "marker_b": ids[b], "reference_length_m": lr,
                    "estimated_length_m": le, "residual_m": le - lr})
    return out


def evaluate_rows(rows: list[MarkerRow], reference: Reference | None, cfg: EvaluateStage
                  ) -> tuple[list[dict], dict[str, Any]]:
    """Match rows to the reference (in place: marker_id, errors), edge residuals, summary.

    Returns
    -------
    edges : list of dict
        See :func:`edge_residuals`, plus ``station_id``.
    summary : dict
        Matched counts, mean/max centre error of accepted markers, edge statistics.
    """
    if reference is None or not rows:
        return [], {"reference": None if reference is None else reference.source}
    centres = np.array([r.centre_m for r in rows])
    ref = reference.centres_m
    accepted = np.array([r.accepted for r in rows])
    registered = reference.station_id is None
    if registered:
        try:
            _, rot, t = register_reference(centres[accepted], ref, cfg.registration_tol_m)
        except DataError as exc:  # too few accepted markers at this station: no evaluation
            return [], {"reference": reference.source, "registered": False,
                        "evaluation_error": str(exc)}
        ref = ref @ rot.T + t
        match = match_nearest(centres, ref, cfg.registration_tol_m)
    else:
        match = match_nearest(centres, ref, cfg.match_distance_m)
    for r, m in zip(rows, match, strict=True):
        r.marker_id = reference.ids[m] if m >= 0 else ""
        r.set_error(ref[m] if m >= 0 else None)
    use = [i for i, r in enumerate(rows) if r.accepted and match[i] >= 0]
    ids = [reference.ids[match[i]] for i in use]
    edges = edge_residuals(ids, centres[use], reference.centres_m[match[use]])
    for e in edges:
        e["station_id"] = rows[0].station_id
    errs = np.array([rows[i].error_m for i in use])
    resid = np.array([e["residual_m"] for e in edges])
    matched_all = {reference.ids[m] for m in match if m >= 0}
    return edges, {
        "reference": reference.source, "registered": registered,
        "n_reference": len(reference.ids), "n_matched_accepted": len(use),
        "unmatched_reference_ids": sorted(set(reference.ids) - matched_all),
        "mean_error_m": float(errs.mean()) if errs.size else None,
        "max_error_m": float(errs.max()) if errs.size else None,
        "n_edges": len(edges),
        "mean_abs_edge_residual_m": float(np.abs(resid).mean()) if resid.size else None,
        "rms_edge_residual_m": float(np.sqrt(np.mean(resid ** 2))) if resid.size else None,
    }



def pick_reference(references: list[Reference], station_id: str) -> Reference | None:
    """The reference for a station: its own truth file, else the (single) external CSV."""
    own = [r for r in references if r.station_id == station_id]
    if own:
        return own[0]
    external = [r for r in references if r.station_id is None]
    return external[0] if external else None


def check_references(references: list[Reference]) -> None:
    """At most one external (CSV) reference; at most one truth file per station."""
    external = [r.source for r in references if r.station_id is None]
    if len(external) > 1:
        raise ConfigError(f"give at most one total-station CSV reference, got {external}")
    ids = [r.station_id for r in references if r.station_id is not None]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise ConfigError(f"several truth files for station(s) {', '.join(dup)}; give one each")

