"""Settings of an error-model fit (validated once, recorded in the model's provenance)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from markerplan.errors import ConfigError

#: Optional predictors the fit may add when cross-validation shows they help.
EXTRA_PREDICTORS = ("visible_fraction", "expected_points")


@dataclass(frozen=True)
class FitConfig:
    """Parameters of :func:`error_model.fit.fit_error_model`.

    Attributes
    ----------
    quantile : float
        Level of the conservative envelope (0.95: 95 % of 3D centre errors below it).
    cv_folds : int
        Folds of the k-fold cross-validation that picks the basis and the optional predictors.
    distance_segments : tuple of int
        Candidate numbers of monotone linear segments in distance.
    elevation_segments : tuple of int
        Candidate numbers of linear segments in ``|elevation|``.
    extra_candidates : tuple of str
        Optional predictors tried (subset of ``visible_fraction``, ``expected_points``).
    extra_min_gain : float
        Relative drop of the cross-validated loss an optional predictor must bring to be kept.
    cv_quantile_max_rows : int
        Rows (seeded subsample) used to cross-validate the envelope's held-out coverage.
    n_bootstrap : int
        Bootstrap replicates for the coefficient intervals (0 disables them).
    bootstrap_max_rows : int
        Rows drawn per replicate (m-out-of-n bootstrap, intervals rescaled by sqrt(m/n)).
    min_rows : int
        Fewest usable rows (accepted, finite) a fit accepts.
    domain_bands : int
        Distance bands (quantile edges) over which the fitted elevation range is recorded.
    domain_elevation_margin_deg : float
        Elevation margin, degrees, added on each side of a band's fitted elevation range.
    solver : str
        cvxpy solver name for both fits.
    estimator : str or None
        Fit only rows of this centre estimator (table column ``estimator``, e.g.
        ``fixed-radius``); required when a table mixes estimators.
    """

    quantile: float = 0.95
    cv_folds: int = 5
    distance_segments: tuple[int, ...] = (1, 2, 3, 5, 8)
    elevation_segments: tuple[int, ...] = (1, 2)
    extra_candidates: tuple[str, ...] = EXTRA_PREDICTORS
    extra_min_gain: float = 0.01
    cv_quantile_max_rows: int = 2000
    n_bootstrap: int = 40
    bootstrap_max_rows: int = 800
    min_rows: int = 30
    domain_bands: int = 8
    domain_elevation_margin_deg: float = 2.0
    solver: str = "CLARABEL"
    estimator: str | None = None

    def __post_init__(self) -> None:
        _fit_config_iv(self)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any] | None) -> FitConfig:
        """Build from a mapping; unknown keys are rejected by name, wrong types refused.

        Raises
        ------
        ConfigError
            Not a mapping, unknown options, or any value :class:`FitConfig` refuses.
        """
        if d is not None and not isinstance(d, Mapping):
            raise ConfigError(f"error-model config: expected a mapping of option -> value, got "
                              f"{type(d).__name__}")
        d = dict(d or {})
        known = {f.name for f in fields(cls)}
        unknown = sorted(map(str, set(d) - known))
        if unknown:
            raise ConfigError(f"error-model config: unknown option(s) {unknown}; "
                              f"known options are {sorted(known)}")
        for key in ("distance_segments", "elevation_segments", "extra_candidates"):
            if key in d:
                if not isinstance(d[key], list | tuple):
                    raise ConfigError(f"{key} must be a list, got {d[key]!r:.60}")
                d[key] = tuple(d[key])
        return cls(**d)


_INTS = ("cv_folds", "cv_quantile_max_rows", "n_bootstrap", "bootstrap_max_rows", "min_rows",
         "domain_bands")
_FLOATS = ("quantile", "extra_min_gain", "domain_elevation_margin_deg")


def _fit_config_iv(c: FitConfig) -> None:
    for name in _INTS:
        v = getattr(c, name)
        if isinstance(v, bool) or not isinstance(v, int | np.integer):
            raise ConfigError(f"{name} must be an integer, got {v!r:.60}")
    for name in _FLOATS:
        v = getattr(c, name)
        if isinstance(v, bool) or not isinstance(v, int | float | np.number) \
                or not math.isfinite(v):
            raise ConfigError(f"{name} must be a finite number, got {v!r:.60}")
    for name in ("distance_segments", "elevation_segments"):
        v = getattr(c, name)
        if not isinstance(v, list | tuple) or not v or any(
                isinstance(k, bool) or not isinstance(k, int | np.integer) or k < 1 for k in v):
            raise ConfigError(f"{name} must be a non-empty list of integers >= 1, got "
                              f"{v!r:.60}")
    if not isinstance(c.extra_candidates, list | tuple) \
            or any(not isinstance(x, str) for x in c.extra_candidates):
        raise ConfigError(f"extra_candidates must be a list of names, got "
                          f"{c.extra_candidates!r:.60}")
    if not isinstance(c.solver, str) or not c.solver:
        raise ConfigError(f"solver must be a cvxpy solver name like 'CLARABEL', got "
                          f"{c.solver!r:.60}")
    if c.estimator is not None and not isinstance(c.estimator, str):
        raise ConfigError(f"estimator must be a name like 'fixed-radius' or None, got "
                          f"{c.estimator!r:.60}")
    if not 0.5 < c.quantile < 1.0:
        raise ConfigError(f"quantile must lie in (0.5, 1), got {c.quantile}; use e.g. 0.95")
    if c.cv_folds < 2:
        raise ConfigError(f"cv_folds must be >= 2, got {c.cv_folds}")
    bad = sorted(set(c.extra_candidates) - set(EXTRA_PREDICTORS))
    if bad:
        raise ConfigError(f"extra_candidates may only contain {list(EXTRA_PREDICTORS)}, "
                          f"got {bad}")
    if c.extra_min_gain < 0:
        raise ConfigError(f"extra_min_gain must be >= 0, got {c.extra_min_gain}")
    for name in ("cv_quantile_max_rows", "bootstrap_max_rows", "min_rows", "domain_bands"):
        if getattr(c, name) < 1:
            raise ConfigError(f"{name} must be >= 1, got {getattr(c, name)}")
    if c.min_rows < 2 * c.cv_folds:
        raise ConfigError(f"min_rows must be >= 2 * cv_folds = {2 * c.cv_folds}, "
                          f"got {c.min_rows}")
    if c.n_bootstrap < 0:
        raise ConfigError(f"n_bootstrap must be >= 0, got {c.n_bootstrap}")
    if c.domain_elevation_margin_deg < 0:
        raise ConfigError("domain_elevation_margin_deg must be >= 0, got "
                          f"{c.domain_elevation_margin_deg}")
