"""``verify --trials N``: a count below one, absurd or not a whole number, and trials of a
network verification, refused in one line before any work."""

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
    Case("verify-trials-network", VERIFY + ["--trials", "2", "--network"],
         "--trials 2: repeated trials are of known-control verification only"),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
