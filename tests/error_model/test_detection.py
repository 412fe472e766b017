"""The detection model: fit against known laws, calibration tables, the Wilson interval's
coverage, and the JSON file's checks."""

import json

import numpy as np
import pytest
from scipy.stats import norm

from error_model.detection import (
    DEFAULT_FEATURES,
    DetectionModel,
    Feature,
    brier_score,
    design_matrix,
    fit_detection_model,
    held_out,
    reliability,
    wilson_interval,
)
from markerplan.errors import ConfigError, DataError, InputFileError


def _pairs(n, rng):
    d = np.exp(rng.uniform(np.log(1.0), np.log(50.0), n))
    return {"distance_m": d, "elevation_deg": -np.degrees(np.arctan2(0.9, d)),
            "visible_fraction": rng.uniform(0.3, 1.0, n),
            "expected_points": 8000.0 / d ** 2 * rng.uniform(0.5, 1.0, n),
            "slope_deg": rng.uniform(0, 15, n), "rim_distance_m": rng.exponential(3.0, n)}


def test_a_logistic_law_is_recovered():
    rng = np.random.default_rng(0)
    cov = _pairs(40000, rng)
    features = (Feature("distance_m", "log"), Feature("distance_m", "log", 15.0),
                Feature("visible_fraction"))
    truth = np.array([3.0, 0.5, -4.0, 2.0])
    p = 1 / (1 + np.exp(-design_matrix(features, cov) @ truth))
    y = rng.random(len(p)) < p
    model = fit_detection_model(cov, y, features, ridge=0.0)
    # within 3 standard errors, from the Fisher information at the truth (built here)
    x = design_matrix(features, cov)
    se = np.sqrt(np.diag(np.linalg.inv(x.T @ ((p * (1 - p))[:, None] * x))))
    assert (np.abs(model.coef - truth) < 3 * se).all(), (model.coef, truth, se)
    assert np.abs(model.probability(**cov) - p).max() < 0.03


def test_a_probit_law_is_calibrated_held_out():
    """Data from another law (a probit in log distance and points): the held-out predictions of
    the default features still agree with the observed rates bin by bin."""
    rng = np.random.default_rng(1)
    cov = _pairs(20000, rng)
    eta = 2.5 - 3.0 * np.maximum(0, np.log(cov["distance_m"] / 20.0)) \
        + 2.0 * (cov["visible_fraction"] - 0.65)
    y = rng.random(len(eta)) < norm.cdf(eta)
    groups = np.arange(len(y)) // 200  # scans of 200 pairs
    p = held_out(cov, y, groups, folds=5)
    table = reliability(p, y)
    assert sum(t["n"] for t in table) == len(y)
    for t in table:
        if t["n"] >= 200:
            assert t["observed_low"] - 0.02 <= t["predicted"] <= t["observed_high"] + 0.02, t
    assert brier_score(p, y) < brier_score(np.full(len(y), y.mean()), y)


def test_separated_outcomes_stay_finite():
    rng = np.random.default_rng(2)
    cov = _pairs(500, rng)
    y = cov["distance_m"] < 20.0  # perfectly separated by distance
    model = fit_detection_model(cov, y)
    assert np.isfinite(model.coef).all() and np.abs(model.coef).max() < 1e3
    p = model.probability(**cov)
    assert p[y].min() > 0.5 > p[~y].max()


def test_wilson_interval_covers_at_its_level():
    rng = np.random.default_rng(3)
    for p_true, n in [(0.95, 40), (0.8, 20), (0.5, 100)]:
        hits = rng.binomial(n, p_true, 4000)
        inside = [lo <= p_true <= hi for lo, hi in (wilson_interval(h, n) for h in hits)]
        assert 0.92 <= np.mean(inside) <= 0.985, (p_true, n, np.mean(inside))


def test_too_few_rows_and_bad_covariates_are_refused():
    rng = np.random.default_rng(4)
    cov = _pairs(5, rng)
    with pytest.raises(DataError, match="cannot fit"):
        fit_detection_model(cov, np.ones(5, bool))
    with pytest.raises(ConfigError, match="needs the covariate 'slope_deg'"):
        fit_detection_model({k: v for k, v in _pairs(50, rng).items() if k != "slope_deg"},
                            np.ones(50, bool))
    bad = _pairs(50, rng)
    bad["distance_m"][3] = -1.0
    with pytest.raises(DataError, match="distance_m has values outside the domain of log"):
        fit_detection_model(bad, np.ones(50, bool))


def test_round_trip_and_impossible_files(tmp_path):
    rng = np.random.default_rng(5)
    cov = _pairs(300, rng)
    model = fit_detection_model(cov, cov["distance_m"] < 30 + rng.normal(0, 5, 300),
                                info={"data": {"rows": 300}})
    path = model.save(tmp_path / "detection_model.json")
    back = DetectionModel.load(path)
    np.testing.assert_array_equal(back.coef, model.coef)
    assert back.features == DEFAULT_FEATURES and back.info == {"data": {"rows": 300}}
    np.testing.assert_array_equal(back.probability(**cov), model.probability(**cov))
    good = json.loads(path.read_text())

    def refused(doc, match):
        p = tmp_path / "bad.json"
        p.write_text(json.dumps(doc))
        with pytest.raises(InputFileError, match=match):
            DetectionModel.load(p)

    refused({**good, "coefficients": good["coefficients"][:-1]}, "coefficients for")
    refused({**good, "coefficients": [*good["coefficients"][:-1], 1e9]}, "beyond")
    refused({**good, "coefficients": [*good["coefficients"][:-1], "x"]}, "expected int")
    refused({**good, "features": [{**good["features"][0], "covariate": "colour"}]},
            "unknown covariate")
    refused({**good, "features": [{**good["features"][1], "knot": -2.0}]}, "outside the domain")
    refused({**good, "format": "markerplan-error-model"}, "not a markerplan detection model")
    refused({**good, "format_version": 9}, "newer")
    refused({k: v for k, v in good.items() if k != "features"}, "missing 'features'")
    with pytest.raises(InputFileError, match="no such file"):
        DetectionModel.load(tmp_path / "absent.json")


def test_features_constant_over_the_rows_keep_a_zero_coefficient():
    """A level field: slope 0, no crater (rim distance capped), visible fraction 1 everywhere;
    the distance terms must still be fitted (a near-constant column once broke the fit)."""
    rng = np.random.default_rng(6)
    d = np.exp(rng.uniform(0, np.log(50), 400))
    cov = {"distance_m": d, "expected_points": 8000 / d ** 2, "visible_fraction": np.ones(400),
           "slope_deg": np.zeros(400), "rim_distance_m": np.full(400, np.inf)}
    y = rng.random(400) < np.where(d < 30, 0.95, 0.2)
    model = fit_detection_model(cov, y)
    constant = [1 + k for k, f in enumerate(model.features)
                if f.covariate in ("visible_fraction", "slope_deg", "rim_distance_m")]
    assert len(constant) == 3 and (model.coef[constant] == 0.0).all()
    p = model.probability(**cov)
    assert p[d < 20].mean() > 0.85 and p[d > 40].mean() < 0.45
