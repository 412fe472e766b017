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
    network_option,
    out_option,
    overwrite_option,
    reference_station_option,
    require_network,
    scheduler_options,
    seed_option,
    sensor_profile_option,
    station_ids_option,
)
from planner.cli.adjust import command as _adjust

#: Most trials one ``verify --trials`` runs (each is a full verification of the plan).
MAX_TRIALS = 1000


def _adjust_options(*names: str):
    """Give a command ``markerplan adjust``'s options of these parameter names (defined once,
    there; in network mode they mean the same)."""
    shared = [next(p for p in _adjust.params if p.name == n) for n in names]

    def decorate(f):
        f.__click_params__ = getattr(f, "__click_params__", []) + shared[::-1]
        return f

    return decorate


@click.command("verify")
@click.argument("plan_path", metavar="PLAN", type=click.Path(dir_okay=False, path_type=Path))
@error_model_option
@seed_option()
@station_ids_option
@mounting_offset_options
@sensor_profile_option
@network_option
@reference_station_option
@_adjust_options("odometry_sigma_m", "odometry_heading_sigma_deg")
@click.option("--trials", type=click.IntRange(1, MAX_TRIALS), default=1, show_default=True,
              metavar="N",
              help="Verify the plan N times with independent noise and turntable-error seeds "
                   "(spawned from --seed; the first trial is --seed's) and report its pass rate "
                   "with a Wilson 95 % interval, per station and per station-marker pair.")
@scheduler_options
@out_option(required=True)
@overwrite_option
@json_option
def command(plan_path, error_model, seed, station_ids, offsets, profile, network,
            reference_station, odometry_sigma_m, odometry_heading_sigma_deg, trials, scheduler,
            workers, out, overwrite, as_json):
    """Check a plan by simulation: scan each station with the planned markers, process the
    scans, register each station to its detected markers, and compare achieved with predicted
    error. Exit code 1 when any station's achieved error exceeds the requirement. The plan's
    marker radius is simulated and fitted; --station-ids verifies some stations only.

    With mounting offsets the simulated rig is mis-mounted and the pipeline self-calibrates
    each station's scan before detecting the markers, as in the field. The simulated sensor
    and turntable errors come from --sensor-profile.

    With --network, or with a plan made by `plan --network` (which is always verified in
    network mode, the mode its predictions are for), no marker is known control: the
    detections are identified without the simulator's truth, all stations and markers are
    adjusted together tied to the plan's reference station (which --station-ids must
    include), and verify.json / verify.md set each station's predicted, adjusted (95 %) and
    achieved error side by side (and the worst), and every marker's; markers.csv holds the
    detections (the input of `markerplan adjust markers.csv --plan PLAN`). A station that
    cannot be tied to the reference (fewer than 2 shared identified markers) fails and is
    left out of the adjustment. --reference-station names the datum: a network plan's
    predictions are relative to its own datum, so for such a plan it may only repeat it.

    Every planned marker's fate is in fates.csv: the stage of the chain that lost it
    (not_in_view, ground, cluster, gate, fit, quality) and why, or accepted, against the
    simulator's truth (its marker_id is the true id, in network mode too, where the
    adjustment never sees it); each station's reason names its losses.

    With --trials N (known control), the plan is verified N times with independent seeds
    (the first is --seed's, the others spawned from it): verify.json / verify.md give the
    plan's pass rate with its Wilson 95 % interval, each station's and each station-marker
    pair's rates and losses, trials.csv one row per trial and station, fates.csv a trial
    column; exit code 1 when any trial fails.

    Each station is a task (simulated on its terrain tile, then processed) run on a dask
    cluster: --scheduler local (the default) starts one on this machine, --scheduler ADDRESS
    uses a running one, --scheduler none runs in this process; the files are the same.

    \b
    Example:
      markerplan plan --out plan/
      markerplan verify plan/plan.json --out verify/
      markerplan verify plan/plan.json --vertical-axis-error-deg 0.3 --lframe-tilt-deg 0.3 \\
          --axis-offset-mm 15,0 --out verify-offsets/
      markerplan verify plan/plan.json --trials 40 --out verify-40/
      markerplan verify plan/plan.json --network --out verify-network/
      markerplan verify plan/plan.json --scheduler tcp://10.0.0.5:8786 --out verify/
    """
    import json

    from markerplan.errors import ConfigError, VerificationFailedError
    from markerplan.output_folder import output_folder
    from planner.distributed import executor
    from planner.outputs.plan_file import load_plan
    from planner.problem.inputs import select_stations
    from planner.verify.fates import write_fates
    from planner.verify.known_control import verify_markdown, verify_plan, verify_record

    plan = load_plan(plan_path)
    ids = select_stations([s.id for s in plan.stations], station_ids)
    inputs = given_paths(plan_path, plan.dem_path, error_model.path)
    planned_network = bool(plan.provenance.get("config", {}).get("network"))
    network = network or planned_network
    require_network(reference_station, network)
    if network and trials > 1:
        raise ConfigError(f"--trials {trials}: repeated trials are of known-control "
                          "verification only; run `verify --network` once per --seed")
    if trials > 1:
        _verify_trials(plan, ids, inputs, error_model, seed, offsets, profile, trials, out,
                       overwrite, as_json, (scheduler, workers))
        return
    if network:
        from planner.verify.network import NetworkVerifySettings

        settings = NetworkVerifySettings(odometry_sigma_m, odometry_heading_sigma_deg)
        _verify_network(plan_path, plan, ids, inputs, error_model, seed, offsets, profile,
                        settings, out, overwrite, as_json, reference_station,
                        (scheduler, workers))
        return
    progress = not as_json or sys.stderr.isatty()
    with executor(scheduler, workers, progress) as ex, \
            output_folder(out, overwrite, "verify", inputs=inputs) as stage:
        checks = verify_plan(plan, error_model.model, seed=seed, offsets=offsets,
                             station_ids=ids, profile=profile, executor=ex)
        rec = verify_record(plan, checks, seed, error_model.name, offsets, profile)
        (stage / "verify.json").write_text(json.dumps(rec, indent=2) + "\n")
        (stage / "verify.md").write_text(verify_markdown(rec))
        write_fates(stage / "fates.csv", [[c.fates for c in checks]])
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
        raise VerificationFailedError("verification failed at " + "; ".join(failing))


def _verify_network(plan_path, plan, ids, inputs, error_model, seed, offsets, profile, settings,
                    out, overwrite, as_json, datum, where):
    """``verify --network``: scan, write the marker table, adjust and compare
    (:mod:`planner.verify.network`); exit code 1 when a station fails. ``datum``: the
    ``--reference-station`` given (a network plan's own datum only); ``where``: ``(scheduler,
    workers)`` of the station tasks."""
    import json

    from markerplan.errors import ConfigError, VerificationFailedError
    from markerplan.output_folder import output_folder
    from pipeline.marker_table import write_marker_table
    from pipeline.network.observations import Datum
    from planner.distributed import executor
    from planner.outputs.plan_file import read_plan
    from planner.verify.fates import write_fates
    from planner.verify.network import (
        adjust_and_compare,
        network_markdown,
        network_record,
        network_summary_line,
        reference_station,
        scan_plan,
    )
    from visibility.sensor_profile import default_profile

    doc = read_plan(plan_path, "PLAN", full=True)
    planned = doc["provenance"].get("config", {})
    named = planned.get("reference_station")
    named = named if isinstance(named, str) else None
    station_list = [s["id"] for s in doc["stations"]]
    planned_datum = Datum(reference_station=named).reference_id(station_list)
    if datum is not None and planned.get("network") and datum != planned_datum:
        raise ConfigError(f"--reference-station {datum}: the plan's predictions are relative to "
                          f"its datum {planned_datum}; verify against that datum, or "
                          f"re-plan with `markerplan plan --network --reference-station {datum}`")
    reference_station(datum or named, station_list, ids)
    profile = profile or default_profile()
    progress = not as_json or sys.stderr.isatty()
    with executor(*where, progress) as ex, \
            output_folder(out, overwrite, "verify", inputs=inputs) as stage:
        rows, truth, fates = scan_plan(plan, seed, offsets=offsets, station_ids=ids,
                                       profile=profile, executor=ex)
        table = write_marker_table(stage / "markers.csv", rows)
        write_fates(stage / "fates.csv", [list(fates.values())])
        check = adjust_and_compare(
            [table], plan_path, error_model.model, truth,
            {s["id"]: s.get("predicted_error_m") for s in doc["stations"]},
            {m["id"]: m.get("predicted_error_m") for m in doc["markers"]}, settings,
            error_model.name, {s["id"]: tuple(s.get("markers", ())) for s in doc["stations"]},
            reference=datum, fates=fates)
        rec = network_record(plan, check, seed, error_model.name, offsets, profile)
        (stage / "verify.json").write_text(json.dumps(rec, indent=2) + "\n")
        (stage / "verify.md").write_text(network_markdown(rec))
    w = rec["worst"]
    summary = {"out": str(out), "mode": "network", "passed": rec["passed"],
               "requirement_m": rec["requirement_m"], "datum": rec["datum"], "worst": w,
               "stations": {s["id"]: {"predicted_error_m": s["predicted_error_m"],
                                      "adjustment_error_95_m": s["adjustment_error_95_m"],
                                      "achieved_error_m": s["achieved_error_m"],
                                      "passed": s["passed"]} for s in rec["stations"]},
               "markers": {m["id"]: {"predicted_error_m": m["predicted_error_m"],
                                     "achieved_error_m": m["achieved_error_m"]}
                           for m in rec["markers"]}}
    emit_summary(summary, as_json, network_summary_line(rec, out))
    if not rec["passed"]:
        failing = [f"{s['id']}: {s['reason']}" for s in rec["stations"] if not s["passed"]]
        raise VerificationFailedError("verification failed at " + "; ".join(failing))


def _verify_trials(plan, ids, inputs, error_model, seed, offsets, profile, n_trials, out,
                   overwrite, as_json, where):
    """``verify --trials N`` (known control, ``N`` > 1; :mod:`planner.verify.trials`): exit
    code 1 when any trial fails. ``where``: ``(scheduler, workers)`` of the tasks."""
    import json

    from markerplan.errors import VerificationFailedError
    from markerplan.output_folder import output_folder
    from planner.distributed import executor
    from planner.verify.fates import write_fates
    from planner.verify.trials import (
        trial_seeds,
        trials_markdown,
        trials_record,
        verify_trials,
        write_trials,
    )

    seeds = trial_seeds(seed, n_trials)
    progress = not as_json or sys.stderr.isatty()
    with executor(*where, progress) as ex, \
            output_folder(out, overwrite, "verify", inputs=inputs) as stage:
        trials = verify_trials(plan, error_model.model, seeds, offsets, ids, profile, ex)
        rec = trials_record(plan, trials, seed, seeds, error_model.name, offsets, profile)
        (stage / "verify.json").write_text(json.dumps(rec, indent=2) + "\n")
        (stage / "verify.md").write_text(trials_markdown(rec))
        write_trials(stage / "trials.csv", trials, seeds)
        write_fates(stage / "fates.csv", [[c.fates for c in checks] for checks in trials])
    pr = rec["pass_rate"]
    low, high = pr["wilson_95"]
    summary = {"out": str(out), "passed": rec["passed"], "requirement_m": rec["requirement_m"],
               "pass_rate": pr, "losses": rec["losses"],
               "stations": {s["id"]: {k: s[k] for k in ("predicted_error_m", "n_passed",
                                                         "rate", "wilson_95")}
                            for s in rec["stations"]}}
    line = (f"passed {pr['n_passed']} of {pr['n_trials']} trials ({100 * pr['rate']:.0f} %, "
            f"95 % {100 * low:.0f}–{100 * high:.0f} %) at requirement "
            f"{rec['requirement_m']:g} m -> {out}/")
    emit_summary(summary, as_json, f"{'PASSED' if rec['passed'] else 'FAILED'}: {line}")
    if not rec["passed"]:
        failing = [f"{s['id']} {s['n_trials'] - s['n_passed']} of {s['n_trials']}"
                   for s in rec["stations"] if s["n_passed"] < s["n_trials"]]
        raise VerificationFailedError(f"verification failed in {pr['n_trials'] - pr['n_passed']}"
                                      f" of {pr['n_trials']} trials (stations failing: "
                                      f"{', '.join(failing)})")
