"""The submission window of planner.distributed: items held and wall time of a long map.

In one run, on one LocalCluster of ``--workers`` worker processes (one thread each):

(a) the baseline: ``Executor(client, window=N)`` over ``N`` items, which submits every task at
    the first ``next`` (as every cluster map did before the window);
(b) the default window (twice the cluster's threads);

each a ``map_groups`` map (results in input order) of ``--items`` tasks whose item is a
``--item-mb`` MB array (a stand-in for a DEM tile) and which sleep ``--task-s`` seconds,
alternating a, b, a, b, ... ``--repeat`` times. It prints, for each, the most items read and
not yet handed back at once (the tiles this process and the scheduler hold), that many times
the item's size, and the fastest wall time; then the ratio of the wall times.

Usage: ``python -u benchmarks/distributed_window.py [--items 300] [--workers 2] [--task-s 0.02]
[--item-mb 1] [--repeat 2]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planner.distributed import Executor


def _nap(item, seconds):
    """A task: sleeps ``seconds`` and returns the item's size in bytes."""
    time.sleep(seconds)
    return item.nbytes


def run(ex: Executor, n: int, item_mb: float, task_s: float) -> tuple[int, float]:
    """The most items held at once and the wall seconds of one map of ``n`` items."""
    import functools

    got, most = 0, 0

    def items():
        nonlocal most
        for k in range(n):
            most = max(most, k + 1 - got)
            yield np.zeros(int(item_mb * 2**20), np.uint8)

    t0 = time.perf_counter()
    for _ in ex(functools.partial(_nap, seconds=task_s), items()):
        got += 1
    return most, time.perf_counter() - t0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--items", type=int, default=300)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--task-s", type=float, default=0.02)
    parser.add_argument("--item-mb", type=float, default=1.0)
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args()
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=40) as lc, Client(lc) as client:
        runs = {"all at once (window = items)": Executor(client, window=args.items),
                "default window": Executor(client)}
        best: dict[str, tuple[int, float]] = {}
        for r in range(args.repeat):
            for name, ex in runs.items():
                most, wall = run(ex, args.items, args.item_mb, args.task_s)
                print(f"round {r + 1} {name}: {most} items held at most, {wall:.2f} s")
                best[name] = (most, min(wall, best.get(name, (0, float("inf")))[1]))
        for name, (most, wall) in best.items():
            print(f"{name:>30}: window {runs[name].window_size():4d}, {most:4d} items held at "
                  f"most ({most * args.item_mb:.0f} MB), fastest {wall:.2f} s")
        (_, base), (_, windowed) = best.values()
        print(f"wall time, default window / all at once: {windowed / base:.2f}")


if __name__ == "__main__":
    main()
