"""``markerplan plan`` of this checkout against another one's, same run: markers, status, wall
time, their ratio, and which output files differ.

    .venv/bin/python -u benchmarks/plan_against.py --baseline /work/main/.venv/bin/markerplan
        [--site default] [--grid-spacing 1.0] [--requirement 0.1] [--time-limit 600]
        [--keep DIR] [-- extra plan options, e.g. --network]

Each plan runs in its own process (``OPENBLAS_NUM_THREADS=1``), the baseline first. Prints
one line per plan, the files that differ (byte for byte), and a final JSON object.
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _plan(cli: str, args: argparse.Namespace, config: Path, out: Path) -> dict:
    cmd = [cli, "plan", "--site", args.site, "--config", str(config), "--time-limit-s",
           str(args.time_limit), "--json", "--out", str(out), "--overwrite", *args.extra]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    t = time.perf_counter()
    run = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t
    if run.returncode:
        sys.exit(f"{cli} failed ({run.returncode}): {run.stderr.strip()[-500:]}")
    doc = json.loads((out / "plan.json").read_text())
    return {"n_markers": doc["n_markers"], "status": doc["solver"].get("status"),
            "dual_bound": doc["solver"].get("dual_bound"), "gap": doc["solver"].get("gap"),
            "wall_s": wall}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="The other checkout's markerplan.")
    ap.add_argument("--site", default="default")
    ap.add_argument("--grid-spacing", type=float, default=1.0, help="Candidate grid, m.")
    ap.add_argument("--requirement", type=float, default=0.1, help="requirement_m, m.")
    ap.add_argument("--time-limit", type=float, default=600.0, help="Solver time limit, s.")
    ap.add_argument("--keep", type=Path, help="Write the plans here.")
    ap.add_argument("extra", nargs="*", help="More plan options (after --).")
    args = ap.parse_args()

    root = args.keep or Path(tempfile.mkdtemp(prefix="markerplan-against-"))
    root.mkdir(parents=True, exist_ok=True)
    config = root / "plan.toml"
    config.write_text(f"grid_spacing_m = {args.grid_spacing}\n"
                      f"requirement_m = {args.requirement}\n")
    this = str(Path(sys.executable).with_name("markerplan"))
    out = {}
    for name, cli in (("baseline", args.baseline), ("this", this)):
        out[name] = _plan(cli, args, config, root / name)
        r = out[name]
        print(f"{name} ({cli}): {r['n_markers']} markers, status {r['status']}, bound "
              f"{r['dual_bound']}, gap {r['gap']}; {r['wall_s']:.1f} s wall")
    files = sorted(p.relative_to(root / "this") for p in (root / "this").rglob("*")
                   if p.is_file())
    other = sorted(p.relative_to(root / "baseline") for p in (root / "baseline").rglob("*")
                   if p.is_file())
    differ = [str(f) for f in files if f not in other
              or not filecmp.cmp(root / "this" / f, root / "baseline" / f, shallow=False)]
    differ += [str(f) for f in other if f not in files]
    out["wall_ratio_baseline_over_this"] = out["baseline"]["wall_s"] / out["this"]["wall_s"]
    out["files_differ"] = differ
    print(f"wall time: baseline / this = {out['wall_ratio_baseline_over_this']:.2f}; "
          f"{len(files)} files, differing: {', '.join(differ) or 'none'}")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
