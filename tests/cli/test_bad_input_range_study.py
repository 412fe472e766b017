"""``range-study --extraction``: an unknown extraction is refused before any work."""

import pytest

from tests.cli.bad_input import Case, check_refused

RANGE = ["range-study", "--frames", "4", "--replicates", "1", "--out", "out"]

CASES = [
    Case("range-study-unknown-extraction", RANGE + ["--extraction", "truth"], "--extraction",
         code=2),
    Case("range-study-empty-extraction", RANGE + ["--extraction", ""], "--extraction", code=2),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
