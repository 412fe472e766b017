"""The CLI's vocabulary: every option that more than one command takes is defined here once,
with one name and one meaning, and (rio-style) a click type or callback that hands the command a
typed value rather than text to parse.

==========================  =====================================================================
option                      meaning (and the value the command receives)
==========================  =====================================================================
``--out DIR``               the folder all output files go to (``Path``)
``--overwrite``             replace ``--out`` if markerplan wrote it
``--json``                  one JSON summary object on stdout
``--site NAME``             site preset (``default``, ``large``, ``km``)
``--site-seed N``           seed of the preset's synthetic terrain
``--seed N``                seed of the simulated noise (``fit-error-model``, which adds none,
                            seeds its resampling with ``--resample-seed``)
``--dem FILE``              DEM instead of the preset's terrain (``Path``)
``--reproject``             resample a ``--dem`` in degrees (or on non-square cells) to a local
                            metric CRS; point and polygon files are then in the DEM file's CRS
                            (``bool``; :func:`visibility.dem.read_dem`, ``to_dem_xy``);
                            refused without a DEM to resample (:func:`require_dem`)
``--stations FILE``         stations CSV/GeoJSON (``Path``)
``--station-ids S1,S3``     which stations to work on (``tuple[str, ...]``)
``--marker-radius-m M``     marker (sphere) radius, metres (``float``)
``--lidar-height-m M``      LiDAR centre above the ground at the station, metres (``float``)
``--error-model FILE``      error model (:class:`ErrorModelChoice`, the shipped one by default)
``--estimator NAME``        sphere-centre estimator, from
                            :data:`pipeline.sphere_centres.sphere_fit.METHODS`
``--sensor-profile NAME``   sensor, turntable and reference errors (a loaded
                            :class:`~visibility.sensor_profile.SensorProfile`; ``calibrated``
                            by default, ``datasheet``, or a JSON file from ``calibrate-sensor``)
``--vertical-axis-error-deg``, ``--lframe-tilt-deg``, ``--axis-offset-mm``
                            the rig's mounting offsets (one
                            :class:`~pipeline.scans.rig.MountingOffsets` argument ``offsets``)
``--config FILE``           TOML plan settings; ``--boundary``, ``--exclude``: GeoJSON polygons
``--time-limit-s S``        solver time limit, seconds
``--network``, ``--datum``,  network mode's datum, requirement kinds and pose aids: defined in
``--requirement-m`` ...     :mod:`planner.cli._network_options`
``--scheduler ADDRESS``     where the per-station tasks run: ``local`` (a LocalCluster sized to
                            the machine), ``none`` (in process) or a dask scheduler address
                            (``str``; :func:`planner.distributed.executor`)
``--workers N``             worker processes of the ``local`` cluster (default and most: one
                            per core this process may use; :func:`_local_workers`)
==========================  =====================================================================

Options whose value has a unit carry it in the name (``-m``, ``-s``, ``-deg``, ``-mm``); a
renamed option keeps its old spelling for one release (:func:`renamed_option`).

Helpers: :func:`emit_summary` (JSON or human summary), :func:`report_timings` (step timings on
stderr, never in files), :func:`given_paths` (the inputs an output folder must not contain).
``--station-ids`` is checked against the stations at hand by
:func:`planner.problem.inputs.select_stations`.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path
from typing import Any, NamedTuple

import click

from pipeline.scans.rig import MountingOffsets
from pipeline.sphere_centres.sphere_fit import METHODS


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
    """The type of every float option: a ``click.FloatRange`` with both bounds, that also
    refuses ``nan`` (which passes its comparisons).

    Both bounds are required: ``inf`` and ``1e308`` pass a one-sided range, and the work a
    value like that sizes (a grid of cells, a square) overflows or explodes.

    Parameters
    ----------
    min, max : float
        The bounds, in the option's unit.
    **kwargs
        As :class:`click.FloatRange` (``min_open``, ``max_open``).
    """

    name = "float"

    def __init__(self, min: float, max: float, **kwargs):
        if min is None or max is None:
            raise TypeError("FiniteRange needs both bounds; an unbounded float option lets "
                            "values through whose use overflows")
        super().__init__(min, max, **kwargs)

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
#: LiDAR centre above the ground, m: the rig's tripod stands 0.8-1.5 m; below 0.3 m the turntable
#: and bracket are in the way, above 3 m no tripod reaches.
LIDAR_HEIGHT_M = FiniteRange(0.3, 3.0)
#: Solver time limits, seconds (one day at most).
TIME_LIMIT_S = FiniteRange(0.0, 86_400.0, min_open=True)
#: A required 95 % error, m (a looser one than 10 m asks nothing of a survey; the plan's bound
#: is planner.config.BOUNDS).
REQUIREMENT_M = FiniteRange(0.0, 10.0, min_open=True)
#: A requirement's ppm term (:data:`planner.config.BOUNDS`).
REQUIREMENT_PPM = FiniteRange(0.0, 1e6)
#: Largest separation of a locally judged station pair, m (planner.config.BOUNDS).
LOCAL_WITHIN_M = FiniteRange(0.0, 10_000.0, min_open=True)
#: Marker (sphere) radius, m.
SPHERE_RADIUS_M = FiniteRange(0.01, 1.0)
#: Largest mounting axis offset (each of dx, dy), mm: the VLP-16 (103 mm across) sits on an
#: L-bracket a few centimetres off the turntable axis; 1 m off it is no longer a turntable
#: rig (and the simulated scan of a LiDAR 1e6 m off its station is empty).
AXIS_OFFSET_MM = 1000.0

overwrite_option = click.option(
    "--overwrite", is_flag=True,
    help="Replace the output folder if markerplan wrote it (its provenance.json lists every "
         "file); anything else is never deleted.")

json_option = click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON summary object on stdout."
)


#: What :func:`deprecated_alias` appends to the parameter name of an old spelling.
DEPRECATED_SUFFIX = "_deprecated_spelling"


def warn_deprecated(old: str, new: str) -> None:
    """The one deprecation line of a renamed spelling, on stderr:
    ``warning: OLD is deprecated; use NEW``."""
    click.echo(f"warning: {old} is deprecated; use {new}", err=True)


def deprecated_alias(old: str, new: str, name: str, **attrs):
    """A hidden option ``old`` for the option ``new``, kept for one release after a rename.

    Both set the command's parameter ``name`` (given both, the later on the command line
    wins); using ``old`` prints ``warning: OLD is deprecated; use NEW`` on stderr.

    Parameters
    ----------
    old, new : str
        The old and the new spelling, e.g. ``"--time-limit"`` and ``"--time-limit-s"``.
    name : str
        The parameter both set, e.g. ``"time_limit_s"``.
    **attrs
        As ``new``'s :func:`click.option` (``type``, ``metavar``, ``multiple``, ``callback``),
        without a default (an option that takes a value, not a flag): a ``callback`` sees only
        values given as ``old``.

    Returns
    -------
    decorator
        A :func:`click.option` decorator.
    """
    convert = attrs.pop("callback", None)

    def warn(ctx, param, value):
        if value is None or value == ():  # not given: ``new``'s value stands
            return
        warn_deprecated(old, new)
        ctx.params[name] = value if convert is None else convert(ctx, param, value)
        ctx.set_parameter_source(name, click.core.ParameterSource.COMMANDLINE)

    return click.option(old, name + DEPRECATED_SUFFIX, hidden=True, expose_value=False,
                        callback=warn, **attrs)


#: The attributes of an option its :func:`deprecated_alias` shares (not its default or help).
_ALIAS_ATTRS = ("type", "metavar", "multiple", "callback")


def renamed_option(new: str, name: str, old: str, **attrs):
    """``click.option(new, name, **attrs)`` with its former spelling ``old`` kept as a
    :func:`deprecated_alias` of the same type, metavar and callback.

    Parameters
    ----------
    new, old : str
        The option's spelling and its former one, e.g. ``"--time-limit-s"``, ``"--time-limit"``.
    name : str
        The command's parameter, e.g. ``"time_limit_s"``.
    **attrs
        As :func:`click.option` (``type``, ``default``, ``help``, ...).

    Returns
    -------
    decorator
        Both options, the alias applied first (as when written as two decorators, ``new``
        above).
    """
    option = click.option(new, name, **attrs)
    alias = deprecated_alias(old, new, name, **{k: attrs[k] for k in _ALIAS_ATTRS if k in attrs})
    return lambda f: option(alias(f))


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


class ErrorModelChoice(NamedTuple):
    """What ``--error-model`` resolves to."""

    model: Any
    """The :class:`error_model.model.ErrorModel`."""
    name: str
    """How outputs name it: the file, or the shipped model."""
    path: Path | None
    """The file given, or ``None`` for the shipped model."""


def _load_error_model(ctx, param, path: Path | None) -> ErrorModelChoice:
    from error_model import default_model
    from error_model.model import ErrorModel

    if path is None:
        return ErrorModelChoice(default_model(), "default (shipped with markerplan)", None)
    return ErrorModelChoice(ErrorModel.load(path), str(path), path)


def _load_sensor_profile(ctx, param, text: str):
    from visibility.sensor_profile import load_profile

    return load_profile(text)


sensor_profile_option = click.option(
    "--sensor-profile", "profile", default="calibrated", show_default=True,
    metavar="NAME|FILE", callback=_load_sensor_profile,
    help="Sensor profile: calibrated (fitted to the published field experiment), datasheet "
         "(Velodyne's figures only), or a JSON file written by calibrate-sensor.")


def id_list(ctx, param, text: str | None) -> tuple[str, ...] | None:
    """Click callback: comma-separated ids -> a tuple without repeats (``None`` if absent)."""
    if text is None:
        return None
    ids = tuple(dict.fromkeys(t.strip() for t in text.split(",") if t.strip()))
    if not ids:
        raise click.BadParameter(f"give comma-separated ids like {param.metavar}, got {text!r}",
                                 ctx, param)
    return ids


def point_option(name: str, default: str | None, metavar: str, help_text: str,
                 dest: str | None = None, old: str | None = None, *, limit: float):
    """An option of as many comma-separated numbers as ``default`` has (or ``metavar``, when
    there is no default: then ``None`` when not given), each finite and within ``+-limit``
    (the option's unit), handed to the command as a tuple of floats (parameter ``dest``,
    default from ``name``); ``old``: its former spelling, kept as a :func:`deprecated_alias`."""
    count = len((default or metavar).split(","))

    def parse(ctx, param, text: str | None) -> tuple[float, ...] | None:
        if text is None:
            return None
        try:
            values = tuple(float(p) for p in text.split(","))
        except ValueError:
            values = ()
        if len(values) != count or not all(abs(v) <= limit for v in values):  # NaN fails too
            words = {2: "two", 3: "three"}.get(count, str(count))
            raise click.BadParameter(f"must be {words} comma-separated numbers, each between "
                                     f"{-limit:g} and {limit:g}, like {metavar}; got {text!r}",
                                     ctx, param)
        return values

    attrs = {"default": default, "show_default": default is not None, "metavar": metavar,
             "callback": parse, "help": help_text}
    if old is None:
        return click.option(name, *([dest] if dest else []), **attrs)
    return renamed_option(name, dest, old, **attrs)


def site_option(default: str | None = "default"):
    """``--site NAME``: the site preset (``None`` default: taken from the command's input)."""
    settings = {"default": default, "show_default": True} if default else {}
    return click.option(
        "--site", "site_name", **settings,
        help="Site preset: default (40 m crater field, 7 stations), large (300 m, 100 "
             "stations) or km (1 km at 0.25 m cells, 311 stations on a traverse; plan it with "
             "grid_spacing_m >= 2 in --config)."
             + ("" if default else " Default: the plan's site, else default."))


site_seed_option = click.option(
    "--site-seed", type=SEED, default=None, metavar="N",
    help="Seed of the site preset's synthetic terrain (default 0, or the plan's).")


def seed_option(help_text: str = "Seed of the simulated noise; the same seed gives the same "
                                 "files."):
    """``--seed N``: the seed of the command's random noise or resampling (default 0)."""
    return click.option("--seed", type=SEED, default=0, show_default=True, metavar="N",
                        help=help_text)


def frames_option_at_least(fewest: int):
    """``--frames N``: frames per turntable revolution, from ``fewest`` (a command whose
    processing needs more than one frame says so) to :data:`FRAMES`' largest."""
    return click.option(
        "--frames", type=click.IntRange(fewest, FRAMES.max), default=800, show_default=True,
        help="Frames per turntable revolution (the rig takes about 800; fewer for a quick run).")


frames_option = frames_option_at_least(FRAMES.min)

rpm_option = click.option(
    "--rpm", type=RPM, default=600, show_default=True,
    help="VLP-16 spin rate, 300-1200 in steps of 60.")

range_noise_option = click.option(
    "--range-noise-mm", type=RANGE_NOISE_MM, default=None,
    help="1-sigma range noise at short range and normal incidence, mm; overrides the sensor "
         "profile's (datasheet: 15, +-3 cm read as 2 sigma).")

#: ``--lidar-height-m M`` (old spelling ``--lidar-height``): the LiDAR centre above the ground,
#: metres.
lidar_height_option = renamed_option(
    "--lidar-height-m", "lidar_height_m", "--lidar-height", type=LIDAR_HEIGHT_M, default=1.0,
    show_default=True, help="LiDAR centre above the ground, metres.")

dem_option = click.option(
    "--dem", "dem_path", type=FILE,
    help="DEM instead of the preset's terrain: any one-band raster GDAL reads (GeoTIFF, .asc, "
         ".vrt, ISIS3/PDS cubes) or .npz, in a metric CRS (UTM, lunar) or none; nodata is a "
         "mask.")

def _height_error(ctx, param, text: str | None):
    """Click callback: ``RMS_M[,CORRELATION_M]`` -> :class:`visibility.orbital.HeightError`
    (``None`` if absent); a bad value is a usage error naming the option."""
    from markerplan.errors import ConfigError
    from visibility.orbital import HeightError

    if text is None:
        return None
    try:
        return HeightError.parse(text)
    except ConfigError as exc:
        raise click.BadParameter(str(exc), ctx, param) from None


terrain_option = click.option(
    "--terrain", type=click.Choice(["truth", "orbital"]), default="truth", show_default=True,
    help="The preset's terrain to plan on: its fine truth, or its orbital-grade planning DEM "
         "(2 m posts, 0.3 m RMS height error correlated over 10 m, no sub-cell rocks; "
         "default and large). verify always simulates on the truth.")

dem_height_error_option = click.option(
    "--dem-height-error", "dem_height_error", metavar="RMS_M[,CORRELATION_M]",
    callback=_height_error,
    help="The planning DEM's height error: 1-sigma RMS and correlation length (default 10), "
         "metres, of a --dem FILE, or replacing --terrain orbital's.")


def require_truth_terrain(terrain: str, dem_path: Path | None) -> None:
    """Refuse ``--terrain orbital`` with ``--dem`` (one-line :class:`ConfigError`): the orbital
    DEM is a preset's, and ``--dem`` replaces the preset's terrain.

    >>> require_truth_terrain("truth", Path("a.tif"))
    """
    from markerplan.errors import ConfigError

    if terrain != "truth" and dem_path is not None:
        raise ConfigError(f"--terrain {terrain} is a site preset's planning DEM and --dem "
                          f"{dem_path} replaces the preset's terrain; drop --terrain (declare the "
                          "file's error with --dem-height-error)")


reproject_option = click.option(
    "--reproject", is_flag=True,
    help="Resample a --dem in a geographic CRS (degrees) or on non-square cells to a local "
         "metric CRS; --stations, --boundary, --exclude and --existing files are then in the "
         "DEM file's CRS.")


def require_dem(reproject: bool, dem_path: Path | None) -> None:
    """Refuse ``--reproject`` without ``--dem`` (one-line :class:`ConfigError`): it resamples
    the DEM file, and a site preset's terrain is already metric.

    >>> require_dem(False, None)
    """
    from markerplan.errors import ConfigError

    if reproject and dem_path is None:
        raise ConfigError("--reproject resamples the --dem FILE to a local metric CRS, and no "
                          "--dem was given (a site preset's terrain is metric already); add "
                          "--dem FILE or drop --reproject")


stations_option = click.option(
    "--stations", "stations_path", type=FILE,
    help="Stations CSV (id,x_m,y_m[,z_m][,heading_deg]; z_m the LiDAR centre) or GeoJSON "
         "Points with an id property (default: the preset's).")

station_ids_option = click.option(
    "--station-ids", callback=id_list, metavar="S1,S3",
    help="Work on these stations only, comma-separated ids (default: all).")


def marker_radius_option(required: bool = False, default_help: str = "",
                         default: float | None = None):
    """``--marker-radius-m M`` (old spelling ``--marker-radius``): the marker (sphere) radius,
    metres. ``required``: the command gets ``None`` when neither spelling is given and refuses
    it with :func:`require_option` (click's own check would refuse the old spelling)."""
    settings = {"default": default, "show_default": True} if default is not None else {}
    return renamed_option(
        "--marker-radius-m", "marker_radius_m", "--marker-radius", type=SPHERE_RADIUS_M,
        **settings, help="Marker (sphere) radius, metres (a 0.20 m sphere has 0.1)."
        + default_help + ("  [required]" if required else ""))


def require_option(value, flag: str) -> None:
    """Refuse a missing required option as click does (exit 2), for one with an old spelling.

    >>> require_option(0.1, "--marker-radius-m")
    """
    if value is None:
        raise click.UsageError(f"Missing option '{flag}'.")


error_model_option = click.option(
    "--error-model", "error_model", type=FILE, callback=_load_error_model,
    help="Error-model JSON from fit-error-model (default: the shipped model).")


def estimator_option(default: str | None = METHODS[0], help_text: str = "Sphere-centre "
                     "estimator: the ASTM E3125-17 line-of-sight fixed-radius fit, or the "
                     "published hemisphere ICP."):
    """``--estimator NAME``: a sphere-centre estimator of
    :data:`pipeline.sphere_centres.sphere_fit.METHODS`."""
    return click.option("--estimator", type=click.Choice(METHODS), default=default,
                        show_default=default is not None, help=help_text)


config_option = click.option(
    "--config", "config_path", type=FILE,
    help="TOML file of plan settings (requirement_m, n_sectors, ...).")

boundary_option = click.option(
    "--boundary", "boundary_path", type=FILE,
    help="GeoJSON polygon: where markers may go (default: the preset's, or the DEM).")

exclude_option = click.option(
    "--exclude", "exclude_paths", type=FILE, multiple=True,
    help="GeoJSON polygon(s) where no marker may go (repeatable).")


def _local_workers(ctx, param, workers: int | None) -> int | None:
    """Click callback: ``--workers``, refused beyond what this machine runs
    (:func:`planner.distributed.check_local_workers`, before any work)."""
    from planner.distributed import check_local_workers

    return None if workers is None else check_local_workers(workers)


def scheduler_options(f):
    """``--scheduler ADDRESS`` and ``--workers N``: where a command's independent tasks run
    (:func:`planner.distributed.executor`); the command receives ``scheduler`` and ``workers``.
    ``--workers`` is bounded by the machine: the cores this process may use and its open-file
    limit (:func:`planner.distributed.local_worker_limit`)."""
    f = click.option(
        "--workers", type=click.IntRange(min=1), default=None, metavar="N",
        callback=_local_workers,
        help="Worker processes of the local cluster: at most one per core this process may "
             "use (the default); for more, a bigger cluster with --scheduler ADDRESS.")(f)
    return click.option(
        "--scheduler", default="local", show_default=True, metavar="ADDRESS",
        help="Where the tasks run: local (a dask LocalCluster on this machine), none (in this "
             "process), or a running dask scheduler such as tcp://host:8786 (see "
             "docs/distributed.md); the files are the same.")(f)


def with_options(config, **overrides):
    """``config.replace(**overrides)`` with the command-line values (``None``: not given, left
    out); a value the configuration refuses is a one-line error that names the command line.

    >>> from planner.config import PlanConfig
    >>> with_options(PlanConfig(), budget=None, time_limit_s=5.0).time_limit_s
    5.0
    """
    from markerplan.errors import ConfigError

    try:
        return config.replace(**{k: v for k, v in overrides.items() if v is not None})
    except ConfigError as exc:
        raise ConfigError(f"{exc} (from the command-line options)") from exc


#: ``--time-limit-s S`` (old spelling ``--time-limit``): the solver time limit, seconds.
time_limit_option = renamed_option(
    "--time-limit-s", "time_limit_s", "--time-limit", type=TIME_LIMIT_S,
    help="Solver time limit for the whole run, seconds (default 60).")


def mounting_offset_options(command):
    """Add ``--vertical-axis-error-deg``, ``--lframe-tilt-deg`` and ``--axis-offset-mm`` to a
    command, which receives them as one ``offsets`` argument (:class:`MountingOffsets`, SI).

    They are the rig's mounting offsets: the true ones of the rig that ``simulate``, ``verify``
    and ``reduce --verify`` simulate (the pipeline self-calibrates them), and the known or
    starting ones of the rig whose scans ``process`` reads.
    """
    @functools.wraps(command)
    def with_offsets(*args, vertical_axis_error_deg, lframe_tilt_deg, axis_offset_mm, **kwargs):
        dx, dy = axis_offset_mm
        offsets = MountingOffsets(math.radians(vertical_axis_error_deg),
                                  math.radians(lframe_tilt_deg), (dx / 1e3, dy / 1e3))
        return command(*args, offsets=offsets, **kwargs)

    for option in reversed([
        click.option("--vertical-axis-error-deg", type=FiniteRange(-10.0, 10.0),
                     default=0.0, show_default=True,
                     help="Mounting offset: vertical-axis error (rotation about the spin "
                          "axis), degrees."),
        click.option("--lframe-tilt-deg", type=FiniteRange(-10.0, 10.0), default=0.0,
                     show_default=True, help="Mounting offset: L-frame tilt, degrees."),
        point_option("--axis-offset-mm", "0,0", "DX,DY",
                     "Mounting offset: horizontal offset of the LiDAR centre from the "
                     "turntable axis, mm.", limit=AXIS_OFFSET_MM),
    ]):
        with_offsets = option(with_offsets)
    return with_offsets
