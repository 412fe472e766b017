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
from markerplan.reading import (
    check_schema_version,
    json_kind,
    json_number,
    json_numbers,
    load_json,
    require_keys,
    require_type,
)

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
        """Rebuild from :meth:`to_json` output.

        Parameters
        ----------
        d : mapping
            The parsed JSON.
        source : str
            How messages name the input, e.g. ``"error model m.json"``.

        Raises
        ------
        InputFileError
            Not an error model, a newer ``format_version``, missing keys, wrong types,
            non-finite or absurd numbers, a quantile outside (0, 1), an inverted or empty
            domain, coefficients that break the fitted sign constraints, or a sigma or
            envelope that is not positive somewhere in the fitted domain. One line.
        """
        basis, sigma, q, quantile, domain = _model_json_iv(d, source)
        skip = {"format", "format_version", "predictors", "sigma_definition", "basis", "domain"}
        info = {k: v for k, v in d.items() if k not in skip}
        info["sigma"] = {k: v for k, v in d["sigma"].items() if k != "coefficients"}
        info["envelope"] = {k: v for k, v in d["envelope"].items()
                            if k not in ("coefficients", "quantile")}
        return cls(basis=basis, sigma_coef=sigma, q_coef=q, quantile=quantile, domain=domain,
                   info=info)

    def save(self, path: str | Path) -> Path:
        """Write the JSON atomically (temporary file in the same folder, then rename)."""
        return save_json(path, self.to_json(), "error model")

    @classmethod
    def load(cls, path: str | Path) -> ErrorModel:
        """Read a model JSON written by :meth:`save`.

        Raises
        ------
        InputFileError
            Missing, unreadable or non-UTF-8 file, invalid JSON (``NaN``/``Infinity``
            included), or any problem :meth:`from_json` refuses. One line.
        """
        path = Path(path)
        what = f"error model {path}"
        if not path.exists():
            raise InputFileError(f"{what}: no such file; pass a JSON written by "
                                 "`markerplan fit-error-model`")
        # any top-level type: from_json says "not a markerplan error model" for a list
        d = load_json(path, what, expect=object)
        return cls.from_json(d, source=what)


def save_json(path: str | Path, doc: dict[str, Any], what: str) -> Path:
    """Write ``doc`` as JSON atomically: a temporary file in the same folder, then a rename,
    so a reader never sees half a model. ``what`` names the file in errors."""
    path = Path(path)
    text = json.dumps(doc, indent=1, sort_keys=True) + "\n"
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.partial-", dir=path.parent or ".")
    except OSError as exc:
        raise OutputError(f"{what} {path}: cannot write in {path.parent} "
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


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: Largest coefficient magnitude accepted, metres per feature unit (a sigma of kilometres is a
#: corrupt or hand-edited file, not a marker-centre error).
MAX_ABS_COEFFICIENT = 1e3
#: Solver round-off tolerated on coefficients the fit constrains to be >= 0.
SIGN_TOLERANCE = 1e-9
_REFIT = "regenerate it with `markerplan fit-error-model`"


def _model_json_iv(d: Any, source: str) -> tuple[Basis, np.ndarray, np.ndarray, float, Domain]:
    """Validate a parsed model JSON; return its basis, coefficients, quantile and domain."""
    if not isinstance(d, Mapping) or d.get("format") != FORMAT:
        got = (f"format {d.get('format')!r}" if isinstance(d, Mapping)
               else f"a JSON object expected at the top level, got {json_kind(d)}")
        raise InputFileError(f"{source}: not a markerplan error model ({got}, expected format "
                             f"{FORMAT!r}); pass a file written by `markerplan fit-error-model`")
    require_keys(d, ["format_version"], source, _REFIT)
    _check_format_version(d["format_version"], source)
    require_keys(d, ["basis", "sigma", "envelope", "domain"], source, _REFIT)
    for key in ("basis", "sigma", "envelope", "domain"):
        require_type(d[key], dict, f"{source}: {key}")
    require_keys(d["sigma"], ["coefficients"], f"{source}: sigma", _REFIT)
    require_keys(d["envelope"], ["coefficients", "quantile"], f"{source}: envelope", _REFIT)
    basis = Basis.from_dict(d["basis"], f"{source}: basis")
    domain = Domain.from_dict(d["domain"], f"{source}: domain")
    quantile = json_number(d["envelope"]["quantile"], f"{source}: envelope quantile")
    if not 0.0 < quantile < 1.0:
        raise InputFileError(f"{source}: envelope quantile must lie in (0, 1), got "
                             f"{quantile:g}; {_REFIT}")
    if "predictors" in d:
        want = ["distance_m", "elevation_rad", *basis.extras]
        if d["predictors"] != want:
            raise InputFileError(f"{source}: predictors {d['predictors']!r:.80} do not match the "
                                 f"basis (expected {want}); {_REFIT}")
    if set(domain.extras) != set(basis.extras):
        raise InputFileError(f"{source}: domain extras {sorted(domain.extras)} differ from "
                             f"basis extras {list(basis.extras)}; {_REFIT}")
    sigma = _coefficients(d["sigma"]["coefficients"], basis, f"{source}: sigma coefficients")
    q = _coefficients(d["envelope"]["coefficients"], basis,
                      f"{source}: envelope coefficients")
    for name, coef in (("sigma", sigma), ("envelope", q)):
        low = _domain_minimum(basis, domain, coef)
        if not low > 0.0:
            raise InputFileError(f"{source}: {name} coefficients give {name} {low:.3g} m <= 0 "
                                 "inside the fitted domain; a centre error is positive, "
                                 f"{_REFIT}")
    return basis, sigma, q, quantile, domain


def _check_format_version(found: Any, source: str) -> int:
    """:func:`~markerplan.reading.check_schema_version` for the model's ``format_version``."""
    try:
        return check_schema_version(found, FORMAT_VERSION, source)
    except InputFileError as exc:
        raise InputFileError(str(exc).replace("schema_version", "format_version")) from None


def _coefficients(values: Any, basis: Basis, what: str) -> np.ndarray:
    """``basis.n_features`` finite coefficients of sane size, signs as the fit constrains."""
    if not isinstance(values, list) or len(values) != basis.n_features:
        got = f"{len(values)}" if isinstance(values, list) else json_kind(values)
        raise InputFileError(f"{what}: expected {basis.n_features} numbers (one per feature "
                             f"{basis.names}), got {got}; {_REFIT}")
    coef = np.array(json_numbers(values, what, MAX_ABS_COEFFICIENT))
    negative = basis.nonneg & (coef < -SIGN_TOLERANCE)
    if negative.any():
        i = int(np.flatnonzero(negative)[0])
        raise InputFileError(f"{what}: {basis.names[i]} must be >= 0 (error never decreases "
                             f"with distance or a worse view), got {coef[i]:.3g}; {_REFIT}")
    return coef


def _domain_minimum(basis: Basis, domain: Domain, coef: np.ndarray) -> float:
    """Smallest ``basis.design(...) @ coef`` over the fitted domain (exact for valid signs).

    Non-negative distance and extra coefficients make the model non-decreasing in distance and
    in the extra features, so the minimum is at each band's nearest edge, the best extra values,
    and, the model being piecewise linear in ``|elevation|``, at the band's elevation bounds,
    the knots inside them or zero.
    """
    edges = np.asarray(domain.band_edges_m)
    d_list, e_list = [], []
    for i in range(edges.size - 1):
        lo, hi = domain.elevation_lo_rad[i], domain.elevation_hi_rad[i]
        knots = np.r_[0.0, basis.elevation_knots_rad]
        cand = np.r_[lo, hi, knots, -knots]
        cand = cand[(cand >= lo) & (cand <= hi)]
        d_list.append(np.full(cand.size, edges[i]))
        e_list.append(cand)
    d, e = np.concatenate(d_list), np.concatenate(e_list)
    best = {"visible_fraction": 1, "expected_points": 1}  # index of (lo, hi): the best value
    extras = {x: np.full(d.size, domain.extras[x][best[x]]) for x in basis.extras}
    return float((basis.design(d, e, extras) @ coef).min())
