"""The shipped default model."""

from __future__ import annotations

import numpy as np

from error_model import ErrorModel, default_model
from error_model.default import DEFAULT_MODEL_PATH


def test_default_model_loads_and_says_what_it_was_fitted_on():
    model = default_model()
    assert isinstance(model, ErrorModel)
    assert model is default_model()  # cached
    assert model.predictors[:2] == ("distance_m", "elevation_rad")
    description = model.info["data"]["description"]
    # either the range-study simulation of the default rig, or an interim placeholder that
    # says plainly that it is not simulation-based
    assert "range study" in description.lower() or "range-study" in description
    assert "NOT simulation-based" in description or "simulat" in description.lower()
    assert len(model.info["data"]["fingerprint"]) == 64
    assert model.info["provenance"]["markerplan_version"]


def test_default_model_is_monotone_non_negative_and_flags_its_domain():
    model = default_model()
    lo, hi = model.domain.distance_range_m
    d = np.linspace(lo, hi, 50)
    dom = model.domain
    e = np.full_like(d, 0.5 * (dom.elevation_lo_rad[0] + dom.elevation_hi_rad[0]))
    extras = {k: np.full_like(d, np.mean(v)) for k, v in model.domain.extras.items()}
    p = model.predict(d, e, **extras)
    assert (np.diff(p.sigma_m) >= -1e-12).all() and (np.diff(p.q95_m) >= -1e-12).all()
    assert (p.sigma_m > 0).all() and (p.q95_m >= p.sigma_m).all()
    assert not model.in_domain(hi + 10.0, 0.0, **{k: v[0] for k, v in extras.items()})


def test_default_model_file_is_shipped_as_package_data():
    assert DEFAULT_MODEL_PATH.name == "default_model.json"
    assert DEFAULT_MODEL_PATH.parent.name == "data"
    assert DEFAULT_MODEL_PATH.read_text().endswith("}\n")


def _regeneration_script():
    import importlib.util

    root = DEFAULT_MODEL_PATH.parents[2]
    spec = importlib.util.spec_from_file_location(
        "make_default_error_model", root / "scripts" / "make_default_error_model.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    return script


def test_regeneration_script_fits_only_the_fixed_radius_rows(tmp_path):
    """The script's fitting step on a range-study-shaped table (both estimators' rows)."""
    from tests.error_model.synthetic import synthetic_table, write_csv

    script = _regeneration_script()
    table = synthetic_table(300, seed=4)
    table["estimator"] = np.where(np.arange(300) % 3, "fixed-radius", "hemisphere-icp")
    write_csv(tmp_path / "markers.csv", table)
    model = script.build_model([tmp_path / "markers.csv"], "calibrated", replicates=1,
                               frames=800, seed=0)
    assert model.info["data"]["counts"]["dropped_other_estimator"] == 100
    description = model.info["data"]["description"]
    assert "range-study --sensor-profile calibrated --replicates 1 --frames 800" in description
    assert "--slope-deg S --extraction full-chain" in description
    assert model.info["provenance"]["config"]["estimator"] == "fixed-radius"


def test_regeneration_script_runs_the_full_station_chain(tmp_path, monkeypatch):
    """Every variant's range study is asked for the full chain explicitly (ground removal,
    clustering, gate, re-search, fit, quality), never the truth-seeded diagnostic."""
    script = _regeneration_script()
    calls = []
    monkeypatch.setattr(script.cli, "main", lambda args, **kw: calls.append(args))
    tables = script.run_variants(tmp_path, "calibrated", replicates=1, frames=100, seed=0)
    assert len(calls) == len(tables) == len(script.VARIANTS)
    for args in calls:
        assert args[args.index("--extraction") + 1] == "full-chain"


def test_check_tolerates_solver_last_digits_but_not_real_changes():
    import copy
    import json

    differences = _regeneration_script()._differences
    shipped = json.loads(DEFAULT_MODEL_PATH.read_text())
    rerun = copy.deepcopy(shipped)
    rerun["sigma"]["coefficients"] = [c * (1 + 3e-14) for c in rerun["sigma"]["coefficients"]]
    rerun["sigma"]["ci95_lo"][0] += 5e-20  # a coefficient at its zero bound
    assert list(differences(shipped, rerun, "")) == []
    rerun["sigma"]["coefficients"][1] *= 1.0001
    rerun["data"]["fingerprint"] = "0" * 64
    rerun["predictors"] = rerun["predictors"][:1]
    found = list(differences(shipped, rerun, ""))
    assert [f.split(":")[0].split(" ")[0] for f in found] == [
        "/data/fingerprint", "/predictors", "/sigma/coefficients[1]"]
