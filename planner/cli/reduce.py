"""``markerplan reduce``: how few of a layout's markers still meet the requirement."""

from __future__ import annotations

import sys

import click

from planner.cli._common import (
    boundary_option,
    config_option,
    dem_option,
    emit_summary,
    error_model_option,
    exclude_option,
    given_paths,
    id_list,
    json_option,
    marker_radius_option,
    mounting_offset_options,
    out_option,
    overwrite_option,
    report_timings,
    reproject_option,
    require_dem,
    scheduler_options,
    seed_option,
    site_option,
    site_seed_option,
    station_ids_option,
    stations_option,
    time_limit_option,
    with_options,
)
from planner.cli._network_options import (
    control_option,
    error_figure_option,
    network_option,
    network_settings,
    reference_station_option,
    requirement_options,
)


@click.command("reduce")
@click.argument("layout_spec", metavar="INPUT")
@site_option(default=None)
@site_seed_option
@dem_option
@reproject_option
@stations_option
@station_ids_option
@boundary_option
@exclude_option
@marker_radius_option(default_help=" Default: the plan's, else the preset's (0.1).")
@error_model_option
@config_option
@click.option("--free", is_flag=True,
              help="Choose the k markers from every candidate site, not only the layout.")
@click.option("--keep", "keep_ids", callback=id_list, metavar="M01,M07",
              help="Marker ids that always stay, comma-separated.")
@click.option("--drop", "drop_ids", callback=id_list, metavar="M03",
              help="Marker ids that must go, comma-separated.")
@click.option("--k-min", "k_min", type=click.IntRange(1, 100_000),
              help="Fewest markers on the curve (default: the fewest meeting the directions).")
@network_option
@reference_station_option
@control_option
@requirement_options
@error_figure_option
@time_limit_option
@click.option("--verify", is_flag=True,
              help="Simulate + process the stations at chosen counts; achieved vs predicted.")
@seed_option()
@click.option("--verify-k", "verify_k",
              help="Counts to verify, comma-separated (default: the full layout and the "
                   "fewest meeting the requirement).")
@mounting_offset_options
@scheduler_options
@out_option(default="markerplan-reduce")
@overwrite_option
@json_option
def command(layout_spec, site_name, site_seed, dem_path, reproject, stations_path, station_ids,
            boundary_path, exclude_paths, marker_radius_m, error_model, config_path, free,
            keep_ids, drop_ids, k_min, network, reference_station, control_path, requirement,
            error_figure, time_limit_s, verify, seed, verify_k, offsets, scheduler, workers, out,
            overwrite, as_json):
    """Trade-off between the number of markers and the worst station's predicted error.

    INPUT is a plan.json from `markerplan plan`, a markers CSV (id,x_m,y_m[,z_m], site frame)
    or 'as-built' (the site preset's own layout); a plan is studied at its own stations
    (--station-ids picks among them, --stations replaces them). For every count k from the
    layout's size down, an integer program finds the k markers minimising the worst station's
    predicted error (proven optimal unless the time limit is hit, which is reported). Writes
    tradeoff.csv, per_station.csv, drop_order.csv, marker_loss.csv, tradeoff.png, report.md and
    reduce.json.

    \b
    Examples:
      markerplan reduce as-built --site default --out reduce/
      markerplan reduce plan/plan.json --free --out reduce-free/
      markerplan reduce markers.csv --keep M01 --verify --verify-k 11,6 --out reduce/
      markerplan reduce plan-network/plan.json --out reduce-network/
      markerplan reduce as-built --network --reference-station S4 --out reduce-s4/

    --seed and the mounting-offset options set the noise and the mis-mounted rig that --verify
    simulates (the pipeline self-calibrates it); its stations run as tasks where --scheduler
    says, as in `markerplan verify` (--scheduler and --workers are for --verify only).

    With --network, or for a plan made by `plan --network` (always studied in network mode,
    the mode its errors are for), every station's and every kept marker's error is the
    network's, relative to the reference station (--reference-station, else the plan's, else
    the first), as `plan --network` judges it; --verify is then refused (use
    `markerplan verify PLAN --network`).

    A count passes when it meets every requirement kind, as `plan` judges a layout: in network
    mode the allowance relative to the datum (--requirement-m, --requirement-ppm; none with
    --no-datum-requirement), the local requirement between stations and, with
    --local-markers, between kept markers (--local-requirement-m, --local-requirement-ppm,
    --local-within-m, --local-kind), with the pose aids (--heading-aid, --odometry-percent)
    and the datum (--control: control points, a lander's fiducials, kept in every subset). A
    plan is judged by the kinds and datum it was made for: these options are refused with a
    plan.json unless they repeat its settings (a --config replaces its configuration as a
    whole); with a markers CSV or as-built they state the kinds to judge.

    \b
      markerplan reduce markers.csv --network --control lander.csv \\
          --local-requirement-m 0.1 --local-markers --out reduce-lander/
    """
    from markerplan.output_folder import output_folder
    from planner.reduction.plot import plot_tradeoff
    from planner.reduction.report import (
        accuracy_mode,
        kinds_text,
        reduce_timings,
        summary,
        write_reduce_files,
    )
    from planner.reduction.study import is_plan

    _where_needs_verify(verify)
    if not is_plan(layout_spec):  # a plan's --reproject applies to the DEM it records
        require_dem(reproject, dem_path)
    inputs_given = given_paths(dem_path, stations_path, boundary_path, error_model.path,
                               config_path, control_path, *exclude_paths,
                               None if layout_spec == "as-built" else layout_spec)
    sources = {"site_name": site_name, "site_seed": site_seed, "dem_path": dem_path,
               "reproject": reproject, "stations_path": stations_path, "station_ids": station_ids,
               "boundary_path": boundary_path, "exclude_paths": exclude_paths,
               "marker_radius_m": marker_radius_m, "control_path": control_path}
    with output_folder(out, overwrite, "reduce", inputs=inputs_given) as stage:
        study, doc, config = _study(
            layout_spec, sources, error_model, config_path, free, keep_ids, drop_ids, k_min,
            time_limit_s, verify, seed, verify_k, offsets, network, reference_station,
            progress=not as_json or sys.stderr.isatty(), where=(scheduler, workers),
            requirement={**requirement, "error_figure": error_figure})
        write_reduce_files(doc, stage)
        plot_tradeoff(doc, stage / "tradeoff.png")
    timings = reduce_timings(study)
    report_timings(timings)
    info = {**summary(doc, out), "timings_s": timings}
    kf = doc["k_feasible"]
    least = "" if doc["k_feasible_minimal"] else "at least "
    human = (f"{least}{doc['markers_that_can_go']} of {doc['layout']['n_markers']} markers can "
             f"go: "
             f"{kf} meet {kinds_text(doc['requirement'], 'network' in doc)} at every station"
             if kf is not None else "no count meets the requirement at every station")
    human += ("" if doc["solver"]["proven_optimal"] else " (time limit: not proven optimal)")
    if "network" in doc:
        human += f"; {accuracy_mode(doc)}"
    emit_summary(info, as_json, human + f" -> {out}/")


def _study(layout_spec, sources, error_model, config_path, free, keep_ids, drop_ids, k_min,
           time_limit_s, verify, seed, verify_k, offsets, network, reference_station, progress,
           where, requirement):
    """Read the inputs, run the study (and ``--verify``); return ``(study, doc, config)``.

    ``sources`` holds the site options as :func:`planner.reduction.study.resolve_inputs`
    takes them; ``where`` is ``(scheduler, workers)`` of ``--verify``'s station tasks;
    ``requirement`` the requirement-kind options and ``--error-figure`` by configuration name
    (``None``: not given)."""
    from markerplan.errors import ConfigError
    from pipeline.scans.rig import MountingOffsets
    from planner.config import load_config
    from planner.problem.inputs import known_ids
    from planner.reduction.report import reduce_record
    from planner.reduction.study import layout_problem, resolve_inputs, run_study

    config = load_config(config_path) if config_path else None
    inputs, layout, config = resolve_inputs(layout_spec, config=config, **sources)
    control = tuple(layout.control_sigma_m)  # the datum: in every subset
    dropped = known_ids(drop_ids or (), layout.ids, "--drop", "marker")
    if set(dropped) & set(control):
        raise ConfigError(f"--drop names control point(s) "
                          f"{', '.join(sorted(set(dropped) & set(control)))}: they are the "
                          "plan's datum and stay in every subset; drop other markers")
    keep = known_ids(keep_ids or (), layout.ids, "--keep", "marker")
    config = with_options(config, existing=keep + tuple(c for c in control if c not in keep),
                          forbidden=dropped, time_limit_s=time_limit_s)
    config = network_settings(config, network, reference_station)
    config = _requirement_settings(config, requirement, layout_spec)
    _control_iv(config, layout, sources["control_path"])
    if config.network and verify:
        raise ConfigError("reduce --verify simulates known-control registration; in network "
                          "mode verify a plan with `markerplan verify PLAN --network` instead")
    ks = _verify_counts(verify_k, verify, len(layout.ids))
    if offsets != MountingOffsets() and not verify:
        raise ConfigError("the mounting-offset options set the rig that --verify simulates; "
                          "add --verify or drop them")
    model, model_name = error_model.model, error_model.name
    problem, mask, timings = layout_problem(inputs, layout, config, model, free=free,
                                            progress=progress)
    study = run_study(problem, config, mask, free=free, k_min=k_min)
    study.timings_s.update(timings)
    verified = None
    if verify:
        import time

        from planner.distributed import executor
        from planner.reduction.verify import verify_points

        t = time.perf_counter()
        with executor(*where, progress) as ex:
            verified = verify_points(study, inputs, ks, model, seed=seed, offsets=offsets,
                                     executor=ex)
        study.timings_s["verify"] = time.perf_counter() - t
    options = {"input": layout_spec, "free": free, "k_min": k_min,
               "verify": verify, "verify_seed": seed if verify else None,
               "verify_mounting_offsets": offsets.to_dict() if verify else None,
               "verify_k": None if ks is None else list(ks)}
    return study, reduce_record(study, layout, inputs, model_name, options, verified), config


def _requirement_settings(config, requirement: dict, layout_spec: str):
    """``config`` with the requirement-kind options; with a plan, an option that differs from
    the plan's setting is refused (:class:`ConfigError`): a plan is judged by the kinds it was
    made for."""
    from markerplan.errors import ConfigError
    from planner.reduction.study import is_plan

    if not is_plan(layout_spec):
        return with_options(config, **requirement)
    for name, value in requirement.items():
        if value is not None and value != getattr(config, name):
            flag = "--no-datum-requirement" if name == "datum_requirement" \
                else f"--{name.replace('_', '-')} {value}"
            raise ConfigError(f"{flag} conflicts with INPUT {layout_spec}'s {name} "
                              f"{getattr(config, name)}: a plan is reduced with the requirement "
                              "it was made for; drop the option, or re-plan with it")
    return config


def _control_iv(config, layout, control_path) -> None:
    """Refuse ``--control`` with a plan (which records its own datum), outside network mode or
    with ``--reference-station`` (:class:`ConfigError`)."""
    from markerplan.errors import ConfigError
    from planner.reduction.study import is_plan

    if control_path is None:
        return
    if is_plan(layout.source):
        raise ConfigError(f"--control: INPUT {layout.source} records its own datum; drop "
                          "--control, or reduce its markers CSV with it")
    if not config.network:
        raise ConfigError("--control gives network mode's datum; add --network or drop "
                          "--control")
    if config.reference_station is not None:
        raise ConfigError("--control points are the datum and fix no station; drop "
                          "--reference-station or --control")


def _where_needs_verify(verify: bool) -> None:
    """Refuse ``--scheduler``/``--workers`` given on the command line without ``--verify``:
    only --verify's station tasks run on a cluster (:class:`ConfigError`)."""
    from click.core import ParameterSource

    from markerplan.errors import ConfigError

    ctx = click.get_current_context()
    given = [f"--{name}" for name in ("scheduler", "workers")
             if ctx.get_parameter_source(name) is not ParameterSource.DEFAULT]
    if given and not verify:
        raise ConfigError(f"{' and '.join(given)} set where --verify's station tasks run, and "
                          f"nothing else in reduce runs there; add --verify or drop "
                          f"{'them' if len(given) > 1 else 'it'}")


def _verify_counts(text: str | None, verify: bool, n: int) -> tuple[int, ...] | None:
    """Parse --verify-k (checked against the curve later); ``None`` means the default."""
    from markerplan.errors import ConfigError

    if text is None:
        return None
    if not verify:
        raise ConfigError("--verify-k needs --verify; add --verify or drop --verify-k")
    try:
        ks = tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        ks = ()
    if not ks or any(not 1 <= k <= n for k in ks):
        raise ConfigError(f"--verify-k must be comma-separated counts in 1..{n} (the layout's "
                          f"markers), got {text!r}")
    return ks
