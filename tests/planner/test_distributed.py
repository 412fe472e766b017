"""Distributed execution (planner.distributed): a LocalCluster of two worker processes, and a
scheduler and two workers started by hand as docs/distributed.md says, give the in-process
results; a failing task is retried, and one that keeps failing is reported."""

import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from markerplan.errors import ConfigError, DataError
from pipeline.tables.marker_table import read_marker_table
from planner import distributed
from planner.distributed import Executor, TaskError, executor
from tests.cli.invoke import run_cli


def _scaled(shared, x):
    """A task with a shared input: ``shared * x`` and the worker's pid."""
    return shared * x, os.getpid()


def _fails_once(flag: str):
    """Raises the first time (``flag`` is created then), succeeds afterwards, in any process."""
    if not Path(flag).exists():
        Path(flag).write_text("tried")
        raise RuntimeError("transient failure")
    return "ok"


def _always_fails(x):
    raise DataError(f"the tile of {x} misses the DEM\nsecond line")


@pytest.fixture
def two_cores(monkeypatch):
    """At least two cores for ``--workers 2`` (the bound is one worker per core), whatever
    the machine running the tests has."""
    cores = distributed.available_cores()
    monkeypatch.setattr(distributed, "available_cores", lambda: max(2, cores))


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of two worker processes, one thread each (as ``--workers 2``)."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=40) as lc, Client(lc) as client:
        yield Executor(client, progress=False)


def test_cluster_maps_in_input_order_on_both_workers(cluster):
    items = list(range(12))
    with executor("none", progress=False) as here:
        expected = here.map(_scaled, items, shared=3)
    got = cluster.map(_scaled, items, shared=3)
    assert [v for v, _ in got] == [v for v, _ in expected] == [3 * x for x in items]
    assert cluster.workers == 2 and cluster.threads(12) == 1 and here.threads(12) is None
    assert len({pid for _, pid in got} - {os.getpid()}) >= 1  # ran outside this process


def test_two_maps_over_the_same_shared_input(cluster):
    """reduce --verify maps twice over one DEM: the second map must not lose the shared data
    when the first map's futures are released (a hashed scatter reuses the key)."""
    import gc

    shared = list(range(1000))
    first = cluster.map(_scaled, [1, 2], shared=shared)
    gc.collect()
    second = cluster.map(_scaled, [3, 4], shared=shared)
    assert [v for v, _ in first] == [shared, shared * 2]
    assert [v for v, _ in second] == [shared * 3, shared * 4]


def _sleeps(seconds):
    """Sleeps ``seconds`` and returns them (tasks that complete out of order)."""
    import time

    time.sleep(seconds)
    return seconds


@pytest.mark.parametrize("where", ["cluster", "none"])
def test_map_groups_form_is_lazy_in_order_and_has_no_bar(cluster, monkeypatch, where):
    """``ex(fn, items)``: an iterator (no list, no bar of its own) of the results in input
    order, though on the cluster the later, shorter tasks finish first."""
    bars = []
    monkeypatch.setattr(distributed, "tqdm", lambda *a, **k: bars.append(k))
    ex = cluster if where == "cluster" else Executor(None, progress=True)
    seconds = [0.6, 0.3, 0.0, 0.0]
    results = ex(_sleeps, iter(seconds))
    assert not isinstance(results, list) and next(results) == 0.6
    assert list(results) == seconds[1:] and bars == []
    assert list(ex(abs, [])) == []


def test_map_groups_form_reads_items_one_at_a_time_in_process():
    """In this process, as the built-in ``map``: an item is read only when its result is
    asked for (tiled visibility makes a DEM tile per item); a cluster's window plays no part."""
    read = []

    def items():
        for x in (-2, 1, -7):
            read.append(x)
            yield x

    ex = Executor(None, progress=False, window=3)
    results = ex(abs, items())
    assert ex.window_size() == 1 and read == [] and next(results) == 2 and read == [-2]
    assert list(results) == [1, 7] and read == [-2, 1, -7]


def _reads(seconds, got, held):
    """The items ``seconds`` one at a time; before each, appends to ``held`` the items read and
    not yet in ``got`` (the consumer's results), this one included."""
    for k, s in enumerate(seconds):
        held.append(k + 1 - len(got))
        yield s


def test_cluster_map_groups_reads_items_only_as_its_window_frees(cluster):
    """A km site's DEM tiles are made as they are read: at most ``window`` are read and not
    yet handed back, though the first task is slow and the others finish long before it (they
    wait for it, in order, and the cluster idles)."""
    seconds = [0.5] + [0.0] * 29
    got, held = [], []
    for result in Executor(cluster.client, progress=False, window=3)(
            _sleeps, _reads(seconds, got, held)):
        got.append(result)
    assert got == seconds and len(held) == 30
    assert max(held) == 3 and held[:4] == [1, 2, 3, 3]  # the 4th read waited for the slow 1st
    with pytest.raises(ValueError, match=r"`window` must be a positive number of tasks, got 0"):
        Executor(cluster.client, window=0)


def test_cluster_map_holds_twice_the_threads_and_advances_its_bar_per_task(cluster,
                                                                           monkeypatch):
    """``map``'s default window is twice the cluster's threads (2 workers x 1 thread): a
    task is submitted only when fewer are running or waiting, one finished frees its slot."""
    done = []

    class Bar:
        def __init__(self, *args, **kwargs):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def update(self):
            done.append(1)

    monkeypatch.setattr(distributed, "tqdm", Bar)
    held, submit = [], cluster.client.submit
    monkeypatch.setattr(cluster.client, "submit",
                        lambda *a, **k: held.append(len(held) + 1 - len(done)) or submit(*a, **k))
    seconds = [0.3, 0.0, 0.1, 0.0] * 5
    assert cluster.window_size() == 4
    assert cluster.map(_sleeps, seconds) == seconds
    assert len(held) == len(done) == 20 and max(held) == 4


def _fails_at_seven(x):
    if x == 7:
        raise DataError("seven is missing")
    return x


def test_a_failing_task_past_the_first_window_is_reported_after_its_retries(cluster):
    """Task 7 is submitted only after 5 is handed back (window 2): the results before it
    arrive in order, then its failure after three tries, and the map stops."""
    ex, got = Executor(cluster.client, progress=False, window=2), []
    with pytest.raises(TaskError, match=r"^task 7 failed after 3 tries: DataError: seven is "
                                        r"missing$"):
        for result in ex(_fails_at_seven, range(12)):
            got.append(result)
    assert got in (list(range(6)), list(range(7)))


def test_the_default_window_grows_with_the_cluster():
    """Workers that join during a map (dask-jobqueue's jobs starting) widen the default window
    at the next freed slot: 2 tasks held on one thread, 4 once a second worker has joined."""
    import itertools

    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                      dashboard_address=":0", silence_logs=40) as lc, Client(lc) as client:
        got, held = [], []
        reads = _reads([0.0] * 16, got, held)

        def items():
            yield from itertools.islice(reads, 4)
            lc.scale(2)
            client.wait_for_workers(2, timeout=30)
            yield from reads

        ex = Executor(client, progress=False)
        assert ex.window_size() == 2
        for result in ex(_sleeps, items()):
            got.append(result)
        assert got == [0.0] * 16 and max(held[:4]) == 2 and max(held) == 4
        assert ex.window_size() == 4


@pytest.mark.parametrize("where", ["cluster", "none"])
def test_a_task_that_fails_once_is_retried(cluster, tmp_path, where):
    flags = [str(tmp_path / f"flag{i}") for i in range(3)]
    ex = cluster if where == "cluster" else Executor(None, progress=False)
    assert ex.map(_fails_once, flags) == ["ok"] * 3
    assert all(Path(f).exists() for f in flags)


@pytest.mark.parametrize("where", ["cluster", "none"])
def test_a_task_that_keeps_failing_is_reported_by_name(cluster, where):
    ex = cluster if where == "cluster" else Executor(None, progress=False)
    with pytest.raises(TaskError) as info:
        ex.map(_always_fails, ["a", "b"], labels=["station S1", "station S2"])
    msg = str(info.value)
    assert msg.startswith("station S") and "failed after 3 tries" in msg
    assert "DataError: the tile of" in msg and "\n" not in msg
    with pytest.raises(TaskError, match=r"^task [01] failed after 3 tries: DataError: the "
                                        r"tile of [ab] misses the DEM$"):
        list(ex(_always_fails, ["a", "b"]))


def test_unreachable_scheduler_is_one_line(monkeypatch):
    monkeypatch.setattr(distributed, "CONNECT_TIMEOUT_S", 1)
    with pytest.raises(ConfigError, match=r"`scheduler` tcp://127.0.0.1:9.*dask scheduler"):
        with executor("tcp://127.0.0.1:9", progress=False):
            pass
    with pytest.raises(ConfigError, match="`workers` 2 sizes the local cluster only"):
        with executor("none", workers=2):
            pass


def test_cli_reports_a_failing_station_without_traceback(tmp_path, capsys, monkeypatch):
    import planner.verify.known_control

    def broken(*args, **kwargs):
        raise DataError("simulated failure")

    monkeypatch.setattr(planner.verify.known_control, "simulate_markers", broken)
    plan = tmp_path / "plan"
    code, _, err = run_cli(capsys, ["plan", "--out", str(plan)])
    assert code == 0, err
    code, _, err = run_cli(capsys, ["verify", str(plan / "plan.json"), "--station-ids", "S2",
                                    "--scheduler", "none", "--out", str(tmp_path / "v")])
    assert code == 1 and "Traceback" not in err
    assert err.strip().splitlines()[-1] == ("error: station S2 failed after 3 tries: DataError: "
                                            "simulated failure")
    assert not (tmp_path / "v").exists()


@pytest.mark.slow
@pytest.mark.parametrize("network", [False, True])
def test_cluster_files_equal_single_process_files(tmp_path, capsys, network, two_cores):
    """One station in known-control mode, two (the fewest) in network mode: ~20 s a station."""
    plan = tmp_path / "plan"
    assert run_cli(capsys, ["plan", "--out", str(plan)])[0] == 0
    common = ["verify", str(plan / "plan.json"), "--json"]
    common += ["--network", "--station-ids", "S1,S2"] if network else ["--station-ids", "S1"]
    code_one, out_one, _ = run_cli(capsys, common + ["--scheduler", "none",
                                                     "--out", str(tmp_path / "one")])
    code_two, out_two, _ = run_cli(capsys, common + ["--workers", "2",
                                                     "--out", str(tmp_path / "two")])
    assert code_one == code_two and out_one.replace("one", "two") == out_two
    names = ["verify.json", "verify.md", "fates.csv"] + (["markers.csv"] if network else [])
    for name in names:
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes()


@pytest.mark.slow
def test_range_study_replicates_on_a_cluster_equal_in_process(tmp_path, capsys, two_cores):
    quick = ["range-study", "--frames", "40", "--replicates", "3", "--max-distance-m", "4"]
    code_one, _, err = run_cli(capsys, quick + ["--scheduler", "none",
                                                "--out", str(tmp_path / "one")])
    assert code_one == 0, err
    code_two, _, err = run_cli(capsys, quick + ["--workers", "2", "--out", str(tmp_path / "two")])
    assert code_two == 0, err
    for name in ("markers.csv", "summary.csv", "summary.json"):
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes()
    rows = read_marker_table(tmp_path / "two" / "markers.csv")
    assert sorted({r["replicate"] for r in rows}) == ["0", "1", "2"]  # none dropped


def test_local_cluster_starts_only_for_more_than_one_task(two_cores):
    """``--scheduler local``: one task runs here (no cluster to start), two start the cluster."""
    with executor("local", workers=2, progress=False) as ex:
        assert ex.threads(1) is None and ex.threads(2) == 1
        assert ex.map(_scaled, [5], shared=2)[0] == (10, os.getpid())
        assert ex.client is None
        got = ex.map(_scaled, [1, 2], shared=2)
        assert [v for v, _ in got] == [2, 4] and ex.workers == 2
    assert ex.client.status == "closed"


def test_tiled_visibility_on_the_cluster_equals_in_process(cluster):
    """Planning-time ray casting (one task per station block, each on its DEM tile) gives the
    in-process answer exactly on two worker processes."""
    import numpy as np

    from visibility.terrain import TerrainSpec, generate_terrain
    from visibility.visibility_matrix import tiled_visibility

    spec = TerrainSpec(extent_m=(-12.0, 12.0, -12.0, 12.0), cell_size_m=0.2, crater_density=0.02,
                       crater_diameter_range_m=(0.5, 3.0))
    dem = generate_terrain(spec, np.random.default_rng(2)).dem
    rng = np.random.default_rng(3)
    sxy = rng.uniform(-10.0, 10.0, (6, 2))
    st = np.column_stack([sxy, dem.height_at(sxy) + 1.0])
    g = np.arange(-11.0, 11.1, 2.0)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    si = np.column_stack([xy, dem.height_at(xy) + 0.1])
    here, _ = tiled_visibility(dem, st, si, 0.1, 6.0, 12, block_m=6.0, progress=False)
    there, stats = tiled_visibility(dem, st, si, 0.1, 6.0, 12, block_m=6.0, progress=False,
                                    map_groups=cluster)
    assert stats["groups"] >= 3
    for name in ("station", "site", "visible_fraction", "expected_points", "distance_m"):
        np.testing.assert_array_equal(getattr(there, name), getattr(here, name), err_msg=name)


def _free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(procs: list[subprocess.Popen]) -> None:
    """Stop processes started in their own sessions: SIGTERM (dask closes its worker
    processes), then SIGKILL to the whole process group of one that lingers."""
    for p in procs:
        p.terminate()
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


@pytest.fixture
def cluster_by_hand(tmp_path):
    """``dask scheduler`` and two ``dask worker`` processes (this venv's executables, one
    thread each) on a free port, as docs/distributed.md starts them by hand; yields the
    scheduler's address and stops all three afterwards, even when the test fails."""
    from distributed import Client

    dask = Path(sys.executable).with_name("dask")
    address = f"tcp://127.0.0.1:{_free_port()}"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    logs = tmp_path / "dask-logs"
    logs.mkdir()
    commands = [[dask, "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                 "--no-dashboard"]]
    commands += [[dask, "worker", address, "--nthreads", "1", "--no-dashboard", "--name",
                  f"w{i}", "--local-directory", str(logs / f"w{i}")] for i in range(2)]
    procs = []
    try:
        for i, command in enumerate(commands):
            with open(logs / f"{i}.log", "wb") as log:
                procs.append(subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT,
                                              env=env, start_new_session=True))
        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=30)
            yield address, client
    finally:
        _stop(procs)


@pytest.mark.slow
def test_range_study_on_a_scheduler_and_workers_started_by_hand(tmp_path, capsys,
                                                                cluster_by_hand):
    """``--scheduler tcp://...`` of a real (not Local) cluster: the same files as in process,
    and the replicates ran on its workers."""
    address, client = cluster_by_hand
    quick = ["range-study", "--frames", "20", "--replicates", "2", "--max-distance-m", "3"]
    code, _, err = run_cli(capsys, quick + ["--scheduler", "none",
                                            "--out", str(tmp_path / "one")])
    assert code == 0, err
    code, _, err = run_cli(capsys, quick + ["--scheduler", address,
                                            "--out", str(tmp_path / "tcp")])
    assert code == 0, err
    for name in ("markers.csv", "summary.csv", "summary.json"):
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "tcp" / name).read_bytes()
    ran = client.run(lambda dask_worker: dask_worker.state.executed_count)
    assert len(ran) == 2 and sum(ran.values()) == 2  # one task per replicate, none here


def _station_id(st, scan, truth):
    """A station's ``process`` that returns its id (the scan is a stub here)."""
    return st.id


def _refuses(st, scan, truth):
    raise DataError(f"no markers seen from {st.id}")


def test_several_plans_are_one_map_under_one_bar(monkeypatch):
    """reduce --verify's counts: every station of every plan is a task of one map (one bar of
    all the tasks), the results come back per plan, and a failure names station and plan."""
    from dataclasses import replace

    import numpy as np

    import planner.verify.known_control
    from planner.outputs.plan_file import PlannedStation, SurveyPlan
    from planner.verify.known_control import map_plan_stations
    from visibility.terrain import TerrainSpec, generate_terrain

    monkeypatch.setattr(planner.verify.known_control, "simulate_markers",
                        lambda *a, **k: (None, {}))
    bars, tqdm = [], distributed.tqdm
    monkeypatch.setattr(distributed, "tqdm", lambda *a, **k: bars.append(k["total"]) or
                        tqdm(*a, **k))
    spec = TerrainSpec(extent_m=(-5.0, 5.0, -5.0, 5.0), cell_size_m=0.5)
    dem = generate_terrain(spec, np.random.default_rng(0)).dem
    stations = tuple(PlannedStation(f"S{i}", np.array([i, 0.0, 1.0]), 0.0, None, ())
                     for i in range(3))
    plan = SurveyPlan(dem, stations, (), np.zeros((0, 3)), 0.1, 0.1, 10.0)
    fewer = replace(plan, stations=stations[:2])
    got = map_plan_stations([plan, fewer], [_station_id, _station_id], progress=False)
    assert got == [["S0", "S1", "S2"], ["S0", "S1"]] and bars == [5]
    with pytest.raises(TaskError, match=r"^station S0 \(k=2\) failed after 3 tries: DataError: "
                                        r"no markers seen from S0$"):
        map_plan_stations([plan, fewer], [_station_id, _refuses], names=["k=3", "k=2"],
                          progress=False)


# --- the local cluster's size is bounded by the machine ---------------------------------

RANGE_QUICK = ["range-study", "--frames", "4", "--replicates", "2", "--max-distance-m", "2"]


def _no_cluster(*args, **kwargs):
    raise AssertionError("a LocalCluster was started")


def _one_error_line(err: str) -> str:
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1, err
    return lines[0]


def test_workers_beyond_the_cores_are_refused_before_any_cluster_starts(tmp_path, capsys,
                                                                        monkeypatch):
    """``--workers`` above the cores this process may use is refused at the option, with the
    limit and the fix, and no worker is started (10000 once spawned workers until the
    machine ran out of file handles)."""
    import distributed as dask_distributed

    monkeypatch.setattr(distributed, "available_cores", lambda: 2)
    monkeypatch.setattr(distributed, "open_file_limit", lambda: None)
    monkeypatch.setattr(dask_distributed, "LocalCluster", _no_cluster)
    code, _, err = run_cli(capsys, RANGE_QUICK + ["--workers", "3", "--out", str(tmp_path / "o")])
    assert code == 1 and not (tmp_path / "o").exists()
    assert _one_error_line(err) == (
        "error: --workers 3 is more worker processes than this machine runs: this process may "
        "use 2 cores (one worker each); give --workers 2 or fewer, or drop --workers and run "
        "the tasks on a bigger cluster with --scheduler ADDRESS (docs/distributed.md)")
    with pytest.raises(ConfigError, match=r"^`workers` 3 is more worker processes"):
        with executor("local", workers=3, progress=False):
            pass


def test_the_open_file_limit_bounds_the_workers_too(monkeypatch):
    """Each worker holds about :data:`FILES_PER_WORKER` files in this process: 64 cores under
    ``ulimit -n 300`` run (300 - 100) / 20 = 10 workers, the default too."""
    monkeypatch.setattr(distributed, "available_cores", lambda: 64)
    monkeypatch.setattr(distributed, "open_file_limit", lambda: 300)
    assert distributed.local_worker_limit() == 10 and distributed.check_local_workers(10) == 10
    with pytest.raises(ConfigError, match=r"`workers` 11 .*: the open-file limit 300 \(ulimit "
                                          r"-n\) holds 10 \(20 files each\); raise it"):
        distributed.check_local_workers(11)
    monkeypatch.setattr(distributed, "open_file_limit", lambda: 50)
    assert distributed.local_worker_limit() == 1  # always one


@pytest.mark.parametrize("failure", [
    OSError(24, "Too many open files"),
    RuntimeError("Nanny failed to start."),
])
def test_a_cluster_that_cannot_start_is_one_line(tmp_path, capsys, monkeypatch, two_cores,
                                                 failure):
    import distributed as dask_distributed

    if isinstance(failure, RuntimeError):  # as distributed raises it: the OSError behind it
        failure.__context__ = AssertionError("Status.starting")
        failure.__context__.__context__ = OSError(24, "Too many open files")

    def cannot_start(*args, **kwargs):
        raise failure

    monkeypatch.setattr(dask_distributed, "LocalCluster", cannot_start)
    code, _, err = run_cli(capsys, RANGE_QUICK + ["--workers", "2", "--out", str(tmp_path / "o")])
    assert code == 1 and not (tmp_path / "o").exists()
    assert _one_error_line(err) == (
        "error: the local dask cluster of 2 worker processes did not start (OSError: [Errno 24] "
        "Too many open files); give fewer --workers, raise the open-file limit (ulimit -n), or "
        "run in this process with --scheduler none")


def test_the_runaway_worker_count_ends_in_seconds_with_no_process_left(tmp_path):
    """The command line that once ran away: one error line within seconds, exit 1, and no
    process of its session left behind."""
    import time

    import psutil

    started = time.perf_counter()
    markerplan = [sys.executable, "-c", "from planner.cli import main; main()"]
    proc = subprocess.Popen(markerplan + RANGE_QUICK + ["--workers", "10000", "--out",
                                                        str(tmp_path / "o")],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:  # the runaway: stop it and everything it started
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    elapsed = time.perf_counter() - started

    def in_session(p):
        try:
            return os.getsid(p.pid) == proc.pid
        except (ProcessLookupError, PermissionError):
            return False

    left = [p.pid for p in psutil.process_iter() if in_session(p)]
    assert proc.returncode == 1 and elapsed < 20 and left == []
    assert _one_error_line(err).startswith("error: --workers 10000 is more worker processes")
    assert not (tmp_path / "o").exists()
