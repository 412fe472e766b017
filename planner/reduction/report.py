"""Outputs of ``markerplan reduce``: ``reduce.json``, ``tradeoff.csv``, ``per_station.csv``,
``drop_order.csv``, ``marker_loss.csv``, ``report.md`` and the ``--json`` summary.

``reduce.json`` schema ``markerplan-reduce`` version 1 (lengths in metres, site frame):

- ``schema``, ``schema_version``, ``provenance`` (:func:`markerplan.provenance.provenance` of the
  resolved configuration, with the error model, solver statuses and inputs), ``frame``;
- ``layout``: source, mode (``layout`` or ``free``), marker ids;
- ``requirement``: every kind judged, as ``plan.json`` records it
  (:func:`planner.accuracy.requirement.requirement_record`: requirement_m, requirement_ppm and
  its text, datum_requirement, the local requirement; sectors, markers, working radius, 95 %
  figure), with ``local_markers`` and ``local_requirement_text``;
- ``curve``: one record per count ``k`` (most markers first) — kept markers, worst and mean
  predicted station error, proven lower bound, per-station errors and directions, whether every
  station passes, whether the point is proven optimal and the status of every solve;
- ``k_directions``, ``k_feasible``, ``markers_that_can_go``;
- ``drop_order`` and ``marker_losses``;
- ``verify`` (with ``--verify``): achieved against predicted errors at chosen counts;
- ``network`` (network mode only): the datum (reference station, fixed parameters,
  inclinometer and heading prior). Every error is then relative to it, and each curve point
  also holds ``worst_station_error_m``, ``worst_marker_error_m`` and ``marker_errors_m`` (its
  ``worst_error_m`` is the worst of stations and kept markers, which the requirement applies
  to), and ``local_pairs_ok`` / ``marker_pairs_ok`` (the local requirement on station and kept
  marker pairs); ``tradeoff.csv`` gains the two worst-error columns. The datum record is
  :meth:`planner.accuracy.network.NetworkModel.datum_record` (a control-point datum lists its
  points) with the pose aids (:meth:`planner.config.PlanConfig.aids_record`);

No file holds a timing (the same inputs give byte-identical files): :func:`reduce_timings`
gives them to the command's stderr and ``--json`` summary.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np

from markerplan.provenance import provenance
from markerplan.writing import json_float, write_csv
from planner.accuracy.requirement import (
    datum_clause,
    datum_text,
    requirement_record,
    requirement_text,
)
from planner.reduction.losses import check_worst, failure_reason

SCHEMA = "markerplan-reduce"
SCHEMA_VERSION = 1
FRAME_NOTE = "site frame: local metres (x, y horizontal, z up)"
SOLVER = "HiGHS via highspy (bisection on the worst-station error)"
#: Network mode: each query is the planner's network program (:func:`planner.program.plan_sites`).
NETWORK_SOLVER = ("HiGHS via highspy (network mode: descent on the worst station or "
                  "kept-marker error, each query the planner's network program)")



def _ids(problem, mask) -> list[str]:
    return [problem.site_ids[j] for j in np.flatnonzero(mask)]


def _stations(problem, check, config) -> list[dict]:
    return [{"id": sid, "error_m": json_float(check.error_m[s]), "n_markers": int(check.count[s]),
             "n_sectors": int(check.sectors[s]), "meets_requirement": bool(check.ok[s]),
             "reason": failure_reason(check, s, config)}
            for s, sid in enumerate(problem.station_ids)]


def _failing(prob, check, cfg) -> dict[str, str]:
    """Failing station id -> reason, and in network mode failing kept marker id -> its error
    and ``"station pairs"`` / ``"marker pairs"`` when some fail the local requirement."""
    out = {prob.station_ids[t]: failure_reason(check, t, cfg) for t in np.flatnonzero(~check.ok)}
    if check.marker_error_m is not None:
        for j in np.flatnonzero(check.marker_error_m > cfg.requirement_m):
            out[prob.site_ids[j]] = (f"marker error {check.marker_error_m[j]:.4f} m > "
                                     f"{cfg.requirement_m:g} m")
    for key, ok in (("station pairs", check.pairs_ok), ("marker pairs", check.marker_pairs_ok)):
        if not ok:
            out[key] = "beyond the local requirement"
    return out


def _requirement(cfg) -> dict:
    """``reduce.json``'s ``requirement``: every kind judged (as ``plan.json`` records it), with
    ``local_markers`` and the local requirement in words (``None`` without one)."""
    from planner.accuracy.local import LocalRequirement

    local = LocalRequirement.of(cfg)
    return {**requirement_record(cfg, redundant=False), "local_markers": cfg.local_markers,
            "local_requirement_text": None if local is None else local.describe()}


def kinds_text(req: dict, network: bool = True) -> str:
    """The requirement kinds a ``reduce.json`` ``requirement`` section judges, in words, e.g.
    ``"0.1 m relative to the datum; local 0.1 m between stations within 50 m (relative
    position), and between kept markers"`` (known control: ``"a predicted error ≤ 10 cm"``)."""
    if not network:
        return f"a predicted error ≤ {100 * req['requirement_m']:g} cm"
    parts = [f"{requirement_text(req)} relative to the datum"
             if req.get("datum_requirement", True) else "nothing relative to the datum"]
    if req.get("local_requirement_text"):
        parts.append(f"local {req['local_requirement_text']}"
                     + (", and between kept markers" if req.get("local_markers") else ""))
    return "; ".join(parts)


def _network(prob, cfg) -> dict:
    """The datum of a network-mode study (as ``plan.json``'s ``network.datum``)."""
    from planner.accuracy.network import network_model

    return {"datum": {**network_model(prob, cfg).datum_record(), **cfg.aids_record()},
            "errors": "95 % figures relative to the datum, from the whole network's information "
                      "(markers are unknowns); a point's worst error is the worst of its "
                      "stations and kept markers"}


def reduce_record(study, layout, inputs, model_name: str, options: dict,
                  verify: dict | None = None) -> dict:
    """The ``reduce.json`` document of a :class:`~planner.reduction.study.ReductionStudy`."""
    prob, cfg, curve = study.problem, study.config, study.curve
    statuses = Counter(s for p in curve.points for s in p.statuses)
    points = []
    for p in curve.points:
        network = {} if p.marker_error_m is None else {
            "worst_station_error_m": json_float(p.worst_station_error_m),
            "worst_marker_error_m": json_float(p.worst_marker_error_m),
            "marker_errors_m": {prob.site_ids[j]: json_float(p.marker_error_m[j])
                                for j in np.flatnonzero(p.selected)},
            "local_pairs_ok": p.pairs_ok, "marker_pairs_ok": p.marker_pairs_ok}
        points.append({
            "k": p.k, "markers": _ids(prob, p.selected),
            "worst_error_m": json_float(p.worst_error_m),
            **network,
            "mean_error_m": json_float(p.mean_error_m),
            "lower_bound_m": json_float(p.lower_bound_m),
            "meets_requirement": p.meets_requirement,
            "directions_ok": bool(np.all((p.count >= cfg.min_markers)
                                         & (p.sectors >= cfg.min_sectors))),
            "proven_optimal": p.proven, "n_solves": p.n_solves,
            "statuses": dict(Counter(p.statuses)),
            "stations": _stations(prob, p, cfg)})
        if study.layout_curve is not None:
            same = [q for q in study.layout_curve.points if q.k == p.k]
            points[-1]["layout_only_worst_error_m"] = json_float(same[0].worst_error_m) if same \
                else None
    drop = []
    for i, s in enumerate(study.drop, start=1):
        best = next((p for p in curve.points if p.k == s.k), None)
        drop.append({"step": i, "removed": prob.site_ids[s.removed], "k": s.k,
                     "worst_error_m": json_float(s.worst_error_m),
                     "mean_error_m": json_float(s.mean_error_m),
                     "meets_requirement": bool(s.check.all_ok),
                     "optimal_worst_error_m": json_float(best.worst_error_m) if best else None,
                     "failing": _failing(prob, s.check, cfg)})
    losses = [{"marker": prob.site_ids[m.marker], "worst_error_m": json_float(check_worst(m.check)),
               "mean_error_m": json_float(m.check.error_m.mean()),
               "failing": _failing(prob, m.check, cfg)} for m in study.losses]
    name = NETWORK_SOLVER if cfg.network else SOLVER
    solver = {"name": name, "statuses": dict(statuses), "proven_optimal": curve.proven,
              "optimality": ("within 0.1 mm (free mode)" if study.free and not cfg.network
                             else "exact (relative 1e-9)"),
              "complete": curve.complete, "time_limit_s": cfg.time_limit_s,
              "n_solves": int(sum(p.n_solves for p in curve.points)),
              "accuracy_cuts": curve.n_cuts}
    doc = {
        "schema": SCHEMA, "schema_version": SCHEMA_VERSION,
        "provenance": provenance({"plan": cfg.to_dict(), "reduce": options},
                                 error_model=model_name,
                                 solver={"name": name, "statuses": dict(statuses),
                                         "proven_optimal": curve.proven},
                                 inputs=dict(inputs.sources, layout=layout.source)),
        "frame": FRAME_NOTE,
        "site": {"name": inputs.site_name, "seed": inputs.site_seed},
        "layout": {"source": layout.source, "mode": "free" if study.free else "layout",
                   "n_markers": study.n_layout, "markers": _ids(prob, study.layout)},
        "requirement": _requirement(cfg),
        "solver": solver,
        "k_directions": curve.k_directions, "k_feasible": curve.k_feasible,
        "k_feasible_minimal": curve.k_feasible_minimal,
        "markers_that_can_go": study.markers_that_can_go,
        "curve": points, "drop_order": drop, "marker_losses": losses,
    }
    if cfg.network:
        doc["network"] = _network(prob, cfg)
    if verify is not None:
        doc["verify"] = verify
    return doc


TRADEOFF_COLUMNS = ("k", "worst_error_m", "mean_error_m", "lower_bound_m", "meets_requirement",
                    "directions_ok", "n_failing", "proven_optimal", "n_solves", "markers")
PER_STATION_COLUMNS = ("k", "station", "error_m", "n_markers", "n_sectors", "meets_requirement",
                       "reason")
DROP_ORDER_COLUMNS = ("step", "removed", "k", "worst_error_m", "mean_error_m",
                      "meets_requirement", "optimal_worst_error_m", "failing")
MARKER_LOSS_COLUMNS = ("marker", "worst_error_m", "mean_error_m", "n_failing", "failing")
#: ``tradeoff.csv``'s extra columns in network mode.
NETWORK_COLUMNS = ("worst_station_error_m", "worst_marker_error_m")


def write_reduce_files(doc: dict, folder: Path) -> None:
    """Write reduce.json, the four CSV tables and report.md into ``folder``."""
    folder = Path(folder)
    (folder / "reduce.json").write_text(json.dumps(doc, indent=2) + "\n")
    columns = TRADEOFF_COLUMNS + (NETWORK_COLUMNS if "network" in doc else ())
    write_csv(folder / "tradeoff.csv", columns, (
        {**p, "meets_requirement": int(p["meets_requirement"]),
         "directions_ok": int(p["directions_ok"]),
         "n_failing": sum(not s["meets_requirement"] for s in p["stations"]),
         "proven_optimal": int(p["proven_optimal"]), "markers": " ".join(p["markers"])}
        for p in doc["curve"]))
    write_csv(folder / "per_station.csv", PER_STATION_COLUMNS, (
        {**s, "k": p["k"], "station": s["id"], "meets_requirement": int(s["meets_requirement"])}
        for p in doc["curve"] for s in p["stations"]))
    write_csv(folder / "drop_order.csv", DROP_ORDER_COLUMNS, (
        {**d, "meets_requirement": int(d["meets_requirement"]),
         "failing": _failing_text(d["failing"])} for d in doc["drop_order"]))
    write_csv(folder / "marker_loss.csv", MARKER_LOSS_COLUMNS, (
        {**m, "n_failing": len(m["failing"]), "failing": _failing_text(m["failing"])}
        for m in doc["marker_losses"]))
    (folder / "report.md").write_text(report_markdown(doc))


def _failing_text(failing: dict) -> str:
    return "; ".join(f"{k}: {v}" for k, v in failing.items())


def _cm(v) -> str:
    return "n/a" if v is None else f"{100 * v:.2f} cm"


def accuracy_mode(doc: dict) -> str:
    """How a ``reduce.json`` document judges accuracy, in words ("network mode, datum S1" or
    "known control")."""
    net = doc.get("network")
    if net is None:
        return "known control"
    return f"network mode, datum {net['datum']['reference_station'] or datum_text(net['datum'])}"


def report_markdown(doc: dict) -> str:
    """Human report of a ``reduce.json`` document (Markdown)."""
    req, lay, sol = doc["requirement"], doc["layout"], doc["solver"]
    kf, go = doc["k_feasible"], doc["markers_that_can_go"]
    least = "" if doc["k_feasible_minimal"] else "at least "
    head = (f"**{least}{go} of {lay['n_markers']} markers can go**: {kf} markers still give "
            "every "
            f"station ≥ {req['min_markers']} markers in ≥ {req['min_sectors']} of "
            f"{req['n_sectors']} directions and "
            f"{kinds_text(req, 'network' in doc)}." if kf is not None else
            "**No count meets the requirement at every station**, not even the full layout.")
    if kf is not None and not doc["k_feasible_minimal"]:
        head += (" Fewer markers were not ruled out: a smaller count hit the time limit or lies "
                 "below --k-min.")
    lines = [f"# Marker reduction — site `{doc['site']['name']}`, layout `{lay['source']}`", "",
             head, "",
             "Mode: " + ("free (any candidate site)" if lay["mode"] == "free"
                         else "subsets of the layout")
             + f"; error: 95 % registered-position error over a {req['working_radius_m']:g} m "
             "working radius, predicted from the error model and the station geometry ("
             + req["error_figure_text"] + ").", ""]
    net = doc.get("network")
    if net is not None:
        d = net["datum"]
        prior = ("no heading prior" if d["heading_prior_sigma_deg"] is None
                 else f"heading prior {d['heading_prior_sigma_deg']:g} deg 1-sigma")
        lines += [f"Accuracy: **{accuracy_mode(doc)}** — markers are unknowns estimated with "
                  f"every station's pose; every error is relative to the datum, "
                  f"{datum_clause(d)} (inclinometer "
                  f"{d['inclinometer_sigma_deg']:g} deg 1-sigma; {prior}), as `plan --network` "
                  "judges a layout: a count's worst error is the worst of its stations and "
                  "its kept markers.", ""]
    lines += ["## Trade-off curve (fewest-markers-first minimax subsets)", ""]
    if net is None:
        lines += ["| markers | worst station | mean | meets requirement | proven optimal | kept |",
                  "|---:|---:|---:|---|---|---|"]
    else:
        lines += ["| markers | worst | worst station | worst marker | mean station | "
                  "meets requirement | proven optimal | kept |",
                  "|---:|---:|---:|---:|---:|---|---|---|"]
    for p in doc["curve"]:
        extra = "" if net is None else \
            f"{_cm(p['worst_station_error_m'])} | {_cm(p['worst_marker_error_m'])} | "
        lines.append(f"| {p['k']} | {_cm(p['worst_error_m'])} | {extra}"
                     f"{_cm(p['mean_error_m'])} | "
                     f"{'yes' if p['meets_requirement'] else 'no'} | "
                     f"{'yes' if p['proven_optimal'] else 'NO (time limit)'} | "
                     f"{', '.join(p['markers'])} |")
    if lay["mode"] == "free":
        lines += ["", "Best with the layout's own markers only (exact): "
                  + ", ".join(f"{p['k']}: {_cm(p.get('layout_only_worst_error_m'))}"
                              for p in doc["curve"]) + "."]
    lines += ["", f"Solver: {sol['name']}; optimality {sol['optimality']}; {sol['n_solves']} "
              f"solves, {sol['accuracy_cuts']} accuracy cuts, statuses {sol['statuses']}"
              + ("" if sol["proven_optimal"] else
                 " — **some points hit the time limit and are not proven optimal**") + ".", "",
              "## Drop order (remove the marker whose loss hurts least, one at a time)", "",
              "| step | removed | left | worst station | best possible with as many | passes |",
              "|---:|---|---:|---:|---:|---|"]
    for d in doc["drop_order"]:
        lines.append(f"| {d['step']} | {d['removed']} | {d['k']} | {_cm(d['worst_error_m'])} | "
                     f"{_cm(d['optimal_worst_error_m'])} | "
                     f"{'yes' if d['meets_requirement'] else 'no'} |")
    lines += ["", "## Losing one marker (robustness of the full layout)", "",
              "| marker lost | worst station | stations that fail |", "|---|---:|---|"]
    for m in doc["marker_losses"]:
        lines.append(f"| {m['marker']} | {_cm(m['worst_error_m'])} | "
                     f"{_failing_text(m['failing']) or '—'} |")
    if "verify" in doc:
        lines += ["", "## Verification (simulator + pipeline)", "",
                  "| markers | station | predicted | achieved |", "|---:|---|---:|---:|"]
        for v in doc["verify"]["points"]:
            for s in v["stations"]:
                lines.append(f"| {v['k']} | {s['id']} | {_cm(s['predicted_error_m'])} | "
                             f"{_cm(s['achieved_error_m'])} |")
    lines += ["", f"markerplan {doc['provenance']['markerplan_version']}; error model "
              f"{doc['provenance']['error_model']}; config sha256 "
              f"`{doc['provenance']['config_sha256'][:12]}`; {FRAME_NOTE}.", ""]
    return "\n".join(lines)


def reduce_timings(study) -> dict[str, float]:
    """Wall-clock seconds of the study's steps, the solver's total among them."""
    return {**{k: round(v, 3) for k, v in study.timings_s.items()},
            "solver": round(study.curve.solve_time_s, 3)}


def summary(doc: dict, out: Path) -> dict:
    """The one-object ``--json`` summary."""
    net = doc.get("network")
    return {"out": str(out), "site": doc["site"]["name"], "layout": doc["layout"]["source"],
            "mode": doc["layout"]["mode"], "accuracy": accuracy_mode(doc),
            "reference_station": None if net is None else net["datum"]["reference_station"],
            "n_markers": doc["layout"]["n_markers"],
            "k_feasible": doc["k_feasible"], "k_feasible_minimal": doc["k_feasible_minimal"],
            "k_directions": doc["k_directions"],
            "markers_that_can_go": doc["markers_that_can_go"],
            "proven_optimal": doc["solver"]["proven_optimal"],
            "statuses": doc["solver"]["statuses"],
            "curve": [{"k": p["k"], "worst_error_m": p["worst_error_m"],
                       "mean_error_m": p["mean_error_m"],
                       "meets_requirement": p["meets_requirement"], "markers": p["markers"]}
                      for p in doc["curve"]],
            "drop_order": [d["removed"] for d in doc["drop_order"]],
            "verified_k": [v["k"] for v in doc.get("verify", {}).get("points", [])]}
