"""The error model shipped with the package (``error_model/data/default_model.json``),
regenerated exactly by ``scripts/make_default_error_model.py``."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from error_model.model import ErrorModel

DEFAULT_MODEL_PATH = Path(__file__).resolve().parent / "data" / "default_model.json"


@lru_cache(maxsize=1)
def _load_default() -> ErrorModel:
    return ErrorModel.load(DEFAULT_MODEL_PATH)


def default_model() -> ErrorModel:
    """The shipped model (see its ``data.description`` for what it was fitted on).

    Returns
    -------
    model : ErrorModel
        Immutable and cached: every call returns the same object.
    """
    return _load_default()
