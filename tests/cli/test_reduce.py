"""``markerplan reduce``: the default site's as-built layout, plan and CSV inputs, and one-line
errors without partial output."""

import csv
import json

import numpy as np
import pytest

from planner.cli import main
from tests.cli.invoke import run_cli
from visibility.sites import load_site


@pytest.fixture(scope="module")
def as_built(tmp_path_factory):
    """One run on the default site's 11-marker as-built layout (shared by several tests)."""
    out = tmp_path_factory.mktemp("reduce") / "r"
    try:
        main(["reduce", "as-built", "--site", "default", "--out", str(out), "--json"])
    except SystemExit as exc:  # pragma: no cover - main exits only on errors
        raise AssertionError(f"reduce failed with exit code {exc.code}") from exc
    return out


def test_as_built_writes_every_output(as_built):
    assert sorted(p.name for p in as_built.iterdir()) == [
        "drop_order.csv", "marker_loss.csv", "per_station.csv", "provenance.json", "reduce.json",
        "report.md", "tradeoff.csv", "tradeoff.png"]
    doc = json.loads((as_built / "reduce.json").read_text())
    assert doc["schema"] == "markerplan-reduce" and doc["layout"]["n_markers"] == 11
    assert doc["provenance"]["solver"]["statuses"]
    assert doc["provenance"]["config"]["plan"]["requirement_m"] == 0.10
    ks = [p["k"] for p in doc["curve"]]
    assert ks[0] == 11 and ks == list(range(11, ks[-1] - 1, -1))
    worst = [p["worst_error_m"] for p in doc["curve"]]
    assert all(b >= a * (1 - 1e-9) for a, b in zip(worst, worst[1:], strict=False))
    assert doc["k_feasible"] == min(p["k"] for p in doc["curve"] if p["meets_requirement"])
    assert doc["markers_that_can_go"] == 11 - doc["k_feasible"]
    for p in doc["curve"]:
        assert len(p["markers"]) == p["k"] and len(p["stations"]) == 7
        assert p["worst_error_m"] == pytest.approx(max(s["error_m"] for s in p["stations"]))
    with (as_built / "tradeoff.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["k"]) for r in rows] == ks
    with (as_built / "per_station.csv").open() as fh:
        assert len(list(csv.DictReader(fh))) == 7 * len(ks)
    assert len(doc["marker_losses"]) == 11
    assert "markers can go" in (as_built / "report.md").read_text()


def test_plan_json_input_uses_its_site_and_configuration(tmp_path, capsys):
    site = load_site("default")
    keep = [0, 2, 4, 6, 7, 8, 9, 10]
    plan = {"schema": "markerplan-plan", "site": {"name": "default", "seed": 0},
            "provenance": {"config": {"requirement_m": 0.08, "budget": 9}, "inputs": {}},
            "markers": [{"id": site.marker_ids[j], "x_m": float(site.marker_centres_m[j, 0]),
                         "y_m": float(site.marker_centres_m[j, 1]),
                         "z_m": float(site.marker_centres_m[j, 2])} for j in keep]}
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(plan))
    code, stdout, _ = run_cli(capsys, ["reduce", str(path), "--keep", "M01", "--out",
                                       str(tmp_path / "o"), "--json"])
    assert code == 0
    summary = json.loads(stdout)
    assert summary["n_markers"] == 8 and summary["curve"][0]["k"] == 8
    assert all("M01" in p["markers"] for p in summary["curve"])
    doc = json.loads((tmp_path / "o" / "reduce.json").read_text())
    assert doc["requirement"]["requirement_m"] == 0.08
    assert doc["provenance"]["config"]["plan"]["budget"] is None


def test_plan_json_input_studies_the_plans_own_stations(tmp_path, capsys, valid_inputs):
    """A plan of one of the preset's seven stations is studied at that station only, whether
    or not its provenance lists the station ids."""
    plan = json.loads((valid_inputs / "plan" / "plan.json").read_text())
    plan["stations"] = [s for s in plan["stations"] if s["id"] == "S4"]
    plan["provenance"]["inputs"].pop("station_ids", None)
    path = tmp_path / "one.json"
    path.write_text(json.dumps(plan))
    out = tmp_path / "o"
    code, _, err = run_cli(capsys, ["reduce", str(path), "--out", str(out), "--json"])
    assert code == 0, err
    with (out / "per_station.csv").open() as fh:
        assert {r["station"] for r in csv.DictReader(fh)} == {"S4"}


def _layout_csv(path, rows):
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["id", "x_m", "y_m"])
        w.writerows(rows)
    return path


@pytest.mark.parametrize("extra, rows, fix", [
    (["--keep", "M99"], None, "unknown marker id(s) M99"),
    ([], [["A", 0.0, 6.0], ["B", 55.0, 0.0]], "marker B at (55.00, 0.00) m lies outside"),
    ([], [["A", 0.0, 6.0], ["B", 25.0, 0.0]], "lies outside the site boundary"),
    (["--k-min", "1"], None, "--k-min must be in"),
    (["--verify", "--verify-k", "12"], None, "--verify-k must be comma-separated counts"),
    (["--verify-k", "5"], None, "--verify-k needs --verify"),
    (["--axis-offset-mm", "15,0"], None, "add --verify or drop them"),
])
def test_bad_input_is_one_line_without_output(tmp_path, capsys, extra, rows, fix):
    site = load_site("default")
    if rows is None:
        rows = [[i, *np.round(c[:2], 3)] for i, c in zip(site.marker_ids,
                                                         site.marker_centres_m, strict=True)]
    layout = _layout_csv(tmp_path / "layout.csv", rows)
    out = tmp_path / "o"
    code, stdout, err = run_cli(capsys, ["reduce", str(layout), "--out", str(out), "--json",
                                         *extra])
    assert code == 1 and stdout == ""
    assert err.startswith("error: ") and err.count("\n") == 1 and fix in err
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["layout.csv"]


@pytest.mark.slow
def test_verify_runs_the_simulator_at_two_points(tmp_path, capsys):
    """On a mis-mounted rig (self-calibrated by the pipeline), as in the field.

    One station keeps it to two simulations (each a full 800-frame turntable scan, processed):
    S6 alone needs only 3 of the 11 markers, and registers at both counts."""
    out = tmp_path / "v"
    code, stdout, _ = run_cli(capsys, ["reduce", "as-built", "--station-ids", "S6", "--verify",
                                       "--axis-offset-mm", "15,0", "--lframe-tilt-deg", "0.3",
                                       "--out", str(out), "--json"])
    assert code == 0
    summary = json.loads(stdout)
    assert summary["k_feasible"] < 11
    assert summary["verified_k"] == [11, summary["k_feasible"]]
    doc = json.loads((out / "reduce.json").read_text())
    rig = doc["provenance"]["config"]["reduce"]["verify_mounting_offsets"]
    assert rig["axis_offset_m"] == [0.015, 0.0]
    curve = {p["k"]: p for p in doc["curve"]}
    points = doc["verify"]["points"]
    assert [v["k"] for v in points] == summary["verified_k"]
    for v in points:
        # the curve's subset at k was simulated, and set beside its prediction
        assert v["markers"] == curve[v["k"]]["markers"]
        assert v["predicted_worst_error_m"] == curve[v["k"]]["worst_error_m"]
        assert [s["id"] for s in v["stations"]] == ["S6"]
        assert all(s["achieved_error_m"] is not None for s in v["stations"])
