"""The arrows point one way: what each top-level package may import of ours.

``markerplan`` imports nothing of ours; ``pipeline`` only ``markerplan``; ``error_model`` only
``markerplan`` and the marker- and fate-table schemas of ``pipeline``; ``visibility`` only
``markerplan`` and, of ``pipeline``, the scan format and the rig/noise contract; ``planner``
anything. Read from the sources' import statements (including imports inside functions), so a
lazy import cannot hide a back-arrow.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
OURS = ("markerplan", "pipeline", "error_model", "visibility", "planner")
#: package -> the modules of ours it may import (a package name allows all of it).
ALLOWED = {
    "markerplan": {"markerplan"},
    "pipeline": {"markerplan", "pipeline"},
    "error_model": {"markerplan", "error_model", "pipeline.tables"},
    "visibility": {"markerplan", "visibility", "pipeline.scans.scan_format", "pipeline.scans.rig",
                   "pipeline.scans.sensor_noise"},
    "planner": set(OURS),
}


def imported_modules(source: str) -> set[str]:
    """Dotted names of every module of ours that ``source`` imports, at any depth."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return {n for n in names if n.split(".")[0] in OURS}


def allowed(package: str, module: str) -> bool:
    return any(module == a or module.startswith(a + ".") for a in ALLOWED[package])


def back_arrows(package: str) -> list[str]:
    out = []
    for f in sorted((ROOT / package).rglob("*.py")):
        for module in sorted(imported_modules(f.read_text())):
            if not allowed(package, module):
                out.append(f"{f.relative_to(ROOT)} imports {module}")
    return out


@pytest.mark.parametrize("package", [p for p in OURS if p != "planner"])
def test_no_back_arrows(package):
    assert back_arrows(package) == []


def test_a_back_arrow_is_seen():
    src = "def f():\n    from planner.run import make_plan\n    import pipeline.chain.process\n"
    assert imported_modules(src) == {"planner.run", "pipeline.chain.process"}
    assert not allowed("visibility", "pipeline.chain.process")
    assert allowed("visibility", "pipeline.scans.rig") and not allowed("pipeline", "planner.run")
