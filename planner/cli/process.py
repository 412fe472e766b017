"""``markerplan process``: scans -> marker table, per-station summary, edge residuals."""

from __future__ import annotations

from pathlib import Path

import click

from planner.cli._common import (
    FiniteRange,
    emit_summary,
    estimator_option,
    id_list,
    json_option,
    marker_radius_option,
    mounting_offset_options,
    out_option,
    overwrite_option,
    renamed_option,
    report_timings,
    sensor_profile_option,
)
from visibility.sites import MARKER_RADIUS_M

#: Quality gate: the largest fit RMS, m.
MAX_RMS_M = FiniteRange(0.0, 1.0, min_open=True)


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


def _scan_inputs(paths: tuple[Path, ...]) -> tuple[list[Path], list[Path]]:
    """The scans and the simulator truths among SCANS (files, or folders ``simulate`` wrote).

    In a folder, ``*.scan.npz`` are the scans and ``*.truth.json`` their truths; other files
    are passed over with a note. Among named files, ``*.truth.json`` are truths, and the
    ``site.json`` / ``provenance.json`` that ``simulate`` writes beside its scans are passed
    over with a note; any other file is read as a scan. Every scan must exist, none twice.
    """
    from markerplan.errors import InputFileError

    scans, truths, passed_over = [], [], []
    for p in paths:
        if p.is_dir():
            found = sorted(p.glob("*.scan.npz"))
            if not found:
                raise InputFileError(f"folder {p} holds no *.scan.npz; give the folder "
                                     "`markerplan simulate` wrote, or the scan files")
            truths += sorted(p.glob("*.truth.json"))
            passed_over += [f for f in sorted(p.iterdir())
                            if f not in found and f not in truths and not f.name.startswith(".")]
            scans += found
        elif p.name.endswith(".truth.json"):
            truths.append(p)
        elif p.name in ("site.json", "provenance.json"):
            passed_over.append(p)
        elif not p.is_file():
            raise InputFileError(f"scan file {p} does not exist; check the path")
        else:
            scans.append(p)
    if passed_over:
        click.echo("note: not scans, passed over: " + ", ".join(str(f) for f in passed_over),
                   err=True)
    if not scans:
        raise InputFileError("no scan among SCANS; give *.scan.npz files or the folder "
                             "`markerplan simulate` wrote")
    seen: dict[Path, Path] = {}
    for p in scans:
        first = seen.setdefault(p.resolve(), p)
        if first is not p:
            raise InputFileError(f"scan file {p} is given twice (also as {first}); give each "
                                 "station's scan once")
    return scans, truths


def _marker_radius(given: float | None, references: list) -> float:
    """``--marker-radius-m``, else the one the references (simulator truths) record, else
    0.1 m."""
    from markerplan.errors import InputFileError

    if given is not None:
        return given
    radii = {r.marker_radius_m for r in references} - {None}
    if len(radii) > 1:
        raise InputFileError(f"the truth files record different marker radii "
                             f"({', '.join(f'{r:g}' for r in sorted(radii))} m); process each "
                             "marker size separately, or give --marker-radius-m")
    return float(radii.pop()) if radii else MARKER_RADIUS_M


def _site_crs(paths: tuple[Path, ...]) -> str | None:
    """The CRS (WKT) of the DEM the ``site.json`` among SCANS (or in their folders) records,
    else None. ``simulate`` writes that file beside its scans."""
    from markerplan.errors import InputFileError
    from markerplan.reading import load_json, require_type

    sites = [p / "site.json" if p.is_dir() else p for p in paths]
    found = {require_type(load_json(s, f"site file {s}").get("dem", {}), dict,
                          f"site file {s}: 'dem'").get("crs") or None
             for s in sites if s.name == "site.json" and s.is_file()} - {None}
    if len(found) > 1:
        raise InputFileError("the site.json files among SCANS record different CRSs; process "
                             "each site separately")
    return found.pop() if found else None


def _station_poses(truth_files: list[Path]) -> dict:
    """{station id: :class:`~pipeline.surveys.point_cloud_io.StationPose`} of the truths among
    ``truth_files`` (the references that are JSON) that record the station's position."""
    from pipeline.scans.scan_format import read_truth
    from pipeline.surveys.point_cloud_io import StationPose

    truths = [read_truth(p) for p in truth_files if p.suffix.lower() == ".json"]
    return {t["station_id"]: StationPose.from_truth(t) for t in truths
            if "position_m" in t["station_pose"]}


@click.command("process")
@click.argument("scans", nargs=-1, required=True, type=click.Path(path_type=Path))
@out_option(required=True)
@overwrite_option
@click.option("--reference", "references", multiple=True, type=click.Path(path_type=Path),
              help="Reference coordinates: a simulator truth JSON (per station; repeat the "
                   "option), a folder of *.truth.json, or one total-station CSV "
                   "id,x_m,y_m,z_m in any frame. Default: the truths among SCANS.")
@estimator_option()
@marker_radius_option(default_help=" Default: the simulator truths', else 0.1.")
@click.option("--no-calibrate", is_flag=True,
              help="Skip self-calibration; apply the mounting offsets (default zero) as known "
                   "values. Without it they are where the calibration starts.")
@mounting_offset_options
@click.option("--min-points", type=click.IntRange(1, 1_000_000),
              help="Quality gate: minimum points per marker.")
@renamed_option("--max-rms-m", "max_rms_m", "--max-rms", type=MAX_RMS_M,
                help="Quality gate: maximum fit RMS, m (replaces the default of 3x the RMS the "
                     "sensor's noise gives).")
@click.option("--min-visible-fraction", type=FiniteRange(0.0, 1.0),
              help="Quality gate: minimum visible fraction.")
@click.option("--set", "stage_options", multiple=True, metavar="STAGE.OPTION=VALUE",
              help="Any stage option, e.g. --set ground.min_height_m=0.1 "
                   "--set gate.max_box_m=0.3 (unknown names are refused).")
@click.option("--cloud", "cloud_formats", callback=id_list, metavar="las,ply",
              help="Also write each station's calibrated, classified cloud in these formats "
                   "(comma-separated: las = LAS 1.4, ply = binary PLY) as "
                   "<station>.station.<format>, and <station>.site.<format> when the station's "
                   "truth gives its pose in the site. Classes in docs/pipeline.md.")
@sensor_profile_option
@json_option
def command(scans, out, overwrite, references, estimator, marker_radius_m, no_calibrate, offsets,
            min_points, max_rms_m, min_visible_fraction, stage_options, cloud_formats, profile,
            as_json) -> None:
    """Process station scans into a marker table.

    SCANS are .scan.npz files or the folder `markerplan simulate` wrote (its scans, with
    their truths as the reference). Writes markers.csv (one row per candidate; columns in
    docs/pipeline.md), stations.csv (per-station summary with calibration estimates), edges.csv
    (edge-length residuals when a reference is given) and summary.json (configuration and
    provenance). Gates and fit follow the range noise the scan records (simulated scans), else
    the one of --sensor-profile. With --cloud, also each station's calibrated cloud, marker and
    ground points classified, in the station frame and (pose known) the site frame, with the
    CRS a site.json among SCANS records.

    \b
    Example:
      markerplan process scans/ --out tables/
      markerplan process scans/station_S1.scan.npz --reference scans/ --out tables/
      markerplan process s1.scan.npz --reference total_station.csv --out t/
      markerplan process scans/ --cloud las,ply --out tables/
    """
    from markerplan.errors import InputFileError
    from markerplan.output_folder import output_folder
    from markerplan.provenance import provenance
    from pipeline.chain.evaluation import check_references, read_reference
    from pipeline.surveys.point_cloud_io import check_formats, classify_cloud, write_station_clouds
    from pipeline.surveys.results import write_results
    from pipeline.surveys.survey import ProcessingSettings, process_scans, processing_config

    scans_given = scans
    scans, truths = _scan_inputs(scans)
    options = _parse_stage_options(stage_options)
    ref_files = [f for p in references
                 for f in (sorted(p.glob("*.truth.json")) if p.is_dir() else [p])]
    if any(p.is_dir() for p in references) and not ref_files:
        raise InputFileError(f"--reference folder(s) {', '.join(map(str, references))} hold no "
                             "*.truth.json; give the truth files or a total-station CSV")
    if not references:
        ref_files = truths
    refs = [read_reference(p) for p in ref_files]
    check_references(refs)
    radius_given = marker_radius_m is None and "radius_m" in options.get("fit", {})
    cfg = processing_config(ProcessingSettings(
        marker_radius_m=None if radius_given else _marker_radius(marker_radius_m, refs),
        estimator=estimator, offsets=offsets, calibrate=not no_calibrate,
        min_points=min_points, max_rms_m=max_rms_m, min_visible_fraction=min_visible_fraction,
        stage_options=options))
    poses, crs_wkt = {}, None
    if cloud_formats:
        check_formats(cloud_formats)
        poses, crs_wkt = _station_poses(ref_files), _site_crs(scans_given)
    with output_folder(out, overwrite, "process", inputs=[*scans, *truths, *references]) as stage:
        cloud_files: list[str] = []

        def write_cloud(scan, result) -> None:
            cloud_files.extend(write_station_clouds(
                stage, classify_cloud(scan, result, cfg.ground), cloud_formats,
                poses.get(scan.station_id), crs_wkt))

        survey = process_scans(scans, cfg, refs, profile.sensor.expected_scatter(),
                               f"sensor profile {profile.name}",
                               each=write_cloud if cloud_formats else None)
        results = survey.results
        prov = provenance(cfg.to_dict(), inputs=survey.inputs,
                          references=[r.source for r in refs], command="process")
        summary = write_results(stage, results, prov, cloud_files)
    timings = {f"{res.summary['station_id']} {step}": t
               for res in results for step, t in res.timings_s.items()}
    report_timings({"total": sum(timings.values())})
    summary.update(out=str(out), timings_s=timings)
    human = "\n".join(
        f"{s['station_id']}: {s['n_accepted']}/{s['n_candidates']} accepted"
        + (f", mean error {s['mean_error_m'] * 1e3:.1f} mm" if s.get("mean_error_m") else "")
        for s in summary["stations"]) + f"\nwrote {out}"
    emit_summary(summary, as_json, human)
