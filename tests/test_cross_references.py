"""Every cross-reference to our code in docstrings and docs names something that exists.

A ``:func:`` / ``:mod:`` / ``:class:`` / ``:data:`` / ``:meth:`` / ``:attr:`` / ``:exc:`` role
whose target starts with one of our packages must import (a module) or be found on what imports
(a function, class, constant, method, or a dataclass field), so that moving or renaming code
leaves no reference pointing at nothing.
"""

from __future__ import annotations

import dataclasses
import importlib
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("markerplan", "pipeline", "visibility", "error_model", "planner")
ROLE = re.compile(r":(?:func|mod|class|data|meth|attr|exc|obj):`~?((?:"
                  + "|".join(PACKAGES) + r")(?:\.\w+)*)`")
SOURCES = [ROOT / p for p in (*PACKAGES, "tests", "benchmarks", "notebooks", "scripts")]


def _found(name: str) -> bool:
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            if hasattr(obj, attr):
                obj = getattr(obj, attr)
            elif dataclasses.is_dataclass(obj) and attr in {f.name for f in
                                                            dataclasses.fields(obj)}:
                obj = None
            else:
                return False
        return True
    return False


def _references():
    files = [f for d in SOURCES for f in sorted(d.rglob("*.py"))]
    files += sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]
    for f in files:
        for n, line in enumerate(f.read_text().splitlines(), 1):
            for m in ROLE.finditer(line):
                yield f"{f.relative_to(ROOT)}:{n}", m.group(1)


def test_every_reference_resolves():
    stale = [f"{where}: {name}" for where, name in _references() if not _found(name)]
    assert not stale, "stale cross-references:\n" + "\n".join(stale)


def test_a_stale_reference_is_caught():
    assert _found("planner.run.make_plan") and _found("planner.problem")
    assert _found("visibility.terrain.TerrainSpec.keepout_xyr_m")  # a dataclass field
    assert not _found("planner.planning.make_plan")
    assert not _found("planner.run.no_such_function")
