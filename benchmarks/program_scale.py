"""Integer program at scale: ``plan_sites`` on main (baseline revision), the plain
cover-plus-sector model given to highspy directly, and the current ``plan_sites``, alternating
in one run on the ``large`` site at a 1 m candidate grid; then network mode before/after.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -u benchmarks/program_scale.py [--site large]
        [--grid-spacing 1.0] [--repeats 3] [--baseline-rev 6391827]
        [--network-site default] [--network-grid 1.0]

The problem (ray casting takes minutes) is built once and cached under /tmp as an .npz keyed
by site, seed and settings. The baseline ``plan_sites`` runs from a ``git worktree`` of
``--baseline-rev`` at /tmp/base-prog in a subprocess (its own imports), fed the same cached
problem. Prints one line per run (time, time solving, objective, bound, gap, status), the
median times and the ratios current/plain and current/baseline, the median time outside the
solves of each (model building, checks: what the planner adds to the solver), and a final
JSON object. Time solving: HiGHS for (b); ``PlanResult.solve_time_s`` for ``plan_sites``
(HiGHS and its solution's post-processing, e.g. moving markers within identical sites).
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
    """The :class:`~planner.problem.usability.PlanProblem` of a site preset (default config, the
    given grid), from the /tmp cache or built (and cached)."""
    from planner.problem.usability import PlanProblem

    path = cache_path(site, seed, grid_spacing)
    if not path.exists():
        from error_model import default_model
        from planner.config import PlanConfig
        from planner.problem.inputs import load_inputs
        from planner.run import build_problem

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


def _summary(result, t: float) -> dict:
    """Time (total and solving), markers and the solver's status, objective, bound and gap
    of one plan."""
    sol = result.solution
    return {"time_s": t, "solver_s": result.solve_time_s, "markers": int(result.selected.sum()),
            "status": sol.status,
            "objective": sol.objective, "bound": sol.dual_bound, "gap": sol.gap}


def run_plan(site: str, grid: float, network: bool, time_limit: float) -> dict:
    """``plan_sites`` of whatever ``planner`` this interpreter imports, on a cached problem."""
    import planner
    from planner.config import PlanConfig
    from planner.program import plan_sites

    problem = cached_problem(site, None, grid)
    config = PlanConfig(grid_spacing_m=grid, time_limit_s=time_limit, network=network)
    t = time.perf_counter()
    result = plan_sites(problem, config)
    out = _summary(result, time.perf_counter() - t)
    out["planner"] = str(Path(planner.__file__).parent)
    return out


def run_baseline(base: Path, site: str, grid: float, network: bool, time_limit: float) -> dict:
    """:func:`run_plan` in a subprocess that imports ``planner`` from the checkout ``base``."""
    code = (f"import sys; sys.path[:0] = [{str(base)!r}, {str(Path(__file__).parent)!r}]; "
            "import json, program_scale as b; "
            f"print(json.dumps(b.run_plan({site!r}, {grid}, {network}, {time_limit})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=base)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if not result["planner"].startswith(str(base)):
        raise RuntimeError(f"baseline imported planner from {result['planner']}, not {base}")
    return result


def plain_model(problem, config) -> dict:
    """The plain cover-plus-sector model given to highspy directly (2 threads): ``x_j`` per
    candidate site with a usable pair, ``y_sk`` per station and occupied sector; rows
    ``sum_{j in U_s} x_j >= min_markers``, ``y_sk <= sum_{j in U_s, sector k} x_j``,
    ``sum_k y_sk >= min_sectors``; minimise the number of markers."""
    import highspy
    import scipy.sparse as sp

    from planner.problem.usability import sector_index

    t = time.perf_counter()
    use = np.flatnonzero(problem.pair_usable)
    sites, col = np.unique(problem.pair_site[use], return_inverse=True)
    station = problem.pair_station[use]
    nx, ns = sites.size, problem.n_stations
    sk = station * config.n_sectors + sector_index(problem.pair_bearing_rad[use],
                                                    config.n_sectors)
    occupied, y_of = np.unique(sk, return_inverse=True)
    ny = occupied.size
    count = sp.csr_array((np.ones(use.size), (station, col)), shape=(ns, nx + ny))
    sector = sp.csr_array((np.r_[-np.ones(use.size), np.ones(ny)],
                           (np.r_[y_of, np.arange(ny)], np.r_[col, nx + np.arange(ny)])),
                          shape=(ny, nx + ny))
    directions = sp.csr_array((np.ones(ny), (occupied // config.n_sectors, nx + np.arange(ny))),
                              shape=(ns, nx + ny))
    # rows station by station (count, its sectors, directions), as a model is usually written
    row_station = np.r_[np.arange(ns), occupied // config.n_sectors, np.arange(ns)]
    row_part = np.r_[np.zeros(ns), 1 + occupied % config.n_sectors,
                     np.full(ns, 1 + config.n_sectors)]
    order = np.lexsort((row_part, row_station))
    a = sp.csc_array(sp.vstack([count, sector, directions]).tocsr()[order])
    lo = np.r_[np.full(ns, config.min_markers), np.full(ny, -np.inf),
               np.full(ns, config.min_sectors)][order]
    hi = np.r_[np.full(ns, np.inf), np.zeros(ny), np.full(ns, np.inf)][order]
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("threads", 2)
    h.setOptionValue("time_limit", config.time_limit_s)
    h.setOptionValue("mip_rel_gap", config.mip_gap)
    n = nx + ny
    t_solver = time.perf_counter()
    h.passModel(n, a.shape[0], a.nnz, 1, 1, 0.0, np.r_[np.ones(nx), np.zeros(ny)],
                np.zeros(n), np.ones(n), lo, hi, a.indptr.astype(np.int32),
                a.indices.astype(np.int32), a.data, np.ones(n, np.int32))
    h.run()
    info = h.getInfo()
    t_end = time.perf_counter()
    return {"time_s": t_end - t, "solver_s": t_end - t_solver,
            "markers": round(info.objective_function_value),
            "status": h.modelStatusToString(h.getModelStatus()),
            "objective": info.objective_function_value, "bound": info.mip_dual_bound,
            "gap": info.mip_gap}


def _line(name: str, r: dict) -> str:
    return (f"  {name}: {r['time_s']:.2f} s ({r['solver_s']:.2f} s solving), "
            f"{r['markers']} markers, status {r['status']}, "
            f"objective {r['objective']:g}, bound {r['bound']:g}, gap {r['gap']:.3g}")


def _median(runs: list, key: str = "time_s") -> float:
    return statistics.median(r[key] for r in runs)


def _outside(runs: list) -> float:
    """Median time outside the solves (model building, checks), s."""
    return statistics.median(r["time_s"] - r["solver_s"] for r in runs)


def _alternate(repeats: int, contenders: list) -> dict:
    """Run each ``(key, label, run)`` of ``contenders`` in turn, ``repeats`` rounds, printing
    each run's line; returns ``{key: [run's result, ...]}``."""
    runs = {key: [] for key, _, _ in contenders}
    for rep in range(repeats):
        print(f"repeat {rep + 1}", flush=True)
        for key, label, run in contenders:
            runs[key].append(run())
            print(_line(label, runs[key][-1]), flush=True)
    return runs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="large")
    ap.add_argument("--grid-spacing", type=float, default=1.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--time-limit", type=float, default=120.0)
    ap.add_argument("--baseline-rev", default="6391827")
    ap.add_argument("--network-site", default="default")
    ap.add_argument("--network-grid", type=float, default=1.0)
    args = ap.parse_args()

    from planner.config import PlanConfig
    from planner.program.highs import highs_version

    base = Path("/tmp/base-prog")
    if not base.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(base), args.baseline_rev],
                       check=True, cwd=Path(__file__).parent, capture_output=True)
    problem = cached_problem(args.site, None, args.grid_spacing)
    config = PlanConfig(grid_spacing_m=args.grid_spacing, time_limit_s=args.time_limit)
    print(f"site {args.site} at {args.grid_spacing:g} m: {problem.n_stations} stations, "
          f"{problem.n_sites:,} candidate sites, {int(problem.pair_usable.sum()):,} usable "
          f"pairs; HiGHS {highs_version()}; baseline {args.baseline_rev}", flush=True)
    runs = _alternate(args.repeats, [
        ("a", "(a) plan_sites at baseline",
         lambda: run_baseline(base, args.site, args.grid_spacing, False, args.time_limit)),
        ("b", "(b) plain cover+sector in highspy", lambda: plain_model(problem, config)),
        ("c", "(c) plan_sites now",
         lambda: run_plan(args.site, args.grid_spacing, False, args.time_limit))])
    med = {k: _median(v) for k, v in runs.items()}
    print(f"median: (a) {med['a']:.2f} s, (b) {med['b']:.2f} s, (c) {med['c']:.2f} s; "
          f"(c)/(b) {med['c'] / med['b']:.2f}, (c)/(a) {med['c'] / med['a']:.2f}", flush=True)
    outside = {k: _outside(v) for k, v in runs.items()}
    print(f"median outside the solves: (a) {outside['a']:.2f} s, (b) {outside['b']:.2f} s, "
          f"(c) {outside['c']:.2f} s", flush=True)

    net_problem = cached_problem(args.network_site, None, args.network_grid)
    print(f"network mode, site {args.network_site} at {args.network_grid:g} m: "
          f"{net_problem.n_stations} stations, {net_problem.n_sites:,} candidate sites",
          flush=True)
    net = _alternate(args.repeats, [
        ("a", "(a) plan_sites --network at baseline",
         lambda: run_baseline(base, args.network_site, args.network_grid, True,
                              args.time_limit)),
        ("c", "(c) plan_sites --network now",
         lambda: run_plan(args.network_site, args.network_grid, True, args.time_limit))])
    net_med = {k: _median(v) for k, v in net.items()}
    print(f"network median: (a) {net_med['a']:.2f} s, (c) {net_med['c']:.2f} s; "
          f"(c)/(a) {net_med['c'] / net_med['a']:.2f}", flush=True)
    print(json.dumps({"site": args.site, "grid_spacing_m": args.grid_spacing,
                      "highs": highs_version(), "baseline": args.baseline_rev, "runs": runs,
                      "median_s": med, "outside_solves_median_s": outside,
                      "c_over_b": med["c"] / med["b"],
                      "c_over_a": med["c"] / med["a"], "network_site": args.network_site,
                      "network_runs": net, "network_median_s": net_med,
                      "network_c_over_a": net_med["c"] / net_med["a"]}))


if __name__ == "__main__":
    main()
