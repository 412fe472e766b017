"""The ``markerplan`` command: one click group, one module per sub-command.

Sub-command modules are imported lazily so ``markerplan --help`` stays instant; each module
imports its heavy dependencies inside the command function.
"""

from __future__ import annotations

import importlib
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


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the CLI, turning our errors into one line and exit code 1
    (128 + the signal's number when SIGTERM or SIGHUP stopped it)."""
    try:
        cli.main(args=argv, prog_name="markerplan", standalone_mode=False)
    except Terminated as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(128 + exc.signum)
    except MarkerPlanError as exc:
        click.echo(f"error: {exc}", err=True)
        sys.exit(1)
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        sys.exit(130)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
