"""``markerplan fit-error-model``: fit sigma(distance, angle) and the 95 % envelope from marker
tables, write the model JSON and optionally a diagnostics PNG."""

from __future__ import annotations

import os
from pathlib import Path

import click

from markerplan.errors import OutputError
from planner.cli._common import emit_summary, json_option, overwrite_option


@click.command("fit-error-model")
@click.argument("tables", nargs=-1, required=True,
                type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "output", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="Model JSON to write (refused if it exists unless --overwrite).")
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write a diagnostics PNG (errors vs distance, sigma, envelope).")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True,
              help="Seed for cross-validation folds and the bootstrap.")
@click.option("--bootstrap", "n_bootstrap", type=click.IntRange(min=0), default=None,
              help="Bootstrap replicates for the intervals (default 40; 0 disables).")
@click.option("--estimator", default=None,
              help="Fit only rows of this centre estimator (e.g. fixed-radius); required when "
                   "the tables mix estimators, as range-study output does.")
@click.option("--description", default=None,
              help="What the tables are (recorded in the model's provenance).")
@overwrite_option
@json_option
def command(tables: tuple[Path, ...], output: Path, plot: Path | None, seed: int,
            n_bootstrap: int | None, estimator: str | None, description: str | None,
            overwrite: bool,
            as_json: bool) -> None:
    """Fit the marker-centre error model from one or more marker tables (CSV).

    Uses accepted markers with a finite error_m. Predictors: distance and elevation;
    visible_fraction and point count only where cross-validation shows they help.

    \b
    Example:
      markerplan fit-error-model tables/markers.csv -o model.json --plot model.png
      markerplan fit-error-model range/markers.csv --estimator fixed-radius -o model.json
    """
    from error_model.config import FitConfig
    from error_model.diagnostics import plot_diagnostics, summary_text
    from error_model.fit import fit_error_model
    from error_model.table import read_marker_tables

    targets = [("-o", output)] + ([("--plot", plot)] if plot is not None else [])
    for option, path in targets:
        _check_target(option, path, overwrite)
    if plot is not None and plot.resolve() == output.resolve():
        raise OutputError(f"--plot {plot} is the same file as -o {output}; choose another name")

    settings = {"estimator": estimator}
    if n_bootstrap is not None:
        settings["n_bootstrap"] = n_bootstrap
    config = FitConfig(**settings)
    table = read_marker_tables(tables)
    model = fit_error_model(table, config, seed=seed, description=description)

    plot_tmp = None
    if plot is not None:
        plot_tmp = plot.resolve().parent / f".{plot.name}.partial-{os.getpid()}.png"
    try:
        if plot_tmp is not None:
            plot_diagnostics(model, table, plot_tmp)
        model.save(output)
        if plot_tmp is not None:
            os.replace(plot_tmp, plot)
    finally:
        if plot_tmp is not None:
            plot_tmp.unlink(missing_ok=True)

    info = model.info
    summary = {
        "model": str(output), "plot": str(plot) if plot is not None else None,
        "rows_used": info["data"]["rows_used"], "predictors": list(model.predictors),
        "fingerprint": info["data"]["fingerprint"],
        "distance_range_m": list(model.domain.distance_range_m),
        "envelope_cv_coverage": info["cross_validation"]["envelope"]["coverage"],
        "effects": info["effects"],
    }
    emit_summary(summary, as_json, summary_text(model) + f"\nwrote {output}"
                 + (f" and {plot}" if plot is not None else ""))


def _check_target(option: str, path: Path, overwrite: bool) -> None:
    if path.exists() and path.is_dir():
        raise OutputError(f"{option} {path} is a folder; give a file name")
    if path.exists() and not overwrite:
        raise OutputError(f"{option} {path} already exists; pass --overwrite or choose another "
                          "file")
    parent = path.resolve().parent
    if not parent.is_dir():
        raise OutputError(f"{option} {path}: folder {parent} does not exist; create it first")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{option} {path}: no write permission in {parent}; choose a writable "
                          "location")
