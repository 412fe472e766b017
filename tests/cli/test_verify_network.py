"""``markerplan verify --network``: the closed loop on three stations of the default plan, and
plans it refuses in one line before simulating anything."""

import csv
import json

import pytest

from pipeline.tables.fate_table import FATE_STAGES
from tests.cli.invoke import run_cli
from tests.cli.network_inputs import plan_document


def _hand_made_plan(tmp_path, **config):
    doc = plan_document(["S1", "S2"], [[0, 0, 1], [10, 0, 1]], [0.0, 0.0], ["M1", "M2"],
                        [[5, 5, 0.1], [5, -5, 0.1]])
    doc["provenance"]["config"].update(config)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("args,config,needle", [
    (["--network", "--station-ids", "S2"], {}, "reference station S1 (the datum of network "
                                               "mode) is not among the stations verified (S2)"),
    ([], {"network": True, "reference_station": "S9"},
     "`reference_station` 'S9' is not a station of the network; valid ids are S1, S2"),
    (["--network", "--odometry-sigma-m", "0"], {}, "--odometry-sigma-m"),
    # --reference-station: a network plan's predictions are relative to its own datum ...
    (["--reference-station", "S2"], {"network": True}, "the plan's predictions are relative "
                                                       "to its datum S1"),
    # ... a known-control plan verified in network mode takes the datum given
    (["--network", "--reference-station", "S2", "--station-ids", "S1"], {},
     "reference station S2 (the datum of network mode) is not among the stations verified"),
])
def test_refused_in_one_line(tmp_path, capsys, args, config, needle):
    out = tmp_path / "v"
    code, _, err = run_cli(capsys, ["verify", str(_hand_made_plan(tmp_path, **config)),
                                    *args, "--out", str(out)])
    assert code != 0 and needle in err, err
    assert "Traceback" not in err and not out.exists()
    if code == 1:  # ours; click's usage errors (exit 2) carry their usage lines
        assert err.count("\n") == 1


@pytest.mark.slow
def test_network_verify_of_three_default_stations(tmp_path, capsys, valid_inputs):
    plan_dir = valid_inputs / "plan"  # the default plan
    out = tmp_path / "v"
    code, stdout, err = run_cli(capsys, ["verify", str(plan_dir / "plan.json"), "--network",
                                         "--station-ids", "S1,S2,S3", "--out", str(out),
                                         "--json"])
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["mode"] == "network" and summary["passed"]
    assert list(summary["stations"]) == ["S1", "S2", "S3"]
    worst = summary["worst"]
    # the must-show: achieved worst station error against predicted, both given
    assert 0.0 < worst["achieved_error_m"] <= 0.10 and 0.0 < worst["predicted_error_m"] <= 0.10
    rec = json.loads((out / "verify.json").read_text())
    assert rec["datum"].startswith("station S1") and rec["adjustment"]["rejected"] == []
    assert {m["id"] for m in rec["markers"]} <= {m["id"] for m in json.loads(
        (plan_dir / "plan.json").read_text())["markers"]}
    assert all(m["achieved_error_m"] < 0.05 for m in rec["markers"])
    assert rec["provenance"]["config"]["sensor_profile"]["name"]
    table = (out / "markers.csv").read_text().splitlines()
    assert table[0].startswith("station_id,marker_id,") and len(table) > 6
    # marker ids are the association's (never read from the truth): planned ids or empty
    ids = {line.split(",")[1] for line in table[1:]}
    planned_ids = {m["id"] for m in json.loads((plan_dir / "plan.json").read_text())["markers"]}
    assert ids - {""} and ids - {""} <= planned_ids
    md = (out / "verify.md").read_text()
    assert "Worst station: predicted" in md and "achieved" in md
    # every planned station-marker pair's fate, by its true id (kept from the adjustment)
    planned = {s["id"]: s["markers"] for s in json.loads(
        (plan_dir / "plan.json").read_text())["stations"]}
    fates = list(csv.DictReader((out / "fates.csv").open()))
    assert [(f["station_id"], f["marker_id"]) for f in fates] == [
        (sid, m) for sid in ("S1", "S2", "S3") for m in planned[sid]]
    assert {f["stage"] for f in fates} <= set(FATE_STAGES) and (out / "fates.csvt").exists()
    for s in rec["stations"]:
        lost = [f for f in fates if f["station_id"] == s["id"] and f["accepted"] == "false"]
        assert [(f["marker_id"], f["stage"]) for f in lost] == [
            (x["marker_id"], x["stage"]) for x in s["lost"]]
    accepted = [f for f in fates if f["accepted"] == "true"]
    assert accepted and all(float(f["error_m"]) < 0.05 for f in accepted)
    assert rec["misidentified"] == [] and "Planned markers lost:" in md
