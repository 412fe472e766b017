"""A network plan's local accuracy in its outputs: ``plan.json``'s ``local`` section, the
``pairs.csv`` table (one row per judged station pair) and the report's "Local accuracy".

``local`` (present when the plan has a local requirement,
:mod:`planner.accuracy.local`): the requirement in words and its numbers, ``n_pairs``,
``meets_requirement``, and ``pairs``: every judged pair's station ids, horizontal separation,
predicted 95 % relative error and allowance (m), and whether it meets it. With
``local_markers`` (:mod:`planner.accuracy.local_markers`) also ``n_marker_pairs``,
``markers_meet_requirement``, ``worst_marker_pair`` and ``marker_pairs`` (each pair of selected
markers' site ids as ``markers``, the same fields), and ``marker_pairs.csv`` (the columns of
``pairs.csv``). ``after_any_single_loss`` (redundant mode): every predicted error is the
worst with the plan and after the loss of any one selected marker (a marker pair one of whose
markers is lost no longer exists and is not judged in that loss).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from markerplan.writing import json_float, write_gis_sidecars

#: ``pairs.csv``: header and ``.csvt`` column types.
PAIR_COLUMNS = ("first", "second", "separation_m", "predicted_error_m", "allowed_error_m",
                "meets_requirement", "kind")
PAIR_TYPES = ("String", "String", "Real", "Real", "Real", "Integer", "String")



def local_record(outcome, net) -> dict | None:
    """The ``local`` section of a network plan (None without a local requirement).

    Parameters
    ----------
    outcome : planner.run.PlanOutcome
    net : planner.accuracy.network.NetworkModel
        The plan's network model.
    """
    from planner.accuracy.local import local_accuracy

    local = local_accuracy(net, outcome.config)
    if local is None:
        return None
    errors = outcome.result.check.pair_error_m
    if errors is None:
        errors = local.errors(net.covariance(net.information(outcome.result.selected)))
    pairs, req = local.pairs, local.requirement
    rows, worst = _pair_rows("stations", outcome.problem.station_ids, pairs, errors)
    out = {"requirement_text": req.describe(), "local_requirement_m": req.constant_m,
           "local_requirement_ppm": req.ppm, "local_within_m": req.within_m,
           "local_kind": req.kind, "n_pairs": pairs.size,
           "meets_requirement": all(r["meets_requirement"] for r in rows),
           "worst_pair": worst, "pairs": rows,
           "after_any_single_loss": bool(outcome.config.redundant)}
    return {**out, **_marker_pairs_record(outcome, net)}


def _marker_pairs_record(outcome, net) -> dict:
    """``local``'s marker-pair fields (none without ``local_markers``)."""
    from planner.accuracy.local_markers import local_marker_accuracy

    local = local_marker_accuracy(net, outcome.config)
    if local is None:
        return {}
    selected = outcome.result.selected
    pairs = local.pairs(selected)
    errors = outcome.result.check.marker_pair_error_m
    if errors is None or errors.size != pairs.size:
        errors = local.errors(net.covariance(net.information(selected)), pairs)
    rows, worst = _pair_rows("markers", outcome.problem.site_ids, pairs, errors)
    return {"n_marker_pairs": pairs.size,
            "markers_meet_requirement": all(r["meets_requirement"] for r in rows),
            "worst_marker_pair": worst, "marker_pairs": rows}


def _pair_rows(key: str, ids, pairs, errors: np.ndarray) -> tuple[list[dict], dict | None]:
    """One record per pair (``key``: ``"stations"`` or ``"markers"``, their ``ids``) with its
    separation, predicted error ``errors`` ((p,) m) and allowance, and the worst of them
    relative to its allowance (None without pairs)."""
    rows = [{key: [ids[a], ids[b]], "separation_m": round(float(d), 3),
             "predicted_error_m": json_float(e), "allowed_error_m": float(allowed),
             "meets_requirement": bool(e <= allowed)}
            for a, b, d, e, allowed in zip(pairs.first, pairs.second, pairs.separation_m,
                                           errors, pairs.allowed_m, strict=True)]
    if not pairs.size:
        return rows, None
    return rows, rows[int(np.argmax(np.nan_to_num(errors / pairs.allowed_m, posinf=1e300)))]


def write_pairs_csv(doc: dict, path: Path, markers: bool = False) -> None:
    """``pairs.csv`` of a plan with a local requirement (header first), with its ``.csvt``;
    ``markers``: ``marker_pairs.csv`` (the marker pairs, their site ids first)."""
    local = doc["local"]
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(PAIR_COLUMNS)
        for r in local["marker_pairs" if markers else "pairs"]:
            err = r["predicted_error_m"]
            w.writerow([*r["markers" if markers else "stations"], f"{r['separation_m']:.3f}",
                        "inf" if err is None else f"{err:.4f}", f"{r['allowed_error_m']:.4f}",
                        int(r["meets_requirement"]), local["local_kind"]])
    write_gis_sidecars(path, PAIR_TYPES, None)


def local_markdown(doc: dict) -> list[str]:
    """The report's "Local accuracy" lines (none without a local requirement)."""
    local = doc.get("local")
    if local is None:
        return []
    lines = ["", "## Local accuracy", "",
             f"Requirement: {local['requirement_text']}, 95 % "
             f"({doc['requirement']['error_figure_text']}); {local['n_pairs']} station pairs "
             f"judged, {'all' if local['meets_requirement'] else 'not all'} within it "
             "(`pairs.csv`)."]
    if local.get("after_any_single_loss"):
        lines += ["", "Redundant mode: each predicted error is the worst with every marker and "
                      "after the loss of any one selected marker (a marker pair whose marker is "
                      "lost is not judged in that loss)."]
    ranked = sorted(local["pairs"], key=lambda r: -math.inf if r["predicted_error_m"] is None
                    else -r["predicted_error_m"] / r["allowed_error_m"])[:5]
    if ranked:
        lines += ["", "| pair | separation | predicted | allowed |", "|---|---:|---:|---:|"]
        for r in ranked:
            err = r["predicted_error_m"]
            lines.append(f"| {r['stations'][0]}–{r['stations'][1]} | {r['separation_m']:.1f} m "
                         f"| {'n/a' if err is None else f'{err:.4f} m'} | "
                         f"{r['allowed_error_m']:.4f} m |")
    if "marker_pairs" in local:
        lines += ["", f"Marker pairs (selected markers within {local['local_within_m']:g} m): "
                      f"{local['n_marker_pairs']} judged, "
                      f"{'all' if local['markers_meet_requirement'] else 'not all'} within it "
                      "(`marker_pairs.csv`)."]
        ranked = sorted(local["marker_pairs"], key=lambda r: -math.inf
                        if r["predicted_error_m"] is None
                        else -r["predicted_error_m"] / r["allowed_error_m"])[:5]
        if ranked:
            lines += ["", "| markers | separation | predicted | allowed |",
                      "|---|---:|---:|---:|"]
            lines += [f"| {r['markers'][0]}–{r['markers'][1]} | {r['separation_m']:.1f} m | "
                      + ("n/a" if r["predicted_error_m"] is None
                         else f"{r['predicted_error_m']:.4f} m")
                      + f" | {r['allowed_error_m']:.4f} m |" for r in ranked]
    return lines
