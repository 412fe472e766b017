"""Network mode's part of the CLI's vocabulary (:mod:`planner.cli._common` holds the rest): the
options ``plan``, ``reduce``, ``verify`` and ``adjust`` share for the datum, the requirement kinds
and the pose aids, each defined here once with one help text.

==========================  =====================================================================
option                      meaning (and the value the command receives)
==========================  =====================================================================
``--network``               network mode: markers and stations estimated together, tied to
                            the datum (:mod:`planner.accuracy.network`)
``--reference-station ID``  the datum station of network mode (default the first station);
                            refused outside network mode (:func:`network_settings`)
``--datum station|free``    network mode's datum kind (``("station" | "free", ID or None)`` or
                            ``None``; ``station:ID`` is the old spelling of
                            ``--reference-station ID``; :func:`datum_choice`)
``--control FILE``          control points, network mode's datum (``plan``, ``reduce``,
                            ``adjust``)
``--error-figure NAME``     how a 95 % error is computed: ``quantile`` of the worst error over
                            the working disc, or the ``ellipsoid`` figure (default)
                            (:mod:`planner.accuracy.figure`; ``str``)
``--requirement-m`` ...     the requirement kinds and pose aids of ``plan`` and ``reduce``
                            (:func:`requirement_options`: one ``requirement`` dict)
==========================  =====================================================================
"""

from __future__ import annotations

import functools
from pathlib import Path

import click

from planner.cli._common import (
    FILE,
    LOCAL_WITHIN_M,
    REQUIREMENT_M,
    REQUIREMENT_PPM,
    FiniteRange,
    warn_deprecated,
    with_options,
)

network_option = click.option(
    "--network", is_flag=True, default=None,
    help="Network mode: markers are unknowns estimated with every station's pose, tied to "
         "the reference station (--reference-station, default the first); no total station "
         "needed.")

#: Odometry's 1-sigma per axis in percent of the distance driven (planner.config.BOUNDS).
ODOMETRY_PERCENT = FiniteRange(0.0, 100.0, min_open=True)

odometry_percent_option = click.option(
    "--odometry-percent", "odometry_percent", type=ODOMETRY_PERCENT,
    help="Odometry between consecutive stations: 1-sigma per axis of the relative position, "
         "percent of the distance driven (e.g. 2).")

reference_station_option = click.option(
    "--reference-station", "reference_station", metavar="ID",
    help="The datum station in network mode (its x, y, z and heading fixed; every error is "
         "relative to it); default the first station. Only with network mode.")


def _datum_text(ctx, param, text: str | None) -> tuple[str, str | None] | None:
    """``station``, ``station:ID`` or ``free`` -> (kind, reference station or ``None``)."""
    if text is None:
        return None
    kind, sep, sid = (t.strip() for t in text.partition(":"))
    if kind == "free" and not sep:
        return "free", None
    if kind != "station" or (sep and not sid):
        raise click.BadParameter(f"give station or free (the datum station: --reference-station "
                                 f"ID); for control points use --control FILE; got {text!r}",
                                 ctx, param)
    if sid:
        warn_deprecated(f"--datum station:{sid}", f"--reference-station {sid}")
    return "station", sid or None


#: ``--datum station|free``: network mode's datum (``plan``, ``adjust``).
datum_option = click.option(
    "--datum", "datum", metavar="station|free", callback=_datum_text,
    help="Network mode's datum: station fixes the reference station's x, y, z and heading "
         "(--reference-station; the default); free fixes nothing (a free network: minimal "
         "constraints on the stations' centroid, and mean heading without a heading aid), "
         "so its figures are datum-free and only relative ones (a local requirement) can be "
         "judged.")


def datum_choice(datum: tuple[str, str | None] | None, control_path: Path | None,
                  reference_station: str | None) -> tuple[str, str | None]:
    """The datum's kind (``"station"``, ``"control"`` or ``"free"``) and reference station
    (or ``None``) from ``--datum`` (its option's value), ``--control`` and
    ``--reference-station``; one-line :class:`ConfigError` for two datums."""
    from markerplan.errors import ConfigError

    if datum is not None and control_path is not None:
        raise ConfigError("give one datum, got --datum and --control: --datum station "
                          "(default; with --reference-station ID), --datum free, or --control "
                          "FILE")
    kind, named = ("control", None) if control_path is not None else datum or ("station", None)
    if reference_station is None:
        return kind, named
    if kind != "station":
        other = "--control" if kind == "control" else "--datum free"
        raise ConfigError(f"--reference-station {reference_station} names the datum station of "
                          f"the station datum; drop it with {other}, which fixes no station "
                          f"(drop --reference-station, or {other})")
    if named is not None and named != reference_station:
        raise ConfigError(f"--datum station:{named} and --reference-station "
                          f"{reference_station} name two datum stations; give one")
    return kind, reference_station


def require_network(reference_station: str | None, network: bool) -> None:
    """Refuse ``--reference-station`` outside network mode (one-line :class:`ConfigError`).

    ``network`` is the resolved mode: ``--network``, ``network = true`` in ``--config``, or a
    plan made with ``plan --network``.
    """
    from markerplan.errors import ConfigError

    if reference_station is not None and not network:
        raise ConfigError(f"--reference-station {reference_station} names the datum of network "
                          "mode; add --network or drop --reference-station")


def network_settings(config, network: bool | None, reference_station: str | None):
    """``config`` (a :class:`~planner.config.PlanConfig`) with ``--network`` and
    ``--reference-station`` applied; :func:`require_network` refuses the datum outside
    network mode. Whether the station exists is checked where the stations are known
    (:func:`planner.accuracy.network.network_model`)."""
    config = with_options(config, network=True if network else None,
                          reference_station=reference_station)
    require_network(reference_station, config.network)
    return config


def error_figure_option(f):
    """``--error-figure quantile|ellipsoid`` (``None`` when not given: the config's or the
    plan's, else :data:`planner.config.DEFAULT_ERROR_FIGURE`)."""
    from planner.config import DEFAULT_ERROR_FIGURE, ERROR_FIGURES

    return click.option(
        "--error-figure", "error_figure", type=click.Choice(ERROR_FIGURES), default=None,
        help="How a 95 % error is computed: quantile = the 95 % quantile of the worst error over "
             "the working disc; ellipsoid = the semi-major axis of the 3-D 95 % error ellipsoid "
             f"at the worst point, usually the larger (default: the config's or the plan's, "
             f"else {DEFAULT_ERROR_FIGURE}).")(f)


#: ``--control FILE``: network mode's datum, control points (``plan``, ``adjust``).
control_option = click.option(
    "--control", "control_path", type=FILE,
    help="Network mode's datum: control points with known coordinates, e.g. a lander's "
         "fiducials, CSV id,x_m,y_m,z_m,sigma_m (site frame; sigma_m per coordinate); no "
         "station is fixed, and together they must fix position and heading.")


def requirement_options(command):
    """Add the requirement kinds and pose aids (``--requirement-m`` to ``--odometry-percent``)
    to a command, which receives them as one ``requirement`` dict by configuration name
    (:class:`planner.config.PlanConfig`; ``None``: not given), for
    :func:`~planner.cli._common.with_options`."""
    from planner.accuracy.aids import HEADING_AIDS
    from planner.config import LOCAL_KINDS

    names = ("requirement_m", "requirement_ppm", "local_requirement_m", "local_requirement_ppm",
             "local_within_m", "local_kind", "local_markers", "no_datum_requirement",
             "heading_aid", "odometry_percent")

    @functools.wraps(command)
    def with_requirement(*args, **kwargs):
        given = {name: kwargs.pop(name) for name in names}
        given["datum_requirement"] = False if given.pop("no_datum_requirement") else None
        return command(*args, requirement=given, **kwargs)

    for option in reversed([
        click.option("--requirement-m", "requirement_m", type=REQUIREMENT_M,
                     help="Required 95 % station error, m. Default: the config's "
                          "requirement_m (reduce: the plan's), else 0.1; in network mode the "
                          "constant part of the allowance (--requirement-ppm)."),
        click.option("--requirement-ppm", "requirement_ppm", type=REQUIREMENT_PPM,
                     help="Network mode: parts per million of each station's (and marker's) "
                          "horizontal distance from the datum added to --requirement-m, e.g. "
                          "--requirement-m 0.10 --requirement-ppm 200 (default 0: constant)."),
        click.option("--local-requirement-m", "local_requirement_m", type=REQUIREMENT_M,
                     help="Network mode: required 95 % relative error between every pair of "
                          "stations at most --local-within-m apart (local accuracy), m; "
                          "default none."),
        click.option("--local-requirement-ppm", "local_requirement_ppm", type=REQUIREMENT_PPM,
                     help="Parts per million of a pair's separation added to "
                          "--local-requirement-m (default 0)."),
        click.option("--local-within-m", "local_within_m", type=LOCAL_WITHIN_M,
                     help="Largest separation of a station pair the local requirement judges, "
                          "m (default 50)."),
        click.option("--local-kind", "local_kind", type=click.Choice(LOCAL_KINDS),
                     help="What the local requirement bounds: position (the relative position "
                          "of any points of the two working discs, default) or distance (their "
                          "edge length)."),
        click.option("--local-markers", "local_markers", is_flag=True, default=None,
                     help="Network mode: the local requirement also judges every pair of "
                          "selected markers at most --local-within-m apart (their relative "
                          "position, or distance, at 95 %)."),
        click.option("--no-datum-requirement", "no_datum_requirement", is_flag=True,
                     default=None,
                     help="Network mode: judge only the local requirement, nothing relative "
                          "to the datum."),
        click.option("--heading-aid", "heading_aid", type=click.Choice(sorted(HEADING_AIDS)),
                     help="Network mode: a heading reference on every station, by class "
                          "(random and boresight-bias sigma: sun-sensor 0.1 and 0.05 deg, "
                          "star-tracker 10 and 20 arcsec); the config's "
                          "heading_prior_sigma_deg and heading_bias_sigma_deg override them."),
        odometry_percent_option,
    ]):
        with_requirement = option(with_requirement)
    return with_requirement
