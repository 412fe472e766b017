"""``markerplan process``: scans -> marker table, per-station summary, edge residuals."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from planner.cli._common import (
    FiniteRange,
    emit_summary,
    json_option,
    out_option,
    overwrite_option,
    report_timings,
)

_METHODS = ("fixed-radius", "hemisphere-icp")


def _parse_stage_options(items: tuple[str, ...]) -> dict[str, dict[str, object]]:
    """``STAGE.OPTION=VALUE`` strings -> nested dict (values parsed as JSON when possible)."""
    import json

    from markerplan.errors import ConfigError

    out: dict[str, dict[str, object]] = {}
    for item in items:
        key, sep, value = item.partition("=")
        stage, dot, option = key.partition(".")
        if not sep or not dot or not stage or not option:
            raise ConfigError(f"--set expects STAGE.OPTION=VALUE like quality.min_points=30, "
                              f"got {item!r}")
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parsed = value
        out.setdefault(stage.strip(), {})[option.strip()] = parsed
    return out


def _parse_offsets(text: str):
    """``VERTICAL_AXIS_DEG,LFRAME_TILT_DEG,DX_M,DY_M`` -> MountingOffsets (SI inside)."""
    import math

    from markerplan.errors import ConfigError
    from pipeline.rig import MountingOffsets

    try:
        v = [float(p) for p in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 4:
        raise ConfigError("--offsets must be VERTICAL_AXIS_DEG,LFRAME_TILT_DEG,DX_M,DY_M like "
                          f"0.3,0.3,0.015,0; got {text!r}")
    return MountingOffsets(math.radians(v[0]), math.radians(v[1]), (v[2], v[3]))


def _scan_files(paths: tuple[Path, ...]) -> list[Path]:
    """The scan files named on the command line: each must exist, none twice."""
    from markerplan.errors import InputFileError

    seen: dict[Path, Path] = {}
    for p in paths:
        if not p.is_file():
            raise InputFileError(f"scan file {p} does not exist; check the path")
        first = seen.setdefault(p.resolve(), p)
        if first is not p:
            raise InputFileError(f"scan file {p} is given twice (also as {first}); give each "
                                 "station's scan once")
    return list(paths)


@click.command("process")
@click.argument("scans", nargs=-1, required=True,
                type=click.Path(dir_okay=False, path_type=Path))
@out_option(required=True)
@overwrite_option
@click.option("--reference", "references", multiple=True, type=click.Path(path_type=Path),
              help="Reference coordinates: a simulator truth JSON (per station; repeat the "
                   "option), a folder of *.truth.json, or one total-station CSV "
                   "id,x_m,y_m,z_m in any frame.")
@click.option("--method", type=click.Choice(_METHODS), default="fixed-radius",
              show_default=True, help="Sphere-centre estimator.")
@click.option("--radius", "radius_m", type=FiniteRange(0.01, 1.0),
              default=0.1, show_default=True,
              help="Marker radius, metres.")
@click.option("--no-calibrate", is_flag=True,
              help="Skip self-calibration; apply --offsets (default zero) as known values.")
@click.option("--offsets", "offsets_text",
              help="Known (with --no-calibrate) or starting mounting offsets "
                   "VERTICAL_AXIS_DEG,LFRAME_TILT_DEG,DX_M,DY_M.")
@click.option("--min-points", type=click.IntRange(1, 1_000_000),
              help="Quality gate: minimum points per marker.")
@click.option("--max-rms", "max_rms_m", type=FiniteRange(0.0, 1.0, min_open=True),
              help="Quality gate: maximum fit RMS, m.")
@click.option("--min-visible-fraction", type=FiniteRange(0.0, 1.0),
              help="Quality gate: minimum visible fraction.")
@click.option("--set", "stage_options", multiple=True, metavar="STAGE.OPTION=VALUE",
              help="Any stage option, e.g. --set ground.min_height_m=0.1 "
                   "--set gate.max_box_m=0.3 (unknown names are refused).")
@json_option
def command(scans, out, overwrite, references, method, radius_m, no_calibrate, offsets_text,
            min_points, max_rms_m, min_visible_fraction, stage_options, as_json) -> None:
    """Process station scans into a marker table.

    Writes markers.csv (one row per candidate; columns in docs/pipeline.md), stations.csv
    (per-station summary with calibration estimates), edges.csv (edge-length residuals when a
    reference is given) and summary.json (configuration and provenance).

    \b
    Example:
      markerplan process scans/station_*.scan.npz --reference scans/ --out tables/
      markerplan process s1.scan.npz --reference total_station.csv --out t/
    """
    from tqdm import tqdm

    from markerplan.errors import InputFileError
    from markerplan.output_folder import output_folder
    from markerplan.provenance import fingerprint_arrays, provenance
    from pipeline.evaluation import check_references, pick_reference, read_reference
    from pipeline.process import process_station
    from pipeline.results import write_results
    from pipeline.rig import MountingOffsets
    from pipeline.scan_format import read_scan
    from pipeline.stages import build_config, with_offsets

    options = _parse_stage_options(stage_options)
    options.setdefault("fit", {}).update(method=method, radius_m=radius_m)
    quality = {"min_points": min_points, "max_rms_m": max_rms_m,
               "min_visible_fraction": min_visible_fraction}
    options.setdefault("quality", {}).update({k: v for k, v in quality.items() if v is not None})
    cfg = build_config(options)
    offsets = _parse_offsets(offsets_text) if offsets_text else MountingOffsets()
    cfg = with_offsets(cfg, offsets, enabled=not no_calibrate)
    ref_files = [f for p in references
                 for f in (sorted(p.glob("*.truth.json")) if p.is_dir() else [p])]
    if any(p.is_dir() for p in references) and not ref_files:
        raise InputFileError(f"--reference folder(s) {', '.join(map(str, references))} hold no "
                             "*.truth.json; give the truth files or a total-station CSV")
    refs = [read_reference(p) for p in ref_files]
    check_references(refs)
    scans = _scan_files(scans)
    with output_folder(out, overwrite, "process", inputs=[*scans, *references]) as stage:
        results, inputs = [], []
        for path in tqdm(scans, desc="stations", file=sys.stderr, disable=None):
            scan = read_scan(path)
            inputs.append({"scan": str(path), "station_id": scan.station_id,
                           "sha256": fingerprint_arrays(scan.xyz_sensor_m, scan.frame_index,
                                                        scan.turntable_angle_rad)})
            results.append(process_station(scan, cfg, pick_reference(refs, scan.station_id)))
            del scan
        prov = provenance(cfg.to_dict(), inputs=inputs,
                          references=[r.source for r in refs], command="process")
        summary = write_results(stage, results, prov)
    timings = {f"{res.summary['station_id']} {step}": t
               for res in results for step, t in res.timings_s.items()}
    report_timings({"total": sum(timings.values())})
    summary.update(out=str(out), timings_s=timings)
    human = "\n".join(
        f"{s['station_id']}: {s['n_accepted']}/{s['n_candidates']} accepted"
        + (f", mean error {s['mean_error_m'] * 1e3:.1f} mm" if s.get("mean_error_m") else "")
        for s in summary["stations"]) + f"\nwrote {out}"
    emit_summary(summary, as_json, human)
