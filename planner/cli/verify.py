"""``markerplan verify``: simulate and process a plan, compare achieved with predicted error."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from planner.cli._common import (
    emit_summary,
    error_model_option,
    given_paths,
    json_option,
    mounting_offset_options,
    out_option,
    overwrite_option,
    seed_option,
    sensor_profile_option,
    station_ids_option,
)


@click.command("verify")
@click.argument("plan_path", metavar="PLAN", type=click.Path(dir_okay=False, path_type=Path))
@error_model_option
@seed_option()
@station_ids_option
@mounting_offset_options
@sensor_profile_option
@out_option(required=True)
@overwrite_option
@json_option
def command(plan_path, error_model, seed, station_ids, offsets, profile, out, overwrite,
            as_json):
    """Check a plan by simulation: scan each station with the planned markers, process the
    scans, register each station to its detected markers, and compare achieved with predicted
    error. Exit code 1 when any station's achieved error exceeds the requirement. The plan's
    marker radius is simulated and fitted; --station-ids verifies some stations only.

    With mounting offsets the simulated rig is mis-mounted and the pipeline self-calibrates
    each station's scan before detecting the markers, as in the field. The simulated sensor
    and turntable errors come from --sensor-profile.

    \b
    Example:
      markerplan plan --out plan/
      markerplan verify plan/plan.json --out verify/
      markerplan verify plan/plan.json --vertical-axis-error-deg 0.3 --lframe-tilt-deg 0.3 \\
          --axis-offset-mm 15,0 --out verify-offsets/
    """
    import json

    from markerplan.errors import InfeasiblePlanError
    from markerplan.output_folder import output_folder
    from planner.plan_file import load_plan
    from planner.planning import select_stations
    from planner.verify import verify_markdown, verify_plan, verify_record

    plan = load_plan(plan_path)
    ids = select_stations([s.id for s in plan.stations], station_ids)
    inputs = given_paths(plan_path, plan.dem_path, error_model.path)
    with output_folder(out, overwrite, "verify", inputs=inputs) as stage:
        checks = verify_plan(plan, error_model.model, seed=seed,
                             progress=not as_json or sys.stderr.isatty(), offsets=offsets,
                             station_ids=ids, profile=profile)
        rec = verify_record(plan, checks, seed, error_model.name, offsets, profile)
        (stage / "verify.json").write_text(json.dumps(rec, indent=2) + "\n")
        (stage / "verify.md").write_text(verify_markdown(rec))
    summary = {"out": str(out), "passed": rec["passed"], "requirement_m": rec["requirement_m"],
               "stations": {s["id"]: {"predicted_error_m": s["predicted_error_m"],
                                      "achieved_error_m": s["achieved_error_m"],
                                      "passed": s["passed"]} for s in rec["stations"]}}
    worst = max((s["achieved_error_m"] if s["achieved_error_m"] is not None else float("inf"))
                for s in rec["stations"])
    emit_summary(summary, as_json, f"{'PASSED' if rec['passed'] else 'FAILED'}: worst achieved "
                 f"error {worst:.4f} m (requirement {rec['requirement_m']:g} m) -> {out}/")
    if not rec["passed"]:
        failing = [f"{s['id']}: {s['reason']}" for s in rec["stations"] if not s["passed"]]
        raise InfeasiblePlanError("verification failed at " + "; ".join(failing))
