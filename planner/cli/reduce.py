"""``markerplan reduce``: how few of a layout's markers still meet the requirement."""

from __future__ import annotations

import sys

import click

from planner.cli._common import (
    FILE,
    SEED,
    TIME_LIMIT_S,
    dem_option,
    emit_summary,
    error_model_option,
    given_paths,
    json_option,
    mounting_offset_options,
    mounting_offsets,
    out_option,
    overwrite_option,
    report_timings,
    stations_option,
)


def _id_list(text: str | None) -> tuple[str, ...]:
    return tuple(t.strip() for t in text.split(",") if t.strip()) if text else ()


@click.command("reduce")
@click.argument("layout_spec", metavar="INPUT")
@click.option("--site", "site_name", default=None,
              help="Site preset (default: the plan's site, else 'default').")
@click.option("--seed", type=SEED, default=None,
              help="Seed of the preset's synthetic terrain (default: the plan's / preset's).")
@dem_option
@stations_option
@click.option("--boundary", "boundary_path", type=FILE,
              help="GeoJSON polygon: where markers may go.")
@click.option("--exclude", "exclude_paths", type=FILE, multiple=True,
              help="GeoJSON polygon(s) where no marker may go (repeatable; with --free).")
@error_model_option
@click.option("--config", "config_path", type=FILE,
              help="TOML file of plan settings (default: the plan's, else the defaults).")
@click.option("--free", is_flag=True,
              help="Choose the k markers from every candidate site, not only the layout.")
@click.option("--keep", "keep_ids", help="Comma-separated marker ids that always stay.")
@click.option("--drop", "drop_ids", help="Comma-separated marker ids that must go.")
@click.option("--k-min", "k_min", type=click.IntRange(1, 100_000),
              help="Fewest markers on the curve (default: the fewest meeting the directions).")
@click.option("--time-limit", "time_limit_s", type=TIME_LIMIT_S,
              help="Solver time limit for the whole curve, seconds (default 60).")
@click.option("--verify", is_flag=True,
              help="Simulate + process the stations at chosen counts; achieved vs predicted.")
@click.option("--verify-seed", "verify_seed", type=SEED, default=0, show_default=True,
              help="Simulation noise seed of --verify.")
@click.option("--verify-k", "verify_k",
              help="Counts to verify, comma-separated (default: the full layout and the "
                   "fewest meeting the requirement).")
@mounting_offset_options
@out_option(default="markerplan-reduce")
@overwrite_option
@json_option
def command(layout_spec, site_name, seed, dem_path, stations_path, boundary_path, exclude_paths,
            error_model_path, config_path, free, keep_ids, drop_ids, k_min, time_limit_s,
            verify, verify_seed, verify_k, vertical_axis_error_deg, lframe_tilt_deg,
            axis_offset_mm, out, overwrite, as_json):
    """Trade-off between the number of markers and the worst station's predicted error.

    INPUT is a plan.json from `markerplan plan`, a markers CSV (id,x_m,y_m[,z_m], site frame)
    or 'as-built' (the site preset's own layout). For every count k from the layout's size down,
    an integer program finds the k markers minimising the worst station's predicted error
    (proven optimal unless the time limit is hit, which is reported). Writes tradeoff.csv,
    per_station.csv, drop_order.csv, marker_loss.csv, tradeoff.png, report.md and reduce.json.

    \b
    Examples:
      markerplan reduce as-built --site default --out reduce/
      markerplan reduce plan/plan.json --free --out reduce-free/
      markerplan reduce markers.csv --keep M01 --verify --verify-k 11,6 --out reduce/

    The mounting-offset options mis-mount the rig simulated by --verify (the pipeline
    self-calibrates it).
    """
    from markerplan.output_folder import output_folder
    from planner.reduction.plot import plot_tradeoff
    from planner.reduction.report import reduce_timings, summary, write_reduce_files

    inputs_given = given_paths(dem_path, stations_path, boundary_path, error_model_path,
                               config_path, *exclude_paths,
                               None if layout_spec == "as-built" else layout_spec)
    with output_folder(out, overwrite, "reduce", inputs=inputs_given) as stage:
        study, doc, config = _study(
            layout_spec, site_name, seed, dem_path, stations_path, boundary_path, exclude_paths,
            error_model_path, config_path, free, keep_ids, drop_ids, k_min, time_limit_s,
            verify, verify_seed, verify_k,
            mounting_offsets(vertical_axis_error_deg, lframe_tilt_deg, axis_offset_mm),
            progress=not as_json or sys.stderr.isatty())
        write_reduce_files(doc, stage)
        plot_tradeoff(doc, stage / "tradeoff.png")
    timings = reduce_timings(study)
    report_timings(timings)
    info = {**summary(doc, out), "timings_s": timings}
    kf = doc["k_feasible"]
    least = "" if doc["k_feasible_minimal"] else "at least "
    human = (f"{least}{doc['markers_that_can_go']} of {doc['layout']['n_markers']} markers can "
             f"go: "
             f"{kf} meet {config.requirement_m:g} m at every station"
             if kf is not None else "no count meets the requirement at every station")
    human += ("" if doc["solver"]["proven_optimal"] else " (time limit: not proven optimal)")
    emit_summary(info, as_json, human + f" -> {out}/")


def _study(layout_spec, site_name, seed, dem_path, stations_path, boundary_path, exclude_paths,
           error_model_path, config_path, free, keep_ids, drop_ids, k_min, time_limit_s,
           verify, verify_seed, verify_k, offsets, progress):
    """Read the inputs, run the study (and ``--verify``); return ``(study, doc, config)``."""
    from markerplan.errors import ConfigError
    from pipeline.rig import MountingOffsets
    from planner.config import load_config
    from planner.reduction.report import reduce_record
    from planner.reduction.study import layout_problem, marker_ids_iv, resolve_inputs, run_study

    config = load_config(config_path) if config_path else None
    inputs, layout, config = resolve_inputs(
        layout_spec, site_name, seed, dem_path=dem_path, stations_path=stations_path,
        boundary_path=boundary_path, exclude_paths=exclude_paths, config=config)
    overrides = {"existing": marker_ids_iv(_id_list(keep_ids), layout, "--keep"),
                 "forbidden": marker_ids_iv(_id_list(drop_ids), layout, "--drop")}
    if time_limit_s is not None:
        overrides["time_limit_s"] = time_limit_s
    try:
        config = config.replace(**overrides)
    except ConfigError as exc:
        raise ConfigError(f"{exc} (from the command-line options)") from exc
    ks = _verify_counts(verify_k, verify, len(layout.ids))
    if offsets != MountingOffsets() and not verify:
        raise ConfigError("the mounting-offset options set the rig that --verify simulates; "
                          "add --verify or drop them")
    if error_model_path is not None:
        from error_model.model import ErrorModel

        model, model_name = ErrorModel.load(error_model_path), str(error_model_path)
    else:
        from error_model import default_model

        model, model_name = default_model(), "default (shipped with markerplan)"
    problem, mask, timings = layout_problem(inputs, layout, config, model, free=free,
                                            progress=progress)
    study = run_study(problem, config, mask, free=free, k_min=k_min)
    study.timings_s.update(timings)
    verified = None
    if verify:
        import time

        from planner.reduction.verify import verify_points

        t = time.perf_counter()
        verified = verify_points(study, inputs, ks, model, seed=verify_seed, progress=progress,
                                 offsets=offsets)
        study.timings_s["verify"] = time.perf_counter() - t
    options = {"input": layout_spec, "free": free, "k_min": k_min,
               "verify": verify, "verify_seed": verify_seed if verify else None,
               "verify_mounting_offsets": offsets.to_dict() if verify else None,
               "verify_k": None if ks is None else list(ks)}
    return study, reduce_record(study, layout, inputs, model_name, options, verified), config


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
