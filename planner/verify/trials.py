"""Verification as an experiment: ``markerplan verify --trials N``, both modes.

A single verification is one draw of the sensor's noise and turntable errors (and, when the
user gives tolerances, of the rig's mounting offsets); whether a plan passes is a random
outcome. ``N`` trials verify the same plan ``N`` times with independent simulation seeds
(:func:`trial_seeds`: trial 0 is the single verification's ``--seed``, the others spawned from
it by :class:`numpy.random.SeedSequence`), every trial x station one task on the same executor
(:func:`verify_trials`, :func:`verify_network_trials`; the results come back in task order
whichever finishes first), and report:

- the plan's pass rate (a trial passes when every station does) with its Wilson 95 % interval
  (:func:`wilson_interval`), beside the plan's predicted pass probability when ``plan.json``
  has one (:func:`read_predictions`);
- each station's pass rate, its achieved errors (median, largest) and the failures' reasons;
- each (station, planned marker) pair's acceptance rate and the stages that lost it, beside
  the plan's predicted detection probability, and the calibration of those predictions over
  the pairs (:func:`calibration`);
- ``trials.csv`` (one row per trial x station, with the trial's rig offsets,
  :func:`write_trials`) beside ``fates.csv`` (one row per trial x station x planned marker).

In network mode (:func:`verify_network_trials`) each trial is a whole network verification
(:mod:`planner.verify.network`): its marker table (``markers/trial_NNN.csv``, ``marker_id``
filled by the association) identified, adjusted and compared; a trial whose datum station
identified nothing fails at every station instead of stopping the run.

The rig's mounting offsets of a trial are the given ones or, with tolerances, drawn from
N(given, tolerance) with the trial's seed (:mod:`planner.verify.rig_draws`, a stream of its
own: the offsets do not share random numbers with the noise).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from error_model.detection import wilson_interval
from markerplan.errors import DataError, InputFileError
from markerplan.provenance import provenance
from markerplan.writing import write_csv, write_gis_sidecars
from pipeline.scans.rig import MountingOffsets
from planner.distributed import Executor
from planner.outputs.plan_file import SurveyPlan
from planner.verify.fates import losses_markdown, lost_by_stage, stage_counts
from planner.verify.known_control import (
    VERIFY_SCHEMA,
    VERIFY_SCHEMA_VERSION,
    StationCheck,
    verify_plans,
)
from planner.verify.rig_draws import OffsetTolerance
from visibility.sensor_profile import SensorProfile, default_profile

#: ``trials.csv``: header and ``.csvt`` column types (the last four: the trial's rig offsets).
TRIALS_COLUMNS = ("trial", "seed", "station_id", "passed", "predicted_error_m",
                  "achieved_error_m", "n_planned", "n_detected", "n_lost", "n_false_accepts",
                  "reason", "vertical_axis_error_deg", "lframe_tilt_deg", "axis_offset_x_mm",
                  "axis_offset_y_mm")
TRIALS_TYPES = ("Integer", "Integer", "String", "String", "Real", "Real", "Integer", "Integer",
                "Integer", "Integer", "String", "Real", "Real", "Real", "Real")

#: Upper edges of the predicted-probability bins of :func:`calibration` (the first from 0).
CALIBRATION_BINS = (0.5, 0.8, 0.9, 0.95, 0.99, 1.0)


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
                  offsets: MountingOffsets | Sequence[MountingOffsets] | None = None,
                  station_ids: list[str] | None = None, profile: SensorProfile | None = None,
                  executor: Executor | None = None, progress: bool = True
                  ) -> list[list[StationCheck]]:
    """Verify a plan once per seed (known control), every trial x station one task of one map.

    Parameters
    ----------
    plan : SurveyPlan
    error_model : ErrorModel
    seeds : sequence of int
        One simulation seed per trial (:func:`trial_seeds`).
    offsets : MountingOffsets or sequence of MountingOffsets, optional
        The rig's true mounting offsets, for every trial or one per trial
        (:func:`~planner.verify.rig_draws.trial_offsets`).
    station_ids, profile, executor, progress
        As :func:`planner.verify.known_control.verify_plan`.

    Returns
    -------
    checks : list of list of StationCheck
        Per trial, in the plan's station order.
    """
    return verify_plans([plan] * len(seeds), error_model, list(seeds), progress, offsets,
                        station_ids, profile, executor, names=_names(len(seeds)))


def verify_network_trials(plan: SurveyPlan, plan_path: Path, doc: dict, error_model,
                          error_model_name: str, seeds: Sequence[int], tables: Path,
                          settings, offsets: MountingOffsets | Sequence[MountingOffsets] |
                          None = None, station_ids: list[str] | None = None,
                          profile: SensorProfile | None = None,
                          executor: Executor | None = None, reference: str | None = None,
                          progress: bool = True) -> list[list[StationCheck]]:
    """Verify a plan once per seed in network mode: every trial x station's scan one task of
    one map (:func:`planner.verify.network.scan_plans`), then each trial's network identified,
    adjusted and compared in this process (:func:`planner.verify.network.verify_scan`).

    Parameters
    ----------
    plan : SurveyPlan
    plan_path : Path
        Its ``plan.json`` (the association's planned markers and poses).
    doc : dict
        The ``plan.json`` document (:func:`planner.outputs.plan_file.read_plan`, full).
    error_model : ErrorModel
    error_model_name : str
    seeds : sequence of int
        One simulation seed per trial (:func:`trial_seeds`).
    tables : Path
        Folder (existing) for the trials' marker tables, ``trial_NNN.csv``.
    settings : planner.verify.network.NetworkVerifySettings
    offsets, station_ids, profile, executor, progress
        As :func:`verify_trials`.
    reference : str, optional
        The datum station (default the plan's).

    Returns
    -------
    trials : list of list of StationCheck
        Per trial, the chosen stations in the plan's order (no per-marker errors: the
        network's are its markers', not a station's).
    """
    from planner.verify.network import NetworkVerifySettings, scan_plans, verify_scan

    body = (settings or NetworkVerifySettings()).body
    scans = scan_plans(plan, list(seeds), progress,
                       list(offsets) if isinstance(offsets, Sequence) else offsets,
                       station_ids, profile, executor, _names(len(seeds)), body, reference)
    planned = {s["id"]: len(s.get("markers", ())) for s in doc["stations"]}
    out = []
    for t, scanned in enumerate(scans):
        fates = scanned[2]
        try:
            check = verify_scan(scanned, tables / f"trial_{t:03d}.csv", plan_path, doc,
                                error_model, error_model_name, settings, reference,
                                seeds[t])
        except InputFileError as exc:  # no datum in this trial: every station fails
            out.append([StationCheck(sid, _predicted(doc, sid), None, planned[sid],
                                     sum(r.accepted for r in f.rows), False,
                                     f"not verified: {exc}", {}, f)
                        for sid, f in fates.items()])
            continue
        out.append([StationCheck(s.station_id, s.predicted_error_m, s.achieved_error_m,
                                 planned[s.station_id], s.n_accepted, s.passed, s.reason, {},
                                 fates.get(s.station_id)) for s in check.stations])
    return out


def _predicted(doc: dict, station_id: str) -> float | None:
    """The plan's predicted error of a station."""
    return next(s.get("predicted_error_m") for s in doc["stations"] if s["id"] == station_id)


def _names(n_trials: int) -> list[str]:
    """Task names of the trials: ``trial 0``, ``trial 1``, ..."""
    return [f"trial {t}" for t in range(n_trials)]


@dataclass(frozen=True)
class Predictions:
    """What a plan predicts of its verification (``plan.json``'s ``detection`` and ``chance``
    sections).

    Attributes
    ----------
    pairs : dict of (str, str) to float
        P(detected and accepted) of each (station, marker) pair.
    plan_pass_probability : float or None
        P(the plan passes) (``chance.plan_pass_probability``).
    stations : dict of str to float
        P(the station passes), where given (``chance.stations``: a number, or a record with
        its ``pass_probability``).
    model : dict
        The detection model's provenance.
    """

    pairs: dict[tuple[str, str], float]
    plan_pass_probability: float | None
    stations: dict[str, float]
    model: dict


def read_predictions(plan_path: Path) -> Predictions | None:
    """The plan's predicted probabilities, ``None`` when its ``plan.json`` has no
    ``detection`` section (a plan made without a detection model).

    Raises
    ------
    DataError
        A section that is not the documented shape, or a probability outside [0, 1].
    """
    doc = json.loads(Path(plan_path).read_text(encoding="utf-8"))
    detection = doc.get("detection")
    if detection is None:
        return None
    fix = "; re-make the plan with `markerplan plan`"
    try:
        pairs = {(str(p["station"]), str(p["site"])): _probability(p["probability"])
                 for p in detection["pairs"]}
        chance = doc.get("chance") or {}
        plan_p = chance.get("plan_pass_probability")
        stations = {str(k): _probability(v["pass_probability"] if isinstance(v, dict) else v)
                    for k, v in (chance.get("stations") or {}).items()}
        return Predictions(pairs, None if plan_p is None else _probability(plan_p), stations,
                           dict(detection.get("model") or {}))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise DataError(f"{plan_path}: its `detection` / `chance` sections are not a plan's "
                        f"({type(exc).__name__}: {exc}){fix}") from None


def _probability(value) -> float:
    """A probability from a plan, refused outside [0, 1] (NaN too)."""
    p = float(value)
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"probability {value!r} outside [0, 1]")
    return p


def trials_record(plan: SurveyPlan, trials: list[list], seed: int, seeds: Sequence[int],
                  model_name: str,
                  offsets: MountingOffsets | Sequence[MountingOffsets] | None = None,
                  profile: SensorProfile | None = None, *, network: dict | None = None,
                  nominal: MountingOffsets | None = None,
                  tolerance: OffsetTolerance | None = None,
                  predictions: Predictions | None = None) -> dict:
    """The ``verify.json`` document of ``verify --trials N`` (``N`` > 1), both modes.

    Parameters
    ----------
    plan : SurveyPlan
    trials : list of list of StationCheck
        :func:`verify_trials`' or :func:`verify_network_trials`' stations, per trial.
    seed : int
        The ``--seed`` the trial seeds were spawned from.
    seeds : sequence of int
        The trials' seeds.
    model_name : str
    offsets : MountingOffsets or sequence of MountingOffsets, optional
        The simulated rig's true mounting offsets, of every trial or per trial.
    profile : SensorProfile, optional
        The simulated sensor (provenance).
    network : dict, optional
        Network mode: the identification and adjustment settings (mode ``network_trials``).
    nominal, tolerance : optional
        The given offsets and their tolerances the trials' offsets were drawn from.
    predictions : Predictions, optional
        The plan's predicted probabilities (:func:`read_predictions`).

    Returns
    -------
    record : dict
        ``passed`` (every trial passed), ``pass_rate`` (trials, passed, rate, Wilson 95 %,
        ``predicted_probability``), ``losses`` (lost planned markers per stage over all
        trials), ``stations`` and ``pairs`` (per station and per (station, planned marker)
        pair: rates, intervals, predictions and the stages of the losses), ``calibration``
        (:func:`calibration`, ``None`` without predictions).
    """
    n = len(trials)
    passed = [all(c.passed for c in checks) for checks in trials]
    profile = profile or default_profile()
    rigs = _per_trial(offsets, n)
    config = {"seed": seed, "trials": n, "trial_seeds": list(seeds),
              "error_model": model_name,
              "mounting_offsets": (nominal or rigs[0]).to_dict(),
              "offset_tolerance": None if tolerance is None else tolerance.to_dict(),
              "trial_mounting_offsets": ([r.to_dict() for r in rigs]
                                         if tolerance is not None else None),
              "sensor_profile": profile.to_dict(),
              "plan_config_sha256": plan.provenance.get("config_sha256")}
    if network is not None:
        config["network"] = network
    pairs = _pair_summaries(trials, predictions)
    return {
        "schema": VERIFY_SCHEMA, "schema_version": VERIFY_SCHEMA_VERSION,
        "mode": "trials" if network is None else "network_trials",
        "provenance": provenance(config, plan=plan.provenance),
        "requirement_m": plan.requirement_m,
        "station_rule": asdict(plan.rule),
        "passed": all(passed),
        "pass_rate": {**_rate(sum(passed), n), "predicted_probability":
                      None if predictions is None else predictions.plan_pass_probability},
        "losses": stage_counts(c.fates for checks in trials for c in checks),
        "stations": [_station_summary([checks[k] for checks in trials], predictions)
                     for k in range(len(trials[0]))],
        "pairs": pairs,
        "calibration": calibration(pairs),
    }


def _per_trial(offsets, n: int) -> list[MountingOffsets]:
    """One rig per trial from the given offsets (one for all, or one each)."""
    if isinstance(offsets, Sequence):
        return list(offsets)
    return [offsets or MountingOffsets()] * n


def _rate(k: int, n: int) -> dict:
    """``k`` of ``n`` as a rate with its Wilson 95 % interval."""
    low, high = wilson_interval(k, n)
    return {"n_trials": n, "n_passed": k, "rate": k / n, "wilson_95": [low, high]}


def _station_summary(checks: list, predictions: Predictions | None) -> dict:
    """One station over the trials: pass rate, achieved errors, losses, failures."""
    achieved = [c.achieved_error_m for c in checks if c.achieved_error_m is not None]
    first = checks[0]
    return {"id": first.station_id, "predicted_error_m": first.predicted_error_m,
            **_rate(sum(c.passed for c in checks), len(checks)),
            "predicted_probability": (None if predictions is None
                                      else predictions.stations.get(first.station_id)),
            "achieved_error_m": ({"median": float(np.median(achieved)), "max": max(achieved)}
                                 if achieved else None),
            "losses": stage_counts(c.fates for c in checks),
            "failures": [f"trial {t}: {c.reason}" for t, c in enumerate(checks)
                         if not c.passed]}


def _pair_summaries(trials: list[list], predictions: Predictions | None) -> list[dict]:
    """Every (station, planned marker) pair over the trials: acceptance rate, losses and the
    plan's predicted probability (``None``: none given)."""
    out = []
    for k, first in enumerate(trials[0]):
        if first.fates is None:
            continue
        for j, row in enumerate(first.fates.rows):
            fates = [checks[k].fates.rows[j] for checks in trials]
            n_ok = sum(f.accepted for f in fates)
            predicted = (None if predictions is None
                         else predictions.pairs.get((first.station_id, row.marker_id)))
            out.append({"station_id": first.station_id, "marker_id": row.marker_id,
                        "distance_m": row.distance_m, "n_trials": len(fates),
                        "n_accepted": n_ok,
                        "accepted_rate": n_ok / len(fates),
                        "wilson_95": list(wilson_interval(n_ok, len(fates))),
                        "predicted_probability": predicted,
                        "lost": lost_by_stage(fates)})
    return out


def calibration(pairs: list[dict], edges: Sequence[float] = CALIBRATION_BINS) -> dict | None:
    """How the plan's predicted detection probabilities compare with the trials' rates.

    Parameters
    ----------
    pairs : list of dict
        :func:`trials_record`'s pairs (``predicted_probability``, ``n_trials``,
        ``n_accepted``).
    edges : sequence of float
        Upper edges of the predicted-probability bins, increasing to 1 (the first bin starts
        at 0; a bin holds ``low < p <= high``, the first also ``p = 0``).

    Returns
    -------
    calibration : dict or None
        ``n_pairs`` (with a prediction), ``mean_predicted`` (over pairs), ``observed``
        (accepted over pair-trials), ``brier`` (mean squared difference of prediction and
        outcome over pair-trials) and ``bins`` (per bin: ``low``, ``high``, ``n_pairs``,
        ``n_trials``, ``n_accepted``, ``mean_predicted``, ``observed``, ``wilson_95``; empty
        bins left out); ``None`` when no pair has a prediction.

    Examples
    --------
    >>> c = calibration([{"predicted_probability": 0.9, "n_trials": 10, "n_accepted": 8},
    ...                  {"predicted_probability": 0.3, "n_trials": 10, "n_accepted": 5}])
    >>> c["mean_predicted"], c["observed"], round(c["brier"], 4), len(c["bins"])
    (0.6, 0.65, 0.23, 2)
    """
    given = [p for p in pairs if p["predicted_probability"] is not None]
    if not given:
        return None
    n_total = sum(p["n_trials"] for p in given)
    brier = sum(p["n_accepted"] * (1 - p["predicted_probability"]) ** 2
                + (p["n_trials"] - p["n_accepted"]) * p["predicted_probability"] ** 2
                for p in given) / n_total
    bins = []
    for low, high in zip((0.0, *edges[:-1]), edges, strict=True):
        inside = [p for p in given
                  if low < p["predicted_probability"] <= high
                  or (low == 0.0 and p["predicted_probability"] == 0.0)]
        if not inside:
            continue
        n = sum(p["n_trials"] for p in inside)
        k = sum(p["n_accepted"] for p in inside)
        bins.append({"low": low, "high": high, "n_pairs": len(inside), "n_trials": n,
                     "n_accepted": k,
                     "mean_predicted": float(np.mean([p["predicted_probability"]
                                                      for p in inside])),
                     "observed": k / n, "wilson_95": list(wilson_interval(k, n))})
    return {"n_pairs": len(given),
            "mean_predicted": float(np.mean([p["predicted_probability"] for p in given])),
            "observed": sum(p["n_accepted"] for p in given) / n_total, "brier": float(brier),
            "bins": bins}


def write_trials(path: Path, trials: list[list], seeds: Sequence[int],
                 offsets: MountingOffsets | Sequence[MountingOffsets] | None = None
                 ) -> list[Path]:
    """Write ``trials.csv`` (one row per trial x station, with the trial's rig offsets in
    degrees and mm) and its ``.csvt``."""
    rigs = _per_trial(offsets, len(trials))
    records = [{"trial": t, "seed": s, "station_id": c.station_id, "passed": c.passed,
                "predicted_error_m": c.predicted_error_m,
                "achieved_error_m": c.achieved_error_m, "n_planned": c.n_planned,
                "n_detected": c.n_detected,
                "n_lost": None if c.fates is None else len(c.fates.lost()),
                "n_false_accepts": None if c.fates is None else c.fates.n_false_accepts,
                "reason": c.reason,
                "vertical_axis_error_deg": math.degrees(rig.vertical_axis_error_rad),
                "lframe_tilt_deg": math.degrees(rig.lframe_tilt_rad),
                "axis_offset_x_mm": 1e3 * rig.axis_offset_m[0],
                "axis_offset_y_mm": 1e3 * rig.axis_offset_m[1]}
               for t, (s, checks, rig) in enumerate(zip(seeds, trials, rigs, strict=True))
               for c in checks]
    return [write_csv(path, TRIALS_COLUMNS, records),
            *write_gis_sidecars(path, TRIALS_TYPES, None)]


def _percent(r: dict, k: str = "n_passed") -> str:
    """``k / n (low–high %)`` of a rate with its Wilson interval."""
    low, high = r["wilson_95"]
    return f"{r[k]} / {r['n_trials']} ({100 * low:.0f}–{100 * high:.0f} %)"


def _p(value: float | None) -> str:
    """A predicted probability, ``—`` for none."""
    return "—" if value is None else f"{value:.3f}"


def trials_markdown(rec: dict) -> str:
    """Human report of ``verify --trials N``: the plan's pass rate beside its predicted
    probability, per station, per pair, and the calibration of the pairs' predictions."""
    pr = rec["pass_rate"]
    rule = rec["station_rule"]
    mode = "network mode, " if rec["mode"] == "network_trials" else ""
    predicted = pr["predicted_probability"]
    lines = [f"# Plan verification, {mode}{pr['n_trials']} trials — passed {_percent(pr)}", "",
             "Predicted P(pass): " + ("not in the plan (made without a detection model)"
                                      if predicted is None else f"{predicted:.3f}") + ".", "",
             f"Requirement: at every station, at least {rule['min_markers']} planned "
             f"markers detected and accepted in at least {rule['min_sectors']} of "
             f"{rule['n_sectors']} directions, and an achieved error ≤ "
             f"{rec['requirement_m']:g} m; a trial passes when every station does (the event "
             "the predicted P(pass) is about). Each trial simulates every station with "
             "its own noise and turntable-error seed"
             + (" and its own draw of the rig's mounting offsets"
                if rec["provenance"]["config"].get("offset_tolerance") else "")
             + "; the interval is Wilson's 95 %.", "", losses_markdown(rec["losses"]), "",
             "| station | predicted | achieved median / max | passed (95 %) | predicted P "
             "| lost by stage |", "|---|---:|---:|---:|---:|---|"]
    for s in rec["stations"]:
        pred = "—" if s["predicted_error_m"] is None else f"{s['predicted_error_m']:.4f} m"
        a = s["achieved_error_m"]
        ach = "—" if a is None else f"{a['median']:.4f} / {a['max']:.4f} m"
        lines.append(f"| {s['id']} | {pred} | {ach} | {_percent(s)} | "
                     f"{_p(s['predicted_probability'])} | {_stages(s['losses'])} |")
    lines += ["", "| station | marker | distance | accepted (95 %) | predicted P | lost by "
              "stage |", "|---|---|---:|---:|---:|---|"]
    for p in rec["pairs"]:
        lines.append(f"| {p['station_id']} | {p['marker_id']} | {p['distance_m']:.1f} m | "
                     f"{_percent(p, 'n_accepted')} | {_p(p['predicted_probability'])} | "
                     f"{_stages(p['lost'])} |")
    lines += ["", *_calibration_markdown(rec["calibration"])]
    failures = [f"{s['id']} {f}" for s in rec["stations"] for f in s["failures"]]
    if failures:
        lines += ["", "Failures:", ""] + [f"- {f}" for f in failures]
    return "\n".join(lines) + "\n"


def _calibration_markdown(cal: dict | None) -> list[str]:
    """The calibration line and binned table of the report."""
    if cal is None:
        return ["Detection calibration: no prediction (the plan has no `detection` section)."]
    lines = [f"Detection calibration over {cal['n_pairs']} pairs: mean predicted "
             f"{cal['mean_predicted']:.3f}, observed {cal['observed']:.3f}, Brier "
             f"{cal['brier']:.4f}.", "",
             "| predicted P | pairs | mean predicted | observed (95 %) |",
             "|---|---:|---:|---:|"]
    for b in cal["bins"]:
        low, high = b["wilson_95"]
        lines.append(f"| {b['low']:g}–{b['high']:g} | {b['n_pairs']} | "
                     f"{b['mean_predicted']:.3f} | {b['n_accepted']} / {b['n_trials']} "
                     f"({100 * low:.0f}–{100 * high:.0f} %) |")
    return lines


def _stages(counts: dict[str, int]) -> str:
    """``gate 2, quality 1`` (false accepts left out), ``—`` for none."""
    return ", ".join(f"{k} {v}" for k, v in counts.items() if k != "false_accepts" and v) or "—"
