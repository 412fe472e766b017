"""Chance-constrained planning: an epsilon outside (0, 0.5] and a detection model with
impossible fields, each refused in one line before any work
(:func:`tests.cli.bad_input.check_refused`)."""

import json

import pytest

from tests.cli.bad_input import Case, check_refused

PLAN = ["plan", "--out", "out"]
EPS = "invalid value for '--chance-epsilon'"


def _model(**changes) -> str:
    """The shipped detection model's JSON with some fields replaced (None: removed)."""
    from error_model.default import DEFAULT_DETECTION_MODEL_PATH

    doc = json.loads(DEFAULT_DETECTION_MODEL_PATH.read_text())
    for key, value in changes.items():
        if value is None:
            doc.pop(key)
        else:
            doc[key] = value
    return json.dumps(doc)


def _feature(**changes) -> list:
    from error_model.default import DEFAULT_DETECTION_MODEL_PATH

    feats = json.loads(DEFAULT_DETECTION_MODEL_PATH.read_text())["features"]
    feats[0] = {**feats[0], **changes}
    return feats


def _cases():
    with_model = PLAN + ["--detection-model", "dm.json"]
    return [
        Case("epsilon-zero", PLAN + ["--chance-epsilon", "0"], f"{EPS}: '0' is not a chance "
             "in (0, 0.5]", code=2),
        Case("epsilon-negative", PLAN + ["--chance-epsilon", "-0.05"], "not a chance in (0, 0.5]",
             code=2),
        Case("epsilon-above-half", PLAN + ["--chance-epsilon", "0.6"], "not a chance in (0, 0.5]",
             code=2),
        Case("epsilon-one", PLAN + ["--chance-epsilon", "1"], "not a chance in (0, 0.5]", code=2),
        Case("epsilon-nan", PLAN + ["--chance-epsilon", "nan"], "not a chance in (0, 0.5]",
             code=2),
        Case("epsilon-text", PLAN + ["--chance-epsilon", "often"], "or 'none'", code=2),
        Case("epsilon-config-above-half", PLAN + ["--config", "c.toml"],
             "`chance_epsilon` must be a finite number in (0, 0.5], got 0.7",
             files={"c.toml": "chance_epsilon = 0.7\n"}),
        Case("epsilon-config-text", PLAN + ["--config", "c.toml"], "`chance_epsilon` must be",
             files={"c.toml": "chance_epsilon = \"rarely\"\n"}),
        Case("detection-model-missing", PLAN + ["--detection-model", "none.json"],
             "none.json"),
        Case("detection-model-not-json", with_model, "dm.json", files={"dm.json": "{not json"}),
        Case("detection-model-error-model", PLAN + ["--detection-model", "{inputs}/model.json"],
             "not a markerplan detection model"),
        Case("detection-model-coefficient-nan", with_model, "coefficient 0",
             files={"dm.json": _model(coefficients=[float("nan")] * 9).replace(
                 "NaN", "\"NaN\"")}),
        Case("detection-model-coefficient-absurd", with_model, "coefficient 2",
             files={"dm.json": _model(coefficients=[0.0, 1.0, 1e9] + [0.0] * 6)}),
        Case("detection-model-too-few-coefficients", with_model,
             "3 coefficients for 8 features", files={"dm.json": _model(coefficients=[0, 1, 2])}),
        Case("detection-model-no-features", with_model, "features",
             files={"dm.json": _model(features=None)}),
        Case("detection-model-unknown-covariate", with_model, "covariate",
             files={"dm.json": _model(features=_feature(covariate="moon_phase"))}),
        Case("detection-model-unknown-transform", with_model, "transform",
             files={"dm.json": _model(features=_feature(transform="sqrt"))}),
        Case("detection-model-negative-knot", with_model, "knot",
             files={"dm.json": _model(features=_feature(knot=-3.0))}),
        Case("detection-model-future-version", with_model, "format",
             files={"dm.json": _model(format_version=99)}),
    ]


@pytest.mark.parametrize("case", _cases(), ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
