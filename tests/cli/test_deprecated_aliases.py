"""Renamed options: each old spelling still works for one release as a hidden alias, prints one
deprecation line on stderr, and gives the command exactly what the new spelling gives."""

from __future__ import annotations

import hashlib
import importlib
import json

import click
import pytest

from planner.cli import COMMANDS
from tests.cli.invoke import run_cli
from tests.cli.network_inputs import write_network_inputs

#: (command, arguments the command needs, old spelling, new spelling, value)
RENAMED = [
    ("simulate", ["--out", "o"], "--marker-radius", "--marker-radius-m", "0.15"),
    ("simulate", ["--out", "o"], "--lidar-height", "--lidar-height-m", "0.8"),
    ("process", ["s.scan.npz", "--out", "o"], "--marker-radius", "--marker-radius-m", "0.05"),
    ("process", ["s.scan.npz", "--out", "o"], "--max-rms", "--max-rms-m", "0.01"),
    ("fit-sphere", ["p.xyz", "--marker-radius-m", "0.1"], "--sensor", "--sensor-m", "0,0,5"),
    ("fit-sphere", ["p.xyz"], "--marker-radius", "--marker-radius-m", "0.1"),
    ("range-study", ["--out", "o"], "--max-distance", "--max-distance-m", "10"),
    ("range-study", ["--out", "o"], "--lidar-height", "--lidar-height-m", "0.8"),
    ("range-study", ["--out", "o"], "--marker-radius", "--marker-radius-m", "0.05"),
    ("fit-error-model", ["m.csv", "--out", "o"], "--seed", "--resample-seed", "3"),
    ("calibrate-sensor", ["--marker-table", "m.csv", "--out", "o"], "--reference-csv",
     "--reference", "ts.csv"),
    ("calibrate-sensor", ["s.json", "--out", "o"], "--marker-radius", "--marker-radius-m",
     "0.05"),
    ("plan", [], "--time-limit", "--time-limit-s", "5"),
    ("plan", [], "--stand-map-cell", "--stand-map-cell-m", "2"),
    ("plan", [], "--marker-radius", "--marker-radius-m", "0.15"),
    ("reduce", ["as-built"], "--time-limit", "--time-limit-s", "5"),
    ("reduce", ["as-built"], "--marker-radius", "--marker-radius-m", "0.15"),
    ("adjust", ["t.csv", "--out", "o"], "--working-radius", "--working-radius-m", "5"),
    ("adjust", ["t.csv", "--out", "o"], "--requirement", "--requirement-m", "0.2"),
]


def _params(capsys, name, args):
    """The parameters ``markerplan NAME ARGS`` hands its command, and its stderr."""
    command = importlib.import_module(f"planner.cli.{COMMANDS[name]}").command
    with command.make_context(name, list(args)) as ctx:
        params = dict(ctx.params)
    return params, capsys.readouterr().err


@pytest.mark.parametrize(("name", "args", "old", "new", "value"), RENAMED,
                         ids=[f"{c}{o}" for c, _, o, _, _ in RENAMED])
def test_old_spelling_gives_the_new_ones_value(capsys, name, args, old, new, value):
    new_params, new_err = _params(capsys, name, [*args, new, value])
    old_params, old_err = _params(capsys, name, [*args, old, value])
    assert old_params == new_params
    assert old_err == f"warning: {old} is deprecated; use {new}\n"
    assert new_err == ""


@pytest.mark.parametrize(("name", "args", "old", "new", "value"), RENAMED[:1])
def test_the_later_spelling_wins(capsys, name, args, old, new, value):
    params, _ = _params(capsys, name, [*args, old, value, new, "0.2"])
    assert params["marker_radius_m"] == 0.2


def test_every_hidden_option_is_a_deprecated_spelling():
    renamed = {(c, o) for c, _, o, _, _ in RENAMED}
    hidden = set()
    for name, module in COMMANDS.items():
        command = importlib.import_module(f"planner.cli.{module}").command
        visible = {o for p in command.params if not getattr(p, "hidden", False) for o in p.opts}
        for param in command.params:
            if isinstance(param, click.Option) and param.hidden:
                hidden |= {(name, o) for o in param.opts}
                assert not set(param.opts) & visible
    assert hidden == renamed


def test_fit_sphere_old_spellings_same_output(tmp_path, capsys):
    points = tmp_path / "p.xyz"
    points.write_text("1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n0.7 0.7 0.1\n")
    code, new_out, new_err = run_cli(capsys, ["fit-sphere", str(points), "--marker-radius-m",
                                              "1", "--sensor-m", "0,0,5", "--json"])
    assert code == 0 and new_err == "", new_err
    code, old_out, old_err = run_cli(capsys, ["fit-sphere", str(points), "--marker-radius", "1",
                                              "--sensor", "0,0,5", "--json"])
    assert code == 0 and old_out == new_out
    assert old_err.splitlines() == [
        "warning: --marker-radius is deprecated; use --marker-radius-m",
        "warning: --sensor is deprecated; use --sensor-m"]


def test_fit_sphere_still_requires_the_radius(tmp_path, capsys):
    code, _, err = run_cli(capsys, ["fit-sphere", str(tmp_path / "p.xyz")])
    assert code == 2 and "Missing option '--marker-radius-m'" in err


def _digests(folder):
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_adjust_datum_station_id_is_reference_station(tmp_path, capsys, monkeypatch):
    net = write_network_inputs(tmp_path / "net", n_stations=4, seed=5)
    monkeypatch.chdir(tmp_path)
    args = ["adjust", *map(str, net.tables), "--plan", str(net.plan), "--json"]
    code, new_out, new_err = run_cli(capsys, [*args, "--reference-station", "S02", "--out", "n"])
    assert code == 0 and new_err.count("warning") == 0, new_err
    code, old_out, old_err = run_cli(capsys, [*args, "--datum", "station:S02", "--out", "o"])
    assert code == 0, old_err
    assert "warning: --datum station:S02 is deprecated; use --reference-station S02\n" in old_err
    assert json.loads(old_out)["datum"] == json.loads(new_out)["datum"]
    assert json.loads((tmp_path / "n" / "adjustment.json").read_text())["datum"][
        "reference_station"] == "S02"
    new, old = _digests(tmp_path / "n"), _digests(tmp_path / "o")
    assert {k: v for k, v in new.items() if k != "provenance.json"} == \
        {k: v for k, v in old.items() if k != "provenance.json"}


@pytest.mark.parametrize(("extra", "needle"), [
    (["--datum", "free"], "drop it with --datum free"),
    (["--datum", "station:S01"], "name two datum stations"),
])
def test_adjust_reference_station_conflicts(tmp_path, capsys, extra, needle):
    code, _, err = run_cli(capsys, ["adjust", str(tmp_path / "t.csv"), "--reference-station",
                                    "S02", *extra, "--out", str(tmp_path / "o")])
    assert code == 1 and needle in err, err
