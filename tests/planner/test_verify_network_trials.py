"""``verify --network --trials N`` end to end on a tiny network (two stations, four markers on a
level field, one frame in eight simulated): each trial's verdicts make the pass rate, every
accepted detection of each trial's marker table carries the id the association gave it, which
is the simulator's true id, and the trials' scans are independent draws."""

import csv
import functools
import json

import numpy as np
import pytest

import planner.verify.known_control as kc
from error_model import default_model
from planner.outputs.plan_file import PlannedStation, SurveyPlan
from planner.verify.network import NetworkVerifySettings
from planner.verify.rig_draws import OffsetTolerance, trial_offsets
from planner.verify.trials import (
    trial_seeds,
    trials_record,
    verify_network_trials,
)
from tests.cli.network_inputs import plan_document

#: Two trials of two stations simulated and adjusted: ~10 s alone, ~30 s on a loaded machine.
pytestmark = pytest.mark.slow

simulate = pytest.importorskip("visibility.simulate")
dem_mod = pytest.importorskip("visibility.dem")

IDS = ("M1", "M2", "M3", "M4")
CENTRES = np.array([[3.0, 4.0, 0.1], [3.0, -4.0, 0.1], [-3.0, 3.0, 0.1], [8.0, -3.0, 0.1]])
STATIONS = (("S1", [0.0, 0.0, 1.0]), ("S2", [6.0, 0.0, 1.0]))


@pytest.fixture(scope="module")
def network_trials(tmp_path_factory):
    root = tmp_path_factory.mktemp("net-trials")
    doc = plan_document([s for s, _ in STATIONS], [p for _, p in STATIONS], [0.0, 0.0],
                        list(IDS), CENTRES.tolist())
    for s in doc["stations"]:
        s.update(markers=list(IDS), predicted_error_m=0.05)
    plan_path = root / "plan.json"
    plan_path.write_text(json.dumps(doc))
    dem = dem_mod.DEM(np.zeros((201, 261)), (-10.0, -10.0), 0.1)
    plan = SurveyPlan(dem, tuple(PlannedStation(s, np.array(p), 0.0, 0.05, IDS)
                                 for s, p in STATIONS), IDS, CENTRES, 0.1, 0.1, 10.0,
                      {"config_sha256": "0" * 64})
    seeds = trial_seeds(4, 2)
    rigs = trial_offsets(None, OffsetTolerance(axis_offset_m=0.001), seeds)
    tables = root / "markers"
    tables.mkdir()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(kc, "simulate_markers", functools.partial(simulate.simulate_markers,
                                                             frames=range(0, 800, 8)))
        trials = verify_network_trials(plan, plan_path, doc, default_model(), "default", seeds,
                                       tables, NetworkVerifySettings(), rigs, progress=False)
    return plan, trials, seeds, rigs, tables


def test_the_pass_rate_is_the_share_of_trials_whose_every_station_passed(network_trials):
    plan, trials, seeds, rigs, _ = network_trials
    assert [[s.station_id for s in t] for t in trials] == [["S1", "S2"]] * 2
    verdicts = [all(s.passed for s in t) for t in trials]
    rec = trials_record(plan, trials, 4, seeds, "default", rigs, network={})
    assert rec["pass_rate"]["n_passed"] == sum(verdicts) and rec["passed"] == all(verdicts)
    assert [s["n_passed"] for s in rec["stations"]] == [sum(t[k].passed for t in trials)
                                                       for k in (0, 1)]
    pairs = {(p["station_id"], p["marker_id"]): p for p in rec["pairs"]}
    assert len(pairs) == 8 and all(p["n_trials"] == 2 for p in pairs.values())
    for (sid, mid), p in pairs.items():
        k = [s for s, _ in STATIONS].index(sid)
        assert p["n_accepted"] == sum(r.accepted for t in trials for r in t[k].fates.rows
                                      if r.marker_id == mid)


def _table(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_every_accepted_detection_carries_the_associations_id_the_true_one(network_trials):
    _, trials, _, _, tables = network_trials
    for t, stations in enumerate(trials):
        rows = _table(tables / f"trial_{t:03d}.csv")
        n_accepted = 0
        for s in stations:
            mine = [r for r in rows if r["station_id"] == s.station_id]
            for fate in s.fates.rows:
                if fate.accepted:
                    n_accepted += 1
                    assert mine[fate.candidate]["marker_id"] == fate.marker_id
        assert n_accepted >= 6  # most of the 8 planned pairs are seen at 5-8 m
        assert all(r["marker_id"] == "" for r in rows if r["accepted"] == "false")


def test_the_trials_are_independent_draws(network_trials):
    _, trials, seeds, rigs, tables = network_trials
    assert seeds[0] != seeds[1] and rigs[0].axis_offset_m != rigs[1].axis_offset_m
    first, second = (_table(tables / f"trial_{t:03d}.csv") for t in (0, 1))
    x = [[float(r["x_m"]) for r in rows if r["accepted"] == "true"] for rows in (first, second)]
    assert len(x[0]) == len(x[1]) and not np.allclose(x[0], x[1], atol=1e-6)
