"""``markerplan import-pcap``: a real VLP-16 capture (+ turntable log) -> one station scan file."""

from __future__ import annotations

import re
from pathlib import Path

import click

from planner.cli._common import (
    FILE,
    emit_summary,
    given_paths,
    json_option,
    out_option,
    overwrite_option,
    report_timings,
)

#: A station id that is also a safe file name: letters, digits, ``_``, ``-``, ``.``; no
#: leading dot.
_STATION_ID = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9_.-]*")
#: Below this azimuth coverage a frame gets a note (packets were lost from the capture).
_LOW_COVERAGE = 0.9


def _station_id(ctx, param, text: str | None) -> str | None:
    """Click callback: a station id usable as a file name (``None``: the capture's name)."""
    if text is not None and not _STATION_ID.fullmatch(text):
        raise click.BadParameter(f"use letters, digits, '_', '-' or '.' (not first), like S1; "
                                 f"got {text!r}", ctx, param)
    return text


@click.command("import-pcap")
@click.argument("capture", type=FILE)
@click.option("--turntable-log", "log_path", type=FILE,
              help="Turntable angle log, CSV: turntable_angle_deg one row per frame (optional "
                   "frame column 0, 1, 2, ...), or time_s,turntable_angle_deg to interpolate "
                   "at each revolution's time (UNIX seconds of the capturing computer). "
                   "Default: the whole capture is one frame at angle 0.")
@click.option("--station-id", callback=_station_id, metavar="ID",
              help="The station's id, and the scan file's name (default: the capture's file "
                   "name without extension).")
@click.option("--keep-partial", is_flag=True,
              help="Keep the capture's last revolution when the file ends mid-spin (default: "
                   "dropped with a note).")
@out_option(required=True)
@overwrite_option
@json_option
def command(capture: Path, log_path: Path | None, station_id: str | None, keep_partial: bool,
            out: Path, overwrite: bool, as_json: bool) -> None:
    """Import a real VLP-16 packet capture as a station scan for `markerplan process`.

    Decodes CAPTURE (.pcap of Ethernet frames, VLP-16, strongest, last or dual return: of
    dual, the last return of each firing is kept) into its spin revolutions and writes
    <station>.scan.npz into --out: one frame per revolution, its turntable angle from
    --turntable-log (one row per frame, or timestamps interpolated at the middle of each
    revolution); without a log, all revolutions are one frame at angle 0. The revolution the
    end of the file cuts short is dropped unless --keep-partial. See docs/pipeline.md, "Real
    captures".

    \b
    Example:
      markerplan import-pcap station1.pcap --turntable-log turntable.csv --out scans/
      markerplan import-pcap my.pcap --station-id S1 --out scans/
      markerplan process scans/ --marker-radius-m 0.1 --out tables/
    """
    import time

    import numpy as np

    from markerplan.errors import DataError
    from markerplan.output_folder import output_folder
    from markerplan.provenance import provenance
    from pipeline.scans.pcap import decode_vlp16_pcap, read_turntable_log, scan_from_revolutions
    from pipeline.scans.scan_format import write_scan

    started = time.perf_counter()
    station = station_id or capture.name.split(".")[0]
    with output_folder(out, overwrite, "import-pcap",
                       inputs=given_paths(capture, log_path)) as stage:
        log = None if log_path is None else read_turntable_log(log_path)
        decoded = decode_vlp16_pcap(capture)
        revolutions = decoded.revolutions
        decoded_s = time.perf_counter() - started
        kept = [r for r in revolutions if r.complete or keep_partial]
        if not kept:
            cut = ("" if decoded.cut_packet is None else
                   f", and the file is cut short inside packet {decoded.cut_packet}")
            raise DataError(f"pcap file {capture} holds only a partial revolution (the file "
                            f"ends mid-spin, {len(revolutions[0].points)} returns{cut}); pass "
                            "--keep-partial to import it")
        _note_capture(decoded, kept, log_path)
        frame_time_s = np.array([r.time_s for r in kept])
        angles = None if log is None else log.frame_angles(frame_time_s)
        scan = scan_from_revolutions(kept, angles, station, capture.name)
        config = {"capture": capture.name, "station_id": station, "keep_partial": keep_partial,
                  "turntable_log": None if log_path is None else log_path.name}
        scan.metadata["provenance"] = provenance(config, command="import-pcap",
                                                 inputs=_fingerprints(capture, log_path))
        name = write_scan(stage / f"{station}.scan.npz", scan).name
    timings = {"decode": decoded_s, "total": time.perf_counter() - started}
    report_timings(timings)
    summary = {
        "out": str(out), "scan": name, "station_id": station, "n_frames": scan.n_frames,
        "n_points": scan.n_points, "revolutions_decoded": len(revolutions),
        "return_mode": decoded.return_mode, "cut_packet": decoded.cut_packet,
        "partial_dropped": len(revolutions) - len(kept),
        "capture_span_s": [kept[0].start_s, kept[-1].end_s],
        "frame_time_s": frame_time_s.tolist() if log is not None else None,
        "turntable_angle_deg": np.degrees(scan.turntable_angle_rad).tolist(),
        "timings_s": timings,
    }
    emit_summary(summary, as_json, f"{station}: {scan.n_frames} frame(s), {scan.n_points} "
                                   f"points -> {out / name}")


def _note_capture(decoded, kept: list, log_path: Path | None) -> None:
    """Notes on stderr: a file cut short, a dual-return capture, a dropped partial revolution,
    revolutions with lost packets, no log.

    ``decoded`` is the :class:`pipeline.scans.pcap.Capture`; ``kept`` its revolutions without the
    partial last one when it was dropped."""
    revolutions = decoded.revolutions
    if decoded.cut_packet is not None:
        click.echo(f"note: the file ends inside packet {decoded.cut_packet} (cut short while "
                   "recording or copying); the whole packets before it were read", err=True)
    if decoded.return_mode == "dual":
        click.echo("note: a dual-return capture: kept the last return of each firing (what "
                   "last-return mode records)", err=True)
    if len(kept) < len(revolutions):
        click.echo(f"note: dropped the capture's last revolution ({len(revolutions[-1].points)} "
                   "returns): the file ends mid-spin; --keep-partial keeps it", err=True)
    for k, rev in enumerate(kept):
        if rev.coverage < _LOW_COVERAGE:
            click.echo(f"note: revolution {k} has returns over {rev.coverage:.0%} of the spin "
                       "(packets lost from the capture, or nothing in range)", err=True)
    if log_path is None:
        click.echo(f"note: no --turntable-log: the {len(kept)} revolution(s) are one frame at "
                   "turntable angle 0 (give the log to make one frame per revolution); one "
                   "turntable angle cannot calibrate the mounting offsets: process the scan "
                   "with --no-calibrate", err=True)


def _fingerprints(*paths: Path | None) -> list[dict[str, str]]:
    """Name and SHA-256 of each input file given (``None`` left out)."""
    import hashlib

    return [{"file": p.name, "sha256": hashlib.sha256(p.read_bytes()).hexdigest()}
            for p in given_paths(*paths)]
