"""``markerplan range-study``: centre error and point density against distance (simulated)."""

from __future__ import annotations

import sys

import click

from pipeline.surveys.range_study import EXTRACTIONS
from planner.cli._common import (
    FiniteRange,
    emit_summary,
    frames_option,
    json_option,
    lidar_height_option,
    marker_radius_option,
    out_option,
    overwrite_option,
    range_noise_option,
    renamed_option,
    rpm_option,
    scheduler_options,
    seed_option,
    sensor_profile_option,
)
from visibility.sites import MARKER_RADIUS_M

#: Ground slope, degrees: regolith's angle of repose is about 30-35 deg, so markers on steeper
#: ground do not stay put.
SLOPE_DEG = FiniteRange(-30.0, 30.0)
#: Farthest published distance kept, m.
MAX_DISTANCE_M = FiniteRange(1.0, 100.0)


@click.command("range-study")
@out_option(required=True)
@overwrite_option
@frames_option
@click.option("--replicates", type=click.IntRange(1, 100), default=3, show_default=True,
              help="Replicates; replicate r is simulated with seed + r.")
@seed_option()
@sensor_profile_option
@rpm_option
@range_noise_option
@marker_radius_option(default=MARKER_RADIUS_M)
@renamed_option("--max-distance-m", "max_distance_m", "--max-distance", type=MAX_DISTANCE_M,
                default=50.0, show_default=True,
                help="Drop the published distances beyond this, metres.")
@lidar_height_option
@click.option("--slope-deg", type=SLOPE_DEG, default=0.0, show_default=True,
              help="Ground slope, degrees: a plane through the station's foot rising towards "
                   "the station frame's +x (negative: falling); markers rest on it.")
@click.option("--extraction", type=click.Choice(EXTRACTIONS), default="full-chain",
              show_default=True,
              help="full-chain: the station chain of process and verify (ground removal, "
                   "clustering, gate, re-search, fit, quality); truth-seeded: a diagnostic "
                   "that re-searches each marker at its true position, skipping ground "
                   "removal, clustering and the gate.")
@scheduler_options
@json_option
def command(out, overwrite, frames, replicates, seed, profile, rpm, range_noise_mm,
            marker_radius_m, max_distance_m, lidar_height_m, slope_deg, extraction, scheduler,
            workers, as_json) -> None:
    """Simulate the published range experiment and fit every marker with both estimators.

    Markers every 1 m from 1-15 m, every 2 m from 15-25 m, every 5 m from 25-50 m around one
    station (0.20 m spheres unless --marker-radius-m says otherwise), on level ground or, with
    --slope-deg, resting on a planar slope (markers towards +x uphill, towards -x downhill);
    the LiDAR centre stands --lidar-height-m above the station's foot. The sensor's and
    turntable's errors come from --sensor-profile (--range-noise-mm overrides its range
    noise). Each scan is processed by the station chain of process and verify, once per
    estimator; a marker the chain did not detect is a rejected row with reason not_detected,
    so the table's acceptance rate is the chain's (--extraction truth-seeded: the old
    diagnostic that fits each marker at its true position instead). Writes markers.csv
    (marker table, all replicates), summary.csv (per estimator and distance: markers
    detected and accepted, median density, median and 95th-percentile centre error),
    range_study.png and summary.json (the extraction, and its provenance the profile, sensor,
    turntable, terrain and extraction). Each replicate is a task run where --scheduler says
    (the files are the same).

    \b
    Example:
      markerplan range-study --out range/ --replicates 3
      markerplan range-study --out quick/ --frames 100 --replicates 1
      markerplan range-study --out slope/ --lidar-height-m 0.8 --slope-deg 15
      markerplan range-study --out seeded/ --extraction truth-seeded
      markerplan range-study --out range/ --scheduler tcp://10.0.0.5:8786
    """
    from tqdm import tqdm

    from markerplan.output_folder import output_folder
    from planner.distributed import executor
    from planner.studies.range_experiment import run_range_study, write_range_study

    progress = not as_json or sys.stderr.isatty()
    with executor(scheduler, workers, progress) as ex, \
            output_folder(out, overwrite, "range-study") as stage, \
            tqdm(total=replicates, desc="replicates", unit="replicate", file=sys.stderr,
                 disable=None if progress else True) as bar:
        study = run_range_study(
            max_distance_m, frames, replicates, seed, profile, marker_radius_m, bar.update,
            rpm=rpm, lidar_height_m=lidar_height_m, slope_deg=slope_deg, map_tasks=ex,
            range_noise_m=None if range_noise_mm is None else range_noise_mm / 1e3,
            extraction=extraction)
        result = write_range_study(study, stage)
        summary_rows = study.summary
        distances = study.distance_of.values()
    result["out"] = str(out)
    methods = ("fixed-radius", "hemisphere-icp")
    lines = [f"extraction: {extraction}",
             f"{'distance_m':>10} " + " ".join(f"{m + ' mm':>18} {'accepted':>9}"
                                               for m in methods)]
    for d in distances:
        at = {s["estimator"]: s for s in summary_rows if s["distance_m"] == d}
        lines.append(f"{d:10.1f} " + " ".join(
            f"{at[m]['median_error_m'] * 1e3:18.2f} {at[m]['n_accepted']:>4}/{at[m]['n_rows']:<4}"
            if m in at else f"{'nan':>18} {'':>9}" for m in methods))
    emit_summary(result, as_json, "\n".join(lines + [f"wrote {out}"]))
