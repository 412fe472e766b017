"""No library error message names a command-line flag: the library names its arguments and
configuration fields (`` `time_limit_s` ``), and the CLI spells them as its flags
(:func:`planner.cli.user_message`)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from planner.cli import command_line_names, user_message

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ("markerplan", "pipeline", "planner", "error_model", "visibility")
FLAG = re.compile(r"--[a-z]")


def _raised_strings(path: Path):
    """(line, text) of every string inside a ``raise`` statement of ``path``: its constants and
    the module-level string constants it names."""
    tree = ast.parse(path.read_text(), str(path))
    constants = {target.id: node.value.value for node in tree.body
                 if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)
                 and isinstance(node.value.value, str)
                 for target in node.targets if isinstance(target, ast.Name)}
    for node in ast.walk(tree):
        if isinstance(node, ast.Raise) and node.exc is not None:
            for part in ast.walk(node.exc):
                if isinstance(part, ast.Constant) and isinstance(part.value, str):
                    yield node.lineno, part.value
                elif isinstance(part, ast.Name) and part.id in constants:
                    yield node.lineno, constants[part.id]


def test_no_library_error_names_a_flag():
    found = [f"{path.relative_to(ROOT)}:{line}: {text!r}"
             for package in LIBRARY for path in sorted((ROOT / package).rglob("*.py"))
             if (ROOT / "planner" / "cli") not in path.parents
             for line, text in _raised_strings(path) if FLAG.search(text)]
    assert not found, "library errors naming CLI flags:\n" + "\n".join(found)


@pytest.mark.parametrize(("argv", "message", "shown"), [
    (["plan", "--time-limit-s", "5"], "raise `time_limit_s`", "raise --time-limit-s"),
    (["plan", "--time-limit", "5"], "raise `time_limit_s`", "raise --time-limit-s"),
    (["plan", "--config", "c.toml"], "raise `time_limit_s`", "raise `time_limit_s`"),
    (["verify", "p.json"], "`reference_station` 'S9' is not", "`reference_station` 'S9' is not"),
    (["verify", "p.json", "--reference-station=S9"], "`reference_station` 'S9' is not",
     "--reference-station 'S9' is not"),
    (["verify", "p.json"], "`plan_path` p.json: bad", "PLAN p.json: bad"),
    (["adjust", "t.csv"], "`plan_path` p.json: bad", "--plan p.json: bad"),
    (["process", "s"], "skip it (`calibrate=False`: known)", "skip it (--no-calibrate: known)"),
    (["plan"], "`max_range_m` must be > 0", "`max_range_m` must be > 0"),
    (["--version"], "`out` o", "`out` o"),
])
def test_the_cli_spells_arguments_as_flags(argv, message, shown):
    assert user_message(message, command_line_names(argv)) == shown
