"""The record and report of one network-mode verification: ``verify.json``, ``verify.md`` and
the summary line of ``markerplan verify --network`` (the check itself:
:mod:`planner.verify.network`)."""

from __future__ import annotations

from markerplan.provenance import provenance
from pipeline.scans.rig import MountingOffsets
from planner.accuracy.requirement import requirement_text
from planner.outputs.plan_file import SurveyPlan
from planner.verify.fates import fates_record, losses_markdown, stage_counts
from planner.verify.known_control import VERIFY_SCHEMA, VERIFY_SCHEMA_VERSION
from planner.verify.local_pairs import pairs_markdown, pairs_record
from planner.verify.network import NetworkVerification, StationOutcome
from visibility.sensor_profile import SensorProfile


def network_record(plan: SurveyPlan, check: NetworkVerification, seed: int, model_name: str,
                   offsets: MountingOffsets | None, profile: SensorProfile) -> dict:
    """The ``verify.json`` document of network mode (``mode: "network"``; configuration,
    version, sensor profile and the rig's true mounting offsets in the provenance)."""
    cfg = {key: value for key, value in check.config.items() if key != "tables"}
    fates = check.fates or {}
    stations = [{"id": s.station_id, "predicted_error_m": s.predicted_error_m,
                 "adjustment_error_95_m": s.stated_error_m,
                 "achieved_error_m": s.achieved_error_m,
                 "allowed_error_m": check.allowed_m.get(s.station_id),
                 "n_detected_markers": s.n_accepted,
                 "n_identified": s.n_identified, "n_used": s.n_used, "passed": s.passed,
                 "reason": s.reason, **fates_record(fates.get(s.station_id))}
                for s in check.stations]
    identification = ({"losses": stage_counts(fates.values()),
                       "misidentified": check.misidentified} if check.fates else {})
    markers = [{"id": m.marker_id, "predicted_error_m": m.predicted_error_m,
                "adjustment_error_95_m": m.stated_error_m, "achieved_error_m": m.achieved_error_m,
                "achieved_xyz_m": list(m.achieved_xyz_m), "stations": list(m.stations)}
               for m in check.markers]
    return {
        "schema": VERIFY_SCHEMA, "schema_version": VERIFY_SCHEMA_VERSION, "mode": "network",
        "provenance": provenance({"seed": seed, "error_model": model_name,
                                  "mounting_offsets": (offsets or MountingOffsets()).to_dict(),
                                  "sensor_profile": profile.to_dict(),
                                  "plan_config_sha256": plan.provenance.get("config_sha256"),
                                  "network": cfg}, plan=plan.provenance),
        "requirement_m": check.config["requirement_m"],
        "requirement_ppm": check.requirement.ppm,
        "requirement_text": check.requirement.describe(),
        "working_radius_m": check.config["working_radius_m"],
        "datum": _datum_words(check.config),
        "passed": check.passed,
        "worst": {"predicted_error_m": _worst(s.predicted_error_m for s in check.stations),
                  "adjustment_error_95_m": _worst(s.stated_error_m for s in check.stations),
                  "achieved_error_m": _worst(s.achieved_error_m for s in check.stations),
                  "achieved_station": _worst_id(check.stations),
                  "not_adjusted": [s.station_id for s in check.stations
                                   if s.achieved_error_m is None],
                  "marker_achieved_error_m": _worst(m.achieved_error_m for m in check.markers),
                  "marker_predicted_error_m": _worst(m.predicted_error_m
                                                     for m in check.markers)},
        **identification,
        "adjustment": {"sigma0_squared": check.sigma0_squared, "dof": check.dof,
                       "rejected": check.rejected,
                       "unidentified_detections": check.unidentified},
        "stations": stations,
        "markers": markers,
        **({"local": pairs_record(check.local, check.pairs, check.marker_pairs)}
           if check.local else {}),
    }


def _worst(values) -> float | None:
    """Largest of the values that are not ``None`` (``None`` if there are none).

    >>> _worst([0.1, None, 0.3]), _worst([None])
    (0.3, None)
    """
    given = [v for v in values if v is not None]
    return max(given) if given else None


def _worst_id(stations: list[StationOutcome]) -> str | None:
    """The adjusted station with the largest achieved error (``None`` if none was adjusted)."""
    done = [s for s in stations if s.achieved_error_m is not None]
    return max(done, key=lambda s: s.achieved_error_m).station_id if done else None


def network_markdown(rec: dict) -> str:
    """Human report of a network-mode verification: predicted against achieved, per station
    and worst, then per marker."""
    def mm(v):
        return "—" if v is None else f"{1e3 * v:.1f} mm"

    w = rec["worst"]
    lines = [f"# Plan verification, network mode — {'PASSED' if rec['passed'] else 'FAILED'}",
             "", f"Datum: {rec['datum']}. Requirement: achieved station error ≤ "
             f"{requirement_text(rec)} over a {rec['working_radius_m']:g} m working radius at "
             "every station (simulated scans processed by the pipeline; markers identified by "
             "gated association with the plan from the planned poses; network adjustment).", "",
             f"Worst station: predicted {mm(w['predicted_error_m'])}, adjustment's 95 % "
             f"{mm(w['adjustment_error_95_m'])}, achieved {mm(w['achieved_error_m'])} "
             f"({w['achieved_station']})"
             + (f"; not in the adjustment: {', '.join(w['not_adjusted'])}."
                if w["not_adjusted"] else "."), "",
             "| station | predicted | adjustment 95 % | achieved | detected / identified / used "
             "| result |", "|---|---:|---:|---:|---:|---|"]
    for s in rec["stations"]:
        lines.append(f"| {s['id']} | {mm(s['predicted_error_m'])} | "
                     f"{mm(s['adjustment_error_95_m'])} | {mm(s['achieved_error_m'])} | "
                     f"{s['n_detected_markers']} / {s['n_identified']} / {s['n_used']} | "
                     f"{s['reason']} |")
    lines += ["", "| marker | predicted | adjustment 95 % | achieved | stations |",
              "|---|---:|---:|---:|---|"]
    for m in rec["markers"]:
        lines.append(f"| {m['id']} | {mm(m['predicted_error_m'])} | "
                     f"{mm(m['adjustment_error_95_m'])} | {mm(m['achieved_error_m'])} | "
                     f"{', '.join(m['stations'])} |")
    lines += pairs_markdown(rec)
    adj = rec["adjustment"]
    removed = ", ".join(f"{r['station_id']}->{r['marker_id']} (w {r['w']:.1f})"
                        for r in adj["rejected"]) or "none"
    s0 = "n/a" if adj["sigma0_squared"] is None else f"{adj['sigma0_squared']:.3f}"
    lines += ["", f"Adjustment: sigma0² {s0}, dof {adj['dof']}; removed by data snooping: "
              f"{removed}; detections left unidentified: {adj['unidentified_detections']}."]
    if "losses" in rec:
        wrong = ", ".join(f"{w['station_id']}: {w['marker_id']} as {w['identified_as'] or '—'}"
                          for w in rec["misidentified"]) or "none"
        lines += ["", losses_markdown(rec["losses"]),
                  f"Accepted planned markers not identified with their true id: {wrong}."]
    lines += ["", "`markers.csv` holds every station's detections: with every station tied, "
              "`markerplan adjust markers.csv --plan PLAN --out DIR` repeats the adjustment "
              "with its full report; `fates.csv` every planned marker's fate, by its true id."]
    return "\n".join(lines) + "\n"


def _datum_words(config: dict) -> str:
    """The verification's datum in words (the record's ``datum``; the summary line keeps the
    part before the first parenthesis)."""
    if config.get("datum") == "free":
        return ("free network, datum-free (nothing fixed; the adjusted network is compared with "
                "the truth after removing its datum motion, so only relative figures count)")
    if config.get("datum") != "control":
        return (f"station {config['reference_station']} (x, y, z, heading at its planned "
                "pose)")
    points = config["control_points"]
    return (f"control points {', '.join(c['marker_id'] for c in points)} (their coordinates "
            f"known to +-{max(c['sigma_m'] for c in points):g} m, drawn from verify's seed; "
            "no station fixed)")


def network_summary_line(rec: dict, out) -> str:
    """The command's human summary: worst achieved against predicted station error.

    >>> rec = {"passed": True, "requirement_m": 0.1, "datum": "station S1 (...)",
    ...        "worst": {"achieved_error_m": 0.012, "achieved_station": "S5",
    ...                  "predicted_error_m": 0.03, "adjustment_error_95_m": 0.02,
    ...                  "marker_achieved_error_m": 0.004, "not_adjusted": []}}
    >>> print(network_summary_line(rec, "v"))  # doctest: +NORMALIZE_WHITESPACE
    PASSED (network mode, datum station S1): worst station error achieved 0.0120 m (S5),
    predicted 0.0300 m, adjustment's 95 % 0.0200 m (requirement 0.1 m); worst marker achieved
    0.0040 m -> v/
    """
    w = rec["worst"]

    def m(v):
        return "—" if v is None else f"{v:.4f} m"

    return (f"{'PASSED' if rec['passed'] else 'FAILED'} (network mode, datum "
            f"{rec['datum'].split(' (')[0]}): worst station error achieved "
            f"{m(w['achieved_error_m'])} ({w['achieved_station']}), predicted "
            f"{m(w['predicted_error_m'])}, adjustment's 95 % {m(w['adjustment_error_95_m'])} "
            f"(requirement {requirement_text(rec)}); worst marker achieved "
            f"{m(w['marker_achieved_error_m'])}"
            + (f"; not adjusted: {', '.join(w['not_adjusted'])}" if w["not_adjusted"] else "")
            + _local_clause(rec.get("local"))
            + f" -> {out}/")


def _local_clause(local: dict | None) -> str:
    """The summary's local-accuracy clause: the worst pair achieved against predicted."""
    if local is None or local["worst"] is None:
        return ""
    w = local["worst"]
    predicted = "n/a" if w["predicted_error_m"] is None else f"{w['predicted_error_m']:.4f} m"
    return (f"; local: worst pair {'-'.join(w['stations'])} achieved "
            f"{w['achieved_error_m']:.4f} m, predicted {predicted}, allowed "
            f"{w['allowed_error_m']:.4f} m")
