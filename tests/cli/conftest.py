"""Fixtures of the CLI tests."""

import pytest

from tests.cli.bad_input import build_valid_inputs


@pytest.fixture(scope="session")
def valid_inputs(tmp_path_factory):
    """A folder of valid inputs shared by the bad-input cases (see ``tests/cli/bad_input.py``).

    Cases must never change it; :func:`tests.cli.bad_input.check_refused` asserts so.
    """
    return build_valid_inputs(tmp_path_factory.mktemp("valid-inputs"))
