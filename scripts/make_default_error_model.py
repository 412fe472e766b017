"""Regenerate ``error_model/data/default_model.json``, the error model shipped with markerplan.

Data: our own simulation of the rig with the ``calibrated`` sensor profile — the published
range experiment (0.20 m markers every 1 m from 1-15 m, every 2 m from 15-25 m, every 5 m from
25-50 m, 800 frames) run by ``markerplan range-study --extraction full-chain`` (the station chain
of ``process`` and ``verify``: ground removal, clustering, gate, re-search, fit, quality; a
marker the chain loses is a rejected row, so the model's domain is where the chain delivers)
on six relief variants (:data:`VARIANTS`): the LiDAR centre 0.8 m and 1.5 m above the ground
(the tripod's lowest and highest setting) times ground slopes of -15, 0 and +15 deg (markers
resting on a plane through the station's foot). On a slope the markers uphill are seen up to
~15 deg higher than on level ground and the markers downhill up to ~15 deg lower, so at every
distance the data span the elevations crater terrain gives (from -59 deg at 1 m to +14 deg
beyond 10 m). The error model's predictors are distance and elevation, not height or slope:
the two extreme heights span the elevations of every height in between, the two signs of the
slope put each marker of the layout once uphill and once downhill, and the level variants fill
the middle with markers at every azimuth. One
replicate per variant (variant ``k``, replicate ``r`` simulated with seed ``seed + k *
replicates + r``) keeps the scan count of the former level-ground design (6 replicates).

The model is fitted on the ``fixed-radius`` estimator's rows (the estimator ``markerplan
process`` uses by default) of all variants together, with the default fit settings and fit
seed 0, except that the point count is not offered as a predictor: the table's ``n_points``
counts the points the fit used, while the planner's ``expected_points`` counts all expected
returns on the marker (about 1.4 times more at 10 m), so a model using it would be optimistic in
planning.
Every step is seeded: on one machine a rerun is byte-identical. Across machines the range
studies (and so the data fingerprint) are identical, but the convex solver's last digits depend
on the CPU's vector instructions (seen: relative differences up to ~1e-13 between two
machines), so ``--check`` compares the data exactly and every number to a relative 1e-9
(absolute 1e-12).

Usage, from the project root:
    .venv/bin/python scripts/make_default_error_model.py            # rewrite the JSON
    .venv/bin/python scripts/make_default_error_model.py --check    # compare, exit 1 if stale
    .venv/bin/python scripts/make_default_error_model.py --keep range/   # keep the studies
    .venv/bin/python scripts/make_default_error_model.py --frames 100 --output /tmp/m.json
                                                                    # smoke run, ~1.5 min

Runtime: one variant is a full 800-frame station simulation with the beam footprint and its
processing by the full chain. The six variants and the fit took 22 min 50 s wall (8 min 9 s
user and 20 s system CPU) on 2026-12-03 on two cores shared with four other sessions (load
average 9-15); the smoke run (``--frames 100``) took 87 s. On two idle cores expect well under
10 min (an estimate, not measured).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from error_model.config import FitConfig  # noqa: E402
from error_model.default import DEFAULT_MODEL_PATH  # noqa: E402
from error_model.fit import fit_error_model  # noqa: E402
from error_model.table import read_marker_tables  # noqa: E402
from planner.cli import cli  # noqa: E402
from visibility.sensor_profile import DEFAULT_PROFILE  # noqa: E402

#: Relief variants: (LiDAR height m, ground slope deg).
VARIANTS = ((0.8, -15.0), (0.8, 0.0), (0.8, 15.0), (1.5, -15.0), (1.5, 0.0), (1.5, 15.0))
REPLICATES = 1
FRAMES = 800
STUDY_SEED = 0
FIT_SEED = 0
ESTIMATOR = "fixed-radius"
#: The station chain of ``process`` and ``verify`` (ground removal, clustering, gate,
#: re-search, fit, quality); ``truth-seeded`` is a diagnostic and never feeds the model.
EXTRACTION = "full-chain"
EXTRA_CANDIDATES = ("visible_fraction",)


def run_variants(folder: Path, profile: str, replicates: int, frames: int,
                 seed: int) -> list[Path]:
    """Run ``markerplan range-study`` once per variant into ``folder`` and return the marker
    tables, in :data:`VARIANTS` order."""
    tables = []
    for k, (height, slope) in enumerate(VARIANTS):
        out = folder / f"h{height:.1f}_slope{slope:+.0f}"
        cli.main(args=["range-study", "--out", str(out), "--sensor-profile", profile,
                       "--replicates", str(replicates), "--frames", str(frames),
                       "--seed", str(seed + k * replicates), "--lidar-height-m", str(height),
                       "--slope-deg", str(slope), "--extraction", EXTRACTION],
                 prog_name="markerplan", standalone_mode=False)
        tables.append(out / "markers.csv")
    return tables


def build_model(tables: list[Path], profile: str, replicates: int, frames: int, seed: int):
    """Fit the default model on the fixed-radius rows of every variant's marker table."""
    variants = ", ".join(f"{h} m / {s:+.0f} deg" for h, s in VARIANTS)
    description = (f"simulation of the rig with sensor profile {profile}: `markerplan "
                   f"range-study --sensor-profile {profile} --replicates {replicates} --frames "
                   f"{frames} --lidar-height H --slope-deg S --extraction {EXTRACTION}` for "
                   f"(H, S) in {variants}, seeds "
                   f"from {seed}; estimator {ESTIMATOR}, optional predictors offered "
                   f"{list(EXTRA_CANDIDATES)}; regenerated by "
                   "scripts/make_default_error_model.py")
    table = read_marker_tables(tables)
    config = FitConfig(estimator=ESTIMATOR, extra_candidates=EXTRA_CANDIDATES)
    return fit_error_model(table, config, seed=FIT_SEED, description=description)


CHECK_RTOL = 1e-9
#: Coefficients at their zero bound (e.g. 2e-13 m) differ relatively more; they are metres,
#: metres squared or ratios, so 1e-12 absolute is far below anything meaningful.
CHECK_ATOL = 1e-12


def _differences(shipped, fresh, where: str):
    """Yield where two model JSON documents differ: structure and non-numbers exactly, numbers
    beyond ``CHECK_RTOL`` (relative) and ``CHECK_ATOL``."""
    if isinstance(shipped, dict) and isinstance(fresh, dict):
        for key in sorted(set(shipped) | set(fresh)):
            if key not in shipped or key not in fresh:
                yield f"{where}/{key} only in one file"
            else:
                yield from _differences(shipped[key], fresh[key], f"{where}/{key}")
    elif isinstance(shipped, list) and isinstance(fresh, list):
        if len(shipped) != len(fresh):
            yield f"{where} has {len(shipped)} items, a rerun {len(fresh)}"
        else:
            for i, (a, b) in enumerate(zip(shipped, fresh, strict=True)):
                yield from _differences(a, b, f"{where}[{i}]")
    elif (isinstance(shipped, float | int) and isinstance(fresh, float | int)
          and not isinstance(shipped, bool) and not isinstance(fresh, bool)):
        if not math.isclose(shipped, fresh, rel_tol=CHECK_RTOL, abs_tol=CHECK_ATOL):
            yield f"{where}: {shipped!r} vs {fresh!r}"
    elif shipped != fresh:
        yield f"{where}: {shipped!r} vs {fresh!r}"


def check_shipped(model, output: Path, scratch: Path) -> int:
    """``--check``: compare a freshly built model (anything with ``save(path)``) with the
    shipped JSON ``output`` (:func:`_differences`), print the verdict; 0 when up to date, 1
    when stale or missing. ``scratch``: a folder for the fresh JSON."""
    fresh = json.loads(model.save(scratch / "fresh.json").read_text())
    shipped = json.loads(output.read_text()) if output.exists() else None
    problems = list(_differences(shipped, fresh, "")) if shipped else ["missing"]
    verdict = "up to date" if not problems else "STALE: " + "; ".join(problems[:5])
    print(f"{output}: {verdict}")
    return 0 if not problems else 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sensor-profile", default=DEFAULT_PROFILE,
                        help="Sensor profile name or file (default %(default)s).")
    parser.add_argument("--replicates", type=int, default=REPLICATES,
                        help="Replicates per variant (default %(default)s).")
    parser.add_argument("--frames", type=int, default=FRAMES,
                        help="Frames per turntable revolution (default %(default)s; 100 for a "
                             "smoke run).")
    parser.add_argument("--seed", type=int, default=STUDY_SEED)
    parser.add_argument("--check", action="store_true",
                        help="Do not write; exit 1 if the shipped JSON differs.")
    parser.add_argument("--keep", type=Path, default=None,
                        help="Keep the range-study outputs in this (new) folder.")
    parser.add_argument("--output", type=Path, default=DEFAULT_MODEL_PATH)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep if args.keep is not None else Path(tmp) / "range"
        tables = run_variants(folder, args.sensor_profile, args.replicates, args.frames,
                              args.seed)
        model = build_model(tables, args.sensor_profile, args.replicates, args.frames,
                            args.seed)
        if args.check:
            return check_shipped(model, args.output, Path(tmp))
    model.save(args.output)
    data = model.info["data"]
    print(f"wrote {args.output}: {data['rows_used']} rows, predictors {model.predictors}, "
          f"fingerprint {data['fingerprint'][:12]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
