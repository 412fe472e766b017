"""The bad-input harness: one table row per refused command line.

Every case asserts what a user is promised for bad input:

- exit code 1 (our error) or 2 (a usage error click reports);
- exactly one line on stderr carrying the error (``error: ...`` or click's ``Error: ...``),
  naming the problem (``needle``, matched case-insensitively), and no traceback;
- nothing written or changed: the working folder (where the case's files live and where
  ``--out`` points) and the shared valid inputs are byte-identical before and after.

Cases run with the working folder set to a fresh temporary folder. In ``args`` and in file
contents, ``{inputs}`` stands for the folder of valid inputs (:func:`valid_inputs`): a small
scan and its truth, a reference CSV, a marker table, the shipped error model and a plan.json.
"""

from __future__ import annotations

import hashlib
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tests.cli.invoke import run_cli


@dataclass(frozen=True)
class Case:
    """One refused command line.

    Parameters
    ----------
    name : str
        Test id.
    args : list of str
        ``markerplan`` arguments; ``{inputs}`` is replaced by the valid-inputs folder.
    needle : str
        Text the error line must contain (case-insensitive).
    code : int
        Expected exit code: 1 for our errors, 2 for click usage errors.
    files : dict
        Files to create in the working folder first: relative path -> ``str`` (written as
        UTF-8 after ``{inputs}`` substitution) or ``bytes`` (written as is).
    setup : callable, optional
        ``setup(cwd, inputs)`` for anything ``files`` cannot express (copying a valid file
        and corrupting it, making a folder...).
    """

    name: str
    args: list[str]
    needle: str
    code: int = 1
    files: dict[str, str | bytes] = field(default_factory=dict)
    setup: Callable[[Path, Path], None] | None = None

    def __str__(self) -> str:
        return self.name


def tree_state(root: Path) -> dict[str, str]:
    """Every path under ``root`` (hidden ones too) -> sha256 of a file, ``"dir"`` of a folder."""
    state = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        if p.is_symlink():
            state[rel] = f"link:{p.readlink()}"
        elif p.is_dir():
            state[rel] = "dir"
        else:
            state[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return state


def prepare(case: Case, cwd: Path, inputs: Path) -> list[str]:
    """Create the case's files in ``cwd`` and return its arguments with ``{inputs}`` filled."""
    for rel, content in case.files.items():
        path = cwd / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content.replace("{inputs}", str(inputs)), encoding="utf-8")
    if case.setup is not None:
        case.setup(cwd, inputs)
    return [a.replace("{inputs}", str(inputs)) for a in case.args]


def check_refused(case: Case, capsys, monkeypatch, cwd: Path, inputs: Path) -> None:
    """Run ``case`` in ``cwd`` and assert the promises listed in the module docstring."""
    args = prepare(case, cwd, inputs)
    before, inputs_before = tree_state(cwd), tree_state(inputs)
    monkeypatch.chdir(cwd)
    code, _, err = run_cli(capsys, args)
    assert "Traceback" not in err, err
    assert code == case.code, f"exit code {code}, expected {case.code}; stderr:\n{err}"
    lines = [ln for ln in err.splitlines() if ln.startswith(("error:", "Error:"))]
    assert len(lines) == 1, f"expected one error line, got:\n{err}"
    assert case.needle.lower() in lines[0].lower(), f"{case.needle!r} not in {lines[0]!r}"
    assert tree_state(cwd) == before, "the working folder changed"
    assert tree_state(inputs) == inputs_before, "an input was changed"


# --- the shared valid inputs -------------------------------------------------------------

STATION_MARKERS = np.array([[3.0, 1.0, -0.9], [-2.5, 2.0, -0.9], [0.5, -4.0, -0.9],
                            [-3.0, -2.5, -0.9]])


def write_synthetic_station(folder: Path, n_frames: int, azimuth_step_deg: float) -> None:
    """Write ``station_S1.scan.npz`` and ``station_S1.truth.json`` into ``folder``: a level,
    offset-free station seeing the four :data:`STATION_MARKERS` (0.10 m radius) out to 8 m."""
    from pipeline.scans.rig import MountingOffsets
    from pipeline.scans.scan_format import write_scan, write_truth
    from tests.pipeline.test_synthesis import synthetic_scan

    scan = synthetic_scan(MountingOffsets(), n_frames=n_frames, azimuth_step_deg=azimuth_step_deg,
                          spheres=[(c, 0.1) for c in STATION_MARKERS], noise_m=0.01,
                          max_range_m=8.0, seed=4)
    write_scan(folder / "station_S1.scan.npz", scan)
    write_truth(folder / "station_S1.truth.json", {
        "station_id": "S1", "mounting_offsets": MountingOffsets().to_dict(),
        "station_pose": {"position_m": [0, 0, 1], "heading_rad": 0.0},
        "marker_radius_m": 0.1,
        "markers": [{"id": f"M{k}", "centre_station_m": c.tolist()}
                    for k, c in enumerate(STATION_MARKERS)]})


def build_valid_inputs(root: Path) -> Path:
    """Write the valid inputs the cases corrupt or point at into ``root``; return ``root``.

    ``scan/station_S1.scan.npz`` + ``scan/station_S1.truth.json`` (a small synthetic station),
    ``reference.csv`` (its markers as total-station CSV), ``markers.csv`` (its marker table from
    ``markerplan process``), ``model.json`` (the shipped error model), ``plan/plan.json`` (the
    default plan) and ``stations.csv`` (the default site's stations).
    """
    from error_model.default import DEFAULT_MODEL_PATH
    from planner.cli import main

    scan_dir = root / "scan"
    scan_dir.mkdir(parents=True)
    write_synthetic_station(scan_dir, n_frames=120, azimuth_step_deg=0.8)
    (root / "reference.csv").write_text(
        "id,x_m,y_m,z_m\n" + "".join(f"M{k},{x},{y},{z}\n"
                                     for k, (x, y, z) in enumerate(STATION_MARKERS)))
    shutil.copy(DEFAULT_MODEL_PATH, root / "model.json")
    for args in (["process", str(scan_dir / "station_S1.scan.npz"), "--reference",
                  str(scan_dir), "--out", str(root / "tables")],
                 ["plan", "--out", str(root / "plan")]):
        try:
            main(args)
        except SystemExit as exc:  # pragma: no cover - a broken fixture must say so
            raise AssertionError(f"building valid inputs failed: markerplan {args}") from exc
    shutil.copy(root / "tables" / "markers.csv", root / "markers.csv")
    from visibility.sites import load_site

    site = load_site("default")
    (root / "stations.csv").write_text(
        "id,x_m,y_m\n" + "".join(f"{s},{x},{y}\n" for s, (x, y) in
                                 zip(site.station_ids, site.station_xy_m, strict=True)))
    return root
