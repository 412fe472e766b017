"""``verify --network`` of a plan with a local requirement: each judged station pair's achieved
relative error against its prediction and allowance.

A station's registration error at a point ``q`` of its working disc is ``D(q) = T_est(q) -
T_true(q)``, the difference between the adjusted and the true mapping of its levelled frame
into the site frame (:func:`planner.accuracy.known_control.registration_differences`, as
:func:`~planner.accuracy.known_control.pose_difference_m`). The pair's
achieved relative error is the worst over both discs (the station and 72 rim points each, as
the prediction) of ``|D_k(q) - D_l(q')|`` (``"position"``) or ``|u . (D_k(q) - D_l(q'))|``
(``"distance"``, ``u`` the unit vector between the planned stations): what a surveyor who
stakes out from both stations' clouds would see between them.

With ``local_markers`` (the plan's ``local`` holds ``marker_pairs``) each judged pair of markers
is verified too: its achieved relative error is ``|delta_k - delta_j|`` (``"position"``) or
``|u . (delta_k - delta_j)|`` (``"distance"``, ``u`` between the planned centres), ``delta``
each marker's adjusted minus true centre (:func:`marker_pair_outcomes`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.accuracy.known_control import registration_differences

#: Rim points of each disc (as the predicted figure's).
_N_RIM = 72


@dataclass(frozen=True)
class PairOutcome:
    """Predicted against achieved for one station pair (m; ``None`` where there is none)."""

    first: str
    second: str
    separation_m: float
    predicted_error_m: float | None
    achieved_error_m: float | None
    allowed_error_m: float
    passed: bool

    def to_json(self) -> dict:
        return {"stations": [self.first, self.second], "separation_m": self.separation_m,
                "predicted_error_m": self.predicted_error_m,
                "achieved_error_m": self.achieved_error_m,
                "allowed_error_m": self.allowed_error_m, "passed": self.passed}


def relative_error_m(errors_first: np.ndarray, errors_second: np.ndarray, kind: str,
                     direction: np.ndarray) -> float:
    """The worst relative error of two stations' registration errors ((73, 3) each) over both
    discs, m: ``max |D_k(q) - D_l(q')|`` or, for ``"distance"``, ``max |u . (D_k - D_l)|``
    (two markers: (1, 3) each, their centres' errors).

    >>> d = np.zeros((73, 3)); e = d.copy(); e[:, 0] = 0.01
    >>> relative_error_m(d, e, "position", np.array([0, 1.0, 0]))
    0.01
    >>> relative_error_m(d, e, "distance", np.array([0, 1.0, 0]))
    0.0
    """
    if kind == "distance":
        a, b = errors_first @ direction, errors_second @ direction
        return float(max(a.max() - b.min(), b.max() - a.min()))
    diff = errors_first[:, None, :] - errors_second[None, :, :]
    return float(np.sqrt(np.einsum("ija,ija->ij", diff, diff).max()))


def pair_outcomes(local: dict, station_xyz: dict[str, np.ndarray],
                  adjusted: dict[str, np.ndarray], truth: dict[str, np.ndarray],
                  radius_m: float) -> list[PairOutcome]:
    """Every judged pair of a plan's ``local`` section, predicted against achieved.

    Parameters
    ----------
    local : dict
        ``plan.json``'s ``local`` (:func:`planner.outputs.local_report.local_record`).
    station_xyz : dict of id -> (3,) float
        Planned station positions (the pair's direction), m.
    adjusted, truth : dict of id -> (6,) float
        Adjusted and true poses of the stations the adjustment holds.
    radius_m : float
        Working radius, m.

    Returns
    -------
    list of PairOutcome
        A pair with a station the adjustment lacks has no achieved error and fails.
    """
    errors = {sid: registration_differences(adjusted[sid], truth[sid], radius_m, _N_RIM)
              for sid in adjusted if sid in truth}
    return _outcomes(local["pairs"], "stations", errors, station_xyz, local["local_kind"])


def _outcomes(rows: list[dict], key: str, errors: dict[str, np.ndarray],
              xyz: dict[str, np.ndarray], kind: str) -> list[PairOutcome]:
    """Each pair record of ``rows`` (ids under ``key``) against the achieved errors of its two
    points (``errors``: id -> (k, 3) adjusted minus true, m; a pair with a point missing has no
    achieved error and fails), along the line between their planned positions ``xyz``."""
    out = []
    for row in rows:
        a, b = row[key]
        achieved = None
        if a in errors and b in errors:
            delta = np.asarray(xyz[b], float) - np.asarray(xyz[a], float)
            norm = np.linalg.norm(delta)
            achieved = relative_error_m(errors[a], errors[b], kind,
                                        delta / norm if norm > 0 else delta)
        allowed = float(row["allowed_error_m"])
        out.append(PairOutcome(a, b, float(row["separation_m"]), row["predicted_error_m"],
                               achieved, allowed, achieved is not None and achieved <= allowed))
    return out


def marker_pair_outcomes(local: dict | None, marker_xyz: dict[str, np.ndarray],
                         markers) -> list[PairOutcome]:
    """Every judged marker pair of a plan's ``local`` section (none without ``marker_pairs``),
    predicted against achieved.

    Parameters
    ----------
    local : dict or None
        ``plan.json``'s ``local``.
    marker_xyz : dict of id -> (3,) float
        Planned marker centres (the pair's direction), m.
    markers : list of planner.verify.network.MarkerOutcome
        The adjusted markers (``achieved_xyz_m``: adjusted minus true centre, m).

    Returns
    -------
    list of PairOutcome
        ``first``/``second`` the markers' ids; a pair with a marker the adjustment lacks has no
        achieved error and fails.

    Examples
    --------
    >>> from types import SimpleNamespace as N
    >>> local = {"local_kind": "position", "marker_pairs": [{"markers": ["a", "b"],
    ...          "separation_m": 5.0, "predicted_error_m": 0.01, "allowed_error_m": 0.02}]}
    >>> got = marker_pair_outcomes(local, {"a": np.zeros(3), "b": np.array([5.0, 0, 0])},
    ...                            [N(marker_id="a", achieved_xyz_m=(0.0, 0.0, 0.0)),
    ...                             N(marker_id="b", achieved_xyz_m=(0.003, 0.004, 0.0))])
    >>> round(got[0].achieved_error_m, 6), got[0].passed
    (0.005, True)
    """
    if not local or "marker_pairs" not in local:
        return []
    errors = {m.marker_id: np.asarray(m.achieved_xyz_m, float)[None] for m in markers}
    return _outcomes(local["marker_pairs"], "markers", errors, marker_xyz, local["local_kind"])


def pairs_record(local: dict, outcomes: list[PairOutcome],
                 marker_outcomes: list[PairOutcome] = ()) -> dict:
    """``verify.json``'s ``local`` section: the requirement, every pair, and the worst (with
    ``local_markers`` also ``marker_pairs``, each with ``markers`` for ``stations``, and
    ``markers_passed``)."""
    achieved = [p for p in outcomes if p.achieved_error_m is not None]
    worst = max(achieved, key=lambda p: p.achieved_error_m / p.allowed_error_m, default=None)
    out = {"requirement_text": local["requirement_text"], "local_kind": local["local_kind"],
           "n_pairs": len(outcomes), "passed": all(p.passed for p in outcomes),
           "worst": None if worst is None else worst.to_json(),
           "pairs": [p.to_json() for p in outcomes]}
    if "marker_pairs" in local:
        out["markers_passed"] = all(p.passed for p in marker_outcomes)
        out["marker_pairs"] = [{"markers": j.pop("stations"), **j}
                               for j in (p.to_json() for p in marker_outcomes)]
    return out


def pairs_markdown(rec: dict) -> list[str]:
    """The verification report's "Local accuracy" lines (none without the section)."""
    local = rec.get("local")
    if local is None:
        return []

    lines = ["", "## Local accuracy", "",
             f"Requirement: {local['requirement_text']}; {local['n_pairs']} station pairs, "
             f"{'all' if local['passed'] else 'not all'} within it.", "",
             *_worst_table("pair", "stations", local["pairs"])]
    if "marker_pairs" in local:
        lines += ["", f"Marker pairs: {len(local['marker_pairs'])}, "
                      f"{'all' if local['markers_passed'] else 'not all'} within it.", "",
                  *_worst_table("markers", "markers", local["marker_pairs"])]
    return lines


def _worst_table(heading: str, key: str, pairs: list[dict]) -> list[str]:
    """The Markdown table of the ten pairs (ids under ``key``) worst relative to their
    allowance, achieved against predicted."""

    def mm(v):
        return "—" if v is None else f"{1e3 * v:.1f} mm"

    lines = [f"| {heading} | separation | predicted | achieved | allowed | passed |",
             "|---|---:|---:|---:|---:|---|"]
    for p in sorted(pairs, key=lambda p: -(p["achieved_error_m"] or np.inf)
                    / p["allowed_error_m"])[:10]:
        lines.append(f"| {p[key][0]}–{p[key][1]} | {p['separation_m']:.1f} m | "
                     f"{mm(p['predicted_error_m'])} | {mm(p['achieved_error_m'])} | "
                     f"{mm(p['allowed_error_m'])} | {'yes' if p['passed'] else 'no'} |")
    return lines
