"""Network adjustment speed: 100 stations, about 1,000 marker observations (aim: < 1 s).

Prints the median wall time of
  (a) :func:`pipeline.network.adjustment.adjust` as shipped: Gauss-Newton on the sparse normal
      equations (SuperLU), full covariance, w-tests, data snooping on (clean data, so only the
      false alarms alpha0 allows are removed), MDBs and their effects;
  (b) the baseline "dense normal equations": the same adjustment with every Gauss-Newton step
      solved by ``numpy.linalg.solve`` on the dense normal matrix,
and the ratio b/a from the same run, with the network's size, the rounds of snooping and the
machine's load average. With ``--robust huber|igg3`` (instead of data snooping) and/or
``--variance-components station|range`` both (a) and (b) run those too, and the reweighting
rounds are printed (each round computes the covariance afresh). Wall and CPU seconds are both
printed: on a busy machine the wall time grows (BLAS threads wait for cores) while the CPU time
shows the work done.

``--blas-threads 1`` caps OpenBLAS (numpy's and scipy's) at one thread, set before numpy is
imported: on a machine busy with other work its idle BLAS threads otherwise spin and wait for
cores, and the wall time doubles.

Usage: ``python benchmarks/adjust_network.py [--stations 100] [--markers-per-station 2.5]
[--repeat 5] [--seed 3] [--blas-threads N] [--robust huber|igg3]
[--variance-components station|range]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from unittest import mock


class _DenseFactor:
    """Stands in for SuperLU's factor: solves with the dense matrix (the baseline)."""

    def __init__(self, matrix):
        self.matrix = matrix.toarray()

    def solve(self, rhs):
        import numpy as np

        return np.linalg.solve(self.matrix, rhs)


def _median_time(fn, repeat: int) -> tuple[float, float, object]:
    """Median wall and CPU (all threads of this process) seconds of ``repeat`` calls."""
    wall, cpu, out = [], [], None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall), statistics.median(cpu), out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stations", type=int, default=100)
    ap.add_argument("--markers-per-station", type=float, default=2.5)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--blas-threads", type=int, default=None)
    ap.add_argument("--robust", choices=("huber", "igg3"), default=None)
    ap.add_argument("--variance-components", choices=("station", "range"), default=None)
    args = ap.parse_args()
    if args.blas_threads is not None:
        os.environ["OPENBLAS_NUM_THREADS"] = os.environ["OMP_NUM_THREADS"] = str(args.blas_threads)

    import numpy as np

    from pipeline.network.adjustment import AdjustmentSettings, adjust
    from pipeline.network.simulation import simulated_network

    obs, truth = simulated_network(n_stations=args.stations,
                                   markers_per_station=args.markers_per_station, seed=args.seed)
    unknowns = 6 * len(obs.station_ids) + 3 * len(obs.marker_ids)
    print(f"network: {len(obs.station_ids)} stations, {len(obs.marker_ids)} markers, "
          f"{obs.n} observations, {unknowns} unknowns; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; BLAS threads "
          f"{args.blas_threads or 'default'}")

    settings = AdjustmentSettings(snooping=args.robust is None, robust=args.robust,
                                  variance_components=args.variance_components)

    def shipped():
        return adjust(obs, settings=settings, nominal=truth.nominal)

    def dense():
        with mock.patch("scipy.sparse.linalg.splu", _DenseFactor):
            return adjust(obs, settings=settings, nominal=truth.nominal)

    shipped()  # warm-up: imports, BLAS threads
    t_sparse, cpu_sparse, result = _median_time(shipped, args.repeat)
    t_dense, cpu_dense, baseline = _median_time(dense, args.repeat)
    assert np.allclose(result.marker_xyz_m, baseline.marker_xyz_m, atol=1e-7)
    mode = ("snooping" if args.robust is None else f"robust {args.robust}") + (
        f", variance components by {args.variance_components}" if args.variance_components
        else "")
    print(f"(a) adjust (sparse Gauss-Newton, covariance, {mode}): {t_sparse:.3f} s wall, "
          f"{cpu_sparse:.3f} s CPU, median of {args.repeat}; {result.iterations} iterations in "
          "the last solution, "
          f"{len(result.rejected)} observations removed by snooping, "
          f"{result.robust_rounds} reweighting rounds, "
          f"{int((result.robust_weight < 1).sum())} observations down-weighted, "
          f"sigma0^2 = {result.sigma0_squared:.3f}, dof = {result.dof}")
    print(f"(b) baseline (dense normal-equation solve per step):    {t_dense:.3f} s wall, "
          f"{cpu_dense:.3f} s CPU")
    print(f"ratio b/a: {t_dense / t_sparse:.2f}; requirement (a) < 1 s: "
          f"{'met' if t_sparse < 1.0 else 'NOT met'}")


if __name__ == "__main__":
    main()
