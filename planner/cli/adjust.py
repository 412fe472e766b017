"""``markerplan adjust``: marker tables of many stations -> network adjustment, reliability,
tables, GeoJSON, report and map."""

from __future__ import annotations

import functools
import math
from pathlib import Path

import click

from pipeline.network.observations import MIN_SIGMA
from planner.cli._common import (
    FILE,
    LOCAL_WITHIN_M,
    REQUIREMENT_M,
    REQUIREMENT_PPM,
    FiniteRange,
    emit_summary,
    error_model_option,
    given_paths,
    json_option,
    out_option,
    overwrite_option,
    renamed_option,
    report_timings,
)
from planner.cli._network_options import (
    control_option,
    datum_choice,
    datum_option,
    error_figure_option,
    odometry_percent_option,
)

#: Bounds of the angle sigmas, degrees: above 10 deg an inclinometer or sun sensor measures
#: nothing, and the small-angle tilt model stops holding; below the adjustment's smallest
#: sigma a prior's weight 1/sigma^2 overflows.
ANGLE_SIGMA_DEG = FiniteRange(math.degrees(MIN_SIGMA), 10.0)
#: Rover odometry, 1-sigma position error, m (up to 50 m of drift between stations; at least
#: the adjustment's smallest sigma, as for the angles).
ODOMETRY_SIGMA_M = FiniteRange(MIN_SIGMA, 50.0)
#: Odometry heading, 1-sigma, degrees.
ODOMETRY_HEADING_SIGMA_DEG = FiniteRange(math.degrees(MIN_SIGMA), 90.0)
#: Odometry between consecutive stations: 1-sigma of the relative heading, degrees per metre
#: (the plan's bound: planner.config; the position's is _common.ODOMETRY_PERCENT).
ODOMETRY_HEADING_DEG_PER_M = FiniteRange(0.0, 10.0, min_open=True)
#: Working radius, m (the plan's bound: planner.config.BOUNDS).
RADIUS_M = FiniteRange(0.0, 100.0, min_open=True)
PROBABILITY = FiniteRange(0.0, 1.0, min_open=True, max_open=True)
#: ``--covariance`` (pipeline.network.settings.COVARIANCE_KINDS, spelled here so that
#: ``--help`` imports no scipy; a test holds them equal).
COVARIANCE_KINDS = ("auto", "dense", "sparse")
#: Robust tuning constants, standardised-residual units (beyond 10 nothing is down-weighted).
ROBUST_K = FiniteRange(0.0, 10.0, min_open=True)


@click.command("adjust")
@click.argument("tables", nargs=-1, required=True, type=click.Path(path_type=Path))
@out_option(required=True)
@overwrite_option
@error_model_option
@click.option("--plan", "plan_path", type=FILE,
              help="plan.json of the survey: its markers and the stations' planned poses "
                   "identify the detections (gated association), give initial values, the "
                   "working radius and the requirement.")
@click.option("--marker-ids", "identity", type=click.Choice(("plan", "geometry", "table")),
              help="How markers are identified across stations: plan (association with --plan's "
                   "markers; the default with --plan), geometry (consistent inter-marker "
                   "distances; the default without), table (the tables' marker_id column: ids "
                   "assigned in the field; for simulated scans that is the simulator's truth).")
@click.option("--odometry-sigma-m", type=ODOMETRY_SIGMA_M, default=0.5, show_default=True,
              help="1-sigma error of a station's planned position as the rover reaches it, m "
                   "(gates the association with --plan).")
@click.option("--odometry-heading-sigma-deg", type=ODOMETRY_HEADING_SIGMA_DEG, default=2.0,
              show_default=True, help="1-sigma error of a station's planned heading, degrees.")
@datum_option
@click.option("--reference-station", "reference_station", metavar="ID",
              help="The datum station of --datum station (its x, y, z and heading fixed; every "
                   "error is relative to it); default: the plan's reference station, else the "
                   "first station of the tables.")
@control_option
@click.option("--heading-prior-sigma-deg", type=ANGLE_SIGMA_DEG,
              help="Heading observed at every station (sun sensor) around its planned heading "
                   "(needs --plan) or its reading in --headings, 1-sigma degrees (default: the "
                   "plan's, else none).")
@click.option("--heading-bias-sigma-deg", type=ANGLE_SIGMA_DEG,
              help="1-sigma of the heading reference's boresight bias, common to every station, "
                   "degrees: the heading observations are then correlated (needs a heading "
                   "prior: --heading-prior-sigma-deg or the plan's; default: the plan's, the "
                   "bias of its heading aid as its network.datum records it, else none).")
@click.option("--headings", "headings_path", type=FILE,
              help="The heading reference's readings: CSV id,heading_deg, one row per station "
                   "(site frame, degrees, the boresight bias included); the heading prior is "
                   "centred on them instead of the planned headings (needs its 1-sigma: "
                   "--heading-prior-sigma-deg or the plan's).")
@click.option("--odometry", "odometry_path", type=FILE,
              help="Odometry between consecutive stations: CSV id,x_m,y_m,z_m,heading_deg of "
                   "the dead-reckoned poses in drive order (any frame); the relative poses of "
                   "consecutive rows are observed (needs --odometry-percent and/or "
                   "--odometry-heading-deg-per-m).")
@odometry_percent_option
@click.option("--odometry-heading-deg-per-m", type=ODOMETRY_HEADING_DEG_PER_M,
              help="1-sigma of an --odometry relative heading, degrees per metre driven.")
@click.option("--inclinometer-sigma-deg", type=ANGLE_SIGMA_DEG,
              help="1-sigma roll and pitch prior of every station, degrees (default: the plan's, "
                   "else 0.01).")
@click.option("--body", type=click.Choice(("plane", "moon", "earth", "crs")), default="plane",
              show_default=True,
              help="The body whose local vertical the inclinometer levels every station to: "
                   "the roll and pitch priors are centred on the vertical's deflection, d/R "
                   "away from the reference station (whose vertical is the site frame's z): "
                   "moon (R 1737.4 km), earth (6371 km), crs (the body of --plan's CRS "
                   "ellipsoid); plane: none (earlier versions, and right for a site frame that "
                   "is no tangent plane).")
@click.option("--snooping/--no-snooping", default=None,
              help="Data snooping: remove the observation whose point test has the largest w "
                   "above the critical value and adjust again, until none is (off: only flag). "
                   "Default: on, off with --robust.")
@click.option("--robust", type=click.Choice(("none", "huber", "igg3")), default="none",
              show_default=True,
              help="Robust estimation instead of data snooping: reweight every observation by "
                   "its standardised residual (Huber, or Yang's IGG-III which gives gross "
                   "errors weight 0); none is plain least squares.")
@click.option("--robust-k0", type=ROBUST_K, default=1.5, show_default=True,
              help="Huber's k, or IGG-III's k0: the standardised residual up to which an "
                   "observation keeps its full weight.")
@click.option("--robust-k1", type=ROBUST_K, default=3.0, show_default=True,
              help="IGG-III's k1: the standardised residual above which an observation gets "
                   "weight 0.")
@click.option("--variance-components", type=click.Choice(("none", "station", "range")),
              default="none", show_default=True,
              help="Estimate a variance factor per observing station or per range band "
                   "(0-10, 10-20, 20-50, 50+ m): is the error model right for each? Written "
                   "to variance_components.csv and the report.")
@click.option("--alpha0", type=PROBABILITY, default=0.001, show_default=True,
              help="Significance level of the test of each point observation.")
@click.option("--beta0", type=PROBABILITY, default=0.80, show_default=True,
              help="Power of the test of each point observation (for the minimal detectable "
                   "biases).")
@renamed_option("--working-radius-m", "working_radius_m", "--working-radius", type=RADIUS_M,
                help="Radius around a station over which its station error is assessed, m "
                     "(default: the plan's, else 10).")
@renamed_option("--requirement-m", "requirement_m", "--requirement", type=REQUIREMENT_M,
                help="Required 95 % station error, m. Default: the plan's, else 0.1.")
@click.option("--relative-within-m", "relative_within_m", type=LOCAL_WITHIN_M, default=50.0,
              show_default=True,
              help="Report the 95 % relative error ellipse of every pair of stations at most "
                   "this far apart horizontally (relative.csv), m.")
@click.option("--relative-requirement-m", "relative_requirement_m", type=REQUIREMENT_M,
              help="Allowed semi-major axis of a pair's 95 % horizontal relative ellipse, "
                   "constant part, m (as a plan's --local-requirement-m); default "
                   "--requirement-m.")
@click.option("--relative-requirement-ppm", "relative_requirement_ppm", type=REQUIREMENT_PPM,
              default=0.0, show_default=True,
              help="Parts per million of a pair's separation added to "
                   "--relative-requirement-m.")
@click.option("--covariance", "covariance", type=click.Choice(COVARIANCE_KINDS),
              default="auto", show_default=True,
              help="dense: the full covariance (covariance.npy); sparse: only the blocks the "
                   "outputs need (stations, markers, observed pairs; no covariance.npy), for "
                   "large networks; auto: sparse above 2,000 unknowns.")
@error_figure_option
@json_option
def command(tables, out, overwrite, error_model, plan_path, identity, odometry_sigma_m,
            odometry_heading_sigma_deg, datum, reference_station, control_path,
            heading_prior_sigma_deg, heading_bias_sigma_deg, headings_path, odometry_path,
            odometry_percent,
            odometry_heading_deg_per_m, inclinometer_sigma_deg, body, snooping, robust, robust_k0,
            robust_k1, variance_components, alpha0, beta0, working_radius_m, requirement_m,
            relative_within_m, relative_requirement_m, relative_requirement_ppm, covariance,
            error_figure, as_json):
    """Adjust a network: estimate every station's pose and every marker's centre together
    from the marker tables (markers.csv of `markerplan process`, accepted detections only) of
    several stations, relative to a datum; test the fit and remove blunders (data snooping),
    or down-weight them (--robust).

    Each detection is weighted by the error model's sigma at its distance and elevation.
    Roll and pitch are unknowns with the inclinometer as prior (centred on the local vertical
    of --body). Writes stations.csv,
    markers.csv, observations.csv, parameters.csv + covariance.npy (full covariance;
    not with --covariance sparse), relative.csv (relative error ellipses of stations within
    --relative-within-m), (with --variance-components) variance_components.csv,
    network.geojson, adjustment.json, report.md and network.png into --out.

    \b
    Example:
      markerplan process scans/ --out tables/
      markerplan adjust tables/markers.csv --plan plan/plan.json --out network/
      markerplan adjust s1/markers.csv s2/markers.csv --control lander.csv --out net/
    """
    import time

    from markerplan.output_folder import output_folder

    kind, reference = datum_choice(datum, control_path, reference_station)
    snooping = _snooping_choice(snooping, robust)
    if identity is None:
        identity = "plan" if plan_path is not None else "geometry"
    _check_identity(identity, plan_path, control_path, heading_prior_sigma_deg, headings_path)
    timings: dict[str, float] = {}
    inputs = given_paths(*tables, plan_path, control_path, odometry_path, headings_path,
                         error_model.path)
    with output_folder(out, overwrite, "adjust", inputs=inputs) as stage:
        from pipeline.network.adjustment import AdjustmentSettings
        from pipeline.network.aids import read_headings, read_odometry
        from pipeline.network.detections import read_control
        from pipeline.network.run import adjust_tables
        from planner.accuracy.local import LocalRequirement
        from planner.network.files import write_network_files
        from planner.network.plan_geometry import (
            body_configuration,
            read_plan_geometry,
            resolved_configuration,
        )
        from planner.network.record import AdjustmentRun, frame_note

        t0 = time.perf_counter()
        plan = read_plan_geometry(plan_path) if plan_path is not None else None
        control = read_control(control_path) if control_path is not None else ()
        dead_reckoned = read_odometry(odometry_path) if odometry_path is not None else None
        measured = read_headings(headings_path) if headings_path is not None else None
        config = resolved_configuration(
            tables=[str(t) for t in tables], plan=_str(plan_path), control=_str(control_path),
            error_model=error_model.name, marker_ids=identity, datum=kind,
            reference_station=None, odometry_sigma_m=odometry_sigma_m,
            odometry_heading_sigma_deg=odometry_heading_sigma_deg,
            heading_prior_sigma_deg=heading_prior_sigma_deg,
            inclinometer_sigma_deg=inclinometer_sigma_deg, working_radius_m=working_radius_m,
            requirement_m=requirement_m, error_figure=error_figure, snooping=snooping,
            alpha0=alpha0, beta0=beta0, robust=robust, robust_k0=robust_k0, robust_k1=robust_k1,
            variance_components=variance_components, relative_within_m=relative_within_m,
            relative_requirement_m=relative_requirement_m,
            relative_requirement_ppm=relative_requirement_ppm, covariance=covariance,
            plan_geometry=plan,
            odometry=_str(odometry_path), odometry_percent=odometry_percent,
            odometry_heading_deg_per_m=odometry_heading_deg_per_m,
            heading_bias_sigma_deg=heading_bias_sigma_deg, headings=_str(headings_path))
        if config["relative_requirement_m"] is None:
            config["relative_requirement_m"] = config["requirement_m"]
        if (heading_bias_sigma_deg is None and plan is not None
                and config["heading_prior_sigma_deg"] is not None):
            config["heading_bias_sigma_deg"] = plan.heading_bias_sigma_deg
        _check_aids(config, odometry_path, headings_path)
        settings = AdjustmentSettings(
            body=_body(body, plan),
            inclinometer_sigma_rad=math.radians(config["inclinometer_sigma_deg"]),
            heading_prior_sigma_rad=_radians(config["heading_prior_sigma_deg"]),
            heading_bias_sigma_rad=_radians(config["heading_bias_sigma_deg"]),
            odometry_ratio=None if odometry_percent is None else odometry_percent / 100.0,
            odometry_heading_rad_per_m=_radians(odometry_heading_deg_per_m),
            alpha0=alpha0, beta0=beta0, snooping=snooping, robust=_none(robust),
            robust_k0=robust_k0, robust_k1=robust_k1,
            variance_components=_none(variance_components), covariance=covariance)
        read_s = time.perf_counter() - t0
        adjusted = adjust_tables(
            tables, error_model.model, functools.partial(_reference, reference, kind, plan),
            functools.partial(_identify, identity, plan=plan, odometry_sigma_m=odometry_sigma_m,
                              odometry_heading_sigma_rad=math.radians(odometry_heading_sigma_deg),
                              inclinometer_sigma_rad=settings.inclinometer_sigma_rad),
            settings, kind, control, plan,
            aids=_aids(dead_reckoned, measured))
        timings.update(adjusted.timings_s)
        timings["read"] += read_s
        result, obs, identified = adjusted.result, adjusted.observations, adjusted.identified
        config.update(body=body_configuration(settings.body,
                                              result.datum.reference_id(obs.station_ids)),
                      reference_station=adjusted.reference_station,
                      max_rejections=settings.max_rejections,
                      max_iterations=settings.max_iterations)
        t0 = time.perf_counter()
        run = AdjustmentRun(
            result=result, observations=obs, config=config,
            working_radius_m=config["working_radius_m"], requirement_m=config["requirement_m"],
            error_figure=config["error_figure"],
            identity=identity, frame=frame_note(
                kind, result.datum.reference_id(obs.station_ids), plan is not None,
                plan.dem if plan else None, plan.crs if plan else None),
            inputs=_input_files(tables, plan_path, control_path, odometry_path, headings_path),
            error_model=error_model.name, unidentified=identified.unidentified,
            plan_markers=(dict(zip(plan.marker_ids, plan.marker_xyz_m, strict=True))
                          if plan and identity != "geometry" else {}),
            crs=plan.crs if plan is not None and kind == "station" else None,
            relative=LocalRequirement(config["relative_requirement_m"],
                                      relative_requirement_ppm, relative_within_m))
        doc = write_network_files(stage, run)
        timings["write"] = time.perf_counter() - t0
    report_timings(timings)
    emit_summary(_summary(doc, out, timings), as_json, _human(doc, out))


def _reference(reference: str | None, kind: str, plan, stations) -> str | None:
    """The reference station: ``--reference-station`` (checked against the tables' stations),
    else the plan's reference station when the tables hold it, else ``None`` (the first)."""
    from pipeline.network.observations import Datum

    ids = [s.station_id for s in stations]
    if reference:
        return Datum(reference_station=reference).reference_id(ids)
    if kind == "station" and plan is not None and plan.reference_station in ids:
        return plan.reference_station
    return None


def _body(choice: str, plan, plan_name: str = "--plan"):
    """``--body`` as a :class:`~pipeline.network.body.Body` (``crs``: the CRS's of ``plan``, a
    :class:`~pipeline.network.detections.PlanGeometry` or None, named ``plan_name`` in the
    error)."""
    from markerplan.errors import ConfigError
    from pipeline.network.body import Body
    from planner.outputs.gis import crs_body

    if choice != "crs":
        return Body.named(choice)
    found = crs_body(plan.crs) if plan is not None else None
    if found is None:
        raise ConfigError(f"--body crs takes the body from the ellipsoid of {plan_name}'s CRS "
                          "(plan.json site.crs_wkt), and there is none; give --body moon, earth "
                          "or plane")
    return found


def _snooping_choice(snooping: bool | None, robust: str) -> bool:
    """``--snooping`` resolved: on by default, off with ``--robust``; both given is refused."""
    from markerplan.errors import ConfigError

    if snooping is None:
        return robust == "none"
    if snooping and robust != "none":
        raise ConfigError(f"--robust {robust} replaces data snooping: drop --snooping (or give "
                          "--robust none)")
    return snooping


def _none(choice: str) -> str | None:
    return None if choice == "none" else choice


def _radians(degrees: float | None) -> float | None:
    return None if degrees is None else math.radians(degrees)


def _aids(dead_reckoned, measured):
    """The :func:`pipeline.network.run.adjust_tables` ``aids`` of ``--odometry`` and
    ``--headings`` (:class:`~pipeline.network.aids.DeadReckonedPoses`,
    :class:`~pipeline.network.aids.MeasuredHeadings`, either None); None without both."""
    if dead_reckoned is None and measured is None:
        return None
    return lambda obs: (None if dead_reckoned is None else dead_reckoned.readings(obs.station_ids),
                        None if measured is None else measured.readings(obs.station_ids))


def _input_files(tables, plan_path, control_path, odometry_path=None,
                 headings_path=None) -> list[dict]:
    """Kind, path and SHA-256 of every input file, for the outputs' provenance."""
    import hashlib

    files = [("marker table", t) for t in tables] + [
        (k, p) for k, p in (("plan", plan_path), ("control", control_path),
                            ("odometry", odometry_path), ("headings", headings_path))
        if p is not None]
    return [{"kind": k, "path": str(p), "sha256": hashlib.sha256(Path(p).read_bytes())
             .hexdigest()} for k, p in files]


def _str(path: Path | None) -> str | None:
    return None if path is None else str(path)


def _check_aids(config: dict, odometry_path, headings_path=None) -> None:
    """``--odometry`` with its sigmas, a boresight bias with a heading prior, and
    ``--headings`` with their sigma."""
    from markerplan.errors import ConfigError

    sigmas = (config["odometry_percent"] is not None
              or config["odometry_heading_deg_per_m"] is not None)
    if odometry_path is not None and not sigmas:
        raise ConfigError("--odometry needs its sigmas: give --odometry-percent and/or "
                          "--odometry-heading-deg-per-m")
    if sigmas and odometry_path is None:
        raise ConfigError("--odometry-percent and --odometry-heading-deg-per-m are the sigmas "
                          "of --odometry FILE; give the file or drop them")
    if config["heading_bias_sigma_deg"] is not None and config["heading_prior_sigma_deg"] is None:
        raise ConfigError("--heading-bias-sigma-deg needs a heading prior: give "
                          "--heading-prior-sigma-deg (with --plan or --headings)")
    if headings_path is not None and config["heading_prior_sigma_deg"] is None:
        raise ConfigError("--headings needs the readings' 1-sigma: give "
                          "--heading-prior-sigma-deg (or a --plan with a heading aid)")


def _check_identity(identity: str, plan_path, control_path, heading_prior,
                    headings_path=None) -> None:
    from markerplan.errors import ConfigError

    if identity == "plan" and plan_path is None:
        raise ConfigError("--marker-ids plan needs --plan PLAN.json; without a plan use "
                          "--marker-ids geometry (or table)")
    if identity == "geometry" and control_path is not None:
        raise ConfigError("--control names markers by id, which association by geometry does "
                          "not know (it names them M001, ...); give --plan or --marker-ids table")
    if heading_prior is not None and plan_path is None and headings_path is None:
        raise ConfigError("--heading-prior-sigma-deg needs --plan or --headings: the heading "
                          "prior is centred on each station's planned heading or its reading")


def _identify(identity: str, stations, plan, odometry_sigma_m: float,
              odometry_heading_sigma_rad: float, inclinometer_sigma_rad: float):
    from markerplan.errors import InputFileError
    from pipeline.network import detections

    if identity == "plan":
        identified = detections.identify_with_plan(stations, plan, odometry_sigma_m,
                                                   odometry_heading_sigma_rad)
    elif identity == "table":
        identified = detections.identify_from_table(stations)
    else:
        identified = detections.identify_by_geometry(stations, inclinometer_sigma_rad)
    lost = [s.station_id for s, ids in zip(identified.stations, identified.ids, strict=True)
            if all(i is None for i in ids)]
    if lost:
        raise InputFileError(f"station(s) {', '.join(lost)}: no detection identified with a "
                             f"marker (--marker-ids {identity}), so they share no markers with "
                             "the network; leave their tables out or check the identification")
    return identified


def _summary(doc: dict, out: Path, timings: dict[str, float]) -> dict:
    st, req, test = doc["statistics"], doc["requirement"], doc["global_test"]
    return {"out": str(out), "n_stations": st["n_stations"], "n_markers": st["n_markers"],
            "n_observations": st["n_observations"], "dof": st["dof"],
            "sigma0_squared": st["sigma0_squared"], "global_test_passed": test["passed"],
            "datum": doc["datum"]["description"], "marker_ids": doc["identity"]["method"],
            "rejected": doc["data_snooping"]["rejected"],
            "robust": None if doc["robust"] is None else doc["robust"]["estimator"],
            "downweighted": [] if doc["robust"] is None else doc["robust"]["downweighted"],
            "variance_components": None if doc["variance_components"] is None else {
                c["group"]: c["sigma0_squared"] for c in doc["variance_components"]["components"]},
            "n_stations_meeting_requirement": req["n_stations_meeting"],
            "requirement_m": req["requirement_m"], "worst_station": req["worst_station"],
            "worst_station_error_95_m": req["worst_station_error_95_m"],
            "stations": {s["id"]: s["station_error_95_m"] for s in doc["stations"]},
            "relative": None if doc["relative"] is None else {
                k: doc["relative"][k] for k in ("requirement", "n_pairs", "n_passed",
                                                "worst_pair", "n_marker_pairs",
                                                "n_marker_passed", "worst_marker_pair")},
            "timings_s": {k: round(v, 3) for k, v in timings.items()}}


def _human(doc: dict, out: Path) -> str:
    st, req, test = doc["statistics"], doc["requirement"], doc["global_test"]
    fit = ("untestable (no redundancy)" if test["passed"] is None else
           "GLOBAL TEST FAILED: noisier than the error model" if not test["passed"] else
           "global test passed" + ("; error model pessimistic" if test["verdict"] != "ok"
                                   else ""))
    rejected = doc["data_snooping"]["rejected"]
    removed = ("; removed " + ", ".join(f"{r['station_id']}->{r['marker_id']} (w {r['w']:.1f})"
                                        for r in rejected)) if rejected else ""
    if doc["robust"] is not None:
        down = doc["robust"]["downweighted"]
        removed += (f"; {doc['robust']['estimator']}: {len(down)} down-weighted"
                    + "".join(f", {d['station_id']}->{d['marker_id']} ({d['weight']:.2f})"
                              for d in down[:5]))
    sigma0 = st["sigma0_squared"]
    return (f"adjusted {st['n_stations']} stations, {st['n_markers']} markers "
            f"({st['n_observations']} observations, dof {st['dof']}): sigma0^2 "
            f"{'n/a' if sigma0 is None else f'{sigma0:.3f}'} ({fit}){removed}\n"
            f"worst station {req['worst_station']}: "
            f"{1e3 * req['worst_station_error_95_m']:.1f} mm (95 %); "
            f"{req['n_stations_meeting']}/{st['n_stations']} within {req['requirement_m']:g} m"
            f"\nwrote {out}/")
