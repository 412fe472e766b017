"""Options and helpers shared by every sub-command (defined once, reused).

- ``out_option`` / ``overwrite_option`` / ``json_option``: the fixed option names.
- :func:`emit_summary`: one JSON object on stdout with ``--json``, a short human summary otherwise.
- :func:`report_timings`: step timings on stderr (never in output files).
- :func:`mounting_offset_options` / :func:`mounting_offsets`: the three true mounting offsets of
  a simulated rig (``simulate``, ``verify``, ``reduce --verify``).
- ``dem_option`` / ``stations_option`` / ``error_model_option``: the site inputs that ``plan``
  and ``reduce`` share.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import click


def out_option(default: str | None = None, required: bool = False):
    """``--out DIR``: the folder all output files go to."""
    # click >= 8.3 counts an explicit ``default=None`` as a value, so a required option gets
    # no ``default`` argument at all (else a missing --out reaches the command as None).
    settings = {"default": default, "show_default": True} if default is not None else \
        {"required": required}
    return click.option(
        "--out",
        "out",
        type=click.Path(file_okay=False, path_type=Path),
        help="Output folder (created; an existing one is replaced only with --overwrite and only "
             "if markerplan wrote it).",
        **settings,
    )


FILE = click.Path(dir_okay=False, path_type=Path)


class FiniteRange(click.FloatRange):
    """``click.FloatRange`` that also refuses ``nan`` and ``inf`` (which pass its comparisons)."""

    name = "finite float range"

    def convert(self, value, param, ctx):
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return number


# Documented bounds of numeric options (click shows them in --help and names the option and
# the range in its message). Beyond them the work explodes or the physics stops making sense.
#: Seeds: any non-negative 63-bit integer (numpy's SeedSequence takes no negative seed).
SEED = click.IntRange(0, 2**63 - 1)
#: Frames per turntable revolution: the rig takes ~800; 20 000 is 25 times that.
FRAMES = click.IntRange(1, 20_000)
#: 1-sigma range noise, mm: the VLP-16 datasheet gives +-30 mm; 500 mm is no longer a LiDAR.
RANGE_NOISE_MM = FiniteRange(0.0, 500.0)
#: VLP-16 spin rate, rpm (the sensor's own range; steps of 60 are checked by the sensor model).
RPM = click.IntRange(300, 1200)
#: Solver time limits, seconds (one day at most).
TIME_LIMIT_S = FiniteRange(0.0, 86_400.0, min_open=True)

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
    "--overwrite", is_flag=True,
    help="Replace the output folder if markerplan wrote it (its provenance.json lists every "
         "file); anything else is never deleted.")

json_option = click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON summary object on stdout."
)


def emit_summary(summary: dict[str, Any], as_json: bool, human: str | None = None) -> None:
    """Print the command's summary: JSON on stdout with ``--json``, else ``human`` text."""
    if as_json:
        click.echo(json.dumps(summary, sort_keys=True, default=str))
    else:
        click.echo(human if human is not None else json.dumps(summary, indent=2, default=str))


def given_paths(*paths: str | Path | None) -> list[Path]:
    """The input files and folders a command was given (``None`` left out), for
    :func:`markerplan.output_folder.output_folder`'s ``inputs``.

    >>> given_paths("a.csv", None, Path("b"))
    [PosixPath('a.csv'), PosixPath('b')]
    """
    return [Path(p) for p in paths if p is not None]


def report_timings(timings: dict[str, float]) -> None:
    """Print the run's step timings (seconds) as one line on stderr.

    Timings never go into output files, which must be byte-identical between identical runs;
    commands also put them in their ``--json`` summary.
    """
    click.echo("timings: " + ", ".join(f"{k} {v:.2f} s" for k, v in timings.items()), err=True)


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
        click.option("--vertical-axis-error-deg", type=FiniteRange(-10.0, 10.0),
                     default=0.0, show_default=True,
                     help="True vertical-axis error (rotation about the spin axis), degrees."),
        click.option("--lframe-tilt-deg", type=FiniteRange(-10.0, 10.0), default=0.0,
                     show_default=True,
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
    from pipeline.rig import MountingOffsets

    dx, dy = parse_numbers(axis_offset_mm, "--axis-offset-mm", "5,-3")
    return MountingOffsets(math.radians(vertical_axis_error_deg), math.radians(lframe_tilt_deg),
                           (dx / 1e3, dy / 1e3))
