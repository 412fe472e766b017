"""Every CSV a command writes opens with pandas' default settings: the header is the first line
(no ``# ...`` comment line before it), so ``pandas.read_csv(path)`` gets the real column names
and one row per record. The ``.csvt`` sidecars of the coordinate tables give one type per
column, and older plan tables (with the comment line) still read."""

from __future__ import annotations

import csv
import json

import pandas as pd
import pytest

from markerplan.reading import read_csv
from tests.cli.invoke import run_cli
from tests.cli.network_inputs import write_network_inputs
from tests.cli.test_reproducible import one_station_plan, synthetic_tables

COMMANDS = {
    "plan": lambda inputs, cwd: ["plan"],
    "plan-network": lambda inputs, cwd: ["plan", "--network", "--station-ids", "S1,S2,S3"],
    "reduce": lambda inputs, cwd: ["reduce", "as-built", "--k-min", "8"],
    "reduce-network": lambda inputs, cwd: ["reduce", "as-built", "--network", "--station-ids",
                                           "S1,S2", "--reference-station", "S2", "--k-min",
                                           "10"],
    "adjust": lambda inputs, cwd: ["adjust", *map(str, (net := write_network_inputs(
        cwd / "net", n_stations=4, seed=3)).tables), "--plan", str(net.plan)],
    "process": lambda inputs, cwd: ["process", f"{inputs}/scan/station_S1.scan.npz",
                                    "--reference", f"{inputs}/scan"],
    "range-study": lambda inputs, cwd: ["range-study", "--frames", "30", "--replicates", "1",
                                        "--max-distance-m", "6"],
    "fit-error-model": lambda inputs, cwd: ["fit-error-model", synthetic_tables(inputs, cwd),
                                            "--bootstrap", "3"],
    "verify": lambda inputs, cwd: ["verify", one_station_plan(inputs, cwd), "--seed", "2"],
    "simulate": lambda inputs, cwd: ["simulate", "--frames", "6", "--station-ids", "S1",
                                     "--seed", "5"],
}
#: Commands that must write at least these CSVs (others may write none).
EXPECTED = {"plan": {"markers.csv"}, "plan-network": {"markers.csv", "stations.csv"},
            "reduce": {"tradeoff.csv", "per_station.csv", "drop_order.csv", "marker_loss.csv"},
            "adjust": {"stations.csv", "markers.csv", "observations.csv", "parameters.csv"},
            "process": {"markers.csv", "stations.csv", "edges.csv"},
            "range-study": {"markers.csv", "summary.csv"}}


def check_defaults(path) -> pd.DataFrame:
    """Read ``path`` with pandas' defaults; its columns must be the header of the first line
    and its rows the file's records."""
    records = [r for r in csv.reader(path.read_text().splitlines()) if r]
    frame = pd.read_csv(path)
    columns = [str(c) for c in frame.columns]
    assert columns == records[0], path
    assert not [c for c in columns if c.startswith(("#", "Unnamed"))], path
    assert len(frame) == len(records) - 1, path
    csvt = path.with_suffix(".csvt")
    if csvt.exists():
        types = next(csv.reader([csvt.read_text()]))
        assert len(types) == len(columns) and set(types) <= {"Integer", "Real", "String"}, csvt
        assert csvt.read_text().startswith('"')
    return frame


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_csv_opens_with_default_settings(command, valid_inputs, tmp_path, capsys,
                                               monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = COMMANDS[command](valid_inputs, tmp_path)
    code, _, err = run_cli(capsys, args + ["--out", "out"])
    assert code in (0, 1) and "Traceback" not in err, err  # verify exits 1 on a failed check
    out = tmp_path / "out"
    written = sorted(out.rglob("*.csv"))
    assert EXPECTED.get(command, set()) <= {p.name for p in written}
    frames = {p.name: check_defaults(p) for p in written}
    if command.startswith("plan"):
        doc = json.loads((out / "plan.json").read_text())
        assert list(frames["markers.csv"]["id"]) == [m["id"] for m in doc["markers"]]
        assert (out / "markers.csvt").exists() and not (out / "markers.prj").exists()
    if command == "plan-network":
        stations = frames["stations.csv"]
        assert len(stations) == 3 and set(stations["error_relative_to"]) == {"station S1"}
    if command == "adjust":
        assert {"stations.csvt", "markers.csvt"} <= {p.name for p in out.iterdir()}


def test_old_plan_tables_with_a_comment_line_still_read(tmp_path):
    new = "id,x_m,y_m,z_m,existing,n_stations,stations\nC1,1.000,2.000,3.000,0,2,S1 S2\n"
    old = tmp_path / "old.csv"
    old.write_text('"# markerplan plan markers; site frame: local metres (x, y horizontal, z '
                   'up); not geographic coordinates, not WGS84"\n' + new)
    (tmp_path / "new.csv").write_text(new)
    assert read_csv(old, "old") == read_csv(tmp_path / "new.csv", "new")
    assert read_csv(old, "old")[0][0] == "id"
