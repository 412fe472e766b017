"""Options and helpers shared by every sub-command (defined once, reused).

- ``out_option`` / ``overwrite_option`` / ``json_option``: the fixed option names.
- :func:`staged_output`: write into a hidden sibling folder, move it into place only on
  success, so a failing command never leaves half-written output.
- :func:`emit_summary`: one JSON object on stdout with ``--json``, a short human summary otherwise.
- :func:`mounting_offset_options` / :func:`mounting_offsets`: the three true mounting offsets of
  a simulated rig (``simulate``, ``verify``, ``reduce --verify``).
- ``dem_option`` / ``stations_option`` / ``error_model_option``: the site inputs that ``plan``
  and ``reduce`` share.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import click

from markerplan.errors import OutputError


def out_option(default: str | None = None, required: bool = False):
    """``--out DIR``: the folder all output files go to."""
    return click.option(
        "--out",
        "out",
        type=click.Path(file_okay=False, path_type=Path),
        default=default,
        required=required and default is None,
        show_default=default is not None,
        help="Output folder (created; refused if it exists unless --overwrite).",
    )


FILE = click.Path(dir_okay=False, path_type=Path)

dem_option = click.option(
    "--dem", "dem_path", type=FILE,
    help="DEM (.tif/.tiff/.npz, site-frame metres) instead of the preset terrain.")

stations_option = click.option(
    "--stations", "stations_path", type=FILE,
    help="Stations CSV (id,x_m,y_m[,z_m][,heading_deg]) or GeoJSON Points.")

error_model_option = click.option(
    "--error-model", "error_model_path", type=FILE,
    help="Error-model JSON from fit-error-model (default: the shipped model).")

overwrite_option = click.option(
    "--overwrite", is_flag=True, help="Replace the output folder if it already exists."
)

json_option = click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON summary object on stdout."
)


def _check_out(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} exists and is not a folder; choose another path")
    if out.exists() and not overwrite:
        raise OutputError(f"--out {out} already exists; pass --overwrite or choose another folder")
    parent = out.resolve().parent
    probe = parent
    while not probe.exists():
        probe = probe.parent
    if not os.access(probe, os.W_OK | os.X_OK):
        raise OutputError(f"--out {out} is not writable (no write permission in {probe}); "
                          "choose a writable folder")


@contextlib.contextmanager
def staged_output(out: Path, overwrite: bool) -> Iterator[Path]:
    """Yield a temporary folder next to ``out``; on success move it to ``out``.

    Parameters
    ----------
    out : Path
        Final output folder.
    overwrite : bool
        Whether an existing ``out`` may be replaced.

    Yields
    ------
    stage : Path
        Folder to write into. Removed if the body raises.
    """
    out = Path(out)
    _check_out(out, overwrite)
    parent = out.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=parent))
    except OSError as exc:
        raise OutputError(f"--out {out} cannot be created ({exc.strerror}); "
                          "choose a writable folder") from exc
    try:
        yield stage
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    os.chmod(stage, 0o755)  # mkdtemp creates 0700; outputs are meant to be shared
    if out.exists():
        shutil.rmtree(out)
    os.replace(stage, out)


def emit_summary(summary: dict[str, Any], as_json: bool, human: str | None = None) -> None:
    """Print the command's summary: JSON on stdout with ``--json``, else ``human`` text."""
    if as_json:
        click.echo(json.dumps(summary, sort_keys=True, default=str))
    else:
        click.echo(human if human is not None else json.dumps(summary, indent=2, default=str))


def parse_numbers(text: str, name: str, example: str) -> tuple[float, ...]:
    """Parse comma-separated numbers, as many as ``example`` has, or raise a ConfigError that
    names the option and shows the example.

    >>> parse_numbers("5,-3", "--axis-offset-mm", "5,-3")
    (5.0, -3.0)
    """
    from markerplan.errors import ConfigError

    count = len(example.split(","))
    try:
        values = tuple(float(p) for p in text.split(","))
    except ValueError:
        values = ()
    if len(values) != count:
        words = {2: "two", 3: "three"}.get(count, str(count))
        raise ConfigError(f"{name} must be {words} comma-separated numbers like {example}; "
                          f"got {text!r}")
    return values


def mounting_offset_options(command):
    """``--vertical-axis-error-deg``, ``--lframe-tilt-deg``, ``--axis-offset-mm``: the true
    mounting offsets of a simulated rig (the pipeline self-calibrates them)."""
    for option in reversed([
        click.option("--vertical-axis-error-deg", type=float, default=0.0, show_default=True,
                     help="True vertical-axis error (rotation about the spin axis), degrees."),
        click.option("--lframe-tilt-deg", type=float, default=0.0, show_default=True,
                     help="True L-frame tilt, degrees."),
        click.option("--axis-offset-mm", default="0,0", show_default=True,
                     help="True horizontal offset DX,DY of the LiDAR centre from the turntable "
                          "axis, mm."),
    ]):
        command = option(command)
    return command


def mounting_offsets(vertical_axis_error_deg: float, lframe_tilt_deg: float,
                     axis_offset_mm: str):
    """The :class:`pipeline.rig.MountingOffsets` (SI units) of the three CLI options."""
    import math

    from pipeline.rig import MountingOffsets

    dx, dy = parse_numbers(axis_offset_mm, "--axis-offset-mm", "5,-3")
    return MountingOffsets(math.radians(vertical_axis_error_deg), math.radians(lframe_tilt_deg),
                           (dx / 1e3, dy / 1e3))
