"""``markerplan plan``: the fewest marker sites meeting the requirement; map, report, GeoJSON."""

from __future__ import annotations

import math
import sys

import click

from planner.cli._common import (
    FILE,
    FiniteRange,
    boundary_option,
    config_option,
    dem_height_error_option,
    dem_option,
    emit_summary,
    error_model_option,
    exclude_option,
    given_paths,
    json_option,
    marker_radius_option,
    out_option,
    overwrite_option,
    point_option,
    renamed_option,
    report_timings,
    reproject_option,
    require_dem,
    require_truth_terrain,
    scheduler_options,
    site_option,
    site_seed_option,
    station_ids_option,
    stations_option,
    terrain_option,
    time_limit_option,
    with_options,
)
from planner.cli._network_options import (
    control_option,
    datum_choice,
    datum_option,
    error_figure_option,
    network_option,
    network_settings,
    reference_station_option,
    requirement_options,
)

#: Cell size of the stand maps, m: rounded to whole DEM cells (at least one), so any positive
#: size up to 10 km (one cell over any site markerplan plans; a km site is 1 km across).
CELL_M = FiniteRange(0.0, 10_000.0, min_open=True)


class ChanceEpsilon(click.ParamType):
    """``--chance-epsilon``: a number in (0, 0.5] or ``none`` (the naive plan, :data:`NAIVE`)."""

    name = "EPSILON|none"

    def convert(self, value, param, ctx):
        if isinstance(value, float) or value is NAIVE:
            return value
        if str(value).strip().lower() == "none":
            return NAIVE
        try:
            eps = float(value)
        except ValueError:
            eps = math.nan
        if not (math.isfinite(eps) and 0.0 < eps <= 0.5):
            self.fail(f"{value!r} is not a chance in (0, 0.5] or 'none'; give e.g. 0.05 (the "
                      "plan fails with chance at most 5 %) or none (every planned marker "
                      "counted as detected)", param, ctx)
        return eps


#: ``--chance-epsilon none``: plan as if every planned marker is detected.
NAIVE = object()


def _load_detection_model(ctx, param, path):
    """Click callback: ``--detection-model FILE`` -> ``(model, name)`` (default: shipped)."""
    from error_model.default import default_detection_model
    from error_model.detection import DetectionModel

    if path is None:
        return default_detection_model(), "default (shipped with markerplan)"
    return DetectionModel.load(path), str(path)


@click.command("plan")
@site_option()
@site_seed_option
@dem_option
@reproject_option
@terrain_option
@dem_height_error_option
@stations_option
@station_ids_option
@click.option("--aoi", "aoi_path", type=FILE,
              help="GeoJSON polygon of the area of interest: choose the stations too (where "
                   "the rover stops to cover it), the markers and the traverse; instead of "
                   "--stations.")
@point_option("--route-start", None, "X,Y",
              "With --aoi: where the traverse starts and ends (the lander), site frame m. "
              "Default: the trafficable point nearest the AOI's centroid.",
              "route_start", limit=1e7)
@click.option("--keep-out", "keep_out_paths", type=FILE, multiple=True,
              help="With --aoi: GeoJSON polygon(s) the rover must not drive into (repeatable).")
@boundary_option
@exclude_option
@marker_radius_option(default_help=" Default: the preset's (0.1).")
@error_model_option
@config_option
@click.option("--visibility", "visibility_path", type=FILE,
              help="Plan from a visibility table CSV (station,site,usable,bearing_deg,sigma_m,"
                   "site_x_m,site_y_m,site_z_m) instead of ray casting.")
@click.option("--redundant", is_flag=True, default=None,
              help="Every station must survive the loss of any one marker.")
@click.option("--chance-epsilon", "chance_epsilon", type=ChanceEpsilon(),
              help="Largest chance that the plan fails through markers the field loses "
                   "(default 0.05, or the config's chance_epsilon); none: count every "
                   "planned marker as detected (the naive plan).")
@click.option("--detection-model", "detection_model", type=FILE,
              callback=_load_detection_model,
              help="Detection-model JSON from fit-detection-model: each pair's chance of "
                   "being detected and accepted (default: the shipped model).")
@click.option("--existing",
              help="Markers already in the field, fixed: 'as-built' or a CSV (id,x_m,y_m[,z_m]).")
@control_option
@click.option("--budget", type=click.IntRange(1, 100_000),
              help="Largest number of markers allowed.")
@requirement_options
@error_figure_option
@network_option
@reference_station_option
@datum_option
@time_limit_option
@renamed_option("--stand-map-cell-m", "stand_map_cell_m", "--stand-map-cell", type=CELL_M,
                help="Cell size (m, rounded to whole DEM cells) of usable_markers.tif and "
                     "station_error.tif. Default: the finest with at most 40,000 cells.")
@scheduler_options
@out_option(default="markerplan-out")
@overwrite_option
@json_option
def command(site_name, site_seed, dem_path, reproject, terrain, dem_height_error,
            stations_path, station_ids, aoi_path, route_start, keep_out_paths,
            boundary_path, exclude_paths, marker_radius_m, error_model, config_path,
            visibility_path, redundant, chance_epsilon, detection_model, existing, control_path,
            budget, requirement, error_figure, network,
            reference_station, datum, time_limit_s, stand_map_cell_m, scheduler, workers, out,
            overwrite, as_json):
    """Plan the fewest marker sites so that every station meets the accuracy requirement.

    Writes under --out: plan.json, markers.csv, report.md, map.png; markers.geojson (WGS84
    lon/lat when the DEM has an Earth CRS, else the DEM's CRS or local site frame); plan.gpkg
    (layers markers, stations, sight_lines, boundary; the DEM's CRS) and the "where can the
    rover stand" GeoTIFFs usable_markers.tif (markers a station at each cell could use) and
    station_error.tif (its predicted error, m; not with --visibility). With --network also
    stations.csv: each station's error relative to the reference station and the stations it
    is tied to. With no arguments: the default site, into ./markerplan-out/.

    With --aoi the plan also chooses the stations: the fewest-cost set of stops on trafficable
    ground that covers every cell of the area of interest (seen within range and incidence
    limits at a minimum point density) and meets the requirement, chosen together with the
    markers, and the traverse through them from --route-start and back. It then also writes
    stations.csv (in route order, with each leg), coverage.tif (stations seeing each cell,
    and the best point density) and the route in plan.gpkg and on the map; the report
    compares mission time with a greedy and a grid choice of stations (and, on a preset, its
    published layout).

    Ray casting runs as one task per block of stations, each on its own DEM tile:
    --scheduler local (the default) starts a dask cluster on this machine when there is
    more than one block, --scheduler ADDRESS uses a running one, --scheduler none runs in
    this process; the files are the same.

    \b
    Examples:
      markerplan plan
      markerplan plan --site default --redundant --out plan-redundant/
      markerplan plan --site large --site-seed 3 --marker-radius-m 0.15 --out plan-large/
      markerplan plan --network --out plan-network/
      markerplan plan --network --reference-station S4 --out plan-network-s4/
      markerplan plan --network --requirement-m 0.10 --requirement-ppm 200 --out p-ppm/
      markerplan plan --network --no-datum-requirement --local-requirement-m 0.10 \
          --local-within-m 50 --out p-local/
      markerplan plan --network --heading-aid star-tracker --odometry-percent 2 --out p-aids/
      markerplan plan --network --datum free --no-datum-requirement --local-requirement-m 0.10 \
          --local-kind distance --out p-free/
      markerplan plan --network --control lander.csv --out p-lander/
      markerplan plan --dem site.tif --stations stations.csv --exclude paths.geojson --out p/
      markerplan plan --dem site.tif --stations stations.csv --stand-map-cell-m 2 --out p/
      markerplan plan --dem lonlat.tif --reproject --stations lonlat.csv --out p/
      markerplan plan --terrain orbital --out plan-orbital/
      markerplan plan --dem nac.tif --dem-height-error 0.3,10 --stations s.csv --out p/
      markerplan plan --site km --scheduler tcp://10.0.0.5:8786 --out plan-km/
      markerplan plan --aoi crater-field.geojson --route-start 0,0 --out plan-aoi/
      markerplan plan --dem site.tif --aoi aoi.geojson --keep-out lander.geojson --out p/
    """
    from markerplan.output_folder import output_folder
    from planner.distributed import executor
    from planner.outputs.gis import write_stand_map
    from planner.outputs.plan_map import draw_plan_map
    from planner.outputs.report import plan_timings, summary, write_plan_files
    from planner.outputs.stand_map import stand_map

    require_dem(reproject, dem_path)
    require_truth_terrain(terrain, dem_path)
    _aoi_iv(aoi_path, stations_path, station_ids, visibility_path, route_start,
            keep_out_paths)
    kind, reference_station = datum_choice(datum, control_path, reference_station)
    inputs_given = given_paths(dem_path, stations_path, boundary_path, error_model.path,
                               config_path, visibility_path, *exclude_paths,
                               None if detection_model[1].startswith("default") else
                               detection_model[1],
                               None if existing == "as-built" else existing, control_path,
                               aoi_path, *keep_out_paths)
    progress = not as_json or sys.stderr.isatty()
    with output_folder(out, overwrite, "plan", inputs=inputs_given) as stage, \
            executor(scheduler, workers, progress) as tasks:
        outcome, config = _plan(site_name, site_seed, dem_path, stations_path, station_ids,
                                boundary_path, exclude_paths, marker_radius_m, error_model,
                                config_path, visibility_path, redundant, existing, budget,
                                time_limit_s, as_json, network, reference_station,
                                reproject, map_groups=tasks, terrain=terrain,
                                dem_height_error=dem_height_error, chance_epsilon=chance_epsilon,
                                control_path=control_path, aoi=(aoi_path, route_start,
                                                                keep_out_paths),
                                detection_model=detection_model, error_figure=error_figure,
                                requirement={**requirement,
                                             "datum": "free" if kind == "free" else None})
        doc = write_plan_files(outcome, stage)
        draw_plan_map(outcome, stage / "map.png")
        stand_s = {}
        if visibility_path is None:
            stand = stand_map(outcome, error_model.model, stand_map_cell_m,
                              progress=progress, map_groups=tasks)
            write_stand_map(stand, stage)
            stand_s = {"stand_map": round(stand.elapsed_s, 3)}
    for name, b in doc["baselines"].items():
        if "note" in b:
            click.echo(f"warning: {name.replace('_', ' ')} baseline falls short: {b['note']}",
                       err=True)
    timings = {**plan_timings(outcome), **stand_s}
    report_timings(timings)
    info = {**summary(doc, out), "timings_s": timings}
    from planner.accuracy.requirement import requirement_text

    need = doc["requirement"]
    if not need.get("datum_requirement", True):
        against = " (not judged relative to the datum); "
    elif need["requirement_ppm"]:
        against = f" (requirement {requirement_text(need)}); "
    else:
        against = f" <= {config.requirement_m:g} m; "
    worst_pair = (doc.get("local") or {}).get("worst_pair")
    if worst_pair is not None:
        err = worst_pair["predicted_error_m"]
        against += (f"local: worst pair {'-'.join(worst_pair['stations'])} "
                    f"{'inf' if err is None else f'{err:.3f}'} m <= "
                    f"{worst_pair['allowed_error_m']:.4g} m; ")
    human = (f"{doc['n_markers']} markers ({solver_status_text(doc['solver'])}); worst station "
             f"{info['worst_station_error_m']:.3f} m" + against
             + chance_text(doc)
             + "; ".join(f"{k.replace('_', ' ')}: {v['n_markers']}"
                         for k, v in doc["baselines"].items())
             + (f"; network mode, datum {info['reference_station'] or info['datum']}, worst marker "
                f"{info['worst_marker_error_m']:.3f} m" if "mode" in info else "")
             + f" -> {out}/")
    emit_summary(info, as_json, human)


def chance_text(doc: dict) -> str:
    """The summary line's chance clause, e.g. ``"P(pass) >= 96.1 % (epsilon 0.05); "``
    (empty without a detection model)."""
    if "chance" not in doc:
        return ""
    ch = doc["chance"]
    eps = ch["epsilon"]
    whole = ch.get("network")
    if whole is not None and whole["max_losses"] == 0 and "sampled" in ch:
        return (f"P(pass) {100 * ch['sampled']['pass_rate']:.1f} % sampled (no certified "
                f"bound: {whole['n_pairs']:,} pairs)"
                + (f" (epsilon {eps:g})" if eps is not None else " (no chance constraint)")
                + "; ")
    return (f"P(pass) >= {100 * ch['plan_pass_probability']:.1f} %"
            + (f" (epsilon {eps:g})" if eps is not None else " (no chance constraint)")
            + "; ")


def solver_status_text(solver: dict) -> str:
    """The solver's status for the summary line; a plan not proven optimal also states its
    proven lower bound and gap, e.g. ``"time_limit, no layout has fewer than 684, gap 5.4 %"``.

    Parameters
    ----------
    solver : dict
        ``plan.json``'s ``solver`` section (``status``, ``dual_bound``, ``gap``; None when
        unknown).
    """
    text = solver["status"]
    bound, gap = solver.get("dual_bound"), solver.get("gap")
    if text != "optimal" and bound is not None and gap is not None and math.isfinite(bound):
        text += f", no layout has fewer than {math.ceil(bound - 1e-6)}, gap {100 * gap:.1f} %"
    return text


def _plan(site_name, site_seed, dem_path, stations_path, station_ids, boundary_path,
          exclude_paths, marker_radius_m, error_model, config_path, visibility_path, redundant,
          existing, budget, time_limit_s, as_json, network=None, reference_station=None,
          reproject=False, map_groups=map, chance_epsilon=None, detection_model=None,
          terrain="truth", dem_height_error=None, error_figure=None, requirement=None,
          control_path=None, aoi=(None, None, ())):
    """Read the inputs and make the plan; return ``(outcome, config)``. A ``--dem`` is read
    only as far as the stations see (``config.max_range_m``); ``map_groups`` maps the ray
    casting's station blocks (:func:`visibility.visibility_matrix.tiled_visibility`).
    ``chance_epsilon``: ``--chance-epsilon`` (``None``: not given, :data:`NAIVE`: none);
    ``detection_model``: ``(model, name)``, or ``None`` for none; ``error_figure``:
    ``--error-figure`` (``None``: not given); ``requirement``: the requirement and pose-aid
    options by their configuration names (``None``: not given); ``control_path``:
    ``--control``; ``aoi``: ``(--aoi, --route-start, --keep-out)``, the stations chosen
    over the area of interest (:func:`planner.design.plan.design_plan`) when ``--aoi`` is
    given."""
    from markerplan.errors import ConfigError
    from planner.config import PlanConfig, load_config
    from planner.problem.inputs import load_inputs
    from planner.run import make_plan

    config = with_options(load_config(config_path) if config_path else PlanConfig(),
                          redundant=True if redundant else None, budget=budget,
                          time_limit_s=time_limit_s, error_figure=error_figure)
    config = network_settings(config, network, reference_station)
    config = with_options(config, **(requirement or {}))
    if chance_epsilon is NAIVE:
        config = config.replace(chance_epsilon=None)
    elif chance_epsilon is not None:
        config = with_options(config, chance_epsilon=chance_epsilon)
    inputs = load_inputs(site_name, site_seed, dem_path=dem_path, stations_path=stations_path,
                         boundary_path=boundary_path, exclude_paths=exclude_paths,
                         existing=existing, marker_radius_m=marker_radius_m,
                         station_ids=station_ids, reproject=reproject,
                         sight_radius_m=config.max_range_m, terrain=terrain,
                         dem_height_error=dem_height_error, control=control_path,
                         stations_chosen=aoi[0] is not None)
    if inputs.existing_ids:
        config = config.replace(existing=tuple(inputs.existing_ids))
    problem = None
    if visibility_path is not None:
        from planner.problem.visibility_table import read_visibility_table

        problem = read_visibility_table(visibility_path, inputs.station_ids, inputs.station_xyz)
        if inputs.existing_ids or inputs.control:
            raise ConfigError("--existing and --control cannot be combined with --visibility; "
                              "plan by ray casting (drop --visibility) to use them")
        model, model_name = None, f"from visibility table {visibility_path}"
    else:
        model, model_name = error_model.model, error_model.name
    dmodel, dname = detection_model if detection_model is not None else (None, "none")
    if aoi[0] is not None:
        return _design_plan(inputs, config, model, model_name, aoi, as_json, map_groups,
                            dmodel, dname), config
    outcome = make_plan(inputs, config, model, model_name, problem=problem,
                        progress=not as_json or sys.stderr.isatty(), map_groups=map_groups,
                        detection_model=dmodel, detection_name=dname)
    return outcome, config


def _aoi_iv(aoi_path, stations_path, station_ids, visibility_path, route_start,
            keep_out_paths) -> None:
    """Refuse ``--aoi`` with the options that give the stations, and the AOI's options
    without it."""
    from markerplan.errors import ConfigError

    if aoi_path is None:
        if route_start is not None or keep_out_paths:
            raise ConfigError("--route-start and --keep-out belong to a plan that chooses its "
                              "stations: add --aoi AOI.geojson, or drop them")
        return
    given = [name for name, v in (("--stations", stations_path), ("--station-ids", station_ids),
                                  ("--visibility", visibility_path)) if v]
    if given:
        raise ConfigError(f"--aoi chooses the stations, {' and '.join(given)} give(s) them: "
                          "drop one")


def _design_plan(inputs, config, model, model_name, aoi, as_json, map_groups, dmodel, dname):
    """The plan of stations chosen over ``aoi`` = ``(--aoi, --route-start, --keep-out)``."""
    from dataclasses import replace
    from pathlib import Path

    from planner.coverage.aoi import read_aoi
    from planner.design.plan import design_plan
    from planner.problem.candidates import load_polygons
    from planner.problem.inputs import polygons_on_dem

    aoi_path, route_start, keep_out_paths = aoi
    area = read_aoi(aoi_path, inputs.dem)
    inputs = replace(inputs, sources={**inputs.sources, "aoi": str(Path(aoi_path).resolve()),
                                      **({"keep_out": [str(Path(p).resolve())
                                                       for p in keep_out_paths]}
                                         if keep_out_paths else {})})
    keepouts = []
    for path in keep_out_paths:
        keepouts += polygons_on_dem(load_polygons(path, "`keep_out_paths`"), inputs.dem)
    return design_plan(inputs, config, model, area, model_name, keepouts=keepouts,
                       route_start_xy=route_start,
                       route_start_source="given (--route-start)",
                       progress=not as_json or sys.stderr.isatty(), map_groups=map_groups,
                       detection_model=dmodel, detection_name=dname,
                       hand_layout=inputs.sources.get("stations") is None
                       and "dem" not in inputs.sources)
