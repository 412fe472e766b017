"""Verify a plan by simulation: scan every station with the planned markers, process the scans
with the pipeline, register each station to its detected markers, and compare the achieved
registration error with the plan's prediction.

Per station:

1. ``visibility.simulate.simulate_markers`` — a full turntable scan of the site's terrain with
   only the planned markers, at the planned station pose, with the sensor and turntable errors
   of a sensor profile (:mod:`visibility.sensor_profile`, ``calibrated`` by default);
2. ``pipeline.process.process_station`` — the published chain; detections are matched to the
   planned markers projected into the station frame with the *planned* (nominal) pose;
3. weighted least squares (:func:`planner.accuracy.fit_pose`, 4 DoF: x, y, z, heading; roll and
   pitch are known, as from the inclinometer) from the accepted, matched markers, each weighted
   by the error model's sigma at its measured distance and elevation;
4. achieved error = the largest 3D difference, over the working radius, between the registered
   and the true mapping of the station frame into the site frame
   (:func:`planner.accuracy.registration_error`).

The plan passes only if every station's achieved error is within the requirement.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from markerplan.provenance import provenance
from pipeline.evaluation import Reference
from pipeline.process import process_station
from pipeline.rig import MountingOffsets, station_to_site_matrix
from pipeline.scan_format import StationScan
from pipeline.stages import build_config
from planner import accuracy
from planner.plan_file import PlannedStation, SurveyPlan
from visibility.sensor_profile import SensorProfile, default_profile
from visibility.simulate import simulate_markers

#: Schema of ``verify.json``, both modes (``mode`` tells a network verification apart).
VERIFY_SCHEMA = "markerplan-verify"
VERIFY_SCHEMA_VERSION = 1

#: Smallest number of matched markers that can fix x, y, z and heading.
MIN_MATCHED = 2


@dataclass
class StationCheck:
    """Verification of one station."""

    station_id: str
    predicted_error_m: float | None
    achieved_error_m: float | None
    n_planned: int
    n_detected: int
    passed: bool
    reason: str
    marker_errors_m: dict


def verify_plan(plan: SurveyPlan, error_model, seed: int = 0, progress: bool = True,
                offsets: MountingOffsets | None = None,
                station_ids: list[str] | None = None,
                profile: SensorProfile | None = None) -> list[StationCheck]:
    """Simulate, process and register every station of a plan (see module docstring).

    Parameters
    ----------
    plan : SurveyPlan
        Terrain, stations, markers (with their radius, which both the simulation and the
        pipeline's fit use) and the requirement.
    error_model : ErrorModel
        Gives the registration weights.
    seed : int
        Simulation seed (the plan's station ``k`` uses ``seed + k``, whichever are verified).
    progress : bool
        Progress bar on stderr.
    offsets : pipeline.rig.MountingOffsets, optional
        True mounting offsets of the simulated rig (default: none). The pipeline self-calibrates
        them from each station's scan, as it would in the field.
    station_ids : list of str, optional
        Verify only these stations (default: all), in the plan's order.
    profile : SensorProfile, optional
        Sensor and turntable errors of the simulated rig (default: the shipped
        ``calibrated`` profile), at 600 rpm.

    Returns
    -------
    checks : list of StationCheck
    """
    ids = list(plan.marker_ids)
    centres = plan.marker_xyz_m
    cfg = build_config({"fit": {"radius_m": plan.marker_radius_m}})
    checks = []
    for st, scan, truth in simulated_stations(plan, seed, progress, offsets, station_ids,
                                              profile):
        rot = station_to_site_matrix(st.heading_rad)
        nominal = (centres - st.position_m) @ rot  # planned markers in the planned station frame
        ref = Reference(tuple(ids), nominal, st.id, "plan (nominal pose)")
        result = process_station(scan, cfg, ref, seed=seed)
        rows = [r for r in result.rows if r.accepted and r.marker_id]
        marker_err = {r.marker_id: r.error_m for r in rows}
        n_planned = len(st.marker_ids)
        if len(rows) < MIN_MATCHED:
            checks.append(StationCheck(st.id, st.predicted_error_m, None, n_planned, len(rows),
                                       False, f"only {len(rows)} planned marker(s) detected and "
                                       f"accepted (needs {MIN_MATCHED})", marker_err))
            continue
        p = np.array([r.centre_m for r in rows])
        site_xyz = centres[[ids.index(r.marker_id) for r in rows]]
        sigma = np.asarray(error_model.predict(np.array([r.distance_m for r in rows]),
                                               np.radians([r.elevation_deg for r in rows]))
                           .sigma_m, float)
        sigma = np.maximum(sigma, 1e-4)
        t, psi = accuracy.fit_pose(p, site_xyz, sigma, heading0_rad=st.heading_rad)
        true_pose = truth["station_pose"]
        achieved = accuracy.registration_error(t, psi, true_pose["position_m"],
                                               true_pose["heading_rad"], plan.working_radius_m)
        ok = achieved <= plan.requirement_m
        missing = sorted(set(st.marker_ids) - {r.marker_id for r in rows})
        reason = ("ok" if ok else
                  f"achieved {achieved:.3f} m > requirement {plan.requirement_m:g} m")
        if missing:
            reason += f" (planned markers not detected: {', '.join(missing)})"
        checks.append(StationCheck(st.id, st.predicted_error_m, achieved, n_planned, len(rows),
                                   ok, reason, marker_err))
    return checks


def simulated_stations(plan: SurveyPlan, seed: int = 0, progress: bool = True,
                       offsets: MountingOffsets | None = None,
                       station_ids: list[str] | None = None,
                       profile: SensorProfile | None = None
                       ) -> Iterator[tuple[PlannedStation, StationScan, dict]]:
    """Simulate the chosen stations of a plan at their planned poses, one at a time (step 1 of
    the module docstring; parameters as :func:`verify_plan`).

    Yields
    ------
    station : PlannedStation
    scan : StationScan
        The full turntable scan with only the planned markers.
    truth : dict
        The simulator's truth (:func:`visibility.simulate.simulate_markers`).
    """
    ids = list(plan.marker_ids)
    profile = profile or default_profile()
    rig = profile.rig_config(offsets=offsets or MountingOffsets())
    chosen = [(k, st) for k, st in enumerate(plan.stations)
              if station_ids is None or st.id in station_ids]
    for k, st in tqdm(chosen, desc="verify", unit="station", file=sys.stderr,
                      disable=None if progress else True):
        scan, truth = simulate_markers(plan.dem, st.position_m, st.heading_rad, plan.marker_xyz_m,
                                       profile.sensor_config(), rig, seed=seed + k,
                                       marker_radius_m=plan.marker_radius_m, marker_ids=ids,
                                       station_id=st.id, sensor_profile=profile.name)
        yield st, scan, truth


def verify_record(plan: SurveyPlan, checks: list[StationCheck], seed: int, model_name: str,
                  offsets: MountingOffsets | None = None,
                  profile: SensorProfile | None = None) -> dict:
    """The ``verify.json`` document (``offsets``: the simulated rig's true mounting offsets;
    ``profile``: its sensor profile, default the shipped one, recorded in the provenance)."""
    true_offsets = (offsets or MountingOffsets()).to_dict()
    profile = profile or default_profile()
    return {
        "schema": VERIFY_SCHEMA, "schema_version": VERIFY_SCHEMA_VERSION,
        "provenance": provenance({"seed": seed, "error_model": model_name,
                                  "mounting_offsets": true_offsets,
                                  "sensor_profile": profile.to_dict(),
                                  "plan_config_sha256": plan.provenance["config_sha256"]},
                                 plan=plan.provenance),
        "requirement_m": plan.requirement_m,
        "passed": all(c.passed for c in checks),
        "stations": [{"id": c.station_id, "predicted_error_m": c.predicted_error_m,
                      "achieved_error_m": c.achieved_error_m, "n_planned_markers": c.n_planned,
                      "n_detected_markers": c.n_detected, "passed": c.passed,
                      "reason": c.reason, "marker_centre_errors_m": c.marker_errors_m}
                     for c in checks],
    }


def verify_markdown(rec: dict) -> str:
    """Human report of a verification."""
    lines = [f"# Plan verification — {'PASSED' if rec['passed'] else 'FAILED'}", "",
             f"Requirement: achieved registration error ≤ {rec['requirement_m']:g} m at every "
             "station (simulated scans, processed by the pipeline, 4-DoF WLS registration).", "",
             "| station | predicted | achieved | markers detected / planned | result |",
             "|---|---:|---:|---:|---|"]
    for s in rec["stations"]:
        pred = "—" if s["predicted_error_m"] is None else f"{s['predicted_error_m']:.4f} m"
        ach = "—" if s["achieved_error_m"] is None else f"{s['achieved_error_m']:.4f} m"
        lines.append(f"| {s['id']} | {pred} | {ach} | {s['n_detected_markers']} / "
                     f"{s['n_planned_markers']} | {s['reason']} |")
    return "\n".join(lines) + "\n"
