"""Same inputs and seed give byte-identical output files, for every command that writes files.

Each command runs twice into two folders; the two folders must hold the same files with the
same SHA-256 (``provenance.json`` lists them, and is compared too).
"""

import hashlib

import pytest

from tests.cli.invoke import run_cli


def digests(folder):
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def one_station_plan(inputs, cwd):
    """A plan of the default site's first station only (keeps verify quick)."""
    from planner.cli import main

    lines = (inputs / "stations.csv").read_text().splitlines()
    (cwd / "one_station.csv").write_text("\n".join(lines[:2]) + "\n")
    main(["plan", "--stations", "one_station.csv", "--out", "plan-s1"])
    return "plan-s1/plan.json"


def synthetic_tables(inputs, cwd):
    from tests.error_model.synthetic import synthetic_table, write_csv

    write_csv(cwd / "table.csv", synthetic_table(400, seed=7))
    return "table.csv"


COMMANDS = {
    "simulate": lambda inputs, cwd: ["simulate", "--frames", "6", "--station-ids", "S1,S2",
                                     "--seed", "5"],
    "process": lambda inputs, cwd: ["process", f"{inputs}/scan/station_S1.scan.npz",
                                    "--reference", f"{inputs}/scan"],
    "range-study": lambda inputs, cwd: ["range-study", "--frames", "30", "--replicates", "1",
                                        "--max-distance-m", "6"],
    "fit-error-model": lambda inputs, cwd: ["fit-error-model", synthetic_tables(inputs, cwd),
                                            "--bootstrap", "3", "--plot"],
    "plan": lambda inputs, cwd: ["plan"],
    "verify": lambda inputs, cwd: ["verify", one_station_plan(inputs, cwd), "--seed", "2"],
    "reduce": lambda inputs, cwd: ["reduce", "as-built", "--k-min", "8"],
    "reduce-network": lambda inputs, cwd: ["reduce", "as-built", "--network", "--station-ids",
                                           "S1,S2", "--reference-station", "S2", "--k-min",
                                           "10"],
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_two_runs_give_byte_identical_files(command, valid_inputs, tmp_path, capsys,
                                            monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = COMMANDS[command](valid_inputs, tmp_path)
    for out in ("first", "second"):
        code, _, err = run_cli(capsys, args + ["--out", out])
        assert code in (0, 1) and "Traceback" not in err, err  # verify exits 1 on a failed check
    first, second = digests(tmp_path / "first"), digests(tmp_path / "second")
    assert "provenance.json" in first and len(first) > 1
    assert first == second
