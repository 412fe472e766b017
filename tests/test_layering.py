"""The arrows point one way: what each top-level package may import of ours.

``markerplan`` imports nothing of ours; ``pipeline`` only ``markerplan``; ``error_model`` only
``markerplan`` and the marker- and fate-table schemas of ``pipeline``; ``visibility`` only
``markerplan`` and, of ``pipeline``, the scan format and the rig/noise contract; ``planner``
anything. Inside ``pipeline``, each package imports only those before it in
:data:`PIPELINE_ORDER` (the map of :mod:`pipeline`). Read from the sources' import statements
(including imports inside functions), so a lazy import cannot hide a back-arrow.
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
#: pipeline's packages (and its one top-level module), each importing only those before it.
PIPELINE_ORDER = ("kernels", "tables", "scans", "sphere_centres", "chain", "surveys", "network")


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


def pipeline_back_arrows(root: Path) -> list[str]:
    """Imports of a ``pipeline`` package, under ``root``, from one after it in the order."""
    out = []
    for f in sorted(root.rglob("*.py")):
        parts = f.relative_to(root).with_suffix("").parts
        if parts[0] == "__init__":
            continue
        rank = PIPELINE_ORDER.index(parts[0])
        for module in sorted(imported_modules(f.read_text())):
            names = module.split(".")
            if names[0] == "pipeline" and len(names) > 1 and (
                    names[1] not in PIPELINE_ORDER[:rank + 1]):
                out.append(f"{f.relative_to(root)} imports {module}")
    return out


def test_pipeline_packages_import_only_earlier_ones():
    assert pipeline_back_arrows(ROOT / "pipeline") == []


def test_a_pipeline_back_arrow_is_seen(tmp_path):
    (tmp_path / "scans").mkdir()
    (tmp_path / "scans" / "rig.py").write_text("def f():\n    from pipeline.chain import gate\n")
    (tmp_path / "chain").mkdir()
    (tmp_path / "chain" / "gate.py").write_text("from pipeline.scans.rig import f\n")
    assert pipeline_back_arrows(tmp_path) == ["scans/rig.py imports pipeline.chain"]


def test_a_back_arrow_is_seen():
    src = "def f():\n    from planner.run import make_plan\n    import pipeline.chain.process\n"
    assert imported_modules(src) == {"planner.run", "pipeline.chain.process"}
    assert not allowed("visibility", "pipeline.chain.process")
    assert allowed("visibility", "pipeline.scans.rig") and not allowed("pipeline", "planner.run")
