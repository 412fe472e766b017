"""``markerplan fit-error-model``: fit sigma(distance, angle) and the 95 % envelope from marker
tables; writes model.json and optionally a diagnostics PNG under ``--out``."""

from __future__ import annotations

from pathlib import Path

import click

from planner.cli._common import (
    SEED,
    emit_summary,
    estimator_option,
    json_option,
    out_option,
    overwrite_option,
    renamed_option,
)


@click.command("fit-error-model")
@click.argument("tables", nargs=-1, required=True,
                type=click.Path(dir_okay=False, path_type=Path))
@out_option(required=True)
@click.option("--plot", is_flag=True,
              help="Also write model.png: errors against distance, sigma and the envelope.")
@renamed_option("--resample-seed", "seed", "--seed", type=SEED, default=0, show_default=True,
                metavar="N",
                help="Seed of the cross-validation folds and the bootstrap resampling (there is "
                     "no noise to seed).")
@click.option("--bootstrap", "n_bootstrap", type=click.IntRange(0, 10_000),
              help="Bootstrap replicates for the intervals (default 40; 0 disables; at most "
                   "10000).")
@estimator_option(None, "Fit only rows of this sphere-centre estimator; required when the "
                        "tables mix estimators, as range-study output does.")
@click.option("--description", default=None,
              help="What the tables are (recorded in the model's provenance).")
@overwrite_option
@json_option
def command(tables: tuple[Path, ...], out: Path, plot: bool, seed: int,
            n_bootstrap: int | None, estimator: str | None, description: str | None,
            overwrite: bool, as_json: bool) -> None:
    """Fit the marker-centre error model from one or more marker tables (CSV).

    Uses accepted markers with a finite error_m. Predictors: distance and elevation;
    visible_fraction and point count only where cross-validation shows they help. Writes
    model.json (give it to `plan --error-model`) and, with --plot, model.png under --out.

    \b
    Example:
      markerplan fit-error-model tables/markers.csv --out model/ --plot
      markerplan fit-error-model range/markers.csv --estimator fixed-radius --out model/
    """
    from error_model.config import FitConfig
    from error_model.diagnostics import plot_diagnostics, summary_text
    from error_model.fit import fit_error_model
    from error_model.table import read_marker_tables
    from markerplan.output_folder import output_folder

    settings = {"estimator": estimator}
    if n_bootstrap is not None:
        settings["n_bootstrap"] = n_bootstrap
    with output_folder(out, overwrite, "fit-error-model", inputs=tables) as stage:
        config = FitConfig(**settings)
        table = read_marker_tables(tables)
        model = fit_error_model(table, config, seed=seed, description=description)
        model.save(stage / "model.json")
        if plot:
            plot_diagnostics(model, table, stage / "model.png")

    info = model.info
    summary = {
        "out": str(out), "model": str(out / "model.json"),
        "plot": str(out / "model.png") if plot else None,
        "rows_used": info["data"]["rows_used"], "predictors": list(model.predictors),
        "fingerprint": info["data"]["fingerprint"],
        "distance_range_m": list(model.domain.distance_range_m),
        "envelope_cv_coverage": info["cross_validation"]["envelope"]["coverage"],
        "effects": info["effects"],
    }
    emit_summary(summary, as_json, summary_text(model) + f"\nwrote {out / 'model.json'}"
                 + (f" and {out / 'model.png'}" if plot else ""))
