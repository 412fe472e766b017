"""Fixtures of the CLI tests."""

import pytest

from tests.cli.bad_input import build_valid_inputs


@pytest.fixture(scope="session")
def valid_inputs(tmp_path_factory):
    """A folder of valid inputs shared by the bad-input cases (see ``tests/cli/bad_input.py``),
    and whose default plan (``plan/plan.json``) the verify tests read instead of planning again.

    Nothing may change it; :func:`tests.cli.bad_input.check_refused` asserts so for the cases.
    """
    return build_valid_inputs(tmp_path_factory.mktemp("valid-inputs"))
