"""markerplan.output_folder: replace only what markerplan wrote; leave nothing half written."""

import errno
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from markerplan.errors import OutputError
from markerplan.output_folder import (
    PROVENANCE_FILE,
    Terminated,
    library_write,
    output_folder,
    remove_stale_stages,
)


def tree(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def write_result(out: Path, **kwargs) -> None:
    with output_folder(out, command="test", **kwargs) as stage:
        (stage / "a.txt").write_text("a\n")
        (stage / "sub").mkdir()
        (stage / "sub" / "b.txt").write_text("b\n")


def test_result_lands_with_its_provenance_and_nothing_else(tmp_path):
    write_result(tmp_path / "out", overwrite=False)
    assert tree(tmp_path) == ["out", "out/a.txt", "out/provenance.json", "out/sub",
                              "out/sub/b.txt"]
    record = json.loads((tmp_path / "out" / PROVENANCE_FILE).read_text())
    assert record["written_by"] == "markerplan" and record["command"] == "test"
    assert sorted(record["files"]) == ["a.txt", "sub/b.txt"]
    assert oct((tmp_path / "out").stat().st_mode & 0o777) == "0o755"


def test_overwrite_replaces_a_folder_markerplan_wrote(tmp_path):
    out = tmp_path / "out"
    write_result(out, overwrite=False)
    with pytest.raises(OutputError, match="`overwrite`"):
        write_result(out, overwrite=False)
    with output_folder(out, overwrite=True, command="test") as stage:
        (stage / "c.txt").write_text("c\n")
    assert tree(tmp_path) == ["out", "out/c.txt", "out/provenance.json"]


@pytest.mark.parametrize("tamper, reason", [
    (lambda out: (out / "notes.txt").write_text("mine"), "notes.txt was not written"),
    (lambda out: (out / "a.txt").write_text("edited"), "a.txt was changed"),
    (lambda out: (out / PROVENANCE_FILE).unlink(), "markerplan did not write it"),
])
def test_overwrite_never_deletes_what_markerplan_did_not_write(tmp_path, tamper, reason):
    out = tmp_path / "out"
    write_result(out, overwrite=False)
    tamper(out)
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    with pytest.raises(OutputError, match=reason):
        write_result(out, overwrite=True)
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert not any(n.startswith(".") for n in os.listdir(tmp_path))


def test_an_empty_existing_folder_is_used(tmp_path):
    (tmp_path / "out").mkdir()
    write_result(tmp_path / "out", overwrite=False)
    assert (tmp_path / "out" / "a.txt").is_file()


def test_a_second_run_on_the_same_out_is_refused_while_the_first_runs(tmp_path):
    out = tmp_path / "out"
    with output_folder(out, overwrite=False, command="test") as stage:
        with pytest.raises(OutputError, match="being written by another markerplan run"):
            write_result(out, overwrite=True)
        (stage / "first.txt").write_text("1\n")
    assert tree(tmp_path) == ["out", "out/first.txt", "out/provenance.json"]


def test_a_destination_that_appears_during_the_run_is_kept_with_the_result(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(OutputError, match="appeared while this run was working"):
        with output_folder(out, overwrite=False, command="test") as stage:
            (stage / "ours.txt").write_text("ours\n")
            out.mkdir()
            (out / "theirs.txt").write_text("theirs\n")
    assert (out / "theirs.txt").read_text() == "theirs\n"
    assert (tmp_path / "out-2" / "ours.txt").read_text() == "ours\n"
    assert not any(n.startswith(".") for n in os.listdir(tmp_path))


def test_an_error_removes_the_stage_and_the_parents_it_made(tmp_path):
    with pytest.raises(RuntimeError):
        with output_folder(tmp_path / "new" / "deeper" / "out", False, "test") as stage:
            (stage / "half.txt").write_text("half")
            raise RuntimeError("boom")
    assert tree(tmp_path) == []


def test_a_full_disk_is_one_output_error_and_leaves_nothing(tmp_path):
    shown = re.escape(f"writing failed ({tmp_path / 'out' / 'part.bin'}): No space left on device")
    with pytest.raises(OutputError, match=f"{shown}; nothing was written; free some space"):
        with output_folder(tmp_path / "out", False, "test") as stage:
            (stage / "part.bin").write_bytes(b"x" * 100)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(stage / "part.bin"))
    assert tree(tmp_path) == []


def test_a_library_failure_the_disk_does_not_explain_is_raised_unchanged(tmp_path):
    """The disk takes :func:`library_write`'s probe: the library's error is a bug, not the disk."""
    with pytest.raises(RuntimeError, match="no such layer") as info:
        with library_write(tmp_path / "x.gpkg"):
            raise RuntimeError("no such layer")
    assert type(info.value) is RuntimeError and os.listdir(tmp_path) == []


def test_sigterm_in_process_raises_terminated_and_cleans_up(tmp_path):
    with pytest.raises(Terminated) as info:
        with output_folder(tmp_path / "out", False, "test") as stage:
            (stage / "half.txt").write_text("half")
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)  # the handler raises before this ends
    assert info.value.signum == signal.SIGTERM
    assert tree(tmp_path) == []


def start_a_run_that_waits(tmp_path: Path) -> subprocess.Popen:
    """A real ``markerplan simulate --out out`` that waits (60 s) inside its stage, after
    writing 1 MB into it: returns once the stage exists."""
    script = textwrap.dedent(f"""
        import sys, time
        from pathlib import Path
        from planner.cli import main
        import markerplan.output_folder as of
        real = of.write_provenance
        def slow(folder, command):
            (Path(folder) / "big.bin").write_bytes(b"x" * 1_000_000)
            print("writing", flush=True)
            time.sleep(60)
        of.write_provenance = slow
        main(["simulate", "--frames", "4", "--station-ids", "S1",
              "--out", {str(tmp_path / "out")!r}])
    """)
    # a shell without job control starts background jobs with SIGINT ignored, and Python keeps
    # an inherited SIG_IGN: give the child the default disposition a terminal user's has
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert proc.stdout.readline().strip() == "writing"
    return proc


def stages(folder: Path) -> list[str]:
    return sorted(n for n in os.listdir(folder) if n.startswith(".out.partial-"))


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_a_signal_to_a_running_command_leaves_nothing(tmp_path, signum):
    """A real process, killed while it writes into its stage."""
    proc = start_a_run_that_waits(tmp_path)
    assert len(stages(tmp_path)) == 1
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == (130 if signum == signal.SIGINT else 128 + signum), err
    assert "Traceback" not in err
    assert os.listdir(tmp_path) == []


def test_the_next_run_removes_the_stage_a_sigkill_left(tmp_path):
    """SIGKILL runs no cleanup: the stage (and the lock file) stay until the next run on the
    same ``--out``, which removes them and writes its result as usual."""
    proc = start_a_run_that_waits(tmp_path)
    proc.kill()
    proc.communicate(timeout=60)
    assert len(stages(tmp_path)) == 1 and (tmp_path / ".out.lock").exists()
    write_result(tmp_path / "out", overwrite=False)
    assert tree(tmp_path) == ["out", "out/a.txt", "out/provenance.json", "out/sub",
                              "out/sub/b.txt"]


def test_the_stage_of_a_live_run_is_left_alone(tmp_path):
    """Its stage lock is held: neither a second run nor the stale-stage sweep touches it."""
    proc = start_a_run_that_waits(tmp_path)
    try:
        stage = tmp_path / stages(tmp_path)[0]
        before = tree(stage)
        assert remove_stale_stages(tmp_path / "out") == []
        with pytest.raises(OutputError, match="being written by another markerplan run"):
            write_result(tmp_path / "out", overwrite=True)
        assert tree(stage) == before and (stage / "big.bin").stat().st_size == 1_000_000
    finally:
        proc.kill()
        proc.communicate(timeout=60)
    assert remove_stale_stages(tmp_path / "out") == [stage]
    assert stages(tmp_path) == []


@pytest.mark.parametrize("content", [
    {"notes.txt": "mine"},
    {".markerplan-stage": '{"written_by": "someone else"}'},
    {},
], ids=["no-marker", "foreign-marker", "empty"])
def test_a_look_alike_stage_markerplan_did_not_make_is_left_alone(tmp_path, content):
    look_alike = tmp_path / ".out.partial-abcd1234"
    look_alike.mkdir()
    for name, text in content.items():
        (look_alike / name).write_text(text)
    write_result(tmp_path / "out", overwrite=False)
    assert sorted(os.listdir(tmp_path)) == [".out.partial-abcd1234", "out"]
    assert {p.name: p.read_text() for p in look_alike.iterdir()} == content
