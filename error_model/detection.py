"""The detection model: the probability that a planned marker is detected and accepted by the
station chain, from what a planner knows of the pair before any scan.

A logistic model ``P = 1 / (1 + exp(-x . beta))`` whose features ``x`` are fixed transforms of
the pair's covariates (:data:`COVARIATES`: distance, elevation, visible fraction, expected
points, terrain slope, crater-rim distance), each a :class:`Feature`: the covariate through a
transform (identity, ``log``, ``log1p``) and, with a knot, the hinge ``max(0, t(x) - t(knot))``
(piecewise-linear in ``t``, so the probability can fall at short range, where the gate loses
markers, and at long range, where too few points land). Fitted by penalised maximum likelihood
(a small ridge on all but the intercept, L-BFGS; deterministic) on the rows of a loss study
(:mod:`planner.studies.loss_study`: every marker in range of a simulated scan and its fate,
``accepted`` or the stage that lost it).

Its calibration is part of the model: :func:`reliability` (predicted against observed
acceptance per probability bin, Wilson 95 % intervals), :func:`brier_score`, and held-out
figures from :func:`held_out` (k folds over groups of rows, e.g. scans, so no scan is both fitted
and scored), stored in the JSON beside the coefficients.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import minimize
from scipy.special import expit, log_expit, ndtri

from error_model.model import save_json
from markerplan.errors import ConfigError, DataError, InputFileError
from markerplan.reading import (
    check_schema_version,
    json_kind,
    json_number,
    load_json,
    require_keys,
    require_type,
)

FORMAT = "markerplan-detection-model"
FORMAT_VERSION = 1

#: Covariates a detection model may use, with their units (what the planner knows of a pair).
COVARIATES = {"distance_m": "m", "elevation_deg": "deg", "visible_fraction": "1",
              "expected_points": "returns", "slope_deg": "deg", "rim_distance_m": "m"}

#: Transforms of a covariate.
TRANSFORMS = {"identity": lambda x: x, "log": np.log, "log1p": np.log1p}

#: Largest coefficient accepted in a file (a logit slope beyond this is a corrupt file).
MAX_ABS_COEFFICIENT = 1e4

#: Two-sided 95 % standard normal quantile.
Z95 = float(ndtri(0.975))

#: Rim distances beyond this are as good as none, metres (``inf`` without craters).
RIM_DISTANCE_CAP_M = 10.0


@dataclass(frozen=True)
class Feature:
    """One feature: ``t(covariate)``, or with ``knot`` the hinge ``max(0, t(x) - t(knot))``."""

    covariate: str
    transform: str = "identity"
    knot: float | None = None

    def __post_init__(self) -> None:
        if self.covariate not in COVARIATES:
            raise ConfigError(f"detection feature: unknown covariate {self.covariate!r}; use "
                              f"one of {', '.join(COVARIATES)}")
        if self.transform not in TRANSFORMS:
            raise ConfigError(f"detection feature of {self.covariate}: unknown transform "
                              f"{self.transform!r}; use one of {', '.join(TRANSFORMS)}")
        if self.knot is not None and not (np.isfinite(self.knot) and (
                self.transform == "identity" or self.knot > (0 if self.transform == "log"
                                                             else -1))):
            raise ConfigError(f"detection feature of {self.covariate}: knot {self.knot} is "
                              f"outside the domain of {self.transform}; give a finite knot "
                              "inside it")

    def values(self, covariates: Mapping[str, np.ndarray]) -> np.ndarray:
        x = _covariate(covariates, self.covariate)
        t = TRANSFORMS[self.transform]
        with np.errstate(divide="ignore", invalid="ignore"):
            v = t(x)
            if self.knot is not None:
                v = np.maximum(0.0, v - t(self.knot))
        if not np.isfinite(v).all():
            raise DataError(f"detection model: {self.covariate} has values outside the domain "
                            f"of {self.transform} (e.g. {x[~np.isfinite(v)][0]!r}); check the "
                            "covariates")
        return v

    def to_json(self) -> dict[str, Any]:
        return {"covariate": self.covariate, "transform": self.transform, "knot": self.knot}


#: The default features: log distance with hinges at 3 m, 15 m and 30 m, the log of the
#: expected points, the visible fraction, the terrain slope and the (capped) distance to a
#: crater rim. The 30 m hinge lets acceptance fall as steeply as it does at 30-40 m (too few
#: points for the quality gate); without it, held out, the 0.5-0.7 bin predicted 0.61 where
#: 0.36 were accepted (``docs/pipeline.md``, the loss-study section).
DEFAULT_FEATURES = (Feature("distance_m", "log"), Feature("distance_m", "log", 3.0),
                    Feature("distance_m", "log", 15.0), Feature("distance_m", "log", 30.0),
                    Feature("expected_points", "log1p"), Feature("visible_fraction"),
                    Feature("slope_deg"), Feature("rim_distance_m", "log1p"))


@dataclass(frozen=True)
class DetectionModel:
    """A fitted detection model; build with :func:`fit_detection_model` or :meth:`load`.

    Attributes
    ----------
    features : tuple of Feature
    coef : (1 + f,) float
        Intercept, then one logit coefficient per feature.
    info : dict
        Recorded at fit time (calibration, held-out figures, data, provenance), kept verbatim.
    """

    features: tuple[Feature, ...]
    coef: np.ndarray
    info: dict = field(default_factory=dict)

    def probability(self, **covariates: Any) -> np.ndarray:
        """P(detected and accepted) of each pair, from its covariates (arrays, broadcast).

        Every covariate a feature uses must be given (:data:`COVARIATES`; ``rim_distance_m``
        may be ``inf``: no crater).
        """
        return expit(design_matrix(self.features, covariates) @ self.coef)

    def to_json(self) -> dict[str, Any]:
        return {"format": FORMAT, "format_version": FORMAT_VERSION,
                "features": [f.to_json() for f in self.features],
                "coefficients": [float(c) for c in self.coef], **self.info}

    @classmethod
    def from_json(cls, d: Any, source: str = "detection model") -> DetectionModel:
        """Validate and build; every problem is one :class:`InputFileError` line."""
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise InputFileError(f"{source}: not a markerplan detection model (expected an "
                                 f"object with format {FORMAT!r}, got {json_kind(d)}); pass a "
                                 "file written by `markerplan fit-detection-model`")
        fix = "refit it with `markerplan fit-detection-model`"
        require_keys(d, ("format_version", "features", "coefficients"), source, fix)
        check_schema_version(d["format_version"], FORMAT_VERSION, f"{source} format")
        feats = require_type(d["features"], list, f"{source}: features")
        features = []
        for k, f in enumerate(feats):
            what = f"{source}: feature {k}"
            require_type(f, dict, what)
            require_keys(f, ("covariate", "transform", "knot"), what, fix)
            knot = None if f["knot"] is None else json_number(f["knot"], f"{what} knot")
            try:
                features.append(Feature(require_type(f["covariate"], str, what),
                                        require_type(f["transform"], str, what), knot))
            except ConfigError as exc:
                raise InputFileError(f"{source}: {exc}") from None
        coef = require_type(d["coefficients"], list, f"{source}: coefficients")
        if len(coef) != 1 + len(features):
            raise InputFileError(f"{source}: {len(coef)} coefficients for {len(features)} "
                                 f"features (needs {1 + len(features)}: the intercept first); "
                                 f"{fix}")
        values = np.array([json_number(c, f"{source}: coefficient {k}", MAX_ABS_COEFFICIENT)
                           for k, c in enumerate(coef)])
        info = {k: v for k, v in d.items()
                if k not in ("format", "format_version", "features", "coefficients")}
        return cls(tuple(features), values, info)

    def save(self, path: str | Path) -> Path:
        """Write the JSON atomically."""
        return save_json(path, self.to_json(), "detection model")

    @classmethod
    def load(cls, path: str | Path) -> DetectionModel:
        """Read a model written by :meth:`save` (one :class:`InputFileError` line if bad)."""
        path = Path(path)
        what = f"detection model {path}"
        if not path.exists():
            raise InputFileError(f"{what}: no such file; pass a JSON written by "
                                 "`markerplan fit-detection-model`")
        return cls.from_json(load_json(path, what, expect=object), source=what)


def _covariate(covariates: Mapping[str, Any], name: str) -> np.ndarray:
    if name not in covariates:
        raise ConfigError(f"detection model needs the covariate {name!r}; give it")
    x = np.asarray(covariates[name], dtype=float)
    if name == "rim_distance_m":
        x = np.minimum(x, RIM_DISTANCE_CAP_M)
    if np.isnan(x).any():
        raise DataError(f"detection model: {name} has NaN values; give finite covariates")
    return x


def design_matrix(features: Sequence[Feature], covariates: Mapping[str, Any]) -> np.ndarray:
    """(n, 1 + f) design matrix: a column of ones, then each feature's values."""
    cols = [f.values(covariates) for f in features]
    shape = np.broadcast_shapes(*(c.shape for c in cols)) if cols else ()
    return np.stack([np.ones(shape), *(np.broadcast_to(c, shape) for c in cols)], axis=-1)


def fit_detection_model(covariates: Mapping[str, Any], accepted: np.ndarray,
                        features: Sequence[Feature] = DEFAULT_FEATURES, ridge: float = 1e-3,
                        info: dict | None = None) -> DetectionModel:
    """Penalised maximum-likelihood logistic fit.

    Parameters
    ----------
    covariates : mapping of str to (n,) arrays
        The pairs' covariates (:data:`COVARIATES` the features use).
    accepted : (n,) bool
        Whether the chain detected and accepted each pair's marker.
    features : sequence of Feature
    ridge : float
        L2 penalty per row on the feature coefficients (not the intercept), >= 0: keeps the fit
        finite when a feature separates the outcomes (every near pair accepted).
    info : dict, optional
        Recorded in the model.

    Returns
    -------
    DetectionModel

    Raises
    ------
    DataError
        Fewer rows than coefficients, or covariates the features cannot use.
    """
    y = np.asarray(accepted, dtype=bool).astype(float)
    x = design_matrix(features, covariates)
    if x.shape[0] != y.shape[0] or x.ndim != 2:
        raise DataError(f"detection model: {x.shape[0]} covariate rows for {y.shape[0]} "
                        "outcomes; give one outcome per row")
    if len(y) <= x.shape[1]:
        raise DataError(f"detection model: {len(y)} rows cannot fit {x.shape[1]} coefficients; "
                        "run a larger loss study")
    if not ridge >= 0:
        raise ConfigError(f"detection model: ridge must be >= 0, got {ridge}")
    # a feature constant over the rows (a level field's slope) is the intercept again: it keeps
    # a zero coefficient; the others are standardised, so the ridge treats them alike
    spread = x.std(axis=0)
    active = spread > 1e-9 * np.maximum(1.0, np.abs(x.mean(axis=0)))
    active[0] = True
    scale = np.where(active, spread, 1.0)
    scale[0] = 1.0
    z = x[:, active] / scale[active]
    penalty = np.full(z.shape[1], ridge * len(y))
    penalty[0] = 0.0

    def loss(b):
        eta = z @ b
        nll = -(y * log_expit(eta) + (1 - y) * log_expit(-eta)).sum()
        grad = z.T @ (expit(eta) - y)
        return nll + 0.5 * (penalty * b * b).sum(), grad + penalty * b

    res = minimize(loss, np.zeros(z.shape[1]), jac=True, method="L-BFGS-B",
                   options={"maxiter": 2000, "gtol": 1e-10})
    coef = np.zeros(x.shape[1])
    coef[active] = res.x / scale[active]
    return DetectionModel(tuple(features), coef, dict(info or {}))


def brier_score(probability: np.ndarray, accepted: np.ndarray) -> float:
    """Mean squared difference of predicted probability and outcome (0 best, 0.25 a coin).

    >>> brier_score(np.array([1.0, 0.0, 0.5]), np.array([True, False, True]))
    0.08333333333333333
    """
    p = np.asarray(probability, float)
    return float(np.mean((p - np.asarray(accepted, bool)) ** 2))


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n``.

    Parameters
    ----------
    k, n : int
        Successes and trials, ``0 <= k <= n``, ``n >= 1``.
    z : float
        Standard normal quantile (default: two-sided 95 %).

    Returns
    -------
    low, high : float
        Within [0, 1].

    Examples
    --------
    >>> [round(v, 4) for v in wilson_interval(38, 40)]
    [0.835, 0.9862]
    >>> [round(v, 4) for v in wilson_interval(8, 8)]
    [0.6756, 1.0]
    """
    if not 0 <= k <= n or n < 1:
        raise ValueError(f"wilson_interval needs 0 <= k <= n and n >= 1, got k={k}, n={n}")
    p = k / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z / (1 + z2 / n) * np.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    return max(0.0, float(centre - half)), min(1.0, float(centre + half))


def reliability(probability: np.ndarray, accepted: np.ndarray,
                edges: Sequence[float] = (0.0, 0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 1.0)
                ) -> list[dict]:
    """The reliability diagram's table: per bin of predicted probability, the pairs, the mean
    prediction, the observed rate and its Wilson 95 % interval (empty bins left out)."""
    p = np.asarray(probability, float)
    y = np.asarray(accepted, bool)
    out = []
    for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        inside = (p >= lo) & ((p < hi) if k < len(edges) - 2 else (p <= hi))
        n = int(inside.sum())
        if not n:
            continue
        hits = int(y[inside].sum())
        low, high = wilson_interval(hits, n)
        out.append({"lo": float(lo), "hi": float(hi), "n": n,
                    "predicted": float(p[inside].mean()), "observed": hits / n,
                    "observed_low": low, "observed_high": high})
    return out


def held_out(covariates: Mapping[str, Any], accepted: np.ndarray, groups: np.ndarray,
             folds: int = 5, features: Sequence[Feature] = DEFAULT_FEATURES,
             ridge: float = 1e-3) -> np.ndarray:
    """Held-out predictions: each group (e.g. a scan) predicted by a model fitted without it.

    The groups are dealt to ``folds`` folds in order of first appearance; each fold is
    predicted by the model fitted on the others.

    Returns
    -------
    probability : (n,) float
    """
    groups = np.asarray(groups)
    _, first, inverse = np.unique(groups, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    fold = rank[inverse.reshape(-1)] % folds
    if len(first) < folds:
        raise DataError(f"held-out calibration needs at least {folds} groups, got "
                        f"{len(first)}; run a larger loss study")
    cov = {k: np.asarray(v, float) for k, v in covariates.items()}
    y = np.asarray(accepted, bool)
    out = np.empty(len(y))
    for k in range(folds):
        test = fold == k
        model = fit_detection_model({c: v[~test] for c, v in cov.items()}, y[~test], features,
                                    ridge)
        out[test] = model.probability(**{c: v[test] for c, v in cov.items()})
    return out


def fit_from_fate_tables(table, folds: int = 5, features: Sequence[Feature] = DEFAULT_FEATURES,
                         ridge: float = 1e-3, description: str | None = None
                         ) -> DetectionModel:
    """Fit on fate tables and record the model's calibration in it.

    Parameters
    ----------
    table : pipeline.tables.fate_table.FateTable
        Rows of known markers and their fates.
    folds : int
        Held-out folds over the scans (each scan's rows kept together), >= 2.
    features, ridge
        As :func:`fit_detection_model`.
    description : str, optional
        What the tables are (recorded).

    Returns
    -------
    model : DetectionModel
        Its ``info`` holds ``data`` (rows, scans, acceptance rate, fingerprint, sources),
        ``calibration`` (in-sample and held-out Brier scores, the Brier score of the constant
        base rate, the held-out reliability table) and ``provenance``.
    """
    from markerplan.provenance import fingerprint_arrays, provenance

    if not 2 <= int(folds) <= 100:
        raise ConfigError(f"held-out folds must be 2..100, got {folds}")
    y = table.accepted
    if y.all() or not y.any():
        raise DataError(f"detection model: all {len(y)} markers were "
                        f"{'accepted' if y.all() else 'lost'}; the tables cannot show how "
                        "detection varies: add scans with both outcomes")
    model = fit_detection_model(table.covariates, y, features, ridge)
    p_out = held_out(table.covariates, y, table.scan, folds, features, ridge)
    p_in = model.probability(**table.covariates)
    arrays = [table.covariates[k] for k in sorted(table.covariates)] + [table.stage, table.scan]
    info = {
        "data": {"rows": len(y), "scans": int(len(np.unique(table.scan))),
                 "accepted_rate": float(y.mean()), "sources": list(table.sources),
                 "fingerprint": fingerprint_arrays(*arrays), "description": description},
        "calibration": {"folds": int(folds), "brier_in_sample": brier_score(p_in, y),
                        "brier_held_out": brier_score(p_out, y),
                        "brier_base_rate": brier_score(np.full(len(y), y.mean()), y),
                        "reliability_held_out": reliability(p_out, y)},
        "provenance": provenance({"features": [f.to_json() for f in features],
                                  "ridge": float(ridge), "folds": int(folds)}),
    }
    return DetectionModel(model.features, model.coef, info)


def plot_calibration(model: DetectionModel, table, path: str | Path) -> Path:
    """A PNG: the held-out reliability diagram (predicted against observed acceptance, Wilson
    95 % bars) beside the observed and predicted acceptance against distance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rel = model.info["calibration"]["reliability_held_out"]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5), dpi=120)
    pred = np.array([r["predicted"] for r in rel])
    obs = np.array([r["observed"] for r in rel])
    err = np.maximum(0.0, [[r["observed"] - r["observed_low"] for r in rel],
                           [r["observed_high"] - r["observed"] for r in rel]])  # round-off
    ax.plot([0, 1], [0, 1], color="0.6", lw=1)
    ax.errorbar(pred, obs, yerr=err, fmt="o", capsize=3)
    for p, o, r in zip(pred, obs, rel, strict=True):
        ax.annotate(str(r["n"]), (p, o), textcoords="offset points", xytext=(5, -10),
                    fontsize=7)
    cal = model.info["calibration"]
    ax.set_title(f"held out ({cal['folds']} folds): Brier {cal['brier_held_out']:.4f} "
                 f"(base rate {cal['brier_base_rate']:.4f})", fontsize=9)
    ax.set_xlabel("predicted P(detected and accepted)")
    ax.set_ylabel("observed rate (Wilson 95 %)")
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    d = table.covariates["distance_m"]
    y = table.accepted
    p = model.probability(**table.covariates)
    edges = np.unique(np.quantile(d, np.linspace(0, 1, 13)))
    mid, o, q = [], [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        inside = (d >= lo) & (d <= hi)
        if inside.any():
            mid.append(np.median(d[inside]))
            o.append(y[inside].mean())
            q.append(p[inside].mean())
    bx.plot(mid, o, "o", label="observed")
    bx.plot(mid, q, "-", label="predicted (mean of the bin)")
    bx.set_xscale("log")
    ticks = [t for t in (1, 2, 5, 10, 20, 50, 100) if d.min() / 2 <= t <= d.max() * 2]
    bx.set_xticks(ticks, [f"{t:g}" for t in ticks])
    bx.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    bx.set_xlabel("distance LiDAR-marker (m)")
    bx.set_ylabel("acceptance rate")
    bx.set_ylim(0, 1.02)
    bx.legend(fontsize=8)
    bx.grid(alpha=0.3)
    fig.suptitle(f"Detection model: {len(y)} marker fates in "
                 f"{model.info['data']['scans']} scans", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, metadata={"Software": None})
    plt.close(fig)
    return path
