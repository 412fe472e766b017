"""``markerplan fit-error-model``: JSON summary, files written, refusals, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from error_model.model import ErrorModel
from tests.cli.invoke import run_cli
from tests.error_model.synthetic import synthetic_table, write_csv


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tables")
    write_csv(folder / "a.csv", synthetic_table(700, seed=31))
    write_csv(folder / "b.csv", synthetic_table(500, seed=32))
    return folder


def test_fit_writes_model_and_plot_and_prints_one_json_object(tables, tmp_path, capsys):
    out_model, out_png = tmp_path / "m" / "model.json", tmp_path / "m" / "model.png"
    code, out, err = run_cli(capsys, ["fit-error-model", str(tables / "a.csv"),
                                      str(tables / "b.csv"),
                                      "--out", str(tmp_path / "m"), "--plot", "--seed", "3",
                                      "--bootstrap", "5", "--json"])
    assert code == 0, err
    summary = json.loads(out)
    assert summary["rows_used"] > 1000
    assert summary["predictors"][:2] == ["distance_m", "elevation_rad"]
    assert 0.9 < summary["envelope_cv_coverage"] < 0.99
    model = ErrorModel.load(out_model)
    assert model.info["data"]["sources"] == ["a.csv", "b.csv"]
    assert model.info["provenance"]["seed"] == 3
    assert out_png.read_bytes()[:4] == b"\x89PNG"
    p = model.predict([5.0, 40.0], np.deg2rad(-10))
    assert p.sigma_m[1] > p.sigma_m[0] and p.in_domain.all()
    assert sorted(x.name for x in tmp_path.iterdir()) == ["m"]
    assert sorted(x.name for x in (tmp_path / "m").iterdir()) == ["model.json", "model.png",
                                                                   "provenance.json"]


def test_existing_output_is_refused_without_overwrite(tables, tmp_path, capsys):
    out = tmp_path / "model"
    args = ["fit-error-model", str(tables / "a.csv"), "--out", str(out), "--bootstrap", "0"]
    assert run_cli(capsys, args)[0] == 0
    code, _, err = run_cli(capsys, args)
    assert code == 1 and "--overwrite" in err and err.count("\n") == 1
    code, _, err = run_cli(capsys, args + ["--overwrite"])
    assert code == 0, err
    assert ErrorModel.load(out / "model.json").info["data"]["rows_used"] > 500


@pytest.mark.parametrize("make, match", [
    (lambda t: t.pop("error_m"), "missing column"),
    (lambda t: [t[k].__setitem__(slice(None), np.nan) for k in ["elevation_deg"]],
     "all NaN"),
    (lambda t: t["accepted"].__setitem__(slice(20, None), False), "usable rows"),
])
def test_bad_tables_give_one_line_errors_and_no_output(tmp_path, capsys, make, match):
    table = synthetic_table(300, seed=1)
    make(table)
    write_csv(tmp_path / "bad.csv", table)
    code, out, err = run_cli(capsys, ["fit-error-model", str(tmp_path / "bad.csv"), "--out",
                                      str(tmp_path / "model"), "--json"])
    assert code == 1
    assert out == ""
    assert err.startswith("error: ") and err.count("\n") == 1 and match in err
    assert sorted(x.name for x in tmp_path.iterdir()) == ["bad.csv"]


def test_missing_table_file_is_an_error(tmp_path, capsys):
    code, _, err = run_cli(capsys, ["fit-error-model", str(tmp_path / "none.csv"), "--out",
                                    str(tmp_path / "m")])
    assert code == 1 and "none.csv" in err and not (tmp_path / "m").exists()


def test_help_has_an_example(capsys):
    code, out, _ = run_cli(capsys, ["fit-error-model", "--help"])
    assert code == 0 and "markerplan fit-error-model tables/markers.csv --out model/" in out


def test_mixed_estimators_need_a_choice(tmp_path, capsys):
    table = synthetic_table(400, seed=2)
    table["estimator"] = np.where(np.arange(400) % 2, "fixed-radius", "hemisphere-icp")
    write_csv(tmp_path / "mixed.csv", table)
    target = tmp_path / "m"
    code, _, err = run_cli(capsys, ["fit-error-model", str(tmp_path / "mixed.csv"), "--out",
                                    str(target), "--bootstrap", "0"])
    assert code == 1 and "several estimators" in err and not target.exists()
    code, _, err = run_cli(capsys, ["fit-error-model", str(tmp_path / "mixed.csv"), "--out",
                                    str(target), "--bootstrap", "0", "--estimator", "fixed-radius"])
    assert code == 0, err
    counts = ErrorModel.load(target / "model.json").info["data"]["counts"]
    assert counts["dropped_other_estimator"] == 200
