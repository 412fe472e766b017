"""Bad marker tables and error-model domains are refused in one line naming the file, the row
or the field, exit 1, nothing written (:mod:`tests.cli.bad_input`).

The marker-table rules are the reader's (:mod:`pipeline.tables.marker_table`), so
``fit-error-model`` and ``adjust`` refuse alike: a row repeated exactly is one detection read twice,
and ``accepted`` is ``true`` or ``false``. An error model's domain must not be inverted; a command
that loads a model (``adjust --error-model``) refuses it before any work.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.cli.bad_input import Case, check_refused


def _table(edit: Callable[[list[str]], list[str]]) -> Callable[[Path, Path], None]:
    """Setup: the valid marker table's lines (header first), edited, written as ``bad.csv``."""

    def setup(cwd: Path, inputs: Path) -> None:
        lines = (inputs / "markers.csv").read_text().splitlines()
        (cwd / "bad.csv").write_text("\n".join(edit(lines)) + "\n")

    return setup


def _every_row_twice(lines: list[str]) -> list[str]:
    return lines + lines[1:]


def _accepted(value: str) -> Callable[[list[str]], list[str]]:
    """Edit: the first data row's ``accepted`` cell set to ``value``."""

    def edit(lines: list[str]) -> list[str]:
        header, first = lines[0].split(","), lines[1].split(",")
        first[header.index("accepted")] = value
        return [lines[0], ",".join(first), *lines[2:]]

    return edit


def _model(edit: Callable[[dict], None]) -> Callable[[Path, Path], None]:
    """Setup: the valid error model with ``edit`` applied to its ``domain``, as ``bad.json``."""

    def setup(cwd: Path, inputs: Path) -> None:
        doc = json.loads((inputs / "model.json").read_text())
        edit(doc["domain"])
        (cwd / "bad.json").write_text(json.dumps(doc))

    return setup


def _reversed(key: str) -> Callable[[dict], None]:
    return lambda domain: domain[key].reverse()


FIT = ["fit-error-model", "bad.csv", "--out", "out"]
ADJUST = ["adjust", "bad.csv", "--out", "out"]
ADJUST_MODEL = ["adjust", "{inputs}/markers.csv", "--error-model", "bad.json", "--out", "out"]

CASES = [
    *(Case(f"{name}-table-every-row-twice", args, "4 rows repeat an earlier row exactly",
           setup=_table(_every_row_twice)) for name, args in (("fit", FIT), ("adjust", ADJUST))),
    *(Case(f"{name}-table-accepted-{value}", args,
           f"column 'accepted' row 2 must be true/false, got '{value}'",
           setup=_table(_accepted(value)))
      for name, args in (("fit", FIT), ("adjust", ADJUST)) for value in ("yes", "no")),
    Case("fit-table-accepted-empty", FIT, "column 'accepted' row 2 must be true/false, got ''",
         setup=_table(_accepted(""))),
    Case("model-domain-distance-range-inverted", ADJUST_MODEL, "domain distance_range_m",
         setup=_model(_reversed("distance_range_m"))),
    Case("model-domain-elevation-deg-inverted", ADJUST_MODEL, "domain elevation_lo_deg",
         setup=_model(lambda d: d.update(elevation_lo_deg=d["elevation_hi_deg"],
                                         elevation_hi_deg=d["elevation_lo_deg"]))),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_table_or_model_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
