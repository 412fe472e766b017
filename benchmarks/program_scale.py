"""Integer program at scale: ``plan_sites`` on main (baseline revision), the plain
cover-plus-sector model given to highspy directly, and the current ``plan_sites``, alternating
in one run on the ``large`` site at a 1 m candidate grid; then network mode before/after.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -u benchmarks/program_scale.py [--site large]
        [--grid-spacing 1.0] [--repeats 3] [--baseline-rev 6391827]
        [--network-site default] [--network-grid 1.0]

The problem (ray casting takes minutes) is built once and cached under /tmp as an .npz keyed
by site, seed and settings. The baseline ``plan_sites`` runs from a ``git worktree`` of
``--baseline-rev`` at /tmp/base-prog in a subprocess (its own imports), fed the same cached
problem. Prints one line per run (time, objective, bound, gap, status), the median times and
the ratios current/plain and current/baseline, and a final JSON object.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

_FIELDS = ("station_xyz", "site_xyz", "site_existing", "site_cost", "pair_station", "pair_site",
           "pair_distance_m", "pair_bearing_rad", "pair_sigma_m", "pair_reason")


def cache_path(site: str, seed: int | None, grid_spacing: float) -> Path:
    """Where the cached problem of one site, seed and grid lives."""
    return Path(f"/tmp/markerplan-program-scale-{site}-seed{seed}-grid{grid_spacing:g}.npz")


def cached_problem(site: str, seed: int | None, grid_spacing: float):
    """The :class:`~planner.usability.PlanProblem` of a site preset (default config, the
    given grid), from the /tmp cache or built (and cached)."""
    from planner.usability import PlanProblem

    path = cache_path(site, seed, grid_spacing)
    if not path.exists():
        from error_model import default_model
        from planner.config import PlanConfig
        from planner.planning import build_problem, load_inputs

        t = time.perf_counter()
        inputs = load_inputs(site, seed)
        problem = build_problem(inputs, PlanConfig(grid_spacing_m=grid_spacing),
                                default_model(), progress=False)[0]
        np.savez(path, station_ids=np.array(problem.station_ids),
                 site_ids=np.array(problem.site_ids),
                 **{f: getattr(problem, f) for f in _FIELDS})
        print(f"built and cached {path} in {time.perf_counter() - t:.0f} s", flush=True)
    with np.load(path) as z:
        return PlanProblem(station_ids=tuple(z["station_ids"].tolist()),
                           site_ids=tuple(z["site_ids"].tolist()),
                           **{f: z[f] for f in _FIELDS})


if __name__ == "__main__" and sys.argv[1:2] == ["--prepare"]:
    p = cached_problem(sys.argv[2], None, float(sys.argv[3]))
    print(p.n_stations, p.n_sites, int(p.pair_usable.sum()))
