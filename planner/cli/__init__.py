"""The ``markerplan`` command: one click group, one module per sub-command.

Sub-command modules are imported lazily so ``markerplan --help`` stays instant; each module
imports its heavy dependencies inside the command function. The options several commands share
are defined once: :mod:`planner.cli._common` (the vocabulary every command draws on),
:mod:`planner.cli._network_options` (network mode's datum, requirement kinds and pose aids) and
:mod:`planner.cli.verify_options` (options only ``verify --trials`` takes).
"""

from __future__ import annotations

import importlib
import re
import sys

import click

from markerplan import __version__
from markerplan.errors import MarkerPlanError
from markerplan.output_folder import Terminated

# name -> module under planner.cli that defines a click command called ``command``
COMMANDS: dict[str, str] = {
    "simulate": "simulate",
    "import-pcap": "import_pcap",
    "process": "process",
    "fit-sphere": "fit_sphere",
    "range-study": "range_study",
    "fit-error-model": "fit_error_model",
    "fit-detection-model": "fit_detection_model",
    "plan": "plan",
    "verify": "verify",
    "reduce": "reduce",
    "calibrate-sensor": "calibrate_sensor",
    "adjust": "adjust",
}


class LazyGroup(click.Group):
    """A click group whose sub-commands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        module_name = COMMANDS.get(cmd_name)
        if module_name is None:
            return None
        module = importlib.import_module(f"planner.cli.{module_name}")
        return module.command


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="markerplan")
def cli() -> None:
    """Plan where to put spherical markers for LiDAR surveys on lunar-like terrain.

    \b
    Typical flow (with a real rig, `markerplan import-pcap capture.pcap --turntable-log
    angles.csv --out scans/` makes the scans):
      markerplan simulate --site default --out scans/
      markerplan process scans/station_*.scan.npz --reference scans/ --out tables/
      markerplan fit-error-model tables/markers.csv --out model/ --plot
      markerplan plan --error-model model/model.json --out plan/
      markerplan verify plan/plan.json --out verify/
      markerplan adjust tables/markers.csv --plan plan/plan.json --out network/
    """


def command_line_names(argv: list[str]) -> dict[str, str]:
    """{parameter name: its spelling on the command line} of the sub-command ``argv`` runs:
    an option's flag (``time_limit_s`` -> ``--time-limit-s``; a ``--no-x`` flag also as
    ``x=False``), an argument's metavar (``plan_path`` -> ``PLAN``); empty without a known
    sub-command. An option that is also a field of the plan settings
    (:class:`~planner.config.PlanConfig`, e.g. ``reference_station``) is spelled as its flag
    only when ``argv`` gives the option (in either spelling): else the value is a ``--config``
    file's or a plan's, which name the field.

    >>> names = command_line_names(["plan", "--network", "--time-limit", "5"])
    >>> names["time_limit_s"], names["out"], "reference_station" in names
    ('--time-limit-s', '--out', False)
    """
    import dataclasses

    from planner.cli._common import DEPRECATED_SUFFIX
    from planner.config import PlanConfig

    name = next((a for a in argv if a in COMMANDS), None)
    if name is None:
        return {}
    command = importlib.import_module(f"planner.cli.{COMMANDS[name]}").command
    fields = {f.name for f in dataclasses.fields(PlanConfig)}
    given = {param.name.removesuffix(DEPRECATED_SUFFIX) for param in command.params
             if any(a == o or a.startswith(f"{o}=") for a in argv for o in param.opts)}
    names = {}
    for param in command.params:
        if isinstance(param, click.Option) and not param.hidden and (
                param.name not in fields or param.name in given):
            names[param.name] = param.opts[0]
            if param.is_flag and param.name.startswith("no_"):
                names[f"{param.name[3:]}=False"] = param.opts[0]
        elif isinstance(param, click.Argument):
            names[param.name] = param.human_readable_name
    return names


def user_message(message: str, names: dict[str, str]) -> str:
    """A library message for the command line: each backquoted name of a parameter of the
    command spelled as the user gives it (library messages name arguments and configuration
    fields, never flags), other names left as they are.

    >>> user_message("`out` o exists; pass `overwrite`; `gap` < 0", {"out": "--out",
    ...              "overwrite": "--overwrite"})
    '--out o exists; pass --overwrite; `gap` < 0'
    """
    return re.sub(r"`(\w+(?:=False)?)`", lambda m: names.get(m.group(1), m.group(0)), message)


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the CLI, turning our errors into one line and exit code 1
    (128 + the signal's number when SIGTERM or SIGHUP stopped it); :func:`user_message`
    spells the parameters a message names as the command line does."""
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        cli.main(args=args, prog_name="markerplan", standalone_mode=False)
    except Terminated as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(128 + exc.signum)
    except MarkerPlanError as exc:
        click.echo(f"error: {user_message(str(exc), command_line_names(args))}", err=True)
        sys.exit(1)
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
