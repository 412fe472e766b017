import pytest

from tests.cli.bad_input import Case, check_refused

CASES = [
    Case("plan-json-list", ["verify", "p.json", "--out", "v"], "plan", files={"p.json": "[1]"}),
    Case("fit-sphere-missing", ["fit-sphere", "nope.xyz", "--radius", "0.1"], "nope.xyz"),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)
