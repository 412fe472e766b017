"""Benchmark: time to fit the error model on 10,000 marker rows (target < 5 s), with the
resulting accuracy against the synthetic generator's truth.

Run from the project root:
    .venv/bin/python benchmarks/fit_error_model.py [--rows 10000] [--repeat 3]

Prints one line per repeat and a summary (median wall time, stages included: row checks,
10 basis candidates x 5-fold CV, optional-predictor selection, both final fits, 5-fold
envelope CV on 2000 rows, 40 bootstrap replicates).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from error_model.fit import fit_error_model  # noqa: E402
from error_model.table import as_marker_table, fit_data  # noqa: E402
from tests.error_model.synthetic import (  # noqa: E402
    synthetic_table,
    true_q95_factor,
    true_sigma,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    table = synthetic_table(args.rows, seed=21)
    heldout = synthetic_table(10_000, seed=22)
    fit_error_model(synthetic_table(300, seed=1), {"n_bootstrap": 2})  # imports, first compile
    times = []
    for r in range(args.repeat):
        t0 = time.perf_counter()
        model = fit_error_model(table, seed=r)
        times.append(time.perf_counter() - t0)
        print(f"repeat {r}: {times[-1]:.2f} s  rows used {model.info['data']['rows_used']}")
    data = fit_data(as_marker_table(heldout), 1)
    pred = model.predict(data.distance_m, data.elevation_rad)
    truth = true_sigma(data.distance_m, data.elevation_rad)
    rel = np.abs(pred.sigma_m / truth - 1)
    q_rel = np.abs(pred.q95_m / (true_q95_factor() * truth) - 1)
    print(f"median fit time for {args.rows} rows: {np.median(times):.2f} s (target < 5 s)")
    print(f"held-out: sigma |rel. error| median {np.median(rel):.3f} max {rel.max():.3f}; "
          f"q95 |rel. error| median {np.median(q_rel):.3f}; envelope coverage "
          f"{np.mean(data.error_m <= pred.q95_m):.3f}")


if __name__ == "__main__":
    main()
