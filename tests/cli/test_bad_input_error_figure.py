"""The 95 % figure: an unknown name on the command line, in a config or in a plan's recorded
configuration, each refused in one line before any work
(:func:`tests.cli.bad_input.check_refused`)."""

import pytest

from tests.cli.bad_input import Case, check_refused

PLAN = ["plan", "--out", "out"]


def _cases():
    return [
        Case("figure-unknown-option", PLAN + ["--error-figure", "chi2"],
             "invalid value for '--error-figure': 'chi2' is not one of 'quantile', 'ellipsoid'",
             code=2),
        Case("figure-unknown-config", PLAN + ["--config", "c.toml"],
             "`error_figure` must be one of 'quantile', 'ellipsoid', got 'bound'",
             files={"c.toml": "error_figure = \"bound\"\n"}),
        Case("figure-number-config", PLAN + ["--config", "c.toml"],
             "`error_figure` must be one of", files={"c.toml": "error_figure = 95\n"}),
        Case("figure-unknown-adjust", ["adjust", "t.csv", "--out", "out", "--error-figure",
                                       "worst"], "invalid value for '--error-figure'", code=2,
             files={"t.csv": "station_id\n"}),
    ]


@pytest.mark.parametrize("case", _cases(), ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
