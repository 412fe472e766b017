"""``verify --trials N``: a count below one, absurd or not a whole number, mounting-offset
tolerances negative, NaN, absurd or without trials, and network trials without their datum,
refused in one line before any work."""

import pytest

from tests.cli.bad_input import Case, check_refused

VERIFY = ["verify", "{inputs}/plan/plan.json", "--out", "out"]

#: click's verdict on a value of --trials (the bare option name would also match "No such
#: option: --trials").
BAD_VALUE = "invalid value for '--trials'"

CASES = [
    Case("verify-trials-zero", VERIFY + ["--trials", "0"], f"{BAD_VALUE}: 0 is not in the range "
         "1<=x<=1000", code=2),
    Case("verify-trials-negative", VERIFY + ["--trials", "-3"], BAD_VALUE, code=2),
    Case("verify-trials-absurd", VERIFY + ["--trials", "1000000000"], BAD_VALUE, code=2),
    Case("verify-trials-fraction", VERIFY + ["--trials", "2.5"], f"{BAD_VALUE}: '2.5' is not a "
         "valid integer", code=2),
    Case("verify-trials-nan", VERIFY + ["--trials", "nan"], BAD_VALUE, code=2),
    Case("verify-tolerance-negative", VERIFY + ["--trials", "2", "--axis-offset-tolerance-mm",
                                                "-1"],
         "invalid value for '--axis-offset-tolerance-mm': -1.0 is not in the range "
         "0.0<=x<=100.0", code=2),
    Case("verify-tolerance-nan", VERIFY + ["--trials", "2", "--lframe-tilt-tolerance-deg",
                                           "nan"],
         "invalid value for '--lframe-tilt-tolerance-deg'", code=2),
    Case("verify-tolerance-absurd", VERIFY + ["--trials", "2",
                                              "--vertical-axis-error-tolerance-deg", "90"],
         "invalid value for '--vertical-axis-error-tolerance-deg': 90.0 is not in the range "
         "0.0<=x<=5.0", code=2),
    Case("verify-tolerance-without-trials", VERIFY + ["--axis-offset-tolerance-mm", "2"],
         "the mounting-offset tolerances are drawn once per trial; give --trials N"),
    Case("verify-trials-network-without-datum", VERIFY + ["--trials", "2", "--network",
                                                          "--station-ids", "S2"],
         "reference station S1 (the datum of network mode) is not among the stations "
         "verified (S2)"),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
