"""``markerplan verify``: simulate and process a plan, compare achieved with predicted error."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from planner.cli._common import (
    FILE,
    emit_summary,
    error_model_option,
    given_paths,
    json_option,
    mounting_offset_options,
    out_option,
    overwrite_option,
    scheduler_options,
    seed_option,
    sensor_profile_option,
    station_ids_option,
)
from planner.cli._network_options import network_option, reference_station_option, require_network
from planner.cli.adjust import command as _adjust
from planner.cli.verify_options import offset_tolerance_options

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
@offset_tolerance_options
@sensor_profile_option
@network_option
@reference_station_option
@_adjust_options("odometry_sigma_m", "odometry_heading_sigma_deg", "body")
@click.option("--trials", type=click.IntRange(1, MAX_TRIALS), default=1, show_default=True,
              metavar="N",
              help="Verify the plan N times with independent noise and turntable-error seeds "
                   "(spawned from --seed; the first trial is --seed's) and report its pass rate "
                   "with a Wilson 95 % interval, per station and per station-marker pair.")
@click.option("--truth-dem", "truth_dem_path", type=FILE,
              help="Simulate on this terrain (the field's, in the plan's site frame; any DEM "
                   "--dem reads) instead of the plan's: the preset's truth terrain, or the "
                   "plan's --dem. Stations and markers keep their planned x, y and height "
                   "above the ground.")
@scheduler_options
@out_option(required=True)
@overwrite_option
@json_option
def command(plan_path, error_model, seed, station_ids, offsets, tolerance, profile, network,
            reference_station, odometry_sigma_m, odometry_heading_sigma_deg, body, trials,
            truth_dem_path, scheduler, workers, out, overwrite, as_json):
    """Check a plan by simulation: scan each station with the planned markers, process the
    scans, register each station to its detected markers, and compare achieved with predicted
    error. A station passes when the markers it detected and accepted meet the plan's rule
    (at least min_markers of them in at least min_sectors of n_sectors directions, as planned)
    and its achieved error the requirement: the promise the plan's P(pass) is about. Exit code
    1 when any station fails. The plan's marker radius is simulated and fitted; --station-ids
    verifies some stations only.

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
    --body (network mode, `adjust`'s option) stands the simulated rover on a curved body: each
    station levels itself to the local vertical at its planned position (tilted by d/R away
    from the reference station, the tangent point of the site frame; the truth records that
    roll and pitch), and the adjustment centres its tilt priors on the same body.

    The scans are simulated on the truth terrain, never on a planning DEM: a plan made with
    `plan --terrain orbital` on the preset's fine terrain, any plan with --truth-dem FILE on
    that file; each station and marker keeps its planned x, y and height above the ground,
    re-seated on the truth ground.

    Every planned marker's fate is in fates.csv: the stage of the chain that lost it
    (not_in_view, ground, cluster, gate, fit, quality) and why, or accepted, against the
    simulator's truth (its marker_id is the true id, in network mode too, where the
    adjustment never sees it); each station's reason names its losses.

    With --trials N (both modes), the plan is verified N times with independent seeds (the
    first is --seed's, the others spawned from it), each trial drawing the rig's mounting
    offsets from N(the offsets given, the --*-tolerance-* given): verify.json / verify.md
    give the plan's pass rate with its Wilson 95 % interval beside the plan's predicted pass
    probability, each station's and each station-marker pair's rates and losses beside the
    plan's predicted detection probabilities (and their calibration), trials.csv one row per
    trial and station (with the trial's offsets), fates.csv a trial column; in network mode
    markers/trial_NNN.csv each trial's detections. Exit code 1 when any trial fails.

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
      markerplan verify plan/plan.json --truth-dem field.tif --out verify-field/
      markerplan verify plan/plan.json --scheduler tcp://10.0.0.5:8786 --out verify/
    """
    import json

    from markerplan.errors import ConfigError, VerificationFailedError
    from markerplan.output_folder import output_folder
    from planner.distributed import executor
    from planner.outputs.plan_file import load_plan
    from planner.problem.inputs import select_stations
    from planner.verify.fates import write_fates
    from planner.verify.known_control import (
        on_truth_terrain,
        verify_markdown,
        verify_plan,
        verify_record,
    )
    from visibility.dem import read_dem

    plan = load_plan(plan_path)
    truth = None if truth_dem_path is None else read_dem(
        truth_dem_path, what=f"--truth-dem {truth_dem_path}")
    plan = on_truth_terrain(plan, truth, f"--truth-dem {truth_dem_path}")
    ids = select_stations([s.id for s in plan.stations], station_ids)
    inputs = given_paths(plan_path, plan.dem_path, error_model.path, truth_dem_path)
    planned_network = bool(plan.provenance.get("config", {}).get("network"))
    network = network or planned_network
    require_network(reference_station, network)
    if body != "plane" and not network:
        raise ConfigError(f"--body {body} levels the simulated stations of network mode and "
                          "centres its adjustment's tilt priors; give --network, or drop it")
    if tolerance is not None and trials == 1:
        raise ConfigError("the mounting-offset tolerances are drawn once per trial; give "
                          "--trials N (N > 1) with them, or drop them")
    if network:
        from planner.verify.network import NetworkVerifySettings

        doc, datum = _network_datum(plan_path, ids, reference_station)
        settings = NetworkVerifySettings(odometry_sigma_m, odometry_heading_sigma_deg,
                                         body=_network_body(body, doc, plan_path))
    if trials > 1:
        _verify_trials(plan_path, plan, ids, inputs, error_model, seed, offsets, tolerance,
                       profile, trials, out, overwrite, as_json, (scheduler, workers),
                       (settings, doc, datum) if network else None)
        return
    if network:
        _verify_network(plan_path, plan, doc, ids, inputs, error_model, seed, offsets, profile,
                        settings, out, overwrite, as_json, datum, (scheduler, workers))
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


def _network_datum(plan_path, ids, datum):
    """The plan document and the ``--reference-station`` given (a network plan's own datum
    only), checked to be a station verified."""
    from markerplan.errors import ConfigError
    from pipeline.network.observations import Datum
    from planner.outputs.plan_file import read_plan
    from planner.verify.network_datum import reference_station

    doc = read_plan(plan_path, "PLAN", full=True)
    if ((doc.get("network") or {}).get("datum") or {}).get("kind") in ("control", "free"):
        from planner.network.plan_geometry import plan_geometry
        from planner.verify.network_datum import verify_datum

        verify_datum(doc, plan_geometry(doc, plan_path), datum, ids, 0)  # refuses up front
        return doc, None
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
    return doc, datum


def _network_body(choice: str, doc: dict, plan_path: Path):
    """``--body`` of network mode (``crs``: the ellipsoid's of the plan's CRS)."""
    from planner.cli.adjust import _body
    from planner.network.plan_geometry import plan_geometry

    return _body(choice, plan_geometry(doc, plan_path) if choice == "crs" else None, "PLAN")


def _verify_network(plan_path, plan, doc, ids, inputs, error_model, seed, offsets, profile,
                    settings, out, overwrite, as_json, datum, where):
    """``verify --network``: scan, write the marker table, adjust and compare
    (:mod:`planner.verify.network`); exit code 1 when a station fails. ``doc``, ``datum``:
    :func:`_network_datum`'s; ``where``: ``(scheduler, workers)`` of the station tasks."""
    import json

    from markerplan.errors import VerificationFailedError
    from markerplan.output_folder import output_folder
    from planner.distributed import executor
    from planner.verify.fates import write_fates
    from planner.verify.network import scan_plan, verify_scan
    from planner.verify.network_report import (
        network_markdown,
        network_record,
        network_summary_line,
    )
    from visibility.sensor_profile import default_profile

    profile = profile or default_profile()
    progress = not as_json or sys.stderr.isatty()
    with executor(*where, progress) as ex, \
            output_folder(out, overwrite, "verify", inputs=inputs) as stage:
        scanned = scan_plan(plan, seed, offsets=offsets, station_ids=ids, profile=profile,
                            executor=ex, body=settings.body, reference=datum)
        write_fates(stage / "fates.csv", [list(scanned[2].values())])
        check = verify_scan(scanned, stage / "markers.csv", plan_path, doc, error_model.model,
                            error_model.name, settings, datum, seed)
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


def _verify_trials(plan_path, plan, ids, inputs, error_model, seed, offsets, tolerance,
                   profile, n_trials, out, overwrite, as_json, where, network):
    """``verify --trials N`` (``N`` > 1; :mod:`planner.verify.trials`): exit code 1 when any
    trial fails. ``where``: ``(scheduler, workers)`` of the tasks; ``network``: ``(settings,
    doc, datum)`` in network mode, else ``None``."""
    import json

    from markerplan.errors import VerificationFailedError
    from markerplan.output_folder import output_folder
    from planner.distributed import executor
    from planner.verify.fates import write_fates
    from planner.verify.rig_draws import trial_offsets
    from planner.verify.trials import (
        read_predictions,
        trial_seeds,
        trials_markdown,
        trials_record,
        verify_network_trials,
        verify_trials,
        write_trials,
    )

    seeds = trial_seeds(seed, n_trials)
    rigs = trial_offsets(offsets, tolerance, seeds)
    predictions = read_predictions(plan_path)
    progress = not as_json or sys.stderr.isatty()
    with executor(*where, progress) as ex, \
            output_folder(out, overwrite, "verify", inputs=inputs) as stage:
        if network is None:
            trials = verify_trials(plan, error_model.model, seeds, rigs, ids, profile, ex)
        else:
            settings, doc, datum = network
            (stage / "markers").mkdir()
            trials = verify_network_trials(plan, plan_path, doc, error_model.model,
                                           error_model.name, seeds, stage / "markers",
                                           settings, rigs, ids, profile, ex, datum)
        rec = trials_record(plan, trials, seed, seeds, error_model.name, rigs, profile,
                            network=None if network is None else
                            {**network[0].record(), "reference_station": datum},
                            nominal=offsets, tolerance=tolerance, predictions=predictions)
        (stage / "verify.json").write_text(json.dumps(rec, indent=2) + "\n")
        (stage / "verify.md").write_text(trials_markdown(rec))
        write_trials(stage / "trials.csv", trials, seeds, rigs)
        write_fates(stage / "fates.csv", [[c.fates for c in checks] for checks in trials])
    pr = rec["pass_rate"]
    low, high = pr["wilson_95"]
    summary = {"out": str(out), "mode": rec["mode"], "passed": rec["passed"],
               "requirement_m": rec["requirement_m"], "pass_rate": pr, "losses": rec["losses"],
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
