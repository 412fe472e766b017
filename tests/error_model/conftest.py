"""Fixtures for the error-model tests: synthetic marker tables with a known error law
(see :mod:`tests.error_model.synthetic`) and a model fitted once per session."""

from __future__ import annotations

import pytest

from error_model.fit import fit_error_model
from error_model.table import as_marker_table
from tests.error_model.synthetic import synthetic_table


@pytest.fixture(scope="session")
def train_table():
    """6000 rows of training data (seed 11)."""
    return as_marker_table(synthetic_table(6000, seed=11))


@pytest.fixture(scope="session")
def heldout_table():
    """4000 independent rows (seed 12), never seen by the fit."""
    return as_marker_table(synthetic_table(4000, seed=12))


@pytest.fixture(scope="session")
def fitted_model(train_table):
    """Model fitted on ``train_table`` with the default settings and seed 0."""
    return fit_error_model(train_table, seed=0)
