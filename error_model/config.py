"""Settings of an error-model fit (validated once, recorded in the model's provenance)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

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
        """Build from a mapping; unknown keys are rejected by name."""
        d = dict(d or {})
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError(f"error-model config: unknown option(s) {unknown}; "
                              f"known options are {sorted(known)}")
        for key in ("distance_segments", "elevation_segments", "extra_candidates"):
            if key in d:
                d[key] = tuple(d[key])
        return cls(**d)


def _fit_config_iv(c: FitConfig) -> None:
    if not 0.5 < c.quantile < 1.0:
        raise ConfigError(f"quantile must lie in (0.5, 1), got {c.quantile}; use e.g. 0.95")
    if c.cv_folds < 2:
        raise ConfigError(f"cv_folds must be >= 2, got {c.cv_folds}")
    for name in ("distance_segments", "elevation_segments"):
        v = getattr(c, name)
        if not v or any(int(k) != k or k < 1 for k in v):
            raise ConfigError(f"{name} must be a non-empty list of integers >= 1, got {list(v)}")
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
