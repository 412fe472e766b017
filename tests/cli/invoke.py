"""Call ``markerplan`` in-process the way a shell would, for the CLI tests."""

from planner.cli import main


def run_cli(capsys, args):
    """Run ``markerplan ARGS`` and return ``(exit_code, stdout, stderr)``.

    ``main`` exits only on errors; a normal return counts as exit code 0.
    """
    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err
