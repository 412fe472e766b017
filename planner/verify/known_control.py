"""Verify a plan by simulation: scan every station with the planned markers, process the scans
with the pipeline, register each station to its detected markers, and compare the achieved
registration error with the plan's prediction.

Per station:

1. ``visibility.simulate.simulate_markers`` — a full turntable scan of the station's terrain
   tile (the station ± the sensor's maximum range) with only the planned markers, at the
   planned station pose, with the sensor and turntable errors
   of a sensor profile (:mod:`visibility.sensor_profile`, ``calibrated`` by default);
2. ``pipeline.chain.process.process_station`` — the published chain, configured for the plan's
   marker radius (:func:`pipeline.surveys.survey.processing_config`); detections are matched to the
   planned markers projected into the station frame with the *planned* (nominal) pose;
3. weighted least squares (:func:`planner.accuracy.known_control.fit_pose`, 4 DoF: x, y, z,
   heading; roll and pitch are known, as from the inclinometer) from the accepted, matched
   markers, each weighted by the error model's sigma at its measured distance and elevation;
4. achieved error = the largest 3D difference, over the working radius, between the registered
   and the true mapping of the station frame into the site frame
   (:func:`planner.accuracy.known_control.registration_error`).

Beside the check, every planned marker of the station gets its fate against the simulator's
truth (:mod:`planner.verify.fates`): the stage of the chain that lost it and why, or
``accepted``; ``fates.csv`` lists them and each station's reason names its losses.

The plan passes only if every station's achieved error is within the requirement.

Verification simulates on the **truth** terrain, never on a planning DEM
(:func:`on_truth_terrain`): a plan made on a preset's orbital DEM (``plan --terrain orbital``)
is simulated on the preset's fine terrain, a plan checked against ``--truth-dem FILE`` on that
file; the stations and markers keep their planned x, y and their height above the ground, re-seated
on the truth ground (a marker rests on it, the rover stands on it). A plan made on the terrain
it is verified on is simulated as planned.

Each station is one task (:func:`station_task`: simulate, then process, returning only the small
result), mapped by :mod:`planner.distributed` in process or over a dask cluster, with the same
results either way.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from markerplan.errors import DataError
from markerplan.provenance import provenance
from pipeline.chain.evaluation import Reference
from pipeline.chain.process import process_station
from pipeline.chain.stages import ProcessConfig
from pipeline.scans.rig import MountingOffsets, station_to_site_matrix
from pipeline.scans.scan_format import StationScan
from pipeline.surveys.survey import ProcessingSettings, processing_config
from planner import distributed
from planner.accuracy import known_control
from planner.distributed import Executor
from planner.outputs.plan_file import PlannedStation, SurveyPlan
from planner.verify.fates import (
    StationFates,
    fates_record,
    losses_markdown,
    stage_counts,
    station_fates,
    unmatched_text,
)
from planner.verify.station_rule import StationRule
from visibility.dem import DEM
from visibility.orbital import reseated
from visibility.sensor_profile import SensorProfile, default_profile
from visibility.simulate import simulate_markers

#: Schema of ``verify.json``, both modes (``mode`` tells a network verification apart).
VERIFY_SCHEMA = "markerplan-verify"
VERIFY_SCHEMA_VERSION = 1

#: Smallest number of matched markers that can fix x, y, z and heading.
MIN_MATCHED = 2

@dataclass
class StationCheck:
    """Verification of one station (``fates``: its planned markers' fates, when the truth
    was known)."""

    station_id: str
    predicted_error_m: float | None
    achieved_error_m: float | None
    n_planned: int
    n_detected: int
    passed: bool
    reason: str
    marker_errors_m: dict
    fates: StationFates | None = None


def verify_plan(plan: SurveyPlan, error_model, seed: int = 0, progress: bool = True,
                offsets: MountingOffsets | None = None,
                station_ids: list[str] | None = None,
                profile: SensorProfile | None = None,
                executor: Executor | None = None) -> list[StationCheck]:
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
        Progress bar on stderr (when no ``executor`` is given).
    offsets : pipeline.scans.rig.MountingOffsets, optional
        True mounting offsets of the simulated rig (default: none). The pipeline self-calibrates
        them from each station's scan, as it would in the field.
    station_ids : list of str, optional
        Verify only these stations (default: all), in the plan's order.
    profile : SensorProfile, optional
        Sensor and turntable errors of the simulated rig (default: the shipped
        ``calibrated`` profile), at 600 rpm.
    executor : planner.distributed.Executor, optional
        Where the stations run (default: one after another in this process); the checks are
        the same either way.

    Returns
    -------
    checks : list of StationCheck
        In the plan's station order.
    """
    return verify_plans([plan], error_model, seed, progress, offsets, station_ids, profile,
                        executor)[0]


def verify_plans(plans: Sequence[SurveyPlan], error_model, seed: int | Sequence[int] = 0,
                 progress: bool = True,
                 offsets: MountingOffsets | Sequence[MountingOffsets] | None = None,
                 station_ids: list[str] | None = None, profile: SensorProfile | None = None,
                 executor: Executor | None = None, names: Sequence[str] | None = None
                 ) -> list[list[StationCheck]]:
    """:func:`verify_plan` of several plans on one terrain (``reduce --verify``'s counts) as
    one map: every station of every plan is a task, all under one progress bar.

    Parameters
    ----------
    plans : sequence of SurveyPlan
        Sharing one DEM (the same object).
    seed : int or sequence of int
        As :func:`verify_plan`, or one per plan (a plan may come more than once: the trials
        of :mod:`planner.verify.trials`).
    offsets : MountingOffsets or sequence of MountingOffsets, optional
        As :func:`verify_plan`, or one per plan (:func:`map_plan_stations`).
    error_model, progress, station_ids, profile, executor
        As :func:`verify_plan`.
    names : sequence of str, optional
        A name per plan for the task errors (e.g. ``k=11``).

    Returns
    -------
    checks : list of list of StationCheck
        Per plan, in the plan's station order.
    """
    seeds = _per_plan(seed, len(plans))
    checks = [functools.partial(check_station, tuple(plan.marker_ids), plan.marker_xyz_m,
                                processing_config(ProcessingSettings(
                                    marker_radius_m=plan.marker_radius_m)),
                                error_model, plan.requirement_m, plan.working_radius_m, s,
                                rule=plan.rule)
              for plan, s in zip(plans, seeds, strict=True)]
    return map_plan_stations(plans, checks, seeds, progress, offsets, station_ids, profile,
                             executor, names)


def _per_plan(seed: int | Sequence[int], n_plans: int) -> list[int]:
    """One seed per plan: ``seed`` for all, or the ``n_plans`` seeds given."""
    seeds = [seed] * n_plans if isinstance(seed, int | np.integer) else list(seed)
    if len(seeds) != n_plans:
        raise ValueError(f"{len(seeds)} seeds for {n_plans} plans")
    return [int(s) for s in seeds]


def check_station(ids: tuple[str, ...], centres: np.ndarray, cfg: ProcessConfig, error_model,
                  requirement_m: float, working_radius_m: float, seed: int,
                  st: PlannedStation, scan: StationScan, truth: dict,
                  rule: StationRule | None = None) -> StationCheck:
    """Steps 2-4 of the module docstring for one simulated station.

    Parameters
    ----------
    ids : tuple of str
        The plan's marker ids.
    centres : (m, 3) float
        Their centres, site frame, metres.
    cfg : ProcessConfig
        Pipeline configuration (:func:`pipeline.surveys.survey.processing_config`).
    error_model : ErrorModel
    requirement_m, working_radius_m : float
        The plan's requirement and working radius, metres.
    seed : int
        The pipeline's seed.
    st : PlannedStation
    scan : StationScan
    truth : dict
        The simulator's truth (:func:`visibility.simulate.simulate_markers`).
    rule : StationRule, optional
        The markers and directions the station must detect (default: the planner's default
        rule); the station passes when it does and meets the requirement.

    Returns
    -------
    check : StationCheck
    """
    ids = list(ids)
    rot = station_to_site_matrix(st.heading_rad)
    nominal = (centres - st.position_m) @ rot  # planned markers in the planned station frame
    ref = Reference(tuple(ids), nominal, st.id, "plan (nominal pose)")
    result = process_station(scan, cfg, ref, seed=seed)
    fates = station_fates(result, truth, st.marker_ids, cfg)
    rows = [r for r in result.rows if r.accepted and r.marker_id]
    marker_err = {r.marker_id: r.error_m for r in rows}
    n_planned = len(st.marker_ids)
    matched = {r.marker_id for r in rows}
    lost = unmatched_text(fates, matched)
    if len(rows) < MIN_MATCHED:
        return StationCheck(st.id, st.predicted_error_m, None, n_planned, len(rows), False,
                            f"only {len(rows)} planned marker(s) detected and accepted (needs "
                            f"{MIN_MATCHED}): {lost}", marker_err, fates)
    p = np.array([r.centre_m for r in rows])
    site_xyz = centres[[ids.index(r.marker_id) for r in rows]]
    sigma = np.asarray(error_model.predict(np.array([r.distance_m for r in rows]),
                                           np.radians([r.elevation_deg for r in rows]))
                       .sigma_m, float)
    sigma = np.maximum(sigma, 1e-4)
    t, psi = known_control.fit_pose(p, site_xyz, sigma, heading0_rad=st.heading_rad)
    true_pose = truth["station_pose"]
    achieved = known_control.registration_error(t, psi, true_pose["position_m"],
                                           true_pose["heading_rad"], working_radius_m)
    ok, reason = (rule or StationRule()).verdict(st.position_m, site_xyz, achieved,
                                                 requirement_m)
    if lost:
        reason += f" ({lost})"
    return StationCheck(st.id, st.predicted_error_m, achieved, n_planned, len(rows), ok, reason,
                        marker_err, fates)


@dataclass(frozen=True)
class StationJob:
    """One station's task: what :func:`station_task` needs besides the DEM (small, picklable).

    Attributes
    ----------
    station : PlannedStation
    seed : int
        The simulation's seed (``seed + k`` for the plan's station ``k``).
    marker_ids : tuple of str
    marker_xyz_m : (m, 3) float
        Planned marker centres, site frame, metres.
    marker_radius_m : float
    profile : SensorProfile
    offsets : MountingOffsets
        True mounting offsets of the simulated rig.
    process : callable
        ``process(station, scan, truth)`` -> the task's small result (a module-level function
        or a ``functools.partial`` of one).
    threads : int or None
        Ray-casting threads (None: all cores).
    tilt_rad : (2,) float
        The station's true roll and pitch, rad: level (zeros) unless it is levelled to a
        curved body's local vertical (:func:`planner.verify.levelling.levelled_tilts`).
    """

    station: PlannedStation
    seed: int
    marker_ids: tuple[str, ...]
    marker_xyz_m: np.ndarray
    marker_radius_m: float
    profile: SensorProfile
    offsets: MountingOffsets
    process: Callable
    threads: int | None = None
    tilt_rad: tuple[float, float] = (0.0, 0.0)


def station_tile(dem: DEM, position_m: np.ndarray, reach_m: float) -> DEM:
    """The DEM tile a station's scan can reach: its position ± ``reach_m`` (the sensor's
    maximum range), on the DEM's own grid (:meth:`visibility.dem.DEM.crop`).

    Parameters
    ----------
    dem : DEM
    position_m : (3,) float
        Station (LiDAR centre), site frame, metres.
    reach_m : float
        Half-width of the tile, metres.

    Returns
    -------
    tile : DEM
    """
    x, y = float(position_m[0]), float(position_m[1])
    return dem.crop(x - reach_m, x + reach_m, y - reach_m, y + reach_m)


def station_task(dem: DEM, job: StationJob):
    """Simulate one planned station on its DEM tile with the planned markers, then hand the
    scan to ``job.process`` and return what it returns (never the scan itself).

    The Embree scene is built here, on the worker, from the tile (it is never pickled); the
    same function runs in process and on a cluster, so the results are the same.

    Parameters
    ----------
    dem : DEM
        The plan's whole terrain (sent to each worker once).
    job : StationJob

    Returns
    -------
    result : object
        ``job.process(station, scan, truth)``.
    """
    st, profile = job.station, job.profile
    sensor = profile.sensor_config()
    rig = profile.rig_config(offsets=job.offsets)
    tile = station_tile(dem, st.position_m, sensor.max_range_m)
    scan, truth = simulate_markers(tile, st.position_m, st.heading_rad, job.marker_xyz_m,
                                   sensor, rig, seed=job.seed,
                                   marker_radius_m=job.marker_radius_m,
                                   marker_ids=list(job.marker_ids), station_id=st.id,
                                   threads=job.threads, sensor_profile=profile.name,
                                   roll_rad=job.tilt_rad[0], pitch_rad=job.tilt_rad[1])
    return job.process(st, scan, truth)


def map_stations(plan: SurveyPlan, process: Callable, seed: int = 0, progress: bool = True,
                 offsets: MountingOffsets | None = None, station_ids: list[str] | None = None,
                 profile: SensorProfile | None = None, executor: Executor | None = None) -> list:
    """Simulate the chosen stations of a plan at their planned poses (step 1 of the module
    docstring) and ``process`` each, as one :func:`station_task` per station.

    Parameters
    ----------
    plan : SurveyPlan
    process : callable
        ``process(station, scan, truth)`` -> a station's result; picklable.
    seed, progress, offsets, station_ids, profile, executor
        As :func:`verify_plan`.

    Returns
    -------
    results : list
        ``process``'s results in the plan's station order.
    """
    return map_plan_stations([plan], [process], seed, progress, offsets, station_ids, profile,
                             executor)[0]


def map_plan_stations(plans: Sequence[SurveyPlan], processes: Sequence[Callable],
                      seed: int | Sequence[int] = 0, progress: bool = True,
                      offsets: MountingOffsets | Sequence[MountingOffsets] | None = None,
                      station_ids: list[str] | None = None,
                      profile: SensorProfile | None = None, executor: Executor | None = None,
                      names: Sequence[str] | None = None,
                      tilt_rad: dict[str, tuple[float, float]] | None = None) -> list[list]:
    """:func:`map_stations` of several plans on one terrain as one map (one progress bar).

    Parameters
    ----------
    plans : sequence of SurveyPlan
        Sharing one DEM (the same object: it is sent to each worker once).
    processes : sequence of callable
        ``process`` of each plan, as :func:`map_stations` takes it.
    seed : int or sequence of int
        As :func:`verify_plan`, or one per plan (a plan may come more than once: the trials
        of ``verify --trials``).
    offsets : MountingOffsets or sequence of MountingOffsets, optional
        As :func:`verify_plan`, or one per plan (the rig offsets of each trial of
        ``verify --trials`` drawn from the user's tolerances).
    progress, station_ids, profile, executor
        As :func:`verify_plan`.
    names : sequence of str, optional
        A name per plan for the task errors (``station S2 (k=11)``); default none.
    tilt_rad : dict of str to (2,) float, optional
        Per station id, its true roll and pitch, rad (:attr:`StationJob.tilt_rad`); default
        every station level.

    Returns
    -------
    results : list of list
        Per plan, its ``process``'s results in the plan's station order.
    """
    if any(plan.dem is not plans[0].dem for plan in plans):
        raise ValueError("map_plan_stations: the plans must share one DEM object")
    profile = profile or default_profile()
    rigs = (list(offsets) if isinstance(offsets, Sequence)
            else [offsets or MountingOffsets()] * len(plans))
    if len(rigs) != len(plans):
        raise ValueError(f"{len(rigs)} mounting offsets for {len(plans)} plans")
    chosen = [[(k, st) for k, st in enumerate(plan.stations)
               if station_ids is None or st.id in station_ids] for plan in plans]
    n_tasks = sum(len(c) for c in chosen)
    seeds = _per_plan(seed, len(plans))
    suffix = [f" ({name})" for name in names] if names is not None else [""] * len(plans)
    with contextlib.ExitStack() as stack:
        if executor is None:
            executor = stack.enter_context(distributed.executor(distributed.IN_PROCESS,
                                                                progress=progress))
        jobs = [StationJob(st, int(s) + k, tuple(plan.marker_ids), plan.marker_xyz_m,
                           plan.marker_radius_m, profile, rig, process,
                           executor.threads(n_tasks), (tilt_rad or {}).get(st.id, (0.0, 0.0)))
                for plan, process, stations, s, rig in zip(plans, processes, chosen, seeds,
                                                           rigs, strict=True)
                for k, st in stations]
        labels = [f"station {st.id}{end}" for stations, end in zip(chosen, suffix, strict=True)
                  for _, st in stations]
        results = iter(executor.map(station_task, jobs, shared=plans[0].dem, labels=labels,
                                    desc="verify"))
    return [list(itertools.islice(results, len(stations))) for stations in chosen]


def on_truth_terrain(plan: SurveyPlan, truth: DEM | None = None,
                     what: str = "`truth_dem`") -> SurveyPlan:
    """The plan as verification simulates it: on the truth terrain (module docstring).

    Parameters
    ----------
    plan : SurveyPlan
        As :func:`planner.outputs.plan_file.load_plan` reads it: ``dem`` is a preset's truth
        terrain or the plan's ``--dem`` file.
    truth : DEM, optional
        The terrain to simulate on instead (``verify --truth-dem``), in the plan's site frame.
    what : str
        How messages name ``truth``.

    Returns
    -------
    plan : SurveyPlan
        ``plan`` itself when it was made on the terrain it is verified on; else on ``truth``
        (or the preset's truth), every station and marker at its planned x, y and planned
        height above the planning ground, on the truth ground.

    Raises
    ------
    DataError
        ``truth`` does not cover every station and marker (or they stand on its nodata):
        names them all and the fix.
    """
    planning = planning_terrain(plan)
    if truth is None:
        truth = plan.dem
    if planning is truth:
        return plan
    _require_covers(truth, plan, what)
    stations = tuple(dataclasses.replace(st, position_m=reseated(st.position_m[None], planning,
                                                                  truth)[0])
                     for st in plan.stations)
    return dataclasses.replace(plan, dem=truth, stations=stations,
                               marker_xyz_m=reseated(plan.marker_xyz_m, planning, truth))


def planning_terrain(plan: SurveyPlan) -> DEM:
    """The DEM a plan was made on: its orbital planning DEM when its provenance says so
    (rebuilt from the recorded cell, height error and seed, :func:`visibility.orbital.orbital_dem`),
    else ``plan.dem``."""
    from visibility.orbital import HeightError, orbital_dem

    inputs = plan.provenance.get("inputs", {})
    terrain = inputs.get("terrain") or {}
    if terrain.get("kind") != "orbital":
        return plan.dem
    error = HeightError(**terrain["height_error"])
    return orbital_dem(plan.dem, terrain["cell_m"], error, seed=terrain["seed"])


def _require_covers(truth: DEM, plan: SurveyPlan, what: str) -> None:
    """Refuse a truth DEM that leaves a station or marker off its measured terrain, naming
    every such id (one-line :class:`DataError`)."""
    ids = [st.id for st in plan.stations] + list(plan.marker_ids)
    xy = np.vstack([[st.position_m[:2] for st in plan.stations],
                    np.asarray(plan.marker_xyz_m)[:, :2]])
    on = truth.valid_at(xy)
    if not on.all():
        off = [i for i, ok in zip(ids, on, strict=True) if not ok]
        shown = ", ".join(off[:20]) + (f" and {len(off) - 20} more" if len(off) > 20 else "")
        xmin, xmax, ymin, ymax = truth.extent()
        raise DataError(f"{what} does not cover {shown} of the plan (it spans [{xmin:.1f}, "
                        f"{xmax:.1f}] x [{ymin:.1f}, {ymax:.1f}] m, site frame); give a truth "
                        "DEM covering every station and marker, in the plan's site frame")


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
        "station_rule": dataclasses.asdict(plan.rule),
        "passed": all(c.passed for c in checks),
        "losses": stage_counts(c.fates for c in checks),
        "stations": [{"id": c.station_id, "predicted_error_m": c.predicted_error_m,
                      "achieved_error_m": c.achieved_error_m, "n_planned_markers": c.n_planned,
                      "n_detected_markers": c.n_detected, "passed": c.passed,
                      "reason": c.reason, "marker_centre_errors_m": c.marker_errors_m,
                      **fates_record(c.fates)}
                     for c in checks],
    }


def verify_markdown(rec: dict) -> str:
    """Human report of a verification."""
    lines = [f"# Plan verification — {'PASSED' if rec['passed'] else 'FAILED'}", "",
             f"Requirement: achieved registration error ≤ {rec['requirement_m']:g} m at every "
             "station (simulated scans, processed by the pipeline, 4-DoF WLS registration)"
             + (f", with at least {rule['min_markers']} planned markers detected and accepted "
                f"in at least {rule['min_sectors']} of {rule['n_sectors']} directions"
                if (rule := rec.get("station_rule")) else "") + ".", "",
             "| station | predicted | achieved | markers detected / planned | result |",
             "|---|---:|---:|---:|---|"]
    for s in rec["stations"]:
        pred = "—" if s["predicted_error_m"] is None else f"{s['predicted_error_m']:.4f} m"
        ach = "—" if s["achieved_error_m"] is None else f"{s['achieved_error_m']:.4f} m"
        lines.append(f"| {s['id']} | {pred} | {ach} | {s['n_detected_markers']} / "
                     f"{s['n_planned_markers']} | {s['reason']} |")
    if "losses" in rec:
        lines += ["", losses_markdown(rec["losses"])]
    return "\n".join(lines) + "\n"
