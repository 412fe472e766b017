"""``verify --trials N``: trial seeds, the Wilson interval against hand-computed cases, every
trial x station one task with its own seed, and the summary of the trials' outcomes."""

import numpy as np
import pytest

import planner.verify.known_control as kc
from planner.outputs.plan_file import PlannedStation, SurveyPlan
from planner.verify.fates import FateRow, StationFates
from planner.verify.known_control import StationCheck
from planner.verify.trials import (
    TRIALS_COLUMNS,
    trial_seeds,
    trials_markdown,
    trials_record,
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

    def fake_check(ids, centres, cfg, model, requirement, radius, seed, st, scan, truth):
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
