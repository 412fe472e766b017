"""Bad input to ``markerplan adjust``: refused in one line that names the stations, tables or
option, exit 1 (2 for click usage errors), nothing written (:mod:`tests.cli.bad_input`).

The marker tables come from a simulated 4-station network (:mod:`tests.cli.network_inputs`),
written into each case's working folder as ``net/table_1.csv`` (S01, S02) and
``net/table_2.csv`` (S03, S04) with ``net/plan.json``.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from tests.cli.bad_input import Case, check_refused
from tests.cli.network_inputs import write_network_inputs
from tests.cli.test_bad_input_output import _cases_for

#: A heading file of the 4 stations
HEAD_HEADER = "id,heading_deg\n"
HEADINGS = HEAD_HEADER + "S01,0\nS02,10\nS03,20\nS04,30\n"
#: An odometry file of the 4 stations (positions along x: only the file's checks matter)
ODO_HEADER = "id,x_m,y_m,z_m,heading_deg\n"
ODO = ODO_HEADER + "S01,0,0,0,0\nS02,15,0,0,0\nS03,30,0,0,0\nS04,45,0,0,0\n"
T1, T2, PLAN = "net/table_1.csv", "net/table_2.csv", "net/plan.json"
TABLES = [T1, T2]


def net(cwd: Path, inputs: Path) -> None:
    write_network_inputs(cwd / "net", n_stations=4, seed=3)


def _edit_table(path: Path, edit) -> None:
    with path.open() as fh:
        rows = list(csv.DictReader(fh))
    rows = edit(rows)
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)


def with_net(edit_table2=None, edit_plan=None):
    """A ``setup``: the network, then ``edit_table2(rows)`` on table 2 and ``edit_plan(doc)``
    on the plan."""
    def setup(cwd: Path, inputs: Path) -> None:
        net(cwd, inputs)
        if edit_table2 is not None:
            _edit_table(cwd / T2, edit_table2)
        if edit_plan is not None:
            doc = json.loads((cwd / PLAN).read_text())
            edit_plan(doc)
            (cwd / PLAN).write_text(json.dumps(doc))
    return setup


def _foreign_markers(rows):
    for r in rows:
        r["marker_id"] = "X" + r["marker_id"] if r["marker_id"] else ""
    return rows


def _moved_plan(doc):
    for m in doc["markers"]:
        m["x_m"] += 500.0


def _inclinometer_sigma(value):
    def edit(doc):
        doc["provenance"]["config"]["inclinometer_sigma_deg"] = value
    return edit


def _heading_bias(value):
    """A network plan whose heading aid's recorded bias is ``value``."""
    def edit(doc):
        doc["provenance"]["config"]["heading_prior_sigma_deg"] = 0.1
        doc["network"] = {"datum": {"heading_prior_sigma_deg": 0.1,
                                    "heading_bias_sigma_deg": value}}
    return edit


def _error_figure(doc):
    doc["provenance"]["config"]["error_figure"] = "worst-case"


def _nan(rows):
    rows[0]["x_m"] = "nan"
    return rows


def _all_rejected(rows):
    for r in rows:
        r["accepted"] = "false"
    return rows


def _station_s01(rows):
    for r in rows:
        r["station_id"] = "S01"
    return rows


def _first_row_twice(rows):
    return [rows[0], *rows]


def _second_estimator(rows):
    """Each accepted detection again, as the other estimator found it (range-study style)."""
    return rows + [{**r, "estimator": "hemisphere-icp", "x_m": f"{float(r['x_m']) + 0.002:f}"}
                   for r in rows if r["accepted"] == "true"]


def _control(*points):
    """A control CSV of ``(id, x, y, z)`` points, 0.01 m sigma."""
    return "id,x_m,y_m,z_m,sigma_m\n" + "".join(f"{p[0]},{p[1]},{p[2]},{p[3]},0.01\n"
                                                for p in points)


def _cases() -> list[Case]:
    a = ["adjust", *TABLES, "--out", "o"]
    return [
        Case("adjust-disconnected-stations", a + ["--marker-ids", "table"],
             "stations S03, S04 share", setup=with_net(_foreign_markers)),
        Case("adjust-control-leaves-heading-free", a + ["--marker-ids", "table", "--control",
                                                        "one.csv"], "heading",
             files={"one.csv": "id,x_m,y_m,z_m,sigma_m\nM005,1,2,3,0.01\n"}, setup=net),
        Case("adjust-tables-of-another-site", a + ["--plan", "{inputs}/plan/plan.json"],
             "S01, S02, S03, S04 of the marker tables are not in --plan", setup=net),
        Case("adjust-detections-match-no-planned-marker", a + ["--plan", PLAN],
             "matches a marker of --plan", setup=with_net(edit_plan=_moved_plan)),
        Case("adjust-missing-table", ["adjust", "nothere.csv", "--out", "o"], "file not found"),
        Case("adjust-wrong-columns", ["adjust", "bad.csv", "--out", "o"], "missing column",
             files={"bad.csv": "id,x,y\nM1,2,3\n"}),
        Case("adjust-no-accepted-detection", a, "table_2.csv holds no accepted detection",
             setup=with_net(_all_rejected)),
        Case("adjust-unknown-datum-station", a + ["--reference-station", "S99"],
             "--reference-station 'S99' is not a station of the network",
             setup=net),
        Case("adjust-datum-syntax", a + ["--datum", "lander"], "give station or free", code=2),
        Case("adjust-two-datums", a + ["--control", "c.csv", "--datum", "free"],
             "give one datum"),
        Case("adjust-table-twice", ["adjust", T1, f"./{T1}", "--out", "o"], "given twice",
             setup=net),
        Case("adjust-station-in-two-tables", a, "station S01 is in marker tables",
             setup=with_net(_station_s01)),
        Case("adjust-non-finite-centre", a, "x_m: must be a finite number", setup=with_net(_nan)),
        Case("adjust-plan-identity-without-plan", a + ["--marker-ids", "plan"], "needs --plan"),
        Case("adjust-control-by-geometry", a + ["--control", "c.csv"], "--control names markers",
             files={"c.csv": "id,x_m,y_m,z_m,sigma_m\nM1,0,0,0,0.01\n"}),
        Case("adjust-control-zero-sigma", a + ["--plan", PLAN, "--control", "c.csv"],
             "sigma_m: must be > 0", files={"c.csv": "id,x_m,y_m,z_m,sigma_m\nM001,0,0,0,0\n"},
             setup=net),
        *(Case(f"adjust-plan-inclinometer-sigma-{name}", a + ["--plan", PLAN],
               "inclinometer_sigma_deg: must be at least",
               setup=with_net(edit_plan=_inclinometer_sigma(value)))
          for name, value in (("zero", 0), ("negative", -0.01))),
        Case("adjust-plan-inclinometer-sigma-nan", a + ["--plan", PLAN],
             "inclinometer_sigma_deg: must be a finite number", setup=with_net(
                 edit_plan=_inclinometer_sigma("nan"))),
        Case("adjust-plan-error-figure-unknown", a + ["--plan", PLAN],
             "error_figure: must be one of 'quantile', 'ellipsoid', got 'worst-case'",
             setup=with_net(edit_plan=_error_figure)),
        Case("adjust-heading-prior-without-plan", a + ["--heading-prior-sigma-deg", "1"],
             "needs --plan"),
        Case("adjust-bad-alpha0", a + ["--alpha0", "0"], "--alpha0", code=2),
        Case("adjust-unknown-body", a + ["--body", "mars"], "--body", code=2),
        Case("adjust-body-crs-without-a-crs", a + ["--plan", PLAN, "--body", "crs"],
             "--body crs takes the body from the ellipsoid of --plan's CRS", setup=net),
        Case("adjust-robust-and-snooping", a + ["--robust", "huber", "--snooping"],
             "--robust huber replaces data snooping: drop --snooping"),
        Case("adjust-unknown-robust-estimator", a + ["--robust", "l1"], "--robust", code=2),
        Case("adjust-igg3-k0-not-below-k1", a + ["--robust", "igg3", "--robust-k0", "3",
                                                 "--robust-k1", "2"],
             "IGG-III needs robust_k0 < robust_k1, got 3.0 and 2.0", setup=net),
        Case("adjust-unknown-variance-groups", a + ["--variance-components", "marker"],
             "--variance-components", code=2),
        Case("adjust-control-two-identical-points", a + ["--marker-ids", "table", "--control",
                                                         "two.csv"], "leave heading",
             files={"two.csv": _control(("M005", 1, 2, 3), ("M006", 1, 2, 3))}, setup=net),
        Case("adjust-control-points-stacked-vertically",
             a + ["--marker-ids", "table", "--control", "two.csv"], "leave heading",
             files={"two.csv": _control(("M005", 1, 2, 3), ("M006", 1, 2, 8))}, setup=net),
        Case("adjust-control-tiny-sigma", a + ["--marker-ids", "table", "--control", "c.csv"],
             "sigma_m: must be > 0 (at least", setup=net, files={
                 "c.csv": "id,x_m,y_m,z_m,sigma_m\nM005,1,2,3,1e-300\nM006,9,2,3,1e-300\n"}),
        Case("adjust-duplicated-detection-row", a + ["--marker-ids", "table"],
             "table_2.csv: 1 row repeats an earlier row exactly: row 3 repeats row 2",
             setup=with_net(_first_row_twice)),
        Case("adjust-mixed-estimators", a + ["--marker-ids", "table"],
             "estimator 'hemisphere-icp'", setup=with_net(_second_estimator)),
        Case("adjust-geometry-with-inclinometer-sigma-10", a + ["--inclinometer-sigma-deg", "10"],
             "--inclinometer-sigma-deg 10 deg", setup=net),
        *(Case(f"adjust-{option}-tiny", a + ["--plan", PLAN, f"--{option}", "1e-300"],
               f"--{option}", code=2, setup=net)
          for option in ("inclinometer-sigma-deg", "heading-prior-sigma-deg", "odometry-sigma-m",
                         "odometry-heading-sigma-deg")),
        Case("adjust-plan-inclinometer-sigma-tiny", a + ["--plan", PLAN],
             "inclinometer_sigma", setup=with_net(
                 edit_plan=_inclinometer_sigma(1e-300))),
        Case("adjust-odometry-without-sigmas", a + ["--odometry", "odo.csv"],
             "--odometry needs its sigmas", files={"odo.csv": ODO}, setup=net),
        Case("adjust-odometry-sigma-without-file", a + ["--odometry-percent", "1"],
             "give the file or drop them", setup=net),
        Case("adjust-odometry-percent-zero", a + ["--odometry", "odo.csv", "--odometry-percent",
                                                  "0"], "--odometry-percent", code=2,
             files={"odo.csv": ODO}, setup=net),
        Case("adjust-odometry-heading-rate-negative",
             a + ["--odometry", "odo.csv", "--odometry-heading-deg-per-m", "-0.1"],
             "--odometry-heading-deg-per-m", code=2, files={"odo.csv": ODO}, setup=net),
        Case("adjust-odometry-unknown-station", a + ["--odometry", "odo.csv",
                                                     "--odometry-percent", "1"],
             "odometry stations S09 are not stations of the network",
             files={"odo.csv": ODO + "S09,40,0,0,0\n"}, setup=net),
        Case("adjust-odometry-one-row", a + ["--odometry", "odo.csv", "--odometry-percent", "1"],
             "odometry needs at least 2 rows", files={"odo.csv": ODO_HEADER + "S01,0,0,0,0\n"},
             setup=net),
        Case("adjust-odometry-repeated-position",
             a + ["--odometry", "odo.csv", "--odometry-percent", "1"], "no distance driven",
             files={"odo.csv": ODO_HEADER + "S01,0,0,0,0\nS02,0,0,0,5\n"}, setup=net),
        Case("adjust-odometry-wrong-columns",
             a + ["--odometry", "odo.csv", "--odometry-percent", "1"], "missing column",
             files={"odo.csv": "id,x_m,y_m\nS01,0,0\n"}, setup=net),
        Case("adjust-odometry-non-finite", a + ["--odometry", "odo.csv", "--odometry-percent",
                                                "1"], "heading_deg: must be a finite number",
             files={"odo.csv": ODO_HEADER + "S01,0,0,0,nan\nS02,1,0,0,0\n"}, setup=net),
        Case("adjust-heading-bias-without-prior", a + ["--heading-bias-sigma-deg", "0.05"],
             "--heading-bias-sigma-deg needs a heading prior", setup=net),
        Case("adjust-headings-without-sigma", a + ["--headings", "h.csv"],
             "--headings needs the readings' 1-sigma", files={"h.csv": HEADINGS}, setup=net),
        *(Case(f"adjust-headings-{name}", a + ["--headings", "h.csv",
                                               "--heading-prior-sigma-deg", "0.1"],
               needle, files={"h.csv": text}, setup=net)
          for name, text, needle in (
              ("missing-station", HEAD_HEADER + "S01,0\nS02,10\n",
               "station(s) S03, S04 have no heading reading"),
              ("unknown-station", HEADINGS + "S09,5\n",
               "heading readings of S09: not stations of the network"),
              ("non-finite", HEAD_HEADER + "S01,0\nS02,inf\n",
               "row 3 heading_deg: must be a finite number"),
              ("wrong-columns", "id,heading_rad\nS01,0\n", "missing column"),
              ("no-rows", HEAD_HEADER, "no rows"),
              ("repeated-id", HEADINGS + "S01,1\n", "appears more than once"))),
        *(Case(f"adjust-plan-heading-bias-{name}", a + ["--plan", PLAN],
               needle, setup=with_net(edit_plan=_heading_bias(value)))
          for name, value, needle in (
              ("negative", -0.05, "heading_bias_sigma_deg: must be 0 (none) or at least"),
              ("text", "big", "heading_bias_sigma_deg: must be a number"))),
        Case("adjust-heading-bias-zero", a + ["--plan", PLAN, "--heading-prior-sigma-deg", "0.1",
                                              "--heading-bias-sigma-deg", "0"],
             "--heading-bias-sigma-deg", code=2, setup=net),
        *(Case(f"adjust-relative-within-{name}", a + ["--relative-within-m", value],
               "--relative-within-m", code=2) for name, value in (("zero", "0"),
                                                                 ("negative", "-5"))),
        Case("adjust-negative-relative-requirement", a + ["--relative-requirement-m", "-0.1"],
             "--relative-requirement-m", code=2),
        Case("adjust-negative-relative-ppm", a + ["--relative-requirement-ppm", "-1"],
             "--relative-requirement-ppm", code=2),
        Case("adjust-unknown-covariance", a + ["--covariance", "cholmod"], "--covariance",
             code=2),
        Case("adjust-out-holds-the-table", ["adjust", "{inputs}/markers.csv", "--out",
                                            "{inputs}", "--overwrite"], "holds the input"),
    ]


CASES = _cases() + _cases_for("adjust", ["adjust", "{inputs}/markers.csv"])


@pytest.mark.parametrize("case", CASES, ids=str)
def test_adjust_refuses(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
