"""Run one function beside the caller: in a forked process where the platform forks (no
interpreter lock shared with the caller, so two cores both work), else in a thread.

The network plan proves its root bound (:func:`planner.program.loop._root_relaxation`) this way
while the greedy incumbent and its local search run.
"""

from __future__ import annotations

import multiprocessing
import threading
import traceback
from collections.abc import Callable
from typing import Any


def in_background(fn: Callable[..., Any], *args,
                  after_fork: Callable[[], None] | None = None) -> Callable[[], Any]:
    """Start ``fn(*args)`` now; return ``result()``, which waits for it and returns its value.

    In a forked child (``fn`` and ``args`` are inherited, not pickled; the value comes back
    pickled through a pipe) when the ``fork`` start method exists, else in a daemon thread.
    ``after_fork()`` runs first in the child (not in the thread), e.g. to drop a thread pool
    whose workers the child did not inherit.

    Raises
    ------
    RuntimeError
        From ``result()``, when ``fn`` raised (with its traceback in the message) or the child
        died without an answer.
    """
    if "fork" in multiprocessing.get_all_start_methods():
        return _forked(fn, args, after_fork)
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = fn(*args)
        except BaseException:  # noqa: BLE001 - handed to result()
            box["error"] = traceback.format_exc()

    thread = threading.Thread(target=run, daemon=True, name=f"background-{fn.__name__}")
    thread.start()

    def result() -> Any:
        thread.join()
        if "error" in box:
            raise RuntimeError(f"{fn.__name__} failed in the background: {box['error']}")
        return box["value"]

    return result


def _forked(fn: Callable[..., Any], args: tuple, after_fork: Callable[[], None] | None
            ) -> Callable[[], Any]:
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)

    def run() -> None:
        try:
            if after_fork is not None:
                after_fork()
            send.send(("value", fn(*args)))
        except BaseException:  # noqa: BLE001 - handed to result()
            send.send(("error", traceback.format_exc()))
        finally:
            send.close()

    proc = ctx.Process(target=run, daemon=True, name=f"background-{fn.__name__}")
    proc.start()
    send.close()

    def result() -> Any:
        try:
            kind, value = recv.recv()
        except EOFError:
            kind, value = "error", f"the child process ended with code {proc.exitcode}"
        finally:
            recv.close()
            proc.join()
        if kind == "error":
            raise RuntimeError(f"{fn.__name__} failed in the background: {value}")
        return value

    return result
