"""The shipped detection model: it loads strictly, its recorded held-out calibration beats the
base rate and agrees bin by bin, its probabilities are sane on the planner's pairs, and the
regeneration script reproduces it and catches a stale file."""

from __future__ import annotations

import copy
import importlib.util
import json
import sys

import numpy as np
import pytest

from error_model.default import DEFAULT_DETECTION_MODEL_PATH, default_detection_model
from error_model.detection import DEFAULT_FEATURES, DetectionModel
from markerplan.errors import InputFileError
from planner.studies.loss_study import level_layout, pair_covariates

SCRIPT = DEFAULT_DETECTION_MODEL_PATH.parents[2] / "scripts" / "make_default_detection_model.py"


def _script():
    spec = importlib.util.spec_from_file_location("make_default_detection_model", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_shipped_model_loads_strictly_and_says_what_it_was_fitted_on(tmp_path):
    model = default_detection_model()
    assert isinstance(model, DetectionModel) and model is default_detection_model()
    assert model.features == DEFAULT_FEATURES
    data = model.info["data"]
    for words in ("sensor profile calibrated", "800 of 800 frames", "default-t0",
                  "default-t1", "level", "scripts/make_default_detection_model.py"):
        assert words in data["description"], words
    assert len(data["fingerprint"]) == 64 and data["scans"] == 46 and data["rows"] == 1444
    # the loader is the strict one: the shipped file with one coefficient too few is refused
    doc = json.loads(DEFAULT_DETECTION_MODEL_PATH.read_text())
    doc["coefficients"] = doc["coefficients"][:-1]
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(InputFileError, match="coefficients for"):
        DetectionModel.load(bad)


def test_recorded_held_out_calibration_beats_the_base_rate_and_agrees_per_bin():
    model = default_detection_model()
    cal = model.info["calibration"]
    assert cal["folds"] == 5
    assert cal["brier_held_out"] < 0.5 * cal["brier_base_rate"]
    bins = cal["reliability_held_out"]
    assert sum(b["n"] for b in bins) == model.info["data"]["rows"]
    for b in bins:
        assert b["lo"] <= b["predicted"] <= b["hi"]
        assert b["observed_low"] <= b["observed"] <= b["observed_high"]
        if b["n"] >= 30:  # the mean prediction within 0.02 of the observed rate's 95 %
            # interval and within 0.1 of the rate (without the 30 m hinge: 0.61 against 0.47)
            assert b["observed_low"] - 0.02 <= b["predicted"] <= b["observed_high"] + 0.02, b
            assert abs(b["predicted"] - b["observed"]) < 0.1, b


def test_probabilities_are_sane_on_a_level_field():
    """Pairs of a station 1 m above a level field (the planner's covariates, computed as the
    loss study computes them): a 10 m marker is a near-certain detection, the probability falls
    beyond 20 m and is low at 40 m (the level study accepted none of 4 there; without the 30 m
    hinge the model said 0.64), and a mostly hidden marker is unlikely."""
    model = default_detection_model()
    distances = np.array([5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0])
    cov = pair_covariates(level_layout(distances, cell_m=0.5), 0, 100.0)  # a plane: any cell
    names = ("distance_m", "elevation_deg", "slope_deg", "rim_distance_m", "visible_fraction",
             "expected_points")
    pairs = {k: cov[k] for k in names}
    p = model.probability(**pairs)
    assert p[1] > 0.95 and p[0] > 0.9
    assert (np.diff(p[3:]) < 0).all() and p[5] < 0.3
    hidden = {**pairs, "visible_fraction": np.full(len(distances), 0.05),
              "expected_points": cov["expected_points"] * 0.05}
    assert model.probability(**hidden)[1] < 0.3


@pytest.mark.slow
def test_script_smoke_run_is_reproduced_and_check_catches_a_changed_coefficient(
        tmp_path, monkeypatch, capsys):
    """The script end to end on a small level study (6 markers at 2-15 m, 40 of 800 frames, 5
    seeds): a rerun reproduces the file, and ``--check`` names a coefficient changed by 1e-6."""
    script = _script()
    monkeypatch.setattr(script, "STUDIES", (script.Study("level", None, 200, 1, 5),))
    monkeypatch.setattr(script, "level_layout", lambda: level_layout(
        np.array([2.0, 4.0, 6.0, 9.0, 12.0, 15.0]), cell_m=0.25))
    out, kept = tmp_path / "model.json", tmp_path / "fates"
    smoke = ["--seeds", "5", "--frames", "40", "--output", str(out)]
    assert script.main([*smoke, "--keep", str(kept)]) == 0
    model = DetectionModel.load(out)
    assert model.info["data"]["scans"] == 5 and model.info["data"]["sources"] == ["level.csv"]
    assert "40 of 800 frames" in model.info["data"]["description"]
    assert script.main([*smoke, "--check"]) == 0  # the studies rerun: the same file
    assert "up to date" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    changed = copy.deepcopy(doc)
    changed["coefficients"][2] *= 1 + 1e-6
    out.write_text(json.dumps(changed))
    assert script.main([*smoke, "--check", "--tables", str(kept)]) == 1
    assert "STALE: /coefficients[2]" in capsys.readouterr().out
    out.write_text(json.dumps(doc))
    assert script.main([*smoke, "--check", "--tables", str(kept)]) == 0
