"""``markerplan fit-detection-model``: fate tables in, a calibrated detection model out; bad
tables refused in one line (:mod:`tests.cli.bad_input`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from error_model.detection import DetectionModel
from pipeline.tables.fate_table import FATE_COLUMNS, write_fate_table
from tests.cli.bad_input import Case, check_refused
from tests.cli.invoke import run_cli


def _rows(n_scans: int = 30, seed: int = 0) -> list[dict]:
    """Scans of 20 markers each: accepted with a probability that falls beyond 25 m."""
    rng = np.random.default_rng(seed)
    rows = []
    for s in range(n_scans):
        for k in range(20):
            d = float(np.exp(rng.uniform(0, np.log(50))))
            p = 0.97 if d < 25 else 0.3
            rows.append({"layout": "test", "seed": s, "station_id": "S1", "marker_id": f"M{k}",
                         "distance_m": d, "elevation_deg": -float(np.degrees(np.arctan(0.9 / d))),
                         "incidence_deg": 80.0, "slope_deg": float(rng.uniform(0, 10)),
                         "rim_distance_m": None if k % 2 else float(rng.uniform(0, 8)),
                         "visible_fraction": float(rng.uniform(0.5, 1)),
                         "expected_points": 8000 / d ** 2, "n_points": 100,
                         "stage": "accepted" if rng.random() < p else "quality",
                         "reason": ""})
    return rows


@pytest.fixture
def table(tmp_path) -> Path:
    return write_fate_table(tmp_path / "fates.csv", _rows())


def test_fits_records_calibration_and_repeats_byte_for_byte(capsys, tmp_path, table):
    code, out, err = run_cli(capsys, ["fit-detection-model", str(table), "--out",
                                      str(tmp_path / "a"), "--plot", "--json"])
    assert code == 0, err
    summary = json.loads(out)
    assert summary["rows"] == 600 and summary["scans"] == 30
    assert summary["brier_held_out"] < summary["brier_base_rate"]
    model = DetectionModel.load(tmp_path / "a" / "detection_model.json")
    p = model.probability(distance_m=np.array([5.0, 45.0]), elevation_deg=0.0,
                          visible_fraction=0.8, expected_points=np.array([320.0, 4.0]),
                          slope_deg=5.0, rim_distance_m=np.inf)
    assert p[0] > 0.85 and p[1] < 0.6
    rel = model.info["calibration"]["reliability_held_out"]
    assert sum(r["n"] for r in rel) == 600
    assert (tmp_path / "a" / "calibration.png").stat().st_size > 10_000
    code, _, err = run_cli(capsys, ["fit-detection-model", str(table), "--out",
                                    str(tmp_path / "b"), "--plot"])
    assert code == 0, err
    for name in ("detection_model.json", "calibration.png"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def _table_file(edit) -> dict:
    rows = _rows(6)
    edit(rows)
    import csv
    import io
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return {"bad.csv": buf.getvalue()}


def _set(key, value, row=0):
    def edit(rows):
        rows[row][key] = value
    return edit


def _drop_column(rows):
    for r in rows:
        del r["slope_deg"]


def _every(stage):
    def edit(rows):
        for r in rows:
            r["stage"] = stage
    return edit


CASES = [
    Case("detection-table-missing-column", ["fit-detection-model", "bad.csv", "--out", "o"],
         "missing column(s) slope_deg", files=_table_file(_drop_column)),
    Case("detection-table-unknown-stage", ["fit-detection-model", "bad.csv", "--out", "o"],
         "stage 'lost' is not one of", files=_table_file(_set("stage", "lost"))),
    Case("detection-table-visible-fraction-above-one",
         ["fit-detection-model", "bad.csv", "--out", "o"], "visible_fraction 1.5 is outside",
         files=_table_file(_set("visible_fraction", 1.5, 3))),
    Case("detection-table-negative-distance", ["fit-detection-model", "bad.csv", "--out", "o"],
         "distance_m -2 is outside", files=_table_file(_set("distance_m", -2.0))),
    Case("detection-table-nan-points", ["fit-detection-model", "bad.csv", "--out", "o"],
         "expected_points: must be a finite number", files=_table_file(
             _set("expected_points", "nan"))),
    Case("detection-table-repeated-marker", ["fit-detection-model", "bad.csv", "--out", "o"],
         "already appears", files=_table_file(_set("marker_id", "M1", 0))),
    Case("detection-table-all-accepted", ["fit-detection-model", "bad.csv", "--out", "o"],
         "all 120 markers were accepted", files=_table_file(_every("accepted"))),
    Case("detection-folds-one", ["fit-detection-model", "bad.csv", "--out", "o", "--folds", "1"],
         "--folds", code=2, files=_table_file(lambda rows: None)),
    Case("detection-fewer-scans-than-folds",
         ["fit-detection-model", "bad.csv", "--out", "o", "--folds", "8"],
         "needs at least 8 groups", files=_table_file(lambda rows: None)),
    Case("detection-table-absent", ["fit-detection-model", "absent.csv", "--out", "o"],
         "absent.csv"),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_bad_fate_tables_are_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)


def test_the_columns_are_the_writers():
    assert tuple(_rows(1)[0]) == FATE_COLUMNS
