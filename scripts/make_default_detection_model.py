"""Regenerate ``error_model/data/default_detection_model.json``, the detection model shipped
with markerplan.

Data: our own simulation of the rig with the ``calibrated`` sensor profile — loss studies
(:mod:`planner.studies.loss_study`: every scan simulated and run through the full station chain
exactly as ``verify`` runs it, one row per station–marker pair in range with its fate and the
planner's covariates) on the layouts of :data:`STUDIES`:

- ``default-t0``: the ``default`` site (terrain seed 0: its seven stations, five named craters,
  random small craters, rocks and boulders), markers on a jittered 4 m grid over the working
  area (jitter seed 0), dealt to 4 interleaved sets, one set per simulation seed, so each set is
  scanned once from every station in 4 seeds;
- ``default-t1``: the same preset with terrain seed 1 (other small craters and rocks, other
  marker jitter): another relief, its markers in 2 sets scanned in 2 seeds (half the scans of
  ``default-t0``, for the runtime);
- ``level``: one station 1 m above a level field with the 25 markers of the published range
  experiment (1-50 m), 4 seeds.

Together they cover 1.3-40 m on relief and 1.3-50 m on the level field, rims within 0.5 m and
slopes up to ~38 deg. Simulation seeds are distinct across studies (``default-t0`` from 0,
``default-t1`` from 100, ``level`` from 200). The model (:data:`error_model.detection.
DEFAULT_FEATURES`) is fitted on all rows together; its calibration is measured on
:data:`FOLDS` held-out folds over the scans (each scan's rows in one fold) and recorded in the
file (``calibration``: held-out and base-rate Brier scores, the reliability table with Wilson
95 % intervals; ``data``: rows, scans, fingerprint).

Every step is seeded: a rerun is byte-identical on one machine; ``--check`` compares every
number to a relative 1e-9 (L-BFGS's last digits may differ across CPUs).

Usage, from the project root:
    .venv/bin/python scripts/make_default_detection_model.py --workers 2 # rewrite the JSON
    .venv/bin/python scripts/make_default_detection_model.py --check     # exit 1 if stale
    .venv/bin/python scripts/make_default_detection_model.py --keep fates/   # keep the tables
    .venv/bin/python scripts/make_default_detection_model.py --tables fates/ # refit from them
    .venv/bin/python scripts/make_default_detection_model.py --seeds 1 --frames 40 \\
        --output /tmp/d.json                                               # smoke run

Runtime: 60 scans of 800 frames. On 2026-12-03, with ``--workers 2`` on two cores shared with
four other sessions (load average 6-16), 32 min wall; ``default-t0`` alone took 531 s in one
process on a lighter load, so two idle cores should need well under 15 min (an estimate).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from error_model.default import DEFAULT_DETECTION_MODEL_PATH  # noqa: E402
from error_model.detection import DEFAULT_FEATURES, fit_from_fate_tables  # noqa: E402
from pipeline.tables.fate_table import read_fate_tables, write_fate_table  # noqa: E402
from planner.studies.loss_study import (  # noqa: E402
    level_layout,
    loss_jobs,
    relief_layout,
    run_loss_study,
)
from visibility.sensor_profile import DEFAULT_PROFILE, load_profile  # noqa: E402

sys.path.insert(0, str(ROOT / "scripts"))
from make_default_error_model import check_shipped  # noqa: E402

FULL_FRAMES = 800
FOLDS = 5


@dataclass(frozen=True)
class Study:
    """One loss study of the design.

    Attributes
    ----------
    name : str
        The layout's name in the fate table (scans are ``name/seed/station``).
    terrain_seed : int or None
        Terrain seed of the ``default`` preset (and the markers' jitter seed); None: the level
        field.
    first_seed : int
        Simulation seeds ``first_seed, first_seed + 1, ...``.
    groups : int
        Interleaved marker sets (seed ``i`` scans set ``i % groups``).
    seeds : int
        Simulation seeds (each scans every station).
    """

    name: str
    terrain_seed: int | None
    first_seed: int
    groups: int
    seeds: int

    def describe(self, seeds: int) -> str:
        terrain = ("level field" if self.terrain_seed is None
                   else f"default preset, terrain seed {self.terrain_seed}")
        sets = f"{self.groups} interleaved marker sets, " if self.groups > 1 else ""
        return (f"{self.name} ({terrain}, {sets}seeds {self.first_seed}-"
                f"{self.first_seed + seeds - 1})")

    def layout(self):
        """The study's :class:`planner.studies.loss_study.LossLayout`."""
        if self.terrain_seed is None:
            return replace(level_layout(), name=self.name)
        from visibility.sites import load_site

        site = load_site("default", seed=self.terrain_seed)
        return replace(relief_layout(site, seed=self.terrain_seed), name=self.name)


STUDIES = (Study("default-t0", 0, 0, 4, 4), Study("default-t1", 1, 100, 2, 2),
           Study("level", None, 200, 1, 4))


def frame_indices(frames: int) -> range | None:
    """The frames simulated: all 800 (None), or ``frames`` evenly spaced ones for a smoke run."""
    if not 1 <= frames <= FULL_FRAMES:
        raise SystemExit(f"--frames must be 1..{FULL_FRAMES}, got {frames}")
    return None if frames == FULL_FRAMES else range(0, FULL_FRAMES, FULL_FRAMES // frames)


def run_studies(folder: Path, profile_name: str, seeds: int | None, frames: int,
                workers: int | None) -> list[Path]:
    """Run every study of :data:`STUDIES` (``seeds`` seeds each if given, for a smoke run)
    and write its fate table into ``folder``.

    Returns
    -------
    tables : list of Path
        ``folder/<study>.csv``, in :data:`STUDIES` order.
    """
    from planner.distributed import executor

    profile = load_profile(profile_name)
    picked = frame_indices(frames)
    folder.mkdir(parents=True, exist_ok=True)
    tables = []
    scheduler = "none" if workers is None else "local"
    with executor(scheduler, workers, progress=False) as ex:
        for study in STUDIES:
            layout = study.layout()
            n = seeds or study.seeds
            jobs = loss_jobs(layout, range(study.first_seed, study.first_seed + n),
                             groups=study.groups, profile=profile, frames=picked)
            scans = run_loss_study(layout, jobs, ex)
            rows = [r for s in scans for r in s.rows]
            false = sum(s.false_accepts for s in scans)
            print(f"{study.name}: {len(jobs)} scans, {len(rows)} pairs, "
                  f"{sum(r['stage'] == 'accepted' for r in rows)} accepted, {false} false "
                  "accepts", flush=True)
            tables.append(write_fate_table(folder / f"{study.name}.csv", rows))
    return tables


def build_model(tables: list[Path], profile: str, seeds: int | None, frames: int):
    """Fit the default detection model on the fate tables and record its calibration."""
    studies = "; ".join(s.describe(seeds or s.seeds) for s in STUDIES)
    description = (f"loss studies (planner.studies.loss_study: scans simulated with sensor "
                   f"profile {profile}, {frames} of {FULL_FRAMES} frames, run through the full "
                   f"station chain as verify runs it): {studies}; {FOLDS} held-out folds over "
                   "the scans; regenerated by scripts/make_default_detection_model.py")
    table = read_fate_tables(tables)
    model = fit_from_fate_tables(table, FOLDS, DEFAULT_FEATURES, description=description)
    # the tables' paths are scratch; the design is in the description
    model.info["data"]["sources"] = [Path(t).name for t in tables]
    return model


def summary(model) -> str:
    """The calibration figures recorded in the model, as printable lines."""
    data, cal = model.info["data"], model.info["calibration"]
    lines = [f"{data['rows']} pairs in {data['scans']} scans, accepted "
             f"{data['accepted_rate']:.3f}; Brier held out {cal['brier_held_out']:.4f}, in "
             f"sample {cal['brier_in_sample']:.4f}, base rate {cal['brier_base_rate']:.4f}",
             "held-out bin | n | predicted | observed (Wilson 95 %)"]
    for b in cal["reliability_held_out"]:
        lines.append(f"  [{b['lo']:.2f}, {b['hi']:.2f}] | {b['n']} | {b['predicted']:.3f} | "
                     f"{b['observed']:.3f} ({b['observed_low']:.3f}-{b['observed_high']:.3f})")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sensor-profile", default=DEFAULT_PROFILE,
                        help="Sensor profile name or file (default %(default)s).")
    parser.add_argument("--seeds", type=int, default=None,
                        help="Simulation seeds of every study (default: the design's, "
                             "4, 2 and 4; 1 for a smoke run).")
    parser.add_argument("--frames", type=int, default=FULL_FRAMES,
                        help="Frames simulated of the 800 of a revolution (default all; a few "
                             "dozen for a smoke run).")
    parser.add_argument("--workers", type=int, default=None,
                        help="Local dask workers (default: run in this process).")
    parser.add_argument("--check", action="store_true",
                        help="Do not write; exit 1 if the shipped JSON differs.")
    parser.add_argument("--keep", type=Path, default=None,
                        help="Keep the fate tables in this folder.")
    parser.add_argument("--tables", type=Path, default=None,
                        help="Fit from the fate tables a --keep run left in this folder "
                             "instead of running the studies (same --seeds and --frames).")
    parser.add_argument("--output", type=Path, default=DEFAULT_DETECTION_MODEL_PATH)
    args = parser.parse_args(argv)
    if args.seeds is not None and args.seeds < 1:
        raise SystemExit(f"--seeds must be >= 1, got {args.seeds}")

    with tempfile.TemporaryDirectory() as tmp:
        if args.tables is not None:
            tables = [args.tables / f"{s.name}.csv" for s in STUDIES]
        else:
            folder = args.keep if args.keep is not None else Path(tmp) / "fates"
            tables = run_studies(folder, args.sensor_profile, args.seeds, args.frames,
                                 args.workers)
        model = build_model(tables, args.sensor_profile, args.seeds, args.frames)
        print(summary(model))
        if args.check:
            return check_shipped(model, args.output, Path(tmp))
    model.save(args.output)
    print(f"wrote {args.output}: coefficients {np.round(model.coef, 4).tolist()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
