"""``markerplan reduce --network``: the network's judgement (against known control on the same
layout), a network plan's mode and datum followed, and the datum named in every output."""

import csv
import functools
import json

from tests.cli.invoke import run_cli

#: Seven of the default site's as-built markers: small enough for a quick curve.
KEEP = ("M04", "M06", "M07", "M08", "M09", "M10", "M11")


@functools.cache
def _layout():
    """(id, x, y, z) of the :data:`KEEP` markers, as the site preset's as-built layout (seated
    on its DEM)."""
    from planner.problem.inputs import load_inputs

    inputs = load_inputs("default", None)
    return [(i, *map(float, c)) for i, c in zip(inputs.as_built_ids, inputs.as_built_xyz,
                                                strict=True) if i in KEEP]


def _reduce(capsys, args):
    code, stdout, err = run_cli(capsys, ["reduce", *args, "--json"])
    assert code == 0, err
    return json.loads(stdout)


def test_the_network_is_judged_worse_than_known_control_at_every_count(tmp_path, capsys):
    """Markers are unknowns: every count's optimum is worse than with known control (the
    planner tests show a requirement the network then needs more markers for)."""
    folder = tmp_path
    common = ["as-built", "--drop", "M01,M02,M03,M05", "--k-min", "5"]  # 7 markers
    known = _reduce(capsys, [*common, "--out", str(folder / "kc")])
    net = _reduce(capsys, [*common, "--network", "--reference-station", "S2",
                           "--out", str(folder / "net")])
    assert known["accuracy"] == "known control" and known["reference_station"] is None
    assert net["accuracy"] == "network mode, datum S2" and net["reference_station"] == "S2"
    assert net["proven_optimal"]
    assert [p["k"] for p in net["curve"]] == [p["k"] for p in known["curve"]] == [7, 6, 5]
    kc_worst = {p["k"]: p["worst_error_m"] for p in known["curve"]}
    for p in net["curve"]:
        assert p["worst_error_m"] > 1.2 * kc_worst[p["k"]]
    doc = json.loads((folder / "net" / "reduce.json").read_text())
    assert doc["network"]["datum"]["reference_station"] == "S2"
    assert doc["provenance"]["config"]["plan"]["network"] is True
    assert doc["provenance"]["config"]["plan"]["reference_station"] == "S2"
    # the datum's own error is the inclinometer's alone: the least of all stations
    assert min(doc["curve"][0]["stations"], key=lambda s: s["error_m"])["id"] == "S2"
    for p in doc["curve"]:
        assert p["worst_error_m"] == max(p["worst_station_error_m"], p["worst_marker_error_m"])
        assert sorted(p["marker_errors_m"]) == p["markers"]
    assert "**network mode, datum S2**" in (folder / "net" / "report.md").read_text()
    with (folder / "net" / "tradeoff.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert {"worst_station_error_m", "worst_marker_error_m"} <= set(rows[0])


def test_a_network_plan_is_reduced_in_network_mode_with_its_datum(tmp_path, capsys):
    rows = _layout()
    plan = {"schema": "markerplan-plan", "site": {"name": "default", "seed": 0},
            "provenance": {"config": {"network": True, "reference_station": "S3"},
                           "inputs": {}},
            "markers": [{"id": i, "x_m": x, "y_m": y, "z_m": z} for i, x, y, z in rows]}
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    summary = _reduce(capsys, [str(path), "--k-min", "6", "--out", str(tmp_path / "o")])
    assert summary["accuracy"] == "network mode, datum S3"
    doc = json.loads((tmp_path / "o" / "reduce.json").read_text())
    assert doc["provenance"]["config"]["plan"]["reference_station"] == "S3"
    assert min(doc["curve"][0]["stations"], key=lambda s: s["error_m"])["id"] == "S3"


def test_a_network_plans_mode_survives_another_config(tmp_path):
    from planner.config import PlanConfig
    from planner.reduction.study import resolve_inputs

    plan = {"schema": "markerplan-plan", "site": {"name": "default", "seed": 0},
            "provenance": {"config": {"network": True, "reference_station": "S3",
                                      "heading_prior_sigma_deg": 0.5}, "inputs": {}},
            "markers": [{"id": i, "x_m": x, "y_m": y, "z_m": z} for i, x, y, z in _layout()]}
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    _, _, config = resolve_inputs(str(path), config=PlanConfig(requirement_m=0.08))
    assert (config.network, config.reference_station, config.heading_prior_sigma_deg,
            config.requirement_m) == (True, "S3", 0.5, 0.08)
