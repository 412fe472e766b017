"""Distributed execution: map independent tasks (one per station, replicate, ...) over
dask.distributed, or over a plain loop in this process.

This is the only module that knows about a cluster. The task functions it runs are ordinary
functions of picklable arguments (:func:`planner.verify.known_control.station_task`, ...);
they return small results and never learn where they run, so a cluster and the in-process loop
give the same results, and byte-identical files.

Three ways to run, chosen by ``--scheduler`` (:func:`executor`):

``local`` (the default)
    A ``distributed.LocalCluster`` sized to the machine: one worker process per core this
    process may use, one thread each (or ``--workers N``, at most :func:`local_worker_limit`),
    started for the command at its first map of more than one task (a single task runs in this
    process, with no cluster to start) and closed after it; a cluster that cannot start is
    :class:`ClusterError`.
``none``
    No cluster: the same task functions in a loop in this process (the single-process baseline).
``tcp://HOST:8786``
    The scheduler of a running cluster (``dask scheduler`` + ``dask worker``, dask-ssh,
    dask-jobqueue, Kubernetes; see ``docs/distributed.md``).

Large inputs shared by every task (the DEM) are sent to each worker once
(``Client.scatter(..., broadcast=True)``); each task returns its small result. A task that
raises is retried (:data:`RETRIES` times); one that still fails stops the run with
:class:`TaskError` naming the task (its station id) and the error — no result is ever dropped.

Memory stays bounded however many tasks a map has: on a cluster at most a *window* of tasks
(default twice the cluster's threads, :meth:`Executor.window_size`) is submitted and not yet
handed back, and the items are read from their iterable only as slots free, so this process
and the scheduler hold at most a window of task arguments (DEM tiles) and results at once.

Two forms: :meth:`Executor.map` returns the list of results and shows a tqdm bar on stderr
advanced as tasks complete; an :class:`Executor` called as ``map_groups(fn, items)`` returns a
lazy iterator of the results in input order with no bar of its own, like the built-in ``map``,
so code that maps groups of work (tiled planning-time visibility, the range study's
replicates) takes either and advances its own progress as results arrive.
"""

from __future__ import annotations

import itertools
import logging
import os
import sys
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import ExitStack, contextmanager
from typing import Any

from tqdm import tqdm

from markerplan.errors import ConfigError, MarkerPlanError

#: How many times a failed task is run again before the run stops with :class:`TaskError`.
RETRIES = 2

#: ``--scheduler`` values that are not addresses.
LOCAL, IN_PROCESS = "local", "none"

#: Seconds to wait for a scheduler at an address before giving up.
CONNECT_TIMEOUT_S = 10

#: Open files a local worker holds in this process (its nanny's pipes, its and the scheduler's
#: sockets): about 9 measured with distributed 2026.8, doubled for connections under load.
FILES_PER_WORKER = 20
#: Open files kept for everything else this process opens (inputs, outputs, the scheduler).
FILES_RESERVED = 100


class TaskError(MarkerPlanError, RuntimeError):
    """A task still failed after its retries; the message names the task and the error."""


class ClusterError(MarkerPlanError, RuntimeError):
    """The local cluster could not start (no file handles, processes or memory left...)."""


def available_cores() -> int:
    """The cores this process may run on: its CPU affinity (a container's or ``taskset``'s
    share of the machine), else every core."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def open_file_limit() -> int | None:
    """This process's open-file limit (``ulimit -n``), None where it has none or it is
    unknown."""
    try:
        import resource
    except ImportError:  # Windows
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    return None if soft == resource.RLIM_INFINITY else soft


def local_worker_limit() -> int:
    """The most worker processes a local cluster may have: one per core this process may use
    (:func:`available_cores`; each worker runs one CPU-bound task at a time, so more only cost
    memory), fewer when the open-file limit cannot hold that many (:data:`FILES_PER_WORKER`
    each); at least 1."""
    limit = available_cores()
    files = open_file_limit()
    if files is not None:
        limit = min(limit, (files - FILES_RESERVED) // FILES_PER_WORKER)
    return max(1, limit)


def check_local_workers(workers: int) -> int:
    """``workers``, refused when the local cluster cannot hold that many worker processes.

    Parameters
    ----------
    workers : int
        Worker processes asked for (``--workers``), >= 1.

    Returns
    -------
    workers : int
        As given.

    Raises
    ------
    ConfigError
        ``workers`` is above :func:`local_worker_limit`; the message names the limit (cores
        or open files) and the fix.
    """
    limit = local_worker_limit()
    if workers <= limit:
        return workers
    cores, files = available_cores(), open_file_limit()
    if limit < cores:
        why = (f"the open-file limit {files} (ulimit -n) holds {limit} "
               f"({FILES_PER_WORKER} files each); raise it (ulimit -n), give")
    else:
        why = f"this process may use {cores} cores (one worker each); give"
    raise ConfigError(f"`workers` {workers} is more worker processes than this machine runs: "
                      f"{why} `workers` {limit} or fewer, or drop `workers` and run the tasks "
                      "on a bigger cluster with `scheduler` ADDRESS (docs/distributed.md)")


class Executor:
    """Runs ``fn`` over items, in a cluster (``client`` given) or in this process.

    Parameters
    ----------
    client : distributed.Client or None
        None: run the tasks in a loop in this process (unless ``start`` is given).
    progress : bool
        :meth:`map`'s progress bar on stderr (the ``map_groups`` form has none).
    retries : int
        Extra runs of a failed task before :class:`TaskError`.
    start : callable, optional
        ``start() -> Client``: connects a cluster the first time a map has more than one task
        (the local cluster, started only when it can help).
    window : int, optional
        On a cluster, the most tasks submitted and not yet handed back at any time (a
        positive int); default twice the cluster's threads, at least 2
        (:meth:`window_size`). Unused in this process, which holds one task at a time.
    """

    def __init__(self, client=None, progress: bool = True, retries: int = RETRIES,
                 start: Callable | None = None, window: int | None = None):
        if window is not None and window < 1:
            raise ValueError(f"Executor: `window` must be a positive number of tasks, "
                             f"got {window}")
        self.client = client
        self.progress = progress
        self.retries = retries
        self.window = window
        self._start = start

    @property
    def workers(self) -> int:
        """Worker processes (1 in process)."""
        if self.client is None:
            return 1
        return len(self.client.scheduler_info(n_workers=-1)["workers"])

    def threads(self, n_tasks: int) -> int | None:
        """Threads each of ``n_tasks`` tasks may use for ray casting: 1 in a cluster (a worker
        per core), None (all cores) in process."""
        return None if self._in_process(n_tasks) else 1

    def window_size(self) -> int:
        """The most tasks a map holds now (submitted, not yet handed back): 1 in process.

        On a cluster ``window`` when given, else twice the cluster's threads (at least 2): one
        task running on each thread and one waiting behind it, so a thread that finishes starts
        its next task without waiting for this process to read and send the next item, while
        only two tasks' arguments per thread are held. Read from the scheduler at every freed
        slot, so a cluster that grows during a map (dask-jobqueue workers arriving) is put to
        work.
        """
        if self.client is None:
            return 1
        if self.window is not None:
            return self.window
        return max(2, 2 * self.client.scheduler_info(n_workers=0)["total_threads"])

    def _in_process(self, n_tasks: int) -> bool:
        """Whether a map of ``n_tasks`` tasks runs in this process."""
        return self.client is None and (self._start is None or n_tasks <= 1)

    def __call__(self, fn: Callable, items: Iterable) -> Iterator:
        """``map_groups`` form: ``fn(item)`` for every item, lazily, in input order.

        No progress bar: the caller advances its own as results arrive. In this process the
        items are read one at a time (as the built-in ``map`` reads them); on a cluster an item
        is read and submitted only while fewer than :meth:`window_size` tasks are submitted and
        not yet yielded. A task's result waits until every earlier one is yielded, and counts
        against the window meanwhile: a slow task holds back the tasks after it (the cluster
        idles once a window's worth has finished behind it) instead of letting later results
        pile up in memory. Retries and :class:`TaskError` as :meth:`map`.

        Parameters
        ----------
        fn : callable
            A module-level function of one item.
        items : iterable
            Picklable task arguments, one per task.

        Returns
        -------
        results : iterator
            ``fn``'s results in the order of ``items``, each as soon as it and every earlier
            one are done.
        """
        return (result for _, result in self._completed(fn, None, items, None, ordered=True))

    def map(self, fn: Callable, items: Sequence, *, shared: Any = None,
            labels: Sequence[str] | None = None, desc: str = "tasks") -> list:
        """Run ``fn(item)`` (or ``fn(shared, item)`` when ``shared`` is given) for every item,
        with a progress bar (tasks completed) on stderr.

        On a cluster at most :meth:`window_size` tasks run or wait at a time; each completed
        one frees its slot for the next item, whatever the order.

        Parameters
        ----------
        fn : callable
            A module-level function (it is pickled by reference to run on a worker).
        items : sequence
            Picklable task arguments, one per task.
        shared : object, optional
            A large input every task needs (a DEM): sent once to every worker.
        labels : sequence of str, optional
            Task names for errors (default ``task 0``, ``task 1``, ...).
        desc : str
            Progress-bar label.

        Returns
        -------
        results : list
            ``fn``'s results in the order of ``items``.

        Raises
        ------
        TaskError
            A task failed ``1 + retries`` times.
        """
        items = list(items)
        results: list = [None] * len(items)
        with tqdm(total=len(items), desc=desc, unit="task", file=sys.stderr,
                  disable=None if self.progress else True) as bar:
            for i, result in self._completed(fn, shared, items, labels, ordered=False):
                results[i] = result
                bar.update()
        return results

    def _completed(self, fn, shared, items: Iterable, labels,
                   ordered: bool) -> Iterator[tuple[int, Any]]:
        """``(index, result)`` of every task, in input order when ``ordered`` (always in this
        process), else as each completes; ``labels`` None names task ``i`` ``task i``."""
        items = iter(items)
        if self.client is None and self._start is not None:
            head = list(itertools.islice(items, 2))  # enough to tell one task from several
            items = itertools.chain(head, items)
            if not self._in_process(len(head)):
                self.client = self._start()
        label = (lambda i: f"task {i}") if labels is None else labels.__getitem__
        if self.client is None:
            for i, item in enumerate(items):
                yield i, self._run_here(fn, shared, item, label(i))
        else:
            yield from self._run_cluster(fn, shared, items, label, ordered)

    def _run_here(self, fn, shared, item, label):
        """One task in this process, with the cluster's retry rule."""
        args = (item,) if shared is None else (shared, item)
        for attempt in range(self.retries + 1):
            try:
                return fn(*args)
            except Exception as exc:  # noqa: BLE001 - reported below, never dropped
                if attempt == self.retries:
                    raise _failed(label, exc, self.retries) from exc

    def _run_cluster(self, fn, shared, items, label, ordered):
        """The tasks on the cluster, a window at a time: ``(index, result)`` as each completes,
        or in index order when ``ordered``; the next item is read and submitted after a
        result is yielded, never while :meth:`window_size` tasks are held."""
        from distributed import as_completed

        client = self.client
        # hash=False: a second map over the same data (reduce --verify's counts) would otherwise
        # reuse the first scatter's key, which the scheduler forgets once the first map's
        # futures are released ("lost dependencies")
        extra = () if shared is None else (client.scatter(shared, broadcast=True, hash=False),)
        todo = enumerate(items)
        held: dict[int, Any] = {}  # index -> future: submitted, not yet yielded
        index: dict[str, int] = {}  # future key -> index, until it completes
        finished: set[int] = set()  # completed, waiting for an earlier one (ordered)
        completing = as_completed()

        def fill():
            for i, item in itertools.islice(todo, max(0, self.window_size() - len(held))):
                held[i] = client.submit(fn, *extra, item, retries=self.retries, pure=False)
                index[held[i].key] = i
                completing.add(held[i])

        try:
            fill()
            for fut in completing:
                i = index.pop(fut.key)
                if fut.status == "error":
                    exc = fut.exception()
                    raise _failed(label(i), exc, self.retries) from exc
                finished.add(i)
                first = min(held) if ordered else i  # the next index that may be yielded
                for j in list(itertools.takewhile(finished.__contains__,
                                                  itertools.count(first))):
                    finished.remove(j)
                    yield j, held.pop(j).result()
                    fill()
        finally:
            client.cancel(list(held.values()))


def _not_started(workers: int, exc: BaseException) -> ClusterError:
    """The one-line report of a local cluster of ``workers`` processes that did not start,
    naming the operating system's refusal when one is behind ``exc`` (distributed raises
    ``Nanny failed to start`` from, or while handling, the ``OSError``)."""
    chain = [exc]
    while (behind := chain[-1].__cause__ or chain[-1].__context__) and behind not in chain:
        chain.append(behind)
    cause = next((e for e in chain if isinstance(e, OSError)), exc)
    what = str(cause).splitlines()[0] if str(cause) else "no reason given"
    processes = "process" if workers == 1 else "processes"
    return ClusterError(f"the local dask cluster of {workers} worker {processes} did not start "
                        f"({type(cause).__name__}: {what}); give fewer `workers`, raise the "
                        "open-file limit (ulimit -n), or run in this process with `scheduler` "
                        "none")


def _failed(label: str, exc: BaseException, retries: int) -> TaskError:
    """The one-line report of a task that failed every try."""
    what = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return TaskError(f"{label} failed after {retries + 1} tries: {type(exc).__name__}: {what}")


@contextmanager
def executor(scheduler: str | None = LOCAL, workers: int | None = None,
             progress: bool = True, retries: int = RETRIES) -> Iterator[Executor]:
    """The executor ``--scheduler`` names, open for the ``with`` block.

    Parameters
    ----------
    scheduler : str or None
        ``local`` (or None): a LocalCluster of ``workers`` processes (default:
        :func:`local_worker_limit`, one per core);
        ``none``: in this process; else a scheduler address such as ``tcp://host:8786``.
    workers : int, optional
        Worker processes of the LocalCluster, at most :func:`local_worker_limit` (its
        default); refused with ``none`` or an address.
    progress : bool
        Progress bar on stderr.
    retries : int
        Extra runs of a failed task.

    Yields
    ------
    executor : Executor

    Raises
    ------
    ConfigError
        ``workers`` with a scheduler that is not ``local``, or more than the machine runs
        (:func:`check_local_workers`), or no scheduler answers at the address.
    ClusterError
        The local cluster could not start (at the first map of more than one task).

    Examples
    --------
    >>> with executor("none", progress=False) as ex:
    ...     ex.map(abs, [-1, 2, -3])
    [1, 2, 3]
    """
    scheduler = LOCAL if scheduler is None else scheduler
    if workers is not None and scheduler != LOCAL:
        raise ConfigError(f"`workers` {workers} sizes the local cluster only; drop it with "
                          f"`scheduler` {scheduler} (the running cluster has its own workers)")
    if scheduler == IN_PROCESS:
        yield Executor(None, progress, retries)
        return
    from distributed import Client, LocalCluster

    if scheduler == LOCAL:
        n = local_worker_limit() if workers is None else check_local_workers(workers)
        with ExitStack() as stack:
            def start():
                # CRITICAL: a worker that fails to start logs its traceback at ERROR; the
                # failure is reported once, below (a failed task by TaskError)
                try:
                    cluster = stack.enter_context(LocalCluster(
                        n_workers=n, threads_per_worker=1, processes=True,
                        dashboard_address=":0", silence_logs=logging.CRITICAL))
                    return stack.enter_context(Client(cluster))
                except (OSError, RuntimeError, TimeoutError) as exc:
                    raise _not_started(n, exc) from exc

            yield Executor(None, progress, retries, start=start)
        return
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ConfigError(f"`scheduler` {scheduler}: no dask scheduler answers there "
                          f"({type(exc).__name__}); start one with `dask scheduler` and "
                          "`dask worker ADDRESS`, or use `scheduler` local") from None
    with client:
        yield Executor(client, progress, retries)
