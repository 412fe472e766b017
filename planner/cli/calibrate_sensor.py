"""``markerplan calibrate-sensor``: fit a sensor profile's free parameters to a field experiment."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from planner.cli._common import (
    FILE,
    FiniteRange,
    emit_summary,
    frames_option_at_least,
    given_paths,
    json_option,
    marker_radius_option,
    out_option,
    overwrite_option,
    renamed_option,
    rpm_option,
    seed_option,
)

#: The fewest frames per turn of the simulated field positions: each is processed with
#: self-calibration, which needs frames all round the turn, and the quality gate needs the far
#: markers seen by enough of them (at 50 frames every marker of the field experiment's second
#: position was rejected, at 100 all three positions gave residuals; the rig takes 800).
FEWEST_FRAMES = 100


@click.command("calibrate-sensor")
@click.argument("summary", type=FILE, required=False)
@click.option("--marker-table", "marker_table", type=FILE,
              help="Instead of SUMMARY: a markers.csv from `markerplan process` of real scans "
                   "(each station one position) ...")
@renamed_option("--reference", "reference", "--reference-csv", type=FILE,
                help="Reference coordinates: with --marker-table, the total-station CSV "
                     "(id,x_m,y_m,z_m) the table was evaluated against.")
@out_option(required=True)
@overwrite_option
@click.option("--base-profile", default="datasheet", show_default=True, metavar="NAME|FILE",
              help="Profile whose other parameters stay fixed (calibrated, datasheet or a file).")
@click.option("--fix", "fixed", multiple=True, metavar="NAME=VALUE",
              help="Fix a profile parameter (repeatable), e.g. reference.aim_sigma_m=0.003; "
                   "default: the field priors of planner.studies.sensor_calibration (but the "
                   "--fit ones).")
@click.option("--fit", "free", multiple=True, metavar="NAME=LOW:HIGH",
              help="A parameter to fit and its search range (one or two; repeatable). "
                   "Default: the one of planner.studies.sensor_calibration.DEFAULT_FREE.")
@click.option("--name", default="calibrated", show_default=True,
              help="Name of the written profile.")
@frames_option_at_least(FEWEST_FRAMES)
@click.option("--replicates", type=click.IntRange(1, 20), default=2, show_default=True,
              help="Simulations per design point and position.")
@click.option("--check-replicates", type=click.IntRange(1, 50), default=6, show_default=True,
              help="Simulations per position of the confirmation and of each hold-out check.")
@click.option("--design-points", type=click.IntRange(3, 12), default=4, show_default=True,
              help="Values per free parameter.")
@click.option("--resolution-mm", type=FiniteRange(0.0, 10.0), default=1.0, show_default=True,
              help="Last digit of the measured residuals (their rounding), mm.")
@click.option("--holdout/--no-holdout", default=True, show_default=True,
              help="Also fit on all but one position and predict that one.")
@marker_radius_option(default=0.1)
@rpm_option
@seed_option()
@json_option
def command(summary, marker_table, reference, out, overwrite, base_profile, fixed, free, name,
            frames, replicates, check_replicates, design_points, resolution_mm, holdout,
            marker_radius_m, rpm, seed, as_json) -> None:
    """Fit the sensor's free parameters so that simulation reproduces a field experiment.

    SUMMARY is a CSV with columns position, distances_m (space-separated, metres) and
    mean_abs_edge_residual_m (metres); without it (and without --marker-table) the published
    field experiment shipped with markerplan is used. Each position is simulated on a level
    field with markers at its distances, processed by the same chain as `markerplan process`,
    and evaluated against a simulated total-station reference. Writes sensor_profile.json (use
    it with --sensor-profile), calibration.json, runs.csv, report.md and calibration.png.

    \b
    Example:
      markerplan calibrate-sensor --out cal/
      markerplan simulate --sensor-profile cal/sensor_profile.json --out scans/
      markerplan calibrate-sensor --marker-table tables/markers.csv --reference ts.csv \\
          --fit sensor.range_noise_m=0.005:0.04 --out cal-real/
    """
    from dataclasses import asdict, replace

    from tqdm import tqdm

    from markerplan.errors import ConfigError
    from markerplan.output_folder import output_folder
    from planner.studies.calibration_report import write_calibration
    from planner.studies.field_summary import (
        FIELD_EXPERIMENT_CSV,
        positions_from_marker_table,
        read_field_summary,
    )
    from planner.studies.sensor_calibration import (
        DEFAULT_FREE,
        FIELD_PRIORS,
        CalibrationSettings,
        FreeParameter,
        calibrate,
        parse_setting,
    )
    from visibility.sensor_profile import load_profile

    if summary is not None and (marker_table or reference):
        raise ConfigError("give either SUMMARY or --marker-table with --reference, not both")
    if (marker_table is None) != (reference is None):
        raise ConfigError("--marker-table and --reference go together; give both")
    base = load_profile(base_profile)
    free_params = [FreeParameter.parse(t) for t in (free or DEFAULT_FREE)]
    fitted = {f.name for f in free_params}
    # the field priors fix what is not fitted; only an explicit --fix can clash with --fit
    settings_fixed = ({k: v for k, v in FIELD_PRIORS.items() if k not in fitted} if not fixed
                      else dict(parse_setting(t) for t in fixed))
    overlap = sorted(set(settings_fixed) & fitted)
    if overlap:
        raise ConfigError(f"{overlap[0]} is both fixed (--fix) and fitted (--fit); give it once")
    settings = CalibrationSettings(frames=frames, replicates=replicates,
                                   check_replicates=check_replicates,
                                   design_points=design_points, marker_radius_m=marker_radius_m,
                                   seed=seed, rpm=rpm, resolution_m=resolution_mm / 1e3,
                                   holdout=holdout)
    data = marker_table or summary or FIELD_EXPERIMENT_CSV
    with output_folder(out, overwrite, "calibrate-sensor",
                       inputs=given_paths(summary, marker_table, reference)) as stage:
        positions = (positions_from_marker_table(marker_table, reference) if marker_table
                     else read_field_summary(data))
        start = base.with_values(settings_fixed)
        n_runs = len(positions) * (replicates * design_points ** len(free_params)
                                   + check_replicates * (2 if holdout else 1))
        with tqdm(total=n_runs, desc="simulated positions", file=sys.stderr,
                  disable=None) as bar:
            result = calibrate(positions, start, free_params, settings, progress=bar.update)
        description = (f"{base.name} profile with {', '.join(settings_fixed) or 'nothing'} "
                       f"fixed and {', '.join(f.name for f in free_params)} fitted to "
                       f"{Path(data).name} by markerplan calibrate-sensor")
        result.profile = replace(result.profile, name=name, description=description)
        config = {"data": str(Path(data).name), "base_profile": base.name,
                  "fixed": settings_fixed, "free": [asdict(f) for f in free_params],
                  "settings": asdict(settings), "name": name}
        write_calibration(result, stage, config)
    for warning in result.warnings:
        click.echo(f"warning: {warning}", err=True)
    lines = [f"{f.name} = {result.values[f.name]:.6g} +- {result.sigmas[f.name]:.2g}"
             for f in free_params]
    if len(free_params) > 1:
        lines.append(f"correlation {result.correlation[0][1]:+.3f}, Jacobian condition "
                     f"{result.jacobian_condition:.3g}")
    lines += [f"position {p['position']}: fitted {p['emulated_m'] * 1e3:.1f} mm, 95 % interval "
              f"{p['interval95_m'][0] * 1e3:.1f}-{p['interval95_m'][1] * 1e3:.1f} mm"
              for p in result.predictions]
    lines += [f"position {c['position']}: measured {c['measured_m'] * 1e3:.1f} mm, predicted "
              + ("none" if c["predicted_m"] is None else
                 f"{c['predicted_m'] * 1e3:.1f} mm (ratio {c['ratio']:.2f})")
              for c in result.confirmation]
    emit_summary({"out": str(out), "values": result.values, "standard_errors": result.sigmas,
                  "correlation": result.correlation,
                  "jacobian_condition": result.jacobian_condition,
                  "predictions": result.predictions,
                  "confirmation": result.confirmation, "holdout": result.holdout},
                 as_json, "\n".join(lines + [f"wrote {out}"]))
