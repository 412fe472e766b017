"""Shared fixtures. Real data lives in ../shared/data/real (absent on a user's clone)."""

from pathlib import Path

import pytest

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


@pytest.fixture
def real_data() -> Path:
    """Path to ../shared/data/real, or skip with the reason."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real data folder {REAL_DATA} is absent (only present beside the project's "
                    "development checkout)")
    return REAL_DATA
