"""Diagnostics of a fitted model: the text "multivariate analysis" (each predictor's effect
with its bootstrap interval, cross-validation) and a PNG of errors against distance coloured
by elevation with the fitted sigma and envelope."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from error_model.model import ErrorModel
from error_model.table import MarkerTable, fit_data


def summary_text(model: ErrorModel) -> str:
    """Plain-text summary: data, basis, each predictor's effect, cross-validation, domain.

    Parameters
    ----------
    model : ErrorModel

    Returns
    -------
    text : str
        Several lines, millimetres for errors.
    """
    info = model.info
    data = info.get("data", {})
    lines = [f"error model fitted on {data.get('rows_used', '?')} accepted markers "
             f"({data.get('description', 'unknown data')})",
             f"predictors: {', '.join(model.predictors)}; basis: "
             f"{len(model.basis.distance_knots_m) + 1} distance segment(s), "
             f"{len(model.basis.elevation_knots_rad) + 1} |elevation| segment(s)",
             "effects (sigma = 3D RMS error; q95 = 95 % envelope; 95 % bootstrap CI):"]
    for name, eff in info.get("effects", {}).items():
        parts = []
        for key, label in (("sigma_m", "sigma"), ("q95_m", "q95")):
            text = f"{label} {1e3 * eff[key]:+.2f} mm"
            if f"{key}_ci95" in eff:
                lo, hi = eff[f"{key}_ci95"]
                text += f" [{1e3 * lo:+.2f}, {1e3 * hi:+.2f}]"
            parts.append(text)
        lines.append(f"  {name}: {'; '.join(parts)} -- {eff['description']}")
    cv = info.get("cross_validation", {})
    extra = cv.get("optional_predictors", {})
    for step in extra.get("steps", []):
        for name, s in step["tried"].items():
            verdict = "kept" if step["kept"] == name else "not kept"
            lines.append(f"  optional {name}: CV mean-squared-error change "
                         f"{-100 * s['relative_gain']:+.1f} % -> {verdict}")
    for name, why in extra.get("unavailable", {}).items():
        lines.append(f"  optional {name}: unavailable ({why})")
    env = cv.get("envelope")
    if env:
        lines.append(f"held-out coverage of the {model.quantile:.0%} envelope: "
                     f"{100 * env['coverage']:.1f} % ({cv['folds']}-fold, {env['rows']} rows, "
                     f"folds by {cv['grouping']})")
    lo, hi = model.domain.distance_range_m
    elo = np.rad2deg(min(model.domain.elevation_lo_rad))
    ehi = np.rad2deg(max(model.domain.elevation_hi_rad))
    lines.append(f"domain: distance {lo:.3g}-{hi:.3g} m, elevation {elo:.3g} to {ehi:.3g} deg "
                 f"(per-band limits in the JSON); outside it predictions are flagged")
    return "\n".join(lines)


def plot_diagnostics(model: ErrorModel, table: MarkerTable, path: str | Path) -> Path:
    """Write a PNG: 3D errors against distance coloured by ``|elevation|``, with sigma and the
    envelope at three elevations (10th, 50th, 90th percentile of the data).

    Parameters
    ----------
    model : ErrorModel
    table : MarkerTable
        The table(s) the model was fitted on (only accepted, finite rows are drawn).
    path : str or Path
        PNG file to write.

    Returns
    -------
    path : Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = fit_data(table, 1, model.basis.extras,
                    model.info.get("provenance", {}).get("config", {}).get("estimator"))
    d, e, err = data.distance_m, data.elevation_rad, data.error_m
    fig, ax = plt.subplots(figsize=(8, 5), dpi=120)
    sc = ax.scatter(d, 1e3 * err, c=np.rad2deg(np.abs(e)), s=6, alpha=0.5, cmap="viridis",
                    rasterized=True)
    fig.colorbar(sc, ax=ax, label="|elevation| (deg)")
    grid = np.linspace(d.min(), d.max(), 200)
    extras = {k: np.full(grid.size, np.median(v)) for k, v in data.extras.items()}
    cmap = plt.get_cmap("viridis")
    a_max = np.rad2deg(np.abs(e)).max() or 1.0
    for q in (10, 50, 90):
        ev = float(np.percentile(e, q))
        pred = model.predict(grid, np.full(grid.size, ev), **extras)
        colour = cmap(np.rad2deg(abs(ev)) / a_max)
        ax.plot(grid, 1e3 * pred.sigma_m, "-", color=colour, lw=2,
                label=f"sigma, elevation {np.rad2deg(ev):.1f} deg")
        ax.plot(grid, 1e3 * pred.q95_m, "--", color=colour, lw=2,
                label=f"{model.quantile:.0%} envelope, {np.rad2deg(ev):.1f} deg")
    ax.set_xlabel("distance LiDAR-marker (m)")
    ax.set_ylabel("3D centre error (mm)")
    ax.set_title(f"Marker-centre error model ({data.n_rows} accepted markers)")
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, metadata={"Software": None})
    plt.close(fig)
    return path
