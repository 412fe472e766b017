"""Verification as an experiment: ``markerplan verify --trials N`` (known control).

A single verification is one draw of the sensor's noise and turntable errors; whether a plan
passes is a random outcome. ``N`` trials verify the same plan ``N`` times with independent
simulation seeds (:func:`trial_seeds`: trial 0 is the single verification's ``--seed``, the
others spawned from it by :class:`numpy.random.SeedSequence`), every trial x station one task
on the same executor (:func:`planner.verify.known_control.verify_plans`), and report:

- the plan's pass rate (a trial passes when every station does) with its Wilson 95 % interval
  (:func:`wilson_interval`);
- each station's pass rate, its achieved errors (median, largest) and the failures' reasons;
- each (station, planned marker) pair's acceptance rate and the stages that lost it;
- ``trials.csv`` (one row per trial x station, :func:`write_trials`) beside ``fates.csv``
  (one row per trial x station x planned marker).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from error_model.detection import wilson_interval
from markerplan.provenance import provenance
from markerplan.writing import write_csv, write_gis_sidecars
from pipeline.rig import MountingOffsets
from planner.distributed import Executor
from planner.outputs.plan_file import SurveyPlan
from planner.verify.fates import losses_markdown, lost_by_stage, stage_counts
from planner.verify.known_control import (
    VERIFY_SCHEMA,
    VERIFY_SCHEMA_VERSION,
    StationCheck,
    verify_plans,
)
from visibility.sensor_profile import SensorProfile, default_profile

#: ``trials.csv``: header and ``.csvt`` column types.
TRIALS_COLUMNS = ("trial", "seed", "station_id", "passed", "predicted_error_m",
                  "achieved_error_m", "n_planned", "n_detected", "n_lost", "n_false_accepts",
                  "reason")
TRIALS_TYPES = ("Integer", "Integer", "String", "String", "Real", "Real", "Integer", "Integer",
                "Integer", "Integer", "String")


def trial_seeds(seed: int, n_trials: int) -> list[int]:
    """The simulation seed of each trial: ``seed`` first, then ``n_trials - 1`` independent
    seeds spawned from it (:meth:`numpy.random.SeedSequence.spawn`, 32 bits each).

    A trial's station ``k`` is simulated with its seed ``+ k``, as a single verification.

    >>> trial_seeds(5, 1)
    [5]
    >>> s = trial_seeds(5, 4); s[0], len(set(s)), s == trial_seeds(5, 4)
    (5, 4, True)
    """
    children = np.random.SeedSequence(seed).spawn(n_trials - 1)
    return [int(seed)] + [int(c.generate_state(1)[0]) for c in children]


def verify_trials(plan: SurveyPlan, error_model, seeds: Sequence[int],
                  offsets: MountingOffsets | None = None,
                  station_ids: list[str] | None = None, profile: SensorProfile | None = None,
                  executor: Executor | None = None, progress: bool = True
                  ) -> list[list[StationCheck]]:
    """Verify a plan once per seed, every trial x station one task of one map.

    Parameters
    ----------
    plan : SurveyPlan
    error_model : ErrorModel
    seeds : sequence of int
        One simulation seed per trial (:func:`trial_seeds`).
    offsets, station_ids, profile, executor, progress
        As :func:`planner.verify.known_control.verify_plan`.

    Returns
    -------
    checks : list of list of StationCheck
        Per trial, in the plan's station order.
    """
    return verify_plans([plan] * len(seeds), error_model, list(seeds), progress, offsets,
                        station_ids, profile, executor,
                        names=[f"trial {t}" for t in range(len(seeds))])


def trials_record(plan: SurveyPlan, trials: list[list[StationCheck]], seed: int,
                  seeds: Sequence[int], model_name: str, offsets: MountingOffsets | None = None,
                  profile: SensorProfile | None = None) -> dict:
    """The ``verify.json`` document of ``verify --trials N`` (``N`` > 1).

    Parameters
    ----------
    plan : SurveyPlan
    trials : list of list of StationCheck
        :func:`verify_trials`' checks.
    seed : int
        The ``--seed`` the trial seeds were spawned from.
    seeds : sequence of int
        The trials' seeds.
    model_name : str
    offsets, profile
        The simulated rig's true mounting offsets and sensor profile (provenance).

    Returns
    -------
    record : dict
        ``passed`` (every trial passed), ``pass_rate`` (trials, passed, rate, Wilson 95 %),
        ``losses`` (lost planned markers per stage over all trials), ``stations`` and
        ``pairs`` (per station and per (station, planned marker) pair: rates, intervals and
        the stages of the losses).
    """
    n = len(trials)
    passed = [all(c.passed for c in checks) for checks in trials]
    profile = profile or default_profile()
    return {
        "schema": VERIFY_SCHEMA, "schema_version": VERIFY_SCHEMA_VERSION, "mode": "trials",
        "provenance": provenance({"seed": seed, "trials": n, "trial_seeds": list(seeds),
                                  "error_model": model_name,
                                  "mounting_offsets": (offsets or MountingOffsets()).to_dict(),
                                  "sensor_profile": profile.to_dict(),
                                  "plan_config_sha256": plan.provenance["config_sha256"]},
                                 plan=plan.provenance),
        "requirement_m": plan.requirement_m,
        "passed": all(passed),
        "pass_rate": _rate(sum(passed), n),
        "losses": stage_counts(c.fates for checks in trials for c in checks),
        "stations": [_station_summary([checks[k] for checks in trials])
                     for k in range(len(trials[0]))],
        "pairs": _pair_summaries(trials),
    }


def _rate(k: int, n: int) -> dict:
    """``k`` of ``n`` as a rate with its Wilson 95 % interval."""
    low, high = wilson_interval(k, n)
    return {"n_trials": n, "n_passed": k, "rate": k / n, "wilson_95": [low, high]}


def _station_summary(checks: list[StationCheck]) -> dict:
    """One station over the trials: pass rate, achieved errors, losses, failures."""
    achieved = [c.achieved_error_m for c in checks if c.achieved_error_m is not None]
    first = checks[0]
    return {"id": first.station_id, "predicted_error_m": first.predicted_error_m,
            **_rate(sum(c.passed for c in checks), len(checks)),
            "achieved_error_m": ({"median": float(np.median(achieved)), "max": max(achieved)}
                                 if achieved else None),
            "losses": stage_counts(c.fates for c in checks),
            "failures": [f"trial {t}: {c.reason}" for t, c in enumerate(checks)
                         if not c.passed]}


def _pair_summaries(trials: list[list[StationCheck]]) -> list[dict]:
    """Every (station, planned marker) pair over the trials: acceptance rate and losses."""
    out = []
    for k, first in enumerate(trials[0]):
        for j, row in enumerate(first.fates.rows):
            fates = [checks[k].fates.rows[j] for checks in trials]
            n_ok = sum(f.accepted for f in fates)
            out.append({"station_id": first.station_id, "marker_id": row.marker_id,
                        "distance_m": row.distance_m, "n_trials": len(fates),
                        "n_accepted": n_ok,
                        "accepted_rate": n_ok / len(fates),
                        "wilson_95": list(wilson_interval(n_ok, len(fates))),
                        "lost": lost_by_stage(fates)})
    return out


def write_trials(path: Path, trials: list[list[StationCheck]], seeds: Sequence[int]
                 ) -> list[Path]:
    """Write ``trials.csv`` (one row per trial x station) and its ``.csvt``."""
    records = [{"trial": t, "seed": s, "station_id": c.station_id, "passed": c.passed,
                "predicted_error_m": c.predicted_error_m,
                "achieved_error_m": c.achieved_error_m, "n_planned": c.n_planned,
                "n_detected": c.n_detected, "n_lost": len(c.fates.lost()),
                "n_false_accepts": c.fates.n_false_accepts, "reason": c.reason}
               for t, (s, checks) in enumerate(zip(seeds, trials, strict=True))
               for c in checks]
    return [write_csv(path, TRIALS_COLUMNS, records),
            *write_gis_sidecars(path, TRIALS_TYPES, None)]


def trials_markdown(rec: dict) -> str:
    """Human report of ``verify --trials N``: the plan's pass rate, per station, per pair."""
    def rate(r):
        low, high = r["wilson_95"]
        return f"{r['n_passed']} / {r['n_trials']} ({100 * low:.0f}–{100 * high:.0f} %)"

    pr = rec["pass_rate"]
    lines = [f"# Plan verification, {pr['n_trials']} trials — passed {rate(pr)}", "",
             f"Requirement: achieved registration error ≤ {rec['requirement_m']:g} m at every "
             "station; a trial passes when every station does. Each trial simulates every "
             "station with its own noise and turntable-error seed; the interval is Wilson's "
             "95 %.", "", losses_markdown(rec["losses"]), "",
             "| station | predicted | achieved median / max | passed (95 %) | lost by stage |",
             "|---|---:|---:|---:|---|"]
    for s in rec["stations"]:
        pred = "—" if s["predicted_error_m"] is None else f"{s['predicted_error_m']:.4f} m"
        a = s["achieved_error_m"]
        ach = "—" if a is None else f"{a['median']:.4f} / {a['max']:.4f} m"
        lines.append(f"| {s['id']} | {pred} | {ach} | {rate(s)} | {_stages(s['losses'])} |")
    lines += ["", "| station | marker | distance | accepted (95 %) | lost by stage |",
              "|---|---|---:|---:|---|"]
    for p in rec["pairs"]:
        low, high = p["wilson_95"]
        lines.append(f"| {p['station_id']} | {p['marker_id']} | {p['distance_m']:.1f} m | "
                     f"{p['n_accepted']} / {p['n_trials']} ({100 * low:.0f}–{100 * high:.0f} "
                     f"%) | {_stages(p['lost'])} |")
    failures = [f"{s['id']} {f}" for s in rec["stations"] for f in s["failures"]]
    if failures:
        lines += ["", "Failures:", ""] + [f"- {f}" for f in failures]
    return "\n".join(lines) + "\n"


def _stages(counts: dict[str, int]) -> str:
    """``gate 2, quality 1`` (false accepts left out), ``—`` for none."""
    return ", ".join(f"{k} {v}" for k, v in counts.items() if k != "false_accepts" and v) or "—"
