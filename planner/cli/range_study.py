"""``markerplan range-study``: centre error and point density against distance (simulated)."""

from __future__ import annotations

import sys

import click

from planner.cli._common import (
    FiniteRange,
    emit_summary,
    frames_option,
    json_option,
    marker_radius_option,
    out_option,
    overwrite_option,
    range_noise_option,
    rpm_option,
    seed_option,
)
from visibility.sites import MARKER_RADIUS_M


@click.command("range-study")
@out_option(required=True)
@overwrite_option
@frames_option
@click.option("--replicates", type=click.IntRange(1, 100), default=3, show_default=True,
              help="Replicates; replicate r is simulated with seed + r.")
@seed_option()
@rpm_option
@range_noise_option
@marker_radius_option(default=MARKER_RADIUS_M)
@click.option("--max-distance", "max_distance_m", type=FiniteRange(1.0, 100.0),
              default=50.0, show_default=True,
              help="Drop the published distances beyond this, metres.")
@json_option
def command(out, overwrite, frames, replicates, seed, rpm, range_noise_mm, marker_radius_m,
            max_distance_m, as_json) -> None:
    """Simulate the published range experiment and fit every marker with both estimators.

    Markers every 1 m from 1-15 m, every 2 m from 15-25 m, every 5 m from 25-50 m on level
    ground around one station (0.20 m spheres unless --marker-radius says otherwise). Writes
    markers.csv (marker table, all replicates), summary.csv (per estimator and distance:
    median density, median and 95th-percentile centre error), range_study.png and
    summary.json.

    \b
    Example:
      markerplan range-study --out range/ --replicates 3
      markerplan range-study --out quick/ --frames 100 --replicates 1
    """
    from tqdm import tqdm

    from markerplan.output_folder import output_folder
    from visibility.range_experiment import run_range_study, write_range_study
    from visibility.sensor import DEFAULT_RANGE_NOISE_M, SensorConfig

    sensor = SensorConfig(rpm=rpm, range_noise_m=DEFAULT_RANGE_NOISE_M if range_noise_mm is None
                          else range_noise_mm / 1e3)
    with output_folder(out, overwrite, "range-study") as stage:
        with tqdm(total=replicates, desc="replicates", file=sys.stderr, disable=None) as bar:
            study = run_range_study(max_distance_m, frames, replicates, seed, sensor,
                                    marker_radius_m, progress=bar.update)
        result = write_range_study(study, stage)
        summary_rows = study.summary
        distances = study.distance_of.values()
    result["out"] = str(out)
    lines = [f"{'distance_m':>10} " + " ".join(f"{m:>16}" for m in ("fixed-radius mm",
                                                                    "hemisphere-icp mm"))]
    for d in distances:
        med = {s["estimator"]: s["median_error_m"] for s in summary_rows if s["distance_m"] == d}
        lines.append(f"{d:10.1f} " + " ".join(
            f"{med.get(m, float('nan')) * 1e3:16.2f}" for m in ("fixed-radius", "hemisphere-icp")))
    emit_summary(result, as_json, "\n".join(lines + [f"wrote {out}"]))
