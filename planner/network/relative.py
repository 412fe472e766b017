"""``relative.csv`` and the ``relative`` section of ``markerplan adjust``: STAR*NET-style
relative error ellipses between neighbouring adjusted stations and between neighbouring
adjusted markers, judged against a local requirement.

The pairs and the allowance are :mod:`planner.accuracy.local`'s (every pair of stations at
most ``within_m`` apart horizontally; ``constant_m + ppm 1e-6 separation``, the meaning of a
plan's ``local_requirement_m/ppm``), and the same for every pair of adjusted markers
(:func:`planner.accuracy.local_markers.marker_pairs`; ``kind`` ``"station"`` or ``"marker"``,
``first``/``second`` their ids); the figures are :mod:`pipeline.network.relative`'s. A pair
passes when the semi-major axis of its 95 % horizontal relative ellipse is within its allowance
(as STAR*NET judges an ALTA/NSPS relative positional precision).
"""

from __future__ import annotations

import numpy as np

from planner.accuracy.local import LocalRequirement, point_pairs
from planner.accuracy.local_markers import marker_pairs

#: Columns of ``relative.csv`` (m, degrees).
RELATIVE_COLUMNS = ("kind", "first", "second", "separation_m", "horizontal_major_95_m",
                    "horizontal_minor_95_m", "azimuth_deg", "vertical_95_m", "ellipsoid_95_m",
                    "along_95_m", "allowed_95_m", "passed")
#: Digits of the figures in ``relative.csv`` and ``adjustment.json`` (0.1 um).
_DIGITS = 7


def relative_rows(result, requirement: LocalRequirement) -> list[dict]:
    """One row (:data:`RELATIVE_COLUMNS`) per pair of adjusted stations at most
    ``requirement.within_m`` apart horizontally, in lexicographic order of station index, then
    one per such pair of adjusted markers (in order of marker index).

    Parameters
    ----------
    result : pipeline.network.adjustment.NetworkAdjustment
    requirement : LocalRequirement

    Returns
    -------
    rows : list of dict
    """
    from pipeline.network.relative import (
        marker_pair_covariances,
        pair_covariances,
        relative_figures,
    )

    pairs = point_pairs(np.asarray(result.pose)[:, :3], requirement)
    rows = [] if not pairs.size else _rows(
        "station", result.observations.station_ids, pairs, relative_figures(
            pair_covariances(result.covariance, pairs.first, pairs.second), pairs.direction))
    xyz = np.asarray(result.marker_xyz_m, dtype=float).reshape(-1, 3)
    markers = marker_pairs(xyz, np.arange(xyz.shape[0]), requirement)
    if markers.size:
        cov = marker_pair_covariances(result.covariance, 6 * np.shape(result.pose)[0],
                                      markers.first, markers.second)
        rows += _rows("marker", result.observations.marker_ids, markers,
                      relative_figures(cov, markers.direction))
    return rows


def _rows(kind: str, ids, pairs, fig) -> list[dict]:
    """The rows of one kind's ``pairs`` (:class:`~planner.accuracy.local.PointPairs` of
    stations or of markers) with figures ``fig``."""
    return [{"kind": kind, "first": ids[int(a)], "second": ids[int(b)],
             "separation_m": round(float(pairs.separation_m[p]), 4),
             "horizontal_major_95_m": round(float(fig.horizontal_major_m[p]), _DIGITS),
             "horizontal_minor_95_m": round(float(fig.horizontal_minor_m[p]), _DIGITS),
             "azimuth_deg": round(float(fig.azimuth_deg[p]), 3),
             "vertical_95_m": round(float(fig.vertical_m[p]), _DIGITS),
             "ellipsoid_95_m": round(float(fig.ellipsoid_m[p]), _DIGITS),
             "along_95_m": round(float(fig.along_m[p]), _DIGITS),
             "allowed_95_m": round(float(pairs.allowed_m[p]), _DIGITS),
             "passed": bool(fig.horizontal_major_m[p] <= pairs.allowed_m[p])}
            for p, (a, b) in enumerate(zip(pairs.first, pairs.second, strict=True))]


def relative_section(rows: list[dict], requirement: LocalRequirement) -> dict:
    """The ``relative`` section of ``adjustment.json``: the requirement, counts and the worst
    pair (largest horizontal semi-major axis over its allowance; None without pairs), of the
    station pairs, then the same of the marker pairs (``n_marker_pairs``,
    ``n_marker_passed``, ``worst_marker_pair``)."""
    def worst(kind):
        of = [r for r in rows if r["kind"] == kind]
        return (max(of, key=lambda r: (r["horizontal_major_95_m"] / r["allowed_95_m"],
                                       r["first"], r["second"])) if of else None)

    stations = [r for r in rows if r["kind"] == "station"]
    markers = [r for r in rows if r["kind"] == "marker"]
    return {"requirement": requirement.describe().replace("(relative position)",
                                                          "(95 % horizontal relative ellipse)"),
            "requirement_m": requirement.constant_m, "requirement_ppm": requirement.ppm,
            "within_m": requirement.within_m, "n_pairs": len(stations),
            "n_passed": sum(r["passed"] for r in stations), "worst_pair": worst("station"),
            "n_marker_pairs": len(markers), "n_marker_passed": sum(r["passed"] for r in markers),
            "worst_marker_pair": worst("marker")}


def relative_markdown(section: dict | None, rows: list[dict]) -> list[str]:
    """The report's lines on relative accuracy (none without a ``relative`` section): the
    station pairs, then the marker pairs."""
    if section is None:
        return []
    lines = ["## Relative accuracy between neighbouring stations", "",
             f"Requirement: {section['requirement']}. Each pair's relative position (x, y, z "
             "of the two stations) has the covariance Σ_ii + Σ_jj − Σ_ij − Σ_ji; the 95 % "
             "horizontal ellipse is scaled by 2.447 (chi² with 2 degrees of freedom), the "
             "vertical and along-the-line figures by 1.96, the 3-D one by √chi²₃(0.95). "
             f"{section['n_passed']} of {section['n_pairs']} pairs pass.", ""]
    stations = [r for r in rows if r["kind"] == "station"]
    lines += _table(stations, "stations") if stations \
        else ["No pair of stations is that close.", ""]
    markers = [r for r in rows if r["kind"] == "marker"]
    if "n_marker_pairs" in section:
        lines += ["### Between neighbouring markers", "",
                  f"The same figures and requirement for every pair of adjusted markers as "
                  f"close: {section['n_marker_passed']} of {section['n_marker_pairs']} pairs "
                  "pass.", ""]
        lines += _table(markers, "markers") if markers \
            else ["No pair of markers is that close.", ""]
    return lines


def _table(rows: list[dict], what: str) -> list[str]:
    """The 20 pairs of ``rows`` nearest their allowance, as a table."""
    lines = [f"| {what} | separation | ellipse major / minor | azimuth | vertical | 3-D | "
             "along line | allowed | |", "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    shown = sorted(rows, key=lambda r: -r["horizontal_major_95_m"] / r["allowed_95_m"])[:20]
    lines += [f"| {r['first']}–{r['second']} | {r['separation_m']:.1f} m | "
              f"{1e3 * r['horizontal_major_95_m']:.1f} / {1e3 * r['horizontal_minor_95_m']:.1f}"
              f" mm | {r['azimuth_deg']:.1f}° | {1e3 * r['vertical_95_m']:.1f} mm | "
              f"{1e3 * r['ellipsoid_95_m']:.1f} mm | {1e3 * r['along_95_m']:.1f} mm | "
              f"{1e3 * r['allowed_95_m']:.1f} mm | {'pass' if r['passed'] else 'FAIL'} |"
              for r in shown]
    if len(rows) > len(shown):
        lines += ["", f"The {len(shown)} pairs nearest their allowance; all {len(rows)} in "
                      "relative.csv."]
    return lines + [""]
