"""Every notebook (jupytext percent-format ``.py``) runs as plain Python, in a temporary working
folder with the Agg backend, writes its figures outside the repository, and finishes within its
time budget (60 s each; ``MARKERPLAN_NB_BUDGET_S`` overrides it on a slow machine)."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("[0-9][0-9]_*.py"))
BUDGET_S = float(os.environ.get("MARKERPLAN_NB_BUDGET_S", "60"))


def test_all_six_notebooks_are_present():
    assert [p.stem for p in NOTEBOOKS] == [
        "01_terrain_and_sensor", "02_processing_a_station", "03_error_model", "04_planning",
        "05_marker_reduction", "06_network_mode"]


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs_within_budget(notebook, tmp_path):
    text = notebook.read_text()
    assert "# %% [markdown]" in text and "\n# %%\n" in text, "not jupytext percent format"
    figures = tmp_path / "figures"
    env = dict(os.environ, MPLBACKEND="Agg", MARKERPLAN_NB_OUT=str(figures))
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, str(notebook)], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=BUDGET_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{notebook.name} exceeded its {BUDGET_S:g} s budget")
    elapsed = time.perf_counter() - t0
    assert proc.returncode == 0, f"{notebook.name} failed:\n{proc.stderr[-3000:]}"
    pngs = sorted(p.name for p in figures.glob("*.png"))
    assert pngs and all(p.startswith(notebook.stem[:2]) for p in pngs), pngs
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figures"], "wrote into its cwd"
    print(f"{notebook.name}: {elapsed:.1f} s, figures {pngs}")
