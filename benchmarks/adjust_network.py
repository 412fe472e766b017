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

``--compare-covariance 200 400 1000`` instead compares the covariance's two forms
(:attr:`pipeline.network.adjustment.AdjustmentSettings.covariance`) at each network size:
``dense`` (the full array) and ``sparse`` (marginal blocks,
:mod:`pipeline.network.marginals`), each case in its own subprocess, printing the wall and CPU
seconds of ``adjust`` (snooping as above; redundancy numbers, MDBs and their effects included)
and the subprocess's peak resident memory (``ru_maxrss``) and its growth during ``adjust``,
with sparse/dense ratios, and the largest relative difference of the variances and redundancy
numbers between the two. Each size uses the first seed from ``--seed`` whose simulated traverse
is tied (every station shares 2 markers with the rest). ``--dense-up-to N`` skips the dense case
above N stations.

Usage: ``python benchmarks/adjust_network.py [--stations 100] [--markers-per-station 2.5]
[--repeat 5] [--seed 3] [--blas-threads N] [--robust huber|igg3]
[--variance-components station|range] [--compare-covariance N [N ...]] [--dense-up-to N]``
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
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


def _covariance_case(args) -> None:
    """One case of ``--compare-covariance`` (in its own process): prints a JSON line and saves
    the variances and redundancy numbers to ``args.case_out``."""
    import numpy as np

    from pipeline.network.adjustment import AdjustmentSettings, adjust, tie_order
    from pipeline.network.simulation import simulated_network

    for seed in range(args.seed, args.seed + 100):  # the first seed whose traverse is tied
        obs, truth = simulated_network(n_stations=args.stations,
                                       markers_per_station=args.markers_per_station, seed=seed)
        if not tie_order(obs, np.ones(obs.n, dtype=bool), 0)[1]:
            break
    settings = AdjustmentSettings(snooping=args.robust is None, robust=args.robust,
                                  variance_components=args.variance_components,
                                  covariance=args.case)
    small, small_truth = simulated_network(n_stations=4, seed=1)
    adjust(small, settings=settings, nominal=small_truth.nominal)  # warm-up: imports, BLAS
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0, c0 = time.perf_counter(), time.process_time()
    result = adjust(obs, settings=settings, nominal=truth.nominal)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    np.savez(args.case_out, variance=result.covariance.diagonal(),
             redundancy=result.redundancy, mdb_effect=result.mdb_effect_m)
    print(json.dumps({"wall_s": wall, "cpu_s": cpu, "peak_mb": peak / 1024,
                      "growth_mb": (peak - before) / 1024, "rejected": len(result.rejected),
                      "stations": len(obs.station_ids), "markers": len(obs.marker_ids),
                      "seed": seed,
                      "observations": obs.n}))


def _compare_covariance(args) -> None:
    import numpy as np

    print(f"covariance forms: load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
          f"BLAS threads {args.blas_threads or 'default'}; "
          + ("snooping" if args.robust is None else f"robust {args.robust}"))
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.compare_covariance:
            cases = {}
            for kind in ("dense", "sparse"):
                if kind == "dense" and args.dense_up_to is not None and n > args.dense_up_to:
                    continue
                out = Path(tmp) / f"{kind}_{n}.npz"
                cmd = [sys.executable, __file__, "--case", kind, "--case-out", str(out),
                       "--stations", str(n), "--markers-per-station",
                       str(args.markers_per_station), "--seed", str(args.seed)]
                cmd += ["--blas-threads", str(args.blas_threads)] if args.blas_threads else []
                cmd += ["--robust", args.robust] if args.robust else []
                cmd += (["--variance-components", args.variance_components]
                        if args.variance_components else [])
                done = subprocess.run(cmd, capture_output=True, text=True, check=False)
                if done.returncode != 0:
                    print(f"{n} stations, {kind}: FAILED ({done.stderr.strip().splitlines()[-1]})")
                    continue
                cases[kind] = json.loads(done.stdout.strip().splitlines()[-1])
                cases[kind]["saved"] = np.load(out)
            for kind, c in cases.items():
                line = (f"{n} stations ({c['markers']} markers, {c['observations']} observations,"
                        f" {6 * c['stations'] + 3 * c['markers']} unknowns, seed {c['seed']}), "
                        f"{kind:6s}: "
                        f"{c['wall_s']:7.2f} s wall, {c['cpu_s']:7.2f} s CPU, peak RSS "
                        f"{c['peak_mb']:7.0f} MB (+{c['growth_mb']:.0f} MB in adjust), "
                        f"{c['rejected']} removed by snooping")
                if kind == "sparse" and "dense" in cases:
                    d, sv, dv = cases["dense"], c["saved"], cases["dense"]["saved"]
                    diff = max(float(np.max(np.abs(sv[k] - dv[k]) / np.maximum(np.abs(dv[k]),
                                                                                1e-300)))
                               for k in ("variance", "redundancy"))
                    line += (f"; sparse/dense: time {c['wall_s'] / d['wall_s']:.2f}, peak RSS "
                             f"{c['peak_mb'] / d['peak_mb']:.2f}, growth "
                             f"{c['growth_mb'] / max(d['growth_mb'], 1e-9):.3f}; largest "
                             f"relative difference of variances and redundancy numbers "
                             f"{diff:.1e}")
                print(line, flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stations", type=int, default=100)
    ap.add_argument("--markers-per-station", type=float, default=2.5)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--blas-threads", type=int, default=None)
    ap.add_argument("--robust", choices=("huber", "igg3"), default=None)
    ap.add_argument("--variance-components", choices=("station", "range"), default=None)
    ap.add_argument("--compare-covariance", type=int, nargs="+", default=None,
                    metavar="STATIONS")
    ap.add_argument("--dense-up-to", type=int, default=None, metavar="STATIONS")
    ap.add_argument("--case", choices=("dense", "sparse"), help=argparse.SUPPRESS)
    ap.add_argument("--case-out", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.blas_threads is not None:
        os.environ["OPENBLAS_NUM_THREADS"] = os.environ["OMP_NUM_THREADS"] = str(args.blas_threads)
    if args.case is not None:
        return _covariance_case(args)
    if args.compare_covariance is not None:
        return _compare_covariance(args)

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
