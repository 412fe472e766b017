"""The models shipped with the package: the error model (``error_model/data/default_model.json``,
regenerated exactly by ``scripts/make_default_error_model.py``) and the detection model
(``error_model/data/default_detection_model.json``, by
``scripts/make_default_detection_model.py``)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from error_model.detection import DetectionModel
from error_model.model import ErrorModel

DEFAULT_MODEL_PATH = Path(__file__).resolve().parent / "data" / "default_model.json"
DEFAULT_DETECTION_MODEL_PATH = (Path(__file__).resolve().parent / "data"
                                / "default_detection_model.json")


@lru_cache(maxsize=1)
def _load_default() -> ErrorModel:
    return ErrorModel.load(DEFAULT_MODEL_PATH)


@lru_cache(maxsize=1)
def _load_default_detection() -> DetectionModel:
    return DetectionModel.load(DEFAULT_DETECTION_MODEL_PATH)


def default_model() -> ErrorModel:
    """The shipped model (see its ``data.description`` for what it was fitted on).

    Returns
    -------
    model : ErrorModel
        Immutable and cached: every call returns the same object.
    """
    return _load_default()


def default_detection_model() -> DetectionModel:
    """The shipped detection model (see its ``data.description`` for the loss studies it was
    fitted on, and ``calibration`` for its held-out calibration).

    Returns
    -------
    model : DetectionModel
        Cached: every call returns the same object (do not mutate its ``info``).
    """
    return _load_default_detection()
