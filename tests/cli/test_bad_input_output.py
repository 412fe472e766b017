"""Every command refuses an unsafe ``--out`` before any work, and changes nothing.

The cases are the data-safety rules of :mod:`markerplan.output_folder`: never the current
folder, one of its ancestors, ``/``, a home folder or a folder holding an input; replace only
what markerplan wrote; a folder where no file can be made (a pseudo-file system such as
``/proc``, where even root cannot create the lock) is one line naming it.
"""

import os

import pytest

from tests.cli.bad_input import Case, check_refused

# the smallest valid command line of every command that writes --out
COMMANDS = {
    "simulate": ["simulate", "--frames", "4", "--station-ids", "S1"],
    "process": ["process", "{inputs}/scan/station_S1.scan.npz"],
    "range-study": ["range-study", "--frames", "4", "--replicates", "1"],
    "fit-error-model": ["fit-error-model", "{inputs}/markers.csv"],
    "plan": ["plan"],
    "verify": ["verify", "{inputs}/plan/plan.json"],
    "reduce": ["reduce", "as-built"],
}


def _link_to_cwd(cwd, inputs):
    os.symlink(cwd, cwd / "here")


def _link_to_parent(cwd, inputs):
    os.symlink(cwd.parent, cwd / "up")


def _cases_for(name, base):
    return [
        Case(f"{name}-out-dot", base + ["--out", ".", "--overwrite"], "is the current folder"),
        Case(f"{name}-out-parent", base + ["--out", "..", "--overwrite"],
             "holds the current folder"),
        Case(f"{name}-out-root", base + ["--out", "/", "--overwrite"], "file-system root"),
        Case(f"{name}-out-home", base + ["--out", "~", "--overwrite"], "home folder"),
        Case(f"{name}-out-symlink-to-cwd", base + ["--out", "here", "--overwrite"],
             "is the current folder", setup=_link_to_cwd),
        Case(f"{name}-out-symlink-to-parent", base + ["--out", "up/x/..", "--overwrite"],
             "current folder", setup=_link_to_parent),
        Case(f"{name}-foreign-folder-with-overwrite", base + ["--out", "mine", "--overwrite"],
             "markerplan did not write it", files={"mine/notes.txt": "my notes"}),
        Case(f"{name}-foreign-folder", base + ["--out", "mine"], "--overwrite",
             files={"mine/notes.txt": "my notes"}),
        Case(f"{name}-out-is-a-file", base + ["--out", "file.txt"], "is a file", code=2,
             files={"file.txt": "x"}),
        Case(f"{name}-forged-provenance", base + ["--out", "mine", "--overwrite"],
             "not one markerplan wrote",
             files={"mine/provenance.json": "[]", "mine/data.csv": "a\n"}),
        Case(f"{name}-unlisted-file", base + ["--out", "mine", "--overwrite"],
             "data.csv was not written by markerplan",
             files={"mine/provenance.json": '{"written_by": "markerplan", "files": {}}',
                    "mine/data.csv": "a\n"}),
        Case(f"{name}-out-in-procfs", base + ["--out", "/proc/markerplan-out"],
             "--out /proc/markerplan-out"),
    ]


def _input_folder_cases():
    return [
        Case("process-out-holds-the-scan", COMMANDS["process"] + ["--out", "{inputs}/scan",
                                                                  "--overwrite"],
             "holds the input"),
        Case("process-out-is-the-reference", COMMANDS["process"] + [
            "--reference", "{inputs}/scan", "--out", "{inputs}/scan", "--overwrite"],
             "holds the input"),
        Case("fit-error-model-out-holds-the-table", COMMANDS["fit-error-model"] + [
            "--out", "{inputs}", "--overwrite"], "holds the input"),
        Case("verify-out-holds-the-plan", COMMANDS["verify"] + ["--out", "{inputs}/plan",
                                                                "--overwrite"],
             "holds the input"),
        Case("reduce-out-holds-the-plan", ["reduce", "{inputs}/plan/plan.json", "--out",
                                           "{inputs}/plan", "--overwrite"], "holds the input"),
        Case("plan-out-holds-the-config", ["plan", "--config", "in/plan.toml", "--out", "in",
                                           "--overwrite"], "holds the input",
             files={"in/plan.toml": "requirement_m = 0.1\n"}),
        Case("simulate-out-holds-the-dem", ["simulate", "--dem", "in/dem.npz", "--out", "in",
                                            "--overwrite"], "holds the input",
             files={"in/dem.npz": b"not read"}),
        Case("plan-out-in-sysfs", ["plan", "--out", "/sys/markerplan-out"],
             "--out /sys/markerplan-out"),
    ]


CASES = [c for name, base in COMMANDS.items() for c in _cases_for(name, base)]
CASES += _input_folder_cases()


@pytest.mark.parametrize("case", CASES, ids=str)
def test_unsafe_out_is_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    work = tmp_path / "work"  # so that '..' is a folder of this test, not pytest's base
    work.mkdir()
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    (tmp_path / "home").mkdir()
    check_refused(case, capsys, monkeypatch, work, valid_inputs)
