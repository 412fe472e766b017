"""``markerplan range-study``: centre error and point density against distance (simulated)."""

from __future__ import annotations

import sys

import click

from planner.cli._common import (
    FiniteRange,
    emit_summary,
    frames_option,
    json_option,
    out_option,
    overwrite_option,
    range_noise_option,
    rpm_option,
    seed_option,
)


@click.command("range-study")
@out_option(required=True)
@overwrite_option
@frames_option
@click.option("--replicates", type=click.IntRange(1, 100), default=3, show_default=True,
              help="Replicates; replicate r is simulated with seed + r.")
@seed_option()
@rpm_option
@range_noise_option
@click.option("--max-distance", "max_distance_m", type=FiniteRange(1.0, 100.0),
              default=50.0, show_default=True,
              help="Drop the published distances beyond this, metres.")
@json_option
def command(out, overwrite, frames, replicates, seed, rpm, range_noise_mm, max_distance_m,
            as_json) -> None:
    """Simulate the published range experiment and fit every marker with both estimators.

    Markers (0.20 m) every 1 m from 1-15 m, every 2 m from 15-25 m, every 5 m from 25-50 m on
    level ground around one station. Writes markers.csv (marker table, all replicates),
    summary.csv (per estimator and distance: median density, median and 95th-percentile
    centre error), range_study.png and summary.json.

    \b
    Example:
      markerplan range-study --out range/ --replicates 3
      markerplan range-study --out quick/ --frames 100 --replicates 1
    """
    import csv
    import json

    import numpy as np
    from tqdm import tqdm

    from markerplan.output_folder import output_folder
    from markerplan.provenance import provenance
    from pipeline.marker_table import write_marker_table
    from pipeline.range_study import (
        RANGE_STUDY_DISTANCES_M,
        SUMMARY_COLUMNS,
        marker_layout,
        measure_markers,
        plot,
        summarise,
    )
    from visibility.dem import DEM
    from visibility.sensor import RigConfig, SensorConfig
    from visibility.simulate import simulate_markers

    distances = RANGE_STUDY_DISTANCES_M[RANGE_STUDY_DISTANCES_M <= max_distance_m]
    sensor = SensorConfig(rpm=rpm, range_noise_m=range_noise_mm / 1e3)
    rig = RigConfig(frames_per_turn=frames)
    centres = marker_layout(distances, 0.1, rig.lidar_height_m)
    ids = [f"R{d:04.1f}" for d in distances]
    half = float(distances.max()) + 5.0
    dem = DEM(np.zeros((int(2 * half / 0.5) + 1,) * 2), (-half, -half), 0.5)
    site_centres = centres + [0.0, 0.0, rig.lidar_height_m]
    config = {"distances_m": distances.tolist(), "frames": frames, "replicates": replicates,
              "seed": seed, "sensor": {"rpm": rpm, "range_noise_m": range_noise_mm / 1e3},
              "terrain": "level ground", "marker_radius_m": 0.1}
    with output_folder(out, overwrite, "range-study") as stage:
        rows = []
        for rep in tqdm(range(replicates), desc="replicates", file=sys.stderr, disable=None):
            scan, _ = simulate_markers(dem, [0.0, 0.0, rig.lidar_height_m], 0.0, site_centres,
                                       sensor, rig, seed=seed + rep, marker_ids=ids,
                                       station_id="RANGE")
            rows += measure_markers(scan, centres, ids, replicate=rep, seed=seed + rep)
            del scan
        dist_of = dict(zip(ids, distances.tolist(), strict=True))
        summary_rows = summarise(rows, dist_of)
        write_marker_table(stage / "markers.csv", rows)
        with (stage / "summary.csv").open("w", newline="") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(SUMMARY_COLUMNS)
            for s in summary_rows:
                w.writerow([f"{s[c]:.6f}" if isinstance(s[c], float) else s[c]
                            for c in SUMMARY_COLUMNS])
        plot(summary_rows, rows, dist_of, stage / "range_study.png")
        result = {"summary": summary_rows,
                  "files": ["markers.csv", "summary.csv", "range_study.png", "summary.json"],
                  "provenance": provenance(config, command="range-study")}
        (stage / "summary.json").write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    result["out"] = str(out)
    lines = [f"{'distance_m':>10} " + " ".join(f"{m:>16}" for m in ("fixed-radius mm",
                                                                    "hemisphere-icp mm"))]
    for d in distances:
        med = {s["estimator"]: s["median_error_m"] for s in summary_rows if s["distance_m"] == d}
        lines.append(f"{d:10.1f} " + " ".join(
            f"{med.get(m, float('nan')) * 1e3:16.2f}" for m in ("fixed-radius", "hemisphere-icp")))
    emit_summary(result, as_json, "\n".join(lines + [f"wrote {out}"]))
