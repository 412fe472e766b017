"""Fit an :class:`~error_model.model.ErrorModel` from marker tables.

Steps (each recorded in the model's JSON):

1. rows: accepted markers with a finite 3D error (:func:`error_model.table.fit_data`);
2. basis: every (distance segments, elevation segments) candidate is scored by grouped k-fold
   cross-validation of the mean-error fit; the smallest basis within one standard error of the
   best is kept;
3. optional predictors: forward selection, each kept only if it lowers the cross-validated
   loss by at least ``extra_min_gain`` (relative);
4. final fits on all rows: least squares for the mean 3D error ``m(x)``, scaled to the RMS
   error ``sigma(x) = kappa m(x)`` with ``kappa = sqrt(sum e^2 / sum m^2)``; quantile
   regression for the envelope;
5. held-out coverage and pinball loss of the envelope (k-fold on a seeded subsample);
6. bootstrap intervals on the coefficients and on each predictor's effect;
7. the fitted domain.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from error_model.basis import Basis
from error_model.bootstrap import bootstrap
from error_model.config import FitConfig
from error_model.crossval import (
    CvScore,
    cv_mean_model,
    cv_quantile_model,
    fold_labels,
    one_se_choice,
)
from error_model.domain import Domain
from error_model.effects import effect_vectors
from error_model.model import ErrorModel
from error_model.solve import Constraints, MeanFitter, QuantileFitter, Scaling
from error_model.table import FitData, MarkerTable, as_marker_table, fit_data
from markerplan.errors import ConfigError
from markerplan.provenance import provenance


def fit_error_model(table: MarkerTable | Mapping[str, Any],
                    config: FitConfig | Mapping[str, Any] | None = None,
                    seed: int = 0, description: str | None = None) -> ErrorModel:
    """Fit sigma and the 95 % envelope of the 3D marker-centre error.

    Parameters
    ----------
    table : MarkerTable or mapping of column -> (n,) array
        Marker table(s) with at least ``distance_m``, ``elevation_deg``, ``error_m`` and
        ``accepted``; ``visible_fraction`` and ``n_points`` (as expected points) are tried as
        optional predictors.
    config : FitConfig or mapping, optional
        Fit settings (defaults: :class:`~error_model.config.FitConfig`).
    seed : int
        Seeds fold assignment, subsampling and the bootstrap; same seed, same model.
    description : str, optional
        What the data is (recorded under ``data.description``).

    Returns
    -------
    model : ErrorModel

    Raises
    ------
    DataError
        Too few usable rows, all-NaN columns, out-of-range values, solver failure.
    ConfigError
        Invalid settings.
    """
    config, rng = _fit_iv(config, seed)
    table = as_marker_table(table)
    data = fit_data(table, config.min_rows, config.extra_candidates, config.estimator)
    y = data.error_m

    labels = fold_labels(data.groups, config.cv_folds, rng)
    basis, basis_cv = _choose_basis(data, y, labels, config)
    basis, extra_cv = _choose_extras(basis, basis_cv["chosen"], data, y, labels, config)

    phi = _design(basis, data)
    cons = Constraints(basis.nonneg, basis.nonneg_rows())
    scaling = Scaling.from_data(phi, y)
    mean_fitter = MeanFitter(cons, scaling, config.solver)
    q_fitter = QuantileFitter(cons, scaling, config.quantile, config.solver)

    def refit(rows: np.ndarray | None) -> np.ndarray:
        f, t = (phi, y) if rows is None else (phi[rows], y[rows])
        mean_coef = mean_fitter.fit(f, t)
        m = f @ mean_coef
        kappa = float(np.sqrt(np.sum(t**2) / np.sum(m**2))) if np.any(m > 0) else 1.0
        q_coef = q_fitter.fit(f, t, reuse=rows is not None)
        return np.r_[kappa * mean_coef, q_coef, kappa]

    p = basis.n_features
    full = refit(None)
    solver_status = {"name": config.solver, "sigma_status": mean_fitter.status,
                     "envelope_status": q_fitter.status}
    sigma_coef, q_coef, kappa = full[:p], full[p:2 * p], float(full[-1])

    sub = np.sort(rng.permutation(y.size)[:config.cv_quantile_max_rows])
    quantile_cv = cv_quantile_model(basis, phi[sub], y[sub], labels[sub], config.quantile,
                                    config.solver)
    quantile_cv["rows"] = int(sub.size)

    info: dict[str, Any] = {"sigma": {"mean_to_rms_factor": kappa},
                            "envelope": {}}
    effects = effect_vectors(basis, data.distance_m, data.elevation_rad, data.extras)
    boot = None
    if config.n_bootstrap > 0:
        grouping = _grouping(data.groups, config.cv_folds)
        groups = data.groups if grouping != "rows" else np.arange(y.size)
        boot = bootstrap(refit, groups, config.n_bootstrap, config.bootstrap_max_rows, rng)
        for key, sl in (("sigma", slice(0, p)), ("envelope", slice(p, 2 * p))):
            lo, hi = boot.interval(full[sl], boot.samples[:, sl])
            info[key].update({"ci95_lo": lo.tolist(), "ci95_hi": hi.tolist()})
        info["bootstrap"] = {"replicates": config.n_bootstrap,
                             "rows_per_replicate": boot.rows_per_replicate,
                             "shrink": boot.shrink,
                             "resampling": f"{grouping}, with replacement"}
    info["effects"] = _effects_summary(effects, sigma_coef, q_coef, boot, p)

    domain = Domain.from_data(data.distance_m, data.elevation_rad,
                              {x: data.extras[x] for x in basis.extras},
                              config.domain_bands, np.deg2rad(config.domain_elevation_margin_deg))
    info["cross_validation"] = {
        "folds": config.cv_folds,
        "grouping": _grouping(data.groups, config.cv_folds),
        "mean_error_mse_m2": basis_cv,
        "optional_predictors": extra_cv,
        "envelope": quantile_cv,
    }
    info["data"] = {"fingerprint": data.fingerprint(), "rows_used": data.n_rows,
                    "counts": data.counts, "sources": [Path(s).name for s in data.sources],
                    "description": description or "marker tables " + ", ".join(
                        Path(s).name for s in data.sources),
                    "unavailable_predictors": data.unavailable}
    info["provenance"] = provenance(config.to_dict(), seed=int(seed),
                                    solver=solver_status)
    return ErrorModel(basis=basis, sigma_coef=sigma_coef, q_coef=q_coef,
                      quantile=config.quantile, domain=domain, info=info)


def _fit_iv(config: FitConfig | Mapping[str, Any] | None, seed: int
            ) -> tuple[FitConfig, np.random.Generator]:
    if not isinstance(config, FitConfig):
        config = FitConfig.from_dict(config)
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ConfigError(f"seed must be a non-negative integer, got {seed!r}")
    return config, np.random.default_rng(seed)


def _grouping(groups: np.ndarray, k: int) -> str:
    """Unit of resampling: whole scans when there are at least ``k`` of them, else rows."""
    n_groups = np.unique(groups).size
    return "rows" if n_groups < k or n_groups == groups.size else "station x replicate"


def _design(basis: Basis, data: FitData) -> np.ndarray:
    return basis.design(data.distance_m, data.elevation_rad, data.extras)


def _choose_basis(data: FitData, y: np.ndarray, labels: np.ndarray,
                  config: FitConfig) -> tuple[Basis, dict]:
    seen: dict[Basis, CvScore] = {}
    for kd in config.distance_segments:
        for ke in config.elevation_segments:
            basis = Basis.from_data(data.distance_m, data.elevation_rad, kd, ke)
            if basis not in seen:
                seen[basis] = cv_mean_model(basis, _design(basis, data), y, labels,
                                            config.solver)
    chosen, score = one_se_choice(list(seen.items()))
    report = {"candidates": [{"distance_segments": len(b.distance_knots_m) + 1,
                              "elevation_segments": len(b.elevation_knots_rad) + 1,
                              **s.to_dict()} for b, s in seen.items()],
              "rule": "smallest basis within one standard error of the best",
              "chosen": score.to_dict()}
    return chosen, report


def _choose_extras(basis: Basis, base: dict, data: FitData, y: np.ndarray,
                   labels: np.ndarray, config: FitConfig) -> tuple[Basis, dict]:
    report: dict[str, Any] = {
        "rule": f"forward selection; kept if the CV mean squared error drops by at least "
                f"{config.extra_min_gain:.0%}",
        "baseline_mse_m2": base["mean"], "steps": [],
        "unavailable": dict(data.unavailable)}
    current = base["mean"]
    remaining = [x for x in config.extra_candidates if x in data.extras]
    while remaining:
        trials = {}
        for x in remaining:
            trial = replace(basis, extras=(*basis.extras, x))
            trials[x] = cv_mean_model(trial, _design(trial, data), y, labels, config.solver)
        best = min(trials, key=lambda x: trials[x].mean)
        step = {x: {"mse_m2": s.mean, "se": s.se, "relative_gain": (current - s.mean) / current}
                for x, s in trials.items()}
        gain = step[best]["relative_gain"]
        kept = gain >= config.extra_min_gain
        report["steps"].append({"tried": step, "kept": best if kept else None})
        if not kept:
            break
        basis = replace(basis, extras=(*basis.extras, best))
        current = trials[best].mean
        remaining.remove(best)
    report["selected"] = list(basis.extras)
    return basis, report


def _effects_summary(effects: dict, sigma_coef: np.ndarray, q_coef: np.ndarray, boot,
                     p: int) -> dict:
    out = {}
    for name, (text, g) in effects.items():
        entry: dict[str, Any] = {"description": text, "sigma_m": float(g @ sigma_coef),
                                 "q95_m": float(g @ q_coef)}
        if boot is not None:
            for key, sl, est in (("sigma_m", slice(0, p), entry["sigma_m"]),
                                 ("q95_m", slice(p, 2 * p), entry["q95_m"])):
                lo, hi = boot.interval(np.array([est]), (boot.samples[:, sl] @ g)[:, None])
                entry[f"{key}_ci95"] = [float(lo[0]), float(hi[0])]
        out[name] = entry
    return out
