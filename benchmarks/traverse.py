"""Trafficability of the site presets and the traverse's solve time (:mod:`planner.traverse`).

Prints, one line each: for each site (default settings, the preset's craters) the map's build
time, node count and the fraction of nodes trafficable and failing each rule; then, on
``large``, for 10, 30 and 100 random trafficable stations reachable from the centre, the
ground-path time (Dijkstra), PyVRP's solve time and tour length, and as the baseline the
nearest-neighbour tour (from the start, always to the nearest unvisited station) on the same
drive lengths, with the ratio PyVRP / nearest neighbour. Finally one JSON object.

    .venv/bin/python -u benchmarks/traverse.py [--sites default,large] [--counts 10,30,100]
        [--seed 0]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from planner.traverse.ground_paths import ground_paths, reachable_nodes
from planner.traverse.route import RouteSettings, solve_tour
from planner.traverse.trafficability import TrafficSettings, trafficable_map
from visibility.sites import load_site


def nearest_neighbour_length(d: np.ndarray) -> float:
    """Length of the nearest-neighbour closed tour from point 0 over ``d`` (k, k), metres."""
    left = set(range(1, len(d)))
    at, total = 0, 0.0
    while left:
        nxt = min(left, key=lambda j: (d[at, j], j))
        total += d[at, nxt]
        left.remove(nxt)
        at = nxt
    return total + d[at, 0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sites", default="default,large")
    ap.add_argument("--counts", default="10,30,100")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    settings = TrafficSettings()
    out = {"settings": dataclasses.asdict(settings),
           "sites": {}, "routes": []}
    maps = {}
    for name in args.sites.split(","):
        site = load_site(name)
        t = time.perf_counter()
        tm = trafficable_map(site.dem, settings, craters=site.craters)
        dt = time.perf_counter() - t
        counts = tm.counts()
        n = sum(counts.values())
        frac = {k: round(v / n, 4) for k, v in counts.items()}
        print(f"{name}: {tm.shape[0]} x {tm.shape[1]} nodes at {tm.grid_m:g} m, "
              f"{len(site.craters)} craters, map {dt:.2f} s; fractions {frac}", flush=True)
        out["sites"][name] = {"nodes": n, "seconds": round(dt, 3), "fractions": frac}
        maps[name] = (site, tm)
    site, tm = maps["large"] if "large" in maps else next(iter(maps.values()))
    start = tm.nearest_trafficable(np.zeros((1, 2)))[0]
    reach = reachable_nodes(tm, start).ravel()
    nodes = tm.node_xy()[reach]
    rng = np.random.default_rng(args.seed)
    for k in (int(c) for c in args.counts.split(",")):
        xy = nodes[rng.choice(len(nodes), k, replace=False)]
        t = time.perf_counter()
        paths = ground_paths(tm, np.vstack([start, xy]), ["start"] + [f"P{i}" for i in range(k)])
        t_paths = time.perf_counter() - t
        t = time.perf_counter()
        _, rec = solve_tour(paths.distance_m, RouteSettings())
        t_solve = time.perf_counter() - t
        nn = nearest_neighbour_length(paths.distance_m)
        row = {"stations": k, "paths_s": round(t_paths, 2), "solve_s": round(t_solve, 2),
               "pyvrp_m": round(rec["objective_m"], 1), "nearest_neighbour_m": round(nn, 1),
               "ratio": round(rec["objective_m"] / nn, 3), "stop": rec["stop"]}
        print(f"{k} stations: paths {t_paths:.2f} s, PyVRP {t_solve:.2f} s "
              f"({rec['stop']}) {rec['objective_m']:.1f} m, nearest neighbour {nn:.1f} m, "
              f"ratio {row['ratio']}", flush=True)
        out["routes"].append(row)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
