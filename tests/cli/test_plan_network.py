"""``markerplan plan --network``: outputs on the default site, the datum, one-line errors."""

import csv
import json

import pytest

from tests.cli.invoke import run_cli


@pytest.fixture(scope="module")
def network_plan(tmp_path_factory):
    import contextlib
    import io

    from planner.cli import main

    out = tmp_path_factory.mktemp("plan-network") / "p"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        main(["plan", "--network", "--json", "--out", str(out)])
    return out, json.loads(buf.getvalue())


@pytest.mark.slow
def test_network_plan_records_the_mode_datum_ties_and_errors(network_plan):
    out, summary = network_plan
    assert sorted(p.name for p in out.iterdir()) == [
        "map.png", "markers.csv", "markers.csvt", "markers.geojson", "plan.gpkg", "plan.json",
        "provenance.json", "reliability.csv", "report.md", "station_error.tif", "stations.csv",
        "stations.csvt", "usable_markers.tif"]
    assert summary["mode"] == "network" and summary["reference_station"] == "S1"
    # chance-constrained by default: the network part is not proven optimal within the limit
    assert summary["status"] in ("optimal", "time_limit") and summary["meets_requirement"]
    doc = json.loads((out / "plan.json").read_text())
    assert doc["provenance"]["config"]["network"] is True
    datum = doc["network"]["datum"]
    assert datum.pop("datum_xyz_m")[:2] == [0.0, 0.0]  # S1's position
    assert datum == {"kind": "station", "reference_station": "S1",
                                       "fixed": ["x_m", "y_m", "z_m", "heading_rad"],
                                       "control": [], "description": "station S1",
                                       "inclinometer_sigma_deg": 0.01,
                                       "heading_prior_sigma_deg": None, "heading_aid": None,
                                       "heading_bias_sigma_deg": None, "odometry_percent": None,
                                       "odometry_heading_deg_per_m": None,
                                       "odometry_loop_m": None}
    for s in doc["stations"]:
        assert s["predicted_error_m"] <= 0.10 and s["tied_to"]
    for m in doc["markers"]:
        assert m["predicted_error_m"] <= 0.10
    assert doc["network"]["weakest_stations"][0]["predicted_error_m"] == pytest.approx(
        summary["worst_station_error_m"])
    assert doc["baselines"]["greedy"]["meets_requirement"]
    # the sampled outcomes (the network's accuracy included) keep the promise here
    assert doc["chance"]["sampled"]["wilson_95"][0] >= 0.95
    # the certified figure is the whole network's, with its accuracy, and the samples agree
    whole = doc["chance"]["network"]
    assert doc["chance"]["plan_pass_probability"] == whole["pass_low"] >= 0.95
    assert whole["fail_low"] <= 1 - doc["chance"]["sampled"]["wilson_95"][0] + 0.01
    assert whole["fail_high"] >= 1 - doc["chance"]["sampled"]["wilson_95"][1] - 0.01
    rows = list(csv.reader((out / "stations.csv").read_text().splitlines()))
    assert rows[0][:5] == ["id", "x_m", "y_m", "z_m", "network_error_m"]
    assert rows[0][-1] == "error_relative_to" and {r[-1] for r in rows[1:]} == {"station S1"}
    assert len(rows) == 1 + len(doc["stations"])
    assert "## Network" in (out / "report.md").read_text()


def test_network_bad_configuration_is_one_line(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text('reference_station = "S9"\n')
    out = tmp_path / "o"
    code, _, err = run_cli(capsys, ["plan", "--network", "--config", str(cfg), "--out", str(out)])
    assert code == 1 and err.count("\n") == 1 and "reference_station" in err and "S9" in err
    assert not out.exists()


def test_reference_station_option_names_the_datum(tmp_path, capsys):
    out = tmp_path / "p"
    code, stdout, err = run_cli(capsys, ["plan", "--network", "--reference-station", "S3",
                                         "--station-ids", "S2,S3", "--json", "--out",
                                         str(out)])
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["reference_station"] == "S3"
    doc = json.loads((out / "plan.json").read_text())
    assert doc["provenance"]["config"]["reference_station"] == "S3"
    assert doc["network"]["datum"]["reference_station"] == "S3"
    rows = list(csv.reader((out / "stations.csv").read_text().splitlines()))
    assert rows[1][rows[0].index("error_relative_to")] == "station S3"


def test_a_plan_not_proven_optimal_states_its_bound_and_gap():
    from planner.cli.plan import solver_status_text

    assert solver_status_text({"status": "optimal", "dual_bound": 3.0, "gap": 0.0}) == "optimal"
    assert solver_status_text({"status": "time_limit", "dual_bound": 683.6,
                               "gap": 0.0545}) == \
        "time_limit, no layout has fewer than 684, gap 5.5 %"
    assert solver_status_text({"status": "time_limit", "dual_bound": None, "gap": None}) == \
        "time_limit"
