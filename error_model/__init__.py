"""Marker-centre error as a function of distance and angle: fitting (cvxpy), prediction,
domain, serialisation and diagnostics; and the detection model (:mod:`error_model.detection`:
the probability that a planned marker is detected and accepted, its calibration). Imports
nothing of ours but :mod:`markerplan` and the table schemas of :mod:`pipeline.tables.marker_table`
and :mod:`pipeline.tables.fate_table`.

Loading and predicting do not import cvxpy (about 2 s); :func:`fit_error_model` does, on first
use.

>>> from error_model import default_model
>>> model = default_model()
>>> model.predictors[:2]
('distance_m', 'elevation_rad')
"""

from error_model.config import FitConfig
from error_model.default import default_detection_model, default_model
from error_model.model import ErrorModel, Prediction
from error_model.table import MarkerTable, read_marker_tables

__all__ = ["ErrorModel", "FitConfig", "MarkerTable", "Prediction", "default_detection_model",
           "default_model", "fit_error_model", "read_marker_tables"]


def __getattr__(name: str):
    if name == "fit_error_model":
        from error_model.fit import fit_error_model

        return fit_error_model
    raise AttributeError(f"module 'error_model' has no attribute {name!r}")
