"""``verify --trials N``: trial seeds, the Wilson interval against hand-computed cases, every
trial x station one task with its own seed and rig, the rig offsets drawn from the tolerances,
network trials counted from each trial's verdicts, the plan's predicted probabilities beside
the observed rates, and the summary of the trials' outcomes."""

import json
import math

import numpy as np
import pytest

import planner.verify.known_control as kc
import planner.verify.network as net
from markerplan.errors import ConfigError, DataError, InputFileError
from pipeline.scans.rig import MountingOffsets
from planner.outputs.plan_file import PlannedStation, SurveyPlan
from planner.verify.fates import FateRow, StationFates
from planner.verify.known_control import StationCheck
from planner.verify.network import NetworkVerification, StationOutcome
from planner.verify.rig_draws import OffsetTolerance, trial_offsets
from planner.verify.trials import (
    TRIALS_COLUMNS,
    read_predictions,
    trial_seeds,
    trials_markdown,
    trials_record,
    verify_network_trials,
    verify_trials,
    wilson_interval,
    write_trials,
)


@pytest.mark.parametrize("k,n,low,high", [
    # worked by hand, z = 1.959964, z² = 3.841459:
    # p = 1/2, n = 8: centre 1/2, half-width z/1.480182 * sqrt(1/32 + z²/256) = 0.284784
    (4, 8, 0.215216, 0.784784),
    # k = 0: [0, (z²/n) / (1 + z²/n)] = [0, 0.768292 / 1.768292]
    (0, 5, 0.0, 0.434482),
    # k = n: [1 / (1 + z²/n), 1] = [1 / 1.096036, 1]
    (40, 40, 0.912378, 1.0),
    # p = 0.95: centre 0.998018 / 1.096036 = 0.910570, half-width
    # z/1.096036 * sqrt(0.0011875 + 0.00060023) = 0.075609
    (38, 40, 0.834961, 0.986179)])
def test_wilson_interval_by_hand(k, n, low, high):
    got = wilson_interval(k, n)
    assert got == pytest.approx((low, high), abs=2e-6)


def test_wilson_interval_refuses_impossible_counts():
    for k, n in ((3, 2), (-1, 4), (0, 0)):
        with pytest.raises(ValueError, match="0 <= k <= n"):
            wilson_interval(k, n)


def test_trial_seeds_start_at_the_seed_and_are_independent_and_reproducible():
    assert trial_seeds(7, 1) == [7]
    seeds = trial_seeds(7, 6)
    assert seeds[0] == 7 and len(set(seeds)) == 6 and seeds == trial_seeds(7, 6)
    assert trial_seeds(7, 3) == seeds[:3]  # more trials extend, never reshuffle
    assert trial_seeds(8, 6)[1:] != seeds[1:] and all(0 <= s < 2**32 for s in seeds)


def _plan():
    from visibility.dem import DEM

    dem = DEM(np.zeros((3, 3)), (0.0, 0.0), 1.0)
    stations = tuple(PlannedStation(f"S{i}", np.array([float(i), 0.0, 1.0]), 0.0, 0.02,
                                    ("M1", "M2")) for i in (1, 2))
    return SurveyPlan(dem, stations, ("M1", "M2"), np.zeros((2, 3)), 0.1, 0.1, 10.0,
                      {"config_sha256": "0" * 64})


def _fates(station_id, lost_stage=None):
    rows = (FateRow(station_id, "M1", 8.0, -5.0, 900, "accepted", "", True, 0.003, 0),
            FateRow(station_id, "M2", 20.0, -2.0, 80, lost_stage or "accepted",
                    "too_large" if lost_stage else "", lost_stage is None, None, None))
    return StationFates(rows, 0)


def test_every_trial_and_station_is_a_task_with_its_own_seed(monkeypatch):
    seen = []

    def fake_simulate(dem, position, heading, centres, sensor, rig, seed, **kw):
        return None, {"seed": seed}

    def fake_check(ids, centres, cfg, model, requirement, radius, seed, st, scan, truth,
                   rule=None):
        seen.append((st.id, seed, truth["seed"]))
        ok = truth["seed"] % 2 == 0
        return StationCheck(st.id, 0.02, 0.01, 2, 2, ok, "ok" if ok else "lost", {},
                            _fates(st.id, None if ok else "gate"))

    monkeypatch.setattr(kc, "simulate_markers", fake_simulate)
    monkeypatch.setattr(kc, "check_station", fake_check)
    seeds = trial_seeds(3, 4)
    trials = verify_trials(_plan(), None, seeds, progress=False)
    assert [[c.station_id for c in t] for t in trials] == [["S1", "S2"]] * 4
    # trial t's station k is simulated with seed_t + k, the pipeline told seed_t
    assert seen == [(f"S{k + 1}", s, s + k) for s in seeds for k in (0, 1)]


def test_the_summary_counts_trials_stations_and_pairs(tmp_path):
    plan = _plan()
    ok = StationCheck("S1", 0.02, 0.01, 2, 2, True, "ok", {}, _fates("S1"))
    bad = StationCheck("S2", 0.02, 0.2, 2, 1, False, "achieved 0.200 m > requirement 0.1 m "
                       "(lost M2 at the gate (too_large))", {}, _fates("S2", "gate"))
    good = StationCheck("S2", 0.02, 0.03, 2, 2, True, "ok", {}, _fates("S2"))
    trials = [[ok, good], [ok, bad], [ok, good], [ok, bad]]
    seeds = trial_seeds(0, 4)
    rec = trials_record(plan, trials, 0, seeds, "default")
    assert rec["passed"] is False and rec["mode"] == "trials"
    assert rec["pass_rate"]["n_passed"] == 2 and rec["pass_rate"]["rate"] == 0.5
    assert rec["pass_rate"]["wilson_95"] == pytest.approx(list(wilson_interval(2, 4)))
    assert rec["losses"] == {"gate": 2, "false_accepts": 0}
    s1, s2 = rec["stations"]
    assert (s1["n_passed"], s2["n_passed"]) == (4, 2)
    assert s2["achieved_error_m"] == {"median": pytest.approx(0.115), "max": 0.2}
    assert s2["failures"] == [f"trial {t}: {bad.reason}" for t in (1, 3)]
    pairs = {(p["station_id"], p["marker_id"]): p for p in rec["pairs"]}
    assert pairs["S2", "M2"]["n_accepted"] == 2 and pairs["S2", "M2"]["lost"] == {"gate": 2}
    assert pairs["S1", "M1"]["accepted_rate"] == 1.0 and pairs["S1", "M1"]["lost"] == {}
    assert rec["provenance"]["config"]["trial_seeds"] == seeds
    md = trials_markdown(rec)
    assert "— passed 2 / 4 (15–85 %)" in md and "| S2 | M2 | 20.0 m | 2 / 4" in md
    assert "- S2 trial 1: achieved 0.200 m" in md
    write_trials(tmp_path / "trials.csv", trials, seeds)
    lines = (tmp_path / "trials.csv").read_text().splitlines()
    assert lines[0] == ",".join(TRIALS_COLUMNS) and len(lines) == 1 + 8
    assert lines[4].startswith(f"1,{seeds[1]},S2,false,0.020000,0.200000,2,1,1,0,")
    assert (tmp_path / "trials.csvt").exists()


NOMINAL = MountingOffsets(math.radians(0.3), math.radians(-0.2), (0.015, -0.004))
TOLERANCE = OffsetTolerance(math.radians(0.1), math.radians(0.05), 0.002)


def _as_array(rigs):
    return np.array([[r.vertical_axis_error_rad, r.lframe_tilt_rad, *r.axis_offset_m]
                     for r in rigs])


def test_rig_offsets_are_drawn_reproducibly_with_the_tolerances_spread():
    seeds = trial_seeds(11, 4000)
    rigs = trial_offsets(NOMINAL, TOLERANCE, seeds)
    assert rigs == trial_offsets(NOMINAL, TOLERANCE, seeds)
    centre = np.array([NOMINAL.vertical_axis_error_rad, NOMINAL.lframe_tilt_rad,
                       *NOMINAL.axis_offset_m])
    sigma = np.array([TOLERANCE.vertical_axis_error_rad, TOLERANCE.lframe_tilt_rad,
                      TOLERANCE.axis_offset_m, TOLERANCE.axis_offset_m])
    z = (_as_array(rigs) - centre) / sigma
    # 4000 standard normals: the mean within 4 standard errors (0.063) of 0, the standard
    # deviation within 0.05 of 1 (4.5 of its standard errors), the four uncorrelated
    assert np.abs(z.mean(axis=0)).max() < 4 / np.sqrt(len(seeds))
    assert z.std(axis=0) == pytest.approx(np.ones(4), abs=0.05)
    assert np.abs(np.corrcoef(z.T) - np.eye(4)).max() < 0.07
    # no tolerance, or zero tolerances: the given offsets in every trial
    assert trial_offsets(NOMINAL, None, seeds[:3]) == [NOMINAL] * 3
    assert trial_offsets(NOMINAL, OffsetTolerance(), seeds[:3]) == [NOMINAL] * 3
    # a stream of its own: not the first normals of the simulation seed's generator
    assert not np.allclose(z[1], np.random.default_rng(seeds[1]).standard_normal(4))


@pytest.mark.parametrize("field,value", [("axis_offset_m", -1e-3), ("lframe_tilt_rad", np.nan),
                                         ("vertical_axis_error_rad", 1.0),
                                         ("axis_offset_m", 0.5)])
def test_tolerances_negative_nan_or_absurd_are_refused(field, value):
    with pytest.raises(ConfigError, match=f"the tolerance `{field}` must be in"):
        OffsetTolerance(**{field: value})


def _fake_chain(monkeypatch, seen):
    def fake_simulate(dem, position, heading, centres, sensor, rig, seed, **kw):
        return None, {"seed": seed, "offsets": rig.offsets}

    def fake_check(ids, centres, cfg, model, requirement, radius, seed, st, scan, truth,
                   rule=None):
        seen.append((st.id, truth["seed"], truth["offsets"]))
        ok = truth["seed"] % 2 == 0
        return StationCheck(st.id, 0.02, 0.01, 2, 2, ok, "ok" if ok else "lost", {},
                            _fates(st.id, None if ok else "gate"))

    monkeypatch.setattr(kc, "simulate_markers", fake_simulate)
    monkeypatch.setattr(kc, "check_station", fake_check)


def test_each_trial_simulates_its_own_rig(monkeypatch):
    seen = []
    _fake_chain(monkeypatch, seen)
    seeds = trial_seeds(3, 3)
    rigs = trial_offsets(NOMINAL, TOLERANCE, seeds)
    verify_trials(_plan(), None, seeds, rigs, progress=False)
    assert [o for _, _, o in seen] == [r for r in rigs for _ in (0, 1)]
    assert len({r.axis_offset_m for r in rigs}) == 3


class _LastFirst:
    """An executor that runs the tasks last first (as a cluster may complete them) and hands
    the results back in task order, as :meth:`planner.distributed.Executor.map` does."""

    def threads(self, n_tasks):
        return 1

    def map(self, fn, items, *, shared=None, labels=None, desc=""):
        items = list(items)
        done = {i: fn(shared, items[i]) for i in reversed(range(len(items)))}
        return [done[i] for i in range(len(items))]


def test_the_trials_do_not_depend_on_the_order_tasks_complete(monkeypatch):
    here, there = [], []
    _fake_chain(monkeypatch, here)
    seeds = trial_seeds(5, 3)
    in_process = verify_trials(_plan(), None, seeds, progress=False)
    _fake_chain(monkeypatch, there)
    reordered = verify_trials(_plan(), None, seeds, executor=_LastFirst(), progress=False)
    assert there == here[::-1]  # the tasks did run last first ...
    assert reordered == in_process  # ... and every trial has the same stations' results


def _doc():
    return {"stations": [{"id": s, "markers": ["M1", "M2"], "predicted_error_m": 0.02}
                         for s in ("S1", "S2")]}


def test_network_trials_count_each_trials_verdict(monkeypatch, tmp_path):
    """Trials 1 and 3 fail: S2 loses M2 at the gate in odd trials, and in trial 3 the datum
    station identified nothing, which fails the trial's every station instead of the run."""
    seeds = trial_seeds(2, 4)
    rigs = trial_offsets(NOMINAL, TOLERANCE, seeds)
    asked = {}

    def fake_scan_plans(plan, seeds_, progress, offsets, station_ids, profile, executor,
                        names, body, reference):
        asked.update(seeds=seeds_, offsets=offsets, names=names)
        assert body.radius_m is None and reference is None  # the plane, the plan's datum
        return [([], {}, {"S1": _fates("S1"), "S2": _fates("S2", "gate" if t % 2 else None)})
                for t in range(len(seeds_))]

    def fake_verify_scan(scanned, table, plan_path, doc, model, name, settings, reference,
                         seed=0):
        if table.name == "trial_003.csv":
            raise InputFileError("the reference station S1 (the datum) has no detection")
        ok = scanned[2]["S2"].rows[1].accepted
        return NetworkVerification(
            [StationOutcome("S1", 0.02, 0.03, 0.004, 2, 2, 2, True, "ok"),
             StationOutcome("S2", 0.02, 0.03, 0.01 if ok else 0.2, 2 if ok else 1, 2, 2, ok,
                            "ok" if ok else "achieved 0.200 m > requirement 0.1 m")],
            [], "S1", {})

    monkeypatch.setattr(net, "scan_plans", fake_scan_plans)
    monkeypatch.setattr(net, "verify_scan", fake_verify_scan)
    trials = verify_network_trials(_plan(), tmp_path / "plan.json", _doc(), None, "default",
                                   seeds, tmp_path, None, rigs, progress=False)
    assert asked == {"seeds": seeds, "offsets": rigs, "names": [f"trial {t}" for t in range(4)]}
    verdicts = [all(s.passed for s in t) for t in trials]
    assert verdicts == [True, False, True, False]
    assert trials[3][0].reason == ("not verified: the reference station S1 (the datum) has no "
                                   "detection") and trials[3][1].n_detected == 1
    rec = trials_record(_plan(), trials, 2, seeds, "default", rigs, network={"x": 1},
                        nominal=NOMINAL, tolerance=TOLERANCE)
    assert rec["mode"] == "network_trials" and rec["passed"] is False
    assert rec["pass_rate"]["n_passed"] == sum(verdicts) == 2
    assert rec["pass_rate"]["wilson_95"] == pytest.approx(list(wilson_interval(2, 4)))
    assert rec["pass_rate"]["predicted_probability"] is None and rec["calibration"] is None
    s1, s2 = rec["stations"]
    assert (s1["n_passed"], s2["n_passed"]) == (3, 2)
    pairs = {(p["station_id"], p["marker_id"]): p for p in rec["pairs"]}
    assert pairs["S2", "M2"]["n_accepted"] == 2 and pairs["S2", "M2"]["lost"] == {"gate": 2}
    cfg = rec["provenance"]["config"]
    assert cfg["network"] == {"x": 1} and cfg["mounting_offsets"] == NOMINAL.to_dict()
    assert cfg["trial_mounting_offsets"] == [r.to_dict() for r in rigs]
    assert "network mode, 4 trials — passed 2 / 4" in trials_markdown(rec)
    write_trials(tmp_path / "trials.csv", trials, seeds, rigs)
    rows = (tmp_path / "trials.csv").read_text().splitlines()[1:]
    assert len(rows) == 8 and rows[2].startswith(f"1,{seeds[1]},S1,true,")
    assert rows[2].endswith(f",{1e3 * rigs[1].axis_offset_m[0]:.6f},"
                            f"{1e3 * rigs[1].axis_offset_m[1]:.6f}")


def _plan_with_predictions(tmp_path, probabilities, chance=None):
    pairs = [{"station": s, "site": m, "probability": p}
             for (s, m), p in probabilities.items()]
    path = tmp_path / "plan.json"
    path.write_text(json.dumps({"markers": [], "detection": {"model": {"name": "test"},
                                                             "pairs": pairs},
                                **({"chance": chance} if chance else {})}))
    return path


def test_the_plans_predicted_probabilities_stand_beside_the_observed_rates(tmp_path):
    predicted = {("S1", "M1"): 0.99, ("S1", "M2"): 0.6, ("S2", "M1"): 0.97, ("S2", "M2"): 0.55}
    pred = read_predictions(_plan_with_predictions(
        tmp_path, predicted, {"epsilon": 0.05, "plan_pass_probability": 0.3,
                              "stations": {"S1": {"pass_probability": 0.6, "exact": True},
                                           "S2": 0.5}}))
    ok = StationCheck("S1", 0.02, 0.01, 2, 2, True, "ok", {}, _fates("S1"))
    bad = StationCheck("S2", 0.02, 0.2, 2, 1, False, "lost M2", {}, _fates("S2", "gate"))
    good = StationCheck("S2", 0.02, 0.03, 2, 2, True, "ok", {}, _fates("S2"))
    rec = trials_record(_plan(), [[ok, good], [ok, bad], [ok, good], [ok, bad]], 0,
                        trial_seeds(0, 4), "default", predictions=pred)
    assert rec["pass_rate"]["predicted_probability"] == 0.3
    assert [s["predicted_probability"] for s in rec["stations"]] == [0.6, 0.5]
    assert {(p["station_id"], p["marker_id"]): p["predicted_probability"]
            for p in rec["pairs"]} == predicted
    cal = rec["calibration"]
    # 16 pair-trials, 14 accepted (S2-M2 lost twice); Brier by hand:
    # (4 * 0.01² + 4 * 0.4² + 4 * 0.03² + 2 * 0.45² + 2 * 0.55²) / 16 = 1.654 / 16
    assert cal["n_pairs"] == 4 and cal["observed"] == 14 / 16
    assert cal["mean_predicted"] == pytest.approx(0.7775) and cal["brier"] == pytest.approx(
        1.654 / 16)
    low, high = cal["bins"]
    assert (low["low"], low["high"], low["n_pairs"], low["n_trials"], low["n_accepted"]) == (
        0.5, 0.8, 2, 8, 6) and low["mean_predicted"] == pytest.approx(0.575)
    assert (high["low"], high["high"], high["n_accepted"]) == (0.95, 0.99, 8)
    md = trials_markdown(rec)
    assert "Predicted P(pass): 0.300." in md and "| S2 | M2 | 20.0 m | 2 / 4" in md
    assert "| S2 | M2 | 20.0 m | 2 / 4 (15–85 %) | 0.550 | gate 2 |" in md
    assert "| 0.5–0.8 | 2 | 0.575 | 6 / 8 (41–93 %) |" in md and "observed 0.875" in md


def test_a_plan_without_predictions_reports_none_and_bad_ones_are_refused(tmp_path):
    path = tmp_path / "plain.json"
    path.write_text(json.dumps({"markers": []}))
    assert read_predictions(path) is None
    rec = trials_record(_plan(), [[StationCheck("S1", 0.02, 0.01, 2, 2, True, "ok", {},
                                                _fates("S1"))]] * 2, 0, [0, 1], "default")
    assert rec["calibration"] is None and rec["pairs"][0]["predicted_probability"] is None
    assert "Predicted P(pass): not in the plan" in trials_markdown(rec)
    assert "Detection calibration: no prediction" in trials_markdown(rec)
    for bad in (1.5, float("nan"), "x"):
        with pytest.raises(DataError, match="its `detection` / `chance` sections are not a "
                                            "plan's") as info:
            read_predictions(_plan_with_predictions(tmp_path, {("S1", "M1"): bad}))
        assert "\n" not in str(info.value)
