"""``markerplan reduce`` states and records the requirement kinds and the datum (issue 29): a
network plan's kinds are judged and recorded; a markers CSV takes them as ``plan``'s options
(the same study as a plan recording them); ``--control`` makes control points the datum; an
option conflicting with a plan is refused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.cli.bad_input import Case, check_refused
from tests.cli.invoke import run_cli
from tests.cli.test_reduce_network import _layout

#: Three fiducials on a lander on the default site (site frame, m).
LANDER = "id,x_m,y_m,z_m,sigma_m\nL1,8,-3.8,1.33,0.005\nL2,6.96,-5.6,1.4,0.005\n" \
    "L3,9.04,-5.6,1.31,0.005\n"
#: A network configuration with the local kinds, as options and as a plan records it.
KINDS = {"network": True, "reference_station": "S3", "requirement_m": 0.3,
         "local_requirement_m": 0.2, "local_within_m": 40.0, "local_markers": True,
         "heading_aid": "sun-sensor"}
OPTIONS = ["--network", "--reference-station", "S3", "--requirement-m", "0.3",
           "--local-requirement-m", "0.2", "--local-within-m", "40", "--local-markers",
           "--heading-aid", "sun-sensor"]


def _plan_json(folder, config) -> str:
    rows = _layout()
    plan = {"schema": "markerplan-plan", "site": {"name": "default", "seed": 0},
            "provenance": {"config": config, "inputs": {}},
            "markers": [{"id": i, "x_m": x, "y_m": y, "z_m": z} for i, x, y, z in rows]}
    path = folder / "plan.json"
    path.write_text(json.dumps(plan))
    return str(path)


def _markers_csv(folder) -> str:
    path = folder / "markers.csv"
    path.write_text("id,x_m,y_m,z_m\n" + "".join(f"{i},{x!r},{y!r},{z!r}\n"
                                                 for i, x, y, z in _layout()))
    return str(path)


def _reduce(capsys, args, k_min: int = 6) -> dict:
    code, _, err = run_cli(capsys, ["reduce", *args, "--k-min", str(k_min), "--json"])
    assert code == 0, err
    return json.loads((_out(args) / "reduce.json").read_text())


def _out(args) -> Path:
    return Path(args[args.index("--out") + 1])


def test_a_plans_kinds_and_the_same_options_on_its_markers_give_one_study(tmp_path, capsys):
    """The plan's recorded kinds are judged; the same kinds given as options on its markers
    CSV give the same curve and record (up to the input named)."""
    few = ["--station-ids", "S2,S3,S4"]  # a cheaper study
    plan = _reduce(capsys, [_plan_json(tmp_path, KINDS), *few, "--out", str(tmp_path / "p")], 7)
    csv = _reduce(capsys, [_markers_csv(tmp_path), *OPTIONS, *few, "--out",
                           str(tmp_path / "c")], 7)
    req = plan["requirement"]
    assert (req["local_requirement_m"], req["local_within_m"], req["local_markers"]) \
        == (0.2, 40.0, True)
    assert req["local_requirement_text"] == \
        "0.2 m between stations within 40 m (relative position)"
    assert plan["network"]["datum"]["heading_aid"] == "sun-sensor"
    assert plan["requirement"] == csv["requirement"]
    assert plan["network"] == csv["network"]
    strip = ("input",)
    assert [{k: v for k, v in p.items() if k not in strip} for p in plan["curve"]] \
        == [{k: v for k, v in p.items() if k not in strip} for p in csv["curve"]]
    for p in plan["curve"]:  # the verdict includes the local kinds
        assert p["meets_requirement"] == (
            p["worst_error_m"] <= 0.3 and p["local_pairs_ok"] and p["marker_pairs_ok"]
            and all(s["meets_requirement"] for s in p["stations"]))
    assert plan["k_feasible"] == 7
    assert "local 0.2 m between stations within 40 m (relative position), and between kept " \
           "markers" in (tmp_path / "p" / "report.md").read_text()


def test_control_points_are_the_datum_and_stay_in_every_subset(tmp_path, capsys):
    (tmp_path / "lander.csv").write_text(LANDER)
    doc = _reduce(capsys, [_markers_csv(tmp_path), "--network", "--control",
                           str(tmp_path / "lander.csv"), "--requirement-m", "0.5", "--out",
                           str(tmp_path / "o")])
    datum = doc["network"]["datum"]
    assert datum["kind"] == "control" and datum["reference_station"] is None
    assert [c["marker_id"] for c in datum["control"]] == ["L1", "L2", "L3"]
    assert doc["layout"]["n_markers"] == 10
    for p in doc["curve"]:
        assert {"L1", "L2", "L3"} <= set(p["markers"])
    assert doc["provenance"]["inputs"]["control"].endswith("lander.csv")
    assert "**control points** L1 (+-0.005 m)" in (tmp_path / "o" / "report.md").read_text()


def _cases(tmp_path):
    plan = _plan_json(tmp_path, KINDS)
    csv = _markers_csv(tmp_path)
    return [
        Case("plan-conflicting-local-within", ["reduce", plan, "--local-within-m", "30",
                                               "--out", "out"],
             "--local-within-m 30.0 conflicts with INPUT"),
        Case("plan-conflicting-datum", ["reduce", plan, "--no-datum-requirement", "--out",
                                        "out"], "--no-datum-requirement conflicts"),
        Case("plan-conflicting-figure", ["reduce", plan, "--error-figure", "quantile",
                                         "--out", "out"], "--error-figure quantile conflicts"),
        Case("plan-control", ["reduce", plan, "--control", "lander.csv", "--out", "out"],
             "records its own datum", files={"lander.csv": LANDER}),
        Case("csv-control-known-control", ["reduce", csv, "--control", "lander.csv", "--out",
                                           "out"], "add --network",
             files={"lander.csv": LANDER}),
        Case("csv-control-and-reference", ["reduce", csv, "--network", "--control",
                                           "lander.csv", "--reference-station", "S1", "--out",
                                           "out"], "drop --reference-station",
             files={"lander.csv": LANDER}),
        Case("csv-control-id-clash", ["reduce", csv, "--network", "--control", "lander.csv",
                                      "--out", "out"], "M04",
             files={"lander.csv": LANDER.replace("L1,", "M04,")}),
        Case("csv-local-known-control", ["reduce", csv, "--local-requirement-m", "0.1",
                                         "--out", "out"], "from the command-line options"),
        Case("csv-local-bad-value", ["reduce", csv, "--local-within-m", "-3", "--out", "out"],
             "--local-within-m", code=2),
    ]


CASE_NAMES = ("plan-conflicting-local-within", "plan-conflicting-datum",
              "plan-conflicting-figure", "plan-control", "csv-control-known-control",
              "csv-control-and-reference", "csv-control-id-clash", "csv-local-known-control",
              "csv-local-bad-value")


@pytest.mark.parametrize("name", CASE_NAMES)
def test_bad_input_is_one_line_and_writes_nothing(name, tmp_path, capsys, monkeypatch):
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    cases = {c.name: c for c in _cases(inputs)}
    assert set(cases) == set(CASE_NAMES)
    case = cases[name]
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    check_refused(case, capsys, monkeypatch, cwd, inputs)
