"""Options and helpers shared by every sub-command (defined once, reused).

- ``out_option`` / ``overwrite_option`` / ``json_option``: the fixed option names.
- :func:`staged_output`: write into a hidden sibling folder, move it into place only on
  success, so a failing command never leaves half-written output.
- :func:`emit_summary`: one JSON object on stdout with ``--json``, a short human summary otherwise.
- :func:`mounting_offset_options` / :func:`mounting_offsets`: the three true mounting offsets of
  a simulated rig (``simulate``, ``verify``).
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


def parse_triplet(text: str | None, name: str) -> tuple[float, float, float] | None:
    """Parse ``"x,y,z"`` into three floats, or raise a ConfigError naming the option."""
    from markerplan.errors import ConfigError

    if text is None:
        return None
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 3:
        raise ConfigError(f"{name} must be three comma-separated numbers like 0,0,1.0; "
                          f"got {text!r}")
    return values  # type: ignore[return-value]


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

    dx, dy = parse_pair(axis_offset_mm, "--axis-offset-mm")
    return MountingOffsets(math.radians(vertical_axis_error_deg), math.radians(lframe_tilt_deg),
                           (dx / 1e3, dy / 1e3))


def parse_pair(text: str, name: str) -> tuple[float, float]:
    """Parse ``"a,b"`` into two floats, or raise a ConfigError naming the option."""
    from markerplan.errors import ConfigError

    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 2:
        raise ConfigError(f"{name} must be two comma-separated numbers like 5,-3; got {text!r}")
    return values  # type: ignore[return-value]
