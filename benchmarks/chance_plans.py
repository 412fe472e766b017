"""Naive, redundant and chance-constrained plans side by side, and what the chance costs.

For each mode asked (known control, network), plans the site three ways with the shipped
error and detection models: naive (``chance_epsilon`` none: every planned marker counted as
detected), ``--redundant`` (every station survives the loss of any one marker) and
chance-constrained (``chance_epsilon``, default 0.05). Prints, per plan: markers, solver
status and gap, the certified chance that every station passes (network mode: the whole
network's, with its accuracy), and the pass rate over ``--samples`` sampled detection
outcomes with its Wilson 95 % interval (the whole check, the network's accuracy included);
then the integer program's time of the redundant and chance-constrained plans as ratios
against the naive plan's, measured in the same run. With ``--verify-trials N`` each plan is
also verified ``N`` times by simulation (``markerplan verify --trials N``: the full station
chain on the true terrain), the observed pass rate beside the predicted one, and one verify
trial's wall time as a ratio against the naive plan.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python -u benchmarks/chance_plans.py \\
        [--site default] [--modes known,network] [--samples 2000] [--verify-trials 0]

Prints one block per mode and a final JSON object.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path


def _plan(inputs, config, error_model, detection_model, samples):
    from planner.run import make_plan

    t = time.perf_counter()
    outcome = make_plan(inputs, config, error_model, detection_model=detection_model,
                        progress=False, samples=samples)
    return outcome, outcome.timings_s["program"], time.perf_counter() - t


def _verify(outcome, trials: int, folder: Path, network: bool) -> tuple[dict, float]:
    """``markerplan verify --trials N`` of a plan written into ``folder``; its record and
    wall time."""
    from planner.cli import cli
    from planner.outputs.report import write_plan_files

    plan_dir = folder / "plan"
    plan_dir.mkdir(parents=True)
    write_plan_files(outcome, plan_dir)
    out = folder / "verify"
    args = ["verify", str(plan_dir / "plan.json"), "--trials", str(trials), "--out", str(out),
            "--scheduler", "none"] + (["--network"] if network else [])
    t = time.perf_counter()
    cli.main(args=args, prog_name="markerplan", standalone_mode=False)
    wall = time.perf_counter() - t
    return json.loads((out / "verify.json").read_text()), wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--site", default="default")
    ap.add_argument("--modes", default="known,network")
    ap.add_argument("--epsilon", type=float, default=0.05)
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--time-limit", type=float, default=120.0)
    ap.add_argument("--verify-trials", type=int, default=0)
    args = ap.parse_args()
    if args.verify_trials == 1:
        ap.error("--verify-trials: 0 (none) or at least 2 (a pass rate)")

    from error_model import default_detection_model, default_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs

    inputs = load_inputs(args.site)
    report = {"site": args.site, "epsilon": args.epsilon, "samples": args.samples, "modes": {}}
    for mode in args.modes.split(","):
        network = mode == "network"
        base = PlanConfig(network=network, time_limit_s=args.time_limit)
        variants = {"naive": base.replace(chance_epsilon=None),
                    "redundant": base.replace(chance_epsilon=None, redundant=True),
                    "chance": base.replace(chance_epsilon=args.epsilon)}
        rows = {}
        print(f"== {args.site}, {'network' if network else 'known control'} ==", flush=True)
        for name, config in variants.items():
            outcome, program_s, wall_s = _plan(inputs, config, default_model(),
                                               default_detection_model(), args.samples)
            sol, sa = outcome.result.solution, outcome.sampled
            ch = outcome.network_chance if network else outcome.chance
            row = {"n_markers": int(outcome.result.selected.sum()), "status": sol.status,
                   "gap": sol.gap, "dual_bound": sol.dual_bound,
                   "certified_pass": ch.pass_low, "sampled": sa.to_json(),
                   "program_s": round(program_s, 3), "plan_wall_s": round(wall_s, 3)}
            low, high = sa.wilson_95
            print(f"{name:>9}: {row['n_markers']} markers ({sol.status}, gap {sol.gap:.3g}); "
                  f"certified P(pass) {100 * ch.pass_low:.2f} %; sampled "
                  f"{100 * sa.rate:.2f} % ({100 * low:.1f}-{100 * high:.1f} %); program "
                  f"{program_s:.2f} s", flush=True)
            if args.verify_trials:
                with tempfile.TemporaryDirectory() as tmp:
                    rec, wall = _verify(outcome, args.verify_trials, Path(tmp), network)
                pr = rec["pass_rate"]
                row["verify"] = {"trials": pr["n_trials"], "passed": pr["n_passed"],
                                 "wilson_95": pr["wilson_95"],
                                 "wall_per_trial_s": round(wall / args.verify_trials, 3)}
                print(f"{'':>9}  verify --trials {pr['n_trials']}: {pr['n_passed']} passed "
                      f"(Wilson {100 * pr['wilson_95'][0]:.0f}-"
                      f"{100 * pr['wilson_95'][1]:.0f} %), "
                      f"{wall / args.verify_trials:.1f} s per trial", flush=True)
            rows[name] = row
        naive_s = rows["naive"]["program_s"]
        for name in ("redundant", "chance"):
            rows[name]["program_ratio_to_naive"] = round(rows[name]["program_s"] / naive_s, 2)
        if args.verify_trials:
            rows["naive"]["verify_trial_ratio_to_naive_plan"] = round(
                rows["naive"]["verify"]["wall_per_trial_s"] / rows["naive"]["plan_wall_s"], 2)
        print(f"program time against the naive plan's ({naive_s:.2f} s): redundant "
              f"{rows['redundant']['program_ratio_to_naive']}x, chance-constrained "
              f"{rows['chance']['program_ratio_to_naive']}x", flush=True)
        report["modes"][mode] = rows
    print(json.dumps(report, indent=2))


if __name__ == "__main__":
    main()
