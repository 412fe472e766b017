"""The ``km`` site preset planned with tiled terrain: ``markerplan plan`` and ``plan --network``
on a 1 km x 1 km crater field at 0.25 m cells (4001 x 4001) with ~300 stations.

Prints, one line each: the preset's build time and peak RSS; for each plan the markers, solver
status, bound/gap, wall time per stage and peak RSS (each in its own process); and, as the
baseline, the peak RSS a mesh of the whole site would need, extrapolated from a scene built on
one tile in the same run (a whole-site scene is not built). Finally one JSON object.

    .venv/bin/python -u benchmarks/km_plan.py [--grid-spacing 4] [--network-grid-spacing G]
        [--time-limit 120] [--network-time-limit 600] [--network-requirement 6] [--keep DIR]
        [--network-local 0.10] [--network-within 50] [--error-figure quantile]
        [--heading-aid sun-sensor|star-tracker] [--chance-epsilon none|0.05]
        [--pass-rate-samples N] [--datum station|free] [--set KEY=VALUE ...]
        [--plans plan,plan_network]

The network plan's requirement is relative to the station nearest the centre, without a heading
aid. With every one of the 19,470 tying sites (4 m grid) the farthest stations reach 1.96 m, and
with a random 60 % of them 2.5 m (the error shrinks about as one over the square root of the
number of markers): 2.5 m would take thousands of markers. 6 m is met by the greedy with about
900.

``--network-local R`` plans the network to a local requirement instead: every pair of stations
within ``--network-within`` m to ``R`` m relative to each other (``local_requirement_m``,
``local_within_m``, ``datum_requirement = false``; datum still at the centre station).
``--plans`` picks the plans run (default both).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Side of the tile the whole-site mesh is extrapolated from, DEM cells.
PROBE_CELLS = 801


def _child(cmd: list[str], log: Path) -> tuple[int, float, float]:
    """Run ``cmd`` (stdout to ``log``, stderr to ``log`` + ``.err``); return (exit code,
    wall s, peak RSS MB of that process alone)."""
    t = time.perf_counter()
    with open(log, "w") as out, open(f"{log}.err", "w") as err:
        proc = subprocess.Popen(cmd, stdout=out, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
    return os.waitstatus_to_exitcode(status), time.perf_counter() - t, usage.ru_maxrss / 1024


_SITE_PROBE = """
import json, resource, time
import numpy as np
t = time.perf_counter()
from visibility.sites import load_site
site = load_site("km")
print(json.dumps({"s": time.perf_counter() - t, "shape": list(site.dem.shape),
                  "cell_m": site.dem.cell_size_m, "extent_m": list(site.dem.extent()),
                  "stations": len(site.station_ids), "markers": len(site.marker_ids),
                  "craters": len(site.craters), "rocks": len(site.rock_radii_m),
                  "centre_station": site.station_ids[int(np.argmin(np.hypot(
                      *site.station_xy_m.T)))],
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""

_MESH_PROBE = """
import json, resource, sys, time
import numpy as np
from visibility.dem import DEM
from visibility.scene import RayScene
from visibility.terrain import fractal_surface
n = int(sys.argv[1])
dem = DEM(fractal_surface((n, n), 0.25, 0.85, 0.02, 30.0, np.random.default_rng(0)),
          (0.0, 0.0), 0.25)
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
t = time.perf_counter()
scene = RayScene(dem)
scene.intersect(np.array([[50.0, 50.0, 5.0]]), np.array([[0.0, 0.0, -1.0]]))  # builds the BVH
s = time.perf_counter() - t
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"triangles": scene.n_triangles, "mb": after - before, "s": s}))
"""


def _probe(code: str, *args: str) -> dict:
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _setting(text: str) -> float | str:
    """A command-line value as a TOML setting: a number, else the string (``"none"``)."""
    try:
        return float(text)
    except ValueError:
        return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid-spacing", type=float, default=4.0,
                    help="Candidate grid spacing, m (the 1 m default gives ~1 M grid points).")
    ap.add_argument("--network-grid-spacing", type=float,
                    help="Candidate grid spacing of the network plan, m (default --grid-spacing; "
                         "network mode takes at most 20,000 sites seen by two stations).")
    ap.add_argument("--time-limit", type=float, default=120.0, help="Solver time limit, s.")
    ap.add_argument("--network-time-limit", type=float, default=600.0,
                    help="Time limit of the network plan, s (its greedy incumbent gets half).")
    ap.add_argument("--network-requirement", type=float, default=6.0,
                    help="requirement_m of the network plan, m (relative to the station nearest "
                         "the centre; with every site the farthest stations reach only 1.96 m).")
    ap.add_argument("--network-local", type=float,
                    help="local_requirement_m of the network plan, m (then datum_requirement = "
                         "false: only pairs within --network-within m are judged)")
    ap.add_argument("--network-within", type=float, default=50.0,
                    help="local_within_m of the network plan with --network-local, m")
    ap.add_argument("--error-figure", help="error_figure of the network plan (default the "
                                           "planner's)")
    ap.add_argument("--heading-aid", help="heading_aid of the network plan (default none)")
    ap.add_argument("--chance-epsilon", help="chance_epsilon of the network plan (default the "
                                             "planner's; none: the naive plan)")
    ap.add_argument("--pass-rate-samples", type=int,
                    help="pass_rate_samples of the network plan (default the planner's 2,000; "
                         "each judges the whole 311-station network)")
    ap.add_argument("--datum", choices=("station", "free"), default="station",
                    help="datum of the network plan: the station nearest the centre "
                         "(default), or a free network (with --network-local only)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="another setting of the network plan, as a TOML line (repeatable), "
                         "e.g. --set 'local_kind=\"distance\"'")
    ap.add_argument("--plans", default="plan,plan_network",
                    help="plans to run, comma-separated: plan, plan_network")
    ap.add_argument("--keep", type=Path, help="Write the configuration and plans here.")
    args = ap.parse_args()

    root = args.keep or Path(tempfile.mkdtemp(prefix="markerplan-km-"))
    root.mkdir(parents=True, exist_ok=True)
    site = _probe(_SITE_PROBE)
    print(f"km preset: DEM {site['shape'][1]} x {site['shape'][0]} cells of {site['cell_m']} m "
          f"over {site['extent_m']}, {site['stations']} stations, {site['markers']} markers, "
          f"{site['craters']} craters, {site['rocks']} rocks; built in {site['s']:.1f} s, "
          f"peak RSS {site['peak_mb']:.0f} MB")
    cells = site["shape"][0] * site["shape"][1]
    whole_triangles = 2 * (site["shape"][0] - 1) * (site["shape"][1] - 1)
    mesh = _probe(_MESH_PROBE, str(PROBE_CELLS))
    whole_mb = mesh["mb"] / mesh["triangles"] * whole_triangles
    whole_s = mesh["s"] / mesh["triangles"] * whole_triangles
    print(f"baseline: a scene of {mesh['triangles']:,} triangles adds {mesh['mb']:.0f} MB peak "
          f"RSS and builds in {mesh['s']:.2f} s; the whole site ({whole_triangles:,} triangles, "
          f"{cells:,} cells) would add ~{whole_mb:,.0f} MB and take ~{whole_s:.0f} s "
          "(extrapolated, not built)")

    config = root / "km.toml"
    config.write_text(f"grid_spacing_m = {args.grid_spacing}\n")
    network = root / "km-network.toml"
    lines = [f"grid_spacing_m = {args.network_grid_spacing or args.grid_spacing}",
             f"requirement_m = {args.network_requirement}"]
    if args.network_local is not None:
        lines += ["network = true", f"local_requirement_m = {args.network_local}",
                  f"local_within_m = {args.network_within}", "datum_requirement = false"]
    if args.error_figure:
        lines.append(f'error_figure = "{args.error_figure}"')
    if args.heading_aid:
        lines.append(f'heading_aid = "{args.heading_aid}"')
    lines += args.set
    if args.pass_rate_samples is not None:
        lines.append(f"pass_rate_samples = {args.pass_rate_samples}")
    if args.chance_epsilon:
        lines.append(f"chance_epsilon = {json.dumps(_setting(args.chance_epsilon))}")
    network.write_text("\n".join(lines) + "\n")
    cli = str(Path(sys.executable).with_name("markerplan"))
    figures = {"site": site, "whole_mesh_mb": whole_mb, "whole_mesh_s": whole_s,
               "probe_mesh": mesh}
    runs = (("plan", config, args.time_limit, []),
            ("plan_network", network, args.network_time_limit,
             ["--network", "--datum", "free"] if args.datum == "free"
             else ["--network", "--reference-station", site["centre_station"]]))
    for name, cfg, limit, extra in (r for r in runs if r[0] in args.plans.split(",")):
        out = root / name
        cmd = [cli, "plan", "--site", "km", "--config", str(cfg), "--time-limit-s", str(limit),
               "--json", "--out", str(out), "--overwrite", *extra]
        code, wall, peak = _child(cmd, root / f"{name}.log")
        if code:
            tail = Path(f"{root / name}.log.err").read_text().strip().splitlines()[-1:]
            sys.exit(f"{name} failed ({code}) after {wall:.0f} s wall, peak RSS {peak:.0f} MB: "
                     f"{tail}")
        summary = json.loads((root / f"{name}.log").read_text().strip().splitlines()[-1])
        doc = json.loads((out / "plan.json").read_text())
        solver = doc["solver"]
        cast_s = summary["timings_s"]["scene"] + summary["timings_s"]["visibility"]
        stages = ", ".join(f"{k} {v:.1f} s" for k, v in summary["timings_s"].items())
        req = "" if not extra else (
            f" (local requirement {args.network_local:g} m within {args.network_within:g} m, "
            f"datum {site['centre_station']})" if args.network_local is not None else
            f" (requirement {args.network_requirement:g} m relative to "
            f"{site['centre_station']}: 0.1 m is out of reach ~200 m from it)")
        greedy = summary.get("baselines", {}).get("greedy", {})
        print(f"{name}{req}: {doc['n_markers']} markers (greedy {greedy.get('n_markers')}, "
              f"meets: {greedy.get('meets_requirement')}), status {solver.get('status')}, bound "
              f"{solver.get('dual_bound')}, gap {solver.get('gap')}; {wall:.0f} s wall "
              f"({stages}); peak RSS {peak:.0f} MB = {peak / whole_mb:.2f} x the whole-site "
              f"mesh alone; tile scenes + ray casting {cast_s / whole_s:.2f} x its build time")
        figures[name] = {"n_markers": doc["n_markers"], "solver": solver, "wall_s": wall,
                         "peak_rss_mb": peak, "peak_vs_whole_mesh": peak / whole_mb,
                         "cast_vs_whole_mesh_build": cast_s / whole_s,
                         "timings_s": summary["timings_s"], "greedy": greedy,
                         "candidates": doc.get("candidates")}
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
