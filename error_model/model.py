"""A fitted error model: prediction of sigma and the 95 % envelope, its domain, and JSON I/O.

``sigma_m`` is the 3D root-mean-square centre error (``sqrt(E[error_m^2])``; for an isotropic
error each axis has ``sigma_m / sqrt(3)``). ``q95_m`` is the conservative envelope: the
fitted 95 % quantile of the 3D error. Both are non-decreasing in distance and non-negative.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from error_model.basis import Basis
from error_model.config import EXTRA_PREDICTORS
from error_model.domain import Domain
from markerplan.errors import ConfigError, InputFileError, OutputError

FORMAT = "markerplan-error-model"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class Prediction:
    """Predicted error of markers, arrays of the broadcast input shape.

    Attributes
    ----------
    sigma_m : ndarray
        3D RMS centre error, metres.
    q95_m : ndarray
        95 % envelope of the 3D centre error, metres.
    in_domain : ndarray of bool
        Query inside the fitted domain (outside: extrapolated, treat as unusable unless the
        user opts in).
    """

    sigma_m: np.ndarray
    q95_m: np.ndarray
    in_domain: np.ndarray


@dataclass(frozen=True)
class ErrorModel:
    """Fitted model; build with :func:`error_model.fit.fit_error_model` or :meth:`load`.

    Attributes
    ----------
    basis : Basis
    sigma_coef : (p,) float
        Coefficients of sigma (metres per feature unit).
    q_coef : (p,) float
        Coefficients of the envelope.
    quantile : float
        Level of the envelope (0.95).
    domain : Domain
    info : dict
        Everything else recorded at fit time (cross-validation, intervals, effects, data,
        provenance), kept verbatim in the JSON.
    """

    basis: Basis
    sigma_coef: np.ndarray
    q_coef: np.ndarray
    quantile: float
    domain: Domain
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def predictors(self) -> tuple[str, ...]:
        """Names of the inputs :meth:`predict` needs."""
        return ("distance_m", "elevation_rad", *self.basis.extras)

    def predict(self, distance_m: Any, elevation_rad: Any, **extra: Any) -> Prediction:
        """Sigma and envelope of the 3D centre error.

        Parameters
        ----------
        distance_m : array_like float
            LiDAR-centre-to-marker distance, metres.
        elevation_rad : array_like float
            Elevation of the marker seen from the LiDAR centre, radians (station frame, z up).
        **extra : array_like float
            ``visible_fraction=`` (0..1), ``expected_points=`` (count); needed only if the
            model uses them (:attr:`predictors`), ignored otherwise.

        Returns
        -------
        prediction : Prediction
            Arrays of the broadcast shape of all inputs.

        Examples
        --------
        >>> from error_model import default_model
        >>> p = default_model().predict([5.0, 20.0], -0.1)
        >>> bool(p.sigma_m[1] >= p.sigma_m[0])
        True
        """
        shape, d, e, ex = self._predict_iv(distance_m, elevation_rad, extra)
        phi = self.basis.design(d, e, ex)
        sigma = np.maximum(phi @ self.sigma_coef, 0.0).reshape(shape)
        q95 = np.maximum(phi @ self.q_coef, 0.0).reshape(shape)
        inside = self.domain.contains(d, e, ex).reshape(shape)
        return Prediction(sigma_m=sigma, q95_m=q95, in_domain=inside)

    def in_domain(self, distance_m: Any, elevation_rad: Any, **extra: Any) -> np.ndarray:
        """Boolean mask (broadcast shape): query inside the fitted domain."""
        shape, d, e, ex = self._predict_iv(distance_m, elevation_rad, extra)
        return self.domain.contains(d, e, ex).reshape(shape)

    def _predict_iv(self, distance_m: Any, elevation_rad: Any, extra: dict[str, Any]):
        unknown = sorted(set(extra) - set(EXTRA_PREDICTORS))
        if unknown:
            raise ConfigError(f"predict: unknown keyword(s) {unknown}; optional predictors are "
                              f"{list(EXTRA_PREDICTORS)}")
        missing = [x for x in self.basis.extras if x not in extra]
        if missing:
            raise ConfigError(f"predict: this model needs {missing} (its predictors are "
                              f"{list(self.predictors)}); pass them as keywords")
        names = ["distance_m", "elevation_rad", *self.basis.extras]
        arrays = [np.asarray(distance_m, float), np.asarray(elevation_rad, float),
                  *(np.asarray(extra[x], float) for x in self.basis.extras)]
        try:
            b = np.broadcast_arrays(*arrays)
        except ValueError:
            shapes = {n: a.shape for n, a in zip(names, arrays, strict=True)}
            raise ConfigError(f"predict: inputs must broadcast together, got shapes {shapes}") \
                from None
        for n, a in zip(names, b, strict=True):
            if not np.isfinite(a).all():
                raise ConfigError(f"predict: {n} must be finite, got {a[~np.isfinite(a)][:3]}")
        return (b[0].shape, b[0].ravel(), b[1].ravel(),
                {x: v.ravel() for x, v in zip(self.basis.extras, b[2:], strict=True)})

    def to_json(self) -> dict[str, Any]:
        """JSON-serialisable dict (see ``docs/error_model.md`` for the fields)."""
        return {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "predictors": list(self.predictors),
            "sigma_definition": "3D RMS centre error sqrt(E[error_m^2]), metres",
            "basis": self.basis.to_dict(),
            "sigma": {**self.info.get("sigma", {}),
                      "coefficients": [float(v) for v in self.sigma_coef]},
            "envelope": {**self.info.get("envelope", {}), "quantile": self.quantile,
                         "coefficients": [float(v) for v in self.q_coef]},
            "domain": self.domain.to_dict(),
            **{k: v for k, v in self.info.items() if k not in ("sigma", "envelope")},
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any], source: str = "error model") -> ErrorModel:
        """Rebuild from :meth:`to_json` output; malformed input raises InputFileError."""
        if not isinstance(d, Mapping) or d.get("format") != FORMAT:
            got = d.get("format") if isinstance(d, Mapping) else type(d).__name__
            raise InputFileError(f"{source}: not a markerplan error model (format {got!r}, "
                                 f"expected {FORMAT!r}); pass a file written by "
                                 "`markerplan fit-error-model`")
        if d.get("format_version") != FORMAT_VERSION:
            raise InputFileError(f"{source}: format_version {d.get('format_version')!r} is not "
                                 f"supported (expected {FORMAT_VERSION}); refit the model")
        try:
            basis = Basis.from_dict(d["basis"])
            sigma = np.asarray(d["sigma"]["coefficients"], float)
            q = np.asarray(d["envelope"]["coefficients"], float)
            quantile = float(d["envelope"]["quantile"])
            domain = Domain.from_dict(d["domain"])
        except InputFileError as exc:
            raise InputFileError(f"{source}: {exc}") from None
        except (KeyError, TypeError, ValueError) as exc:
            raise InputFileError(f"{source}: malformed error model (missing or bad field "
                                 f"{exc!s}); regenerate it with `markerplan fit-error-model`") \
                from None
        for name, c in (("sigma", sigma), ("envelope", q)):
            if c.shape != (basis.n_features,) or not np.isfinite(c).all():
                raise InputFileError(f"{source}: {name} coefficients must be {basis.n_features} "
                                     f"finite numbers, got shape {c.shape}; regenerate the model")
        if set(domain.extras) != set(basis.extras):
            raise InputFileError(f"{source}: domain extras {sorted(domain.extras)} differ from "
                                 f"basis extras {list(basis.extras)}; regenerate the model")
        skip = {"format", "format_version", "predictors", "sigma_definition", "basis", "domain"}
        info = {k: v for k, v in d.items() if k not in skip}
        info["sigma"] = {k: v for k, v in d["sigma"].items() if k != "coefficients"}
        info["envelope"] = {k: v for k, v in d["envelope"].items()
                            if k not in ("coefficients", "quantile")}
        return cls(basis=basis, sigma_coef=sigma, q_coef=q, quantile=quantile, domain=domain,
                   info=info)

    def save(self, path: str | Path) -> Path:
        """Write the JSON atomically (temporary file in the same folder, then rename)."""
        path = Path(path)
        text = json.dumps(self.to_json(), indent=1, sort_keys=True) + "\n"
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.partial-", dir=path.parent or ".")
        except OSError as exc:
            raise OutputError(f"error model {path}: cannot write in {path.parent} "
                              f"({exc.strerror}); choose a writable location") from None
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(text)
            os.chmod(tmp, 0o666 & ~_umask())
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path

    @classmethod
    def load(cls, path: str | Path) -> ErrorModel:
        """Read a model JSON; a missing, unreadable or corrupted file raises InputFileError."""
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except FileNotFoundError:
            raise InputFileError(f"error model {path}: no such file; pass a JSON written by "
                                 "`markerplan fit-error-model`") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise InputFileError(f"error model {path}: cannot be read ({exc}); check the "
                                 "path") from None
        except json.JSONDecodeError as exc:
            raise InputFileError(f"error model {path}: not valid JSON ({exc.msg} at line "
                                 f"{exc.lineno}); the file is corrupted, regenerate it with "
                                 "`markerplan fit-error-model`") from None
        return cls.from_json(d, source=f"error model {path}")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
