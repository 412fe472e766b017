"""Shared fixtures. Real data lives in ../shared/data/real (absent on a user's clone)."""

from pathlib import Path

import pytest
from hypothesis import settings

# The suite is a gate: the same examples on every run (CI must not fail at random). Explore new
# ones with `pytest --hypothesis-profile=explore`.
settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile("ci")

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


@pytest.fixture
def real_data() -> Path:
    """Path to ../shared/data/real, or skip with the reason."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real data folder {REAL_DATA} is absent (only present beside the project's "
                    "development checkout)")
    return REAL_DATA
