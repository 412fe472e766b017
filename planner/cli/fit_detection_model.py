"""``markerplan fit-detection-model``: fit P(a planned marker is detected and accepted) from
fate tables; writes detection_model.json and, with ``--plot``, its calibration PNG."""

from __future__ import annotations

from pathlib import Path

import click

from planner.cli._common import emit_summary, json_option, out_option, overwrite_option


@click.command("fit-detection-model")
@click.argument("tables", nargs=-1, required=True,
                type=click.Path(dir_okay=False, path_type=Path))
@out_option(required=True)
@click.option("--folds", type=click.IntRange(2, 100), default=5, show_default=True,
              help="Held-out folds over the scans for the calibration figures (2-100).")
@click.option("--plot", is_flag=True,
              help="Also write calibration.png: the held-out reliability diagram and the "
                   "acceptance against distance.")
@click.option("--description", default=None,
              help="What the tables are (recorded in the model's provenance).")
@overwrite_option
@json_option
def command(tables: tuple[Path, ...], out: Path, folds: int, plot: bool,
            description: str | None, overwrite: bool, as_json: bool) -> None:
    """Fit the detection model from one or more fate tables (CSV: one row per known marker in
    range of a scan, the stage of the chain that lost it or `accepted`, and the planner's
    covariates of the pair; `benchmarks/loss_study.py --csv` writes them from simulated scans
    run through the full chain).

    A logistic model in log distance (with hinges at 3, 15 and 30 m), log expected points,
    visible fraction, terrain slope and crater-rim distance. Its calibration is measured on
    held-out scans (each scan's rows kept in one fold) and recorded in detection_model.json:
    Brier scores (in sample, held out, and of the constant base rate) and the reliability table.

    \b
    Example:
      python benchmarks/loss_study.py --layout default --seeds 8 --csv losses.csv
      markerplan fit-detection-model losses.csv --out detection/ --plot
    """
    from error_model.detection import fit_from_fate_tables, plot_calibration
    from markerplan.output_folder import output_folder
    from pipeline.tables.fate_table import read_fate_tables

    with output_folder(out, overwrite, "fit-detection-model", inputs=tables) as stage:
        table = read_fate_tables(tables)
        model = fit_from_fate_tables(table, folds, description=description)
        model.save(stage / "detection_model.json")
        if plot:
            plot_calibration(model, table, stage / "calibration.png")
    data, cal = model.info["data"], model.info["calibration"]
    summary = {"out": str(out), "model": str(out / "detection_model.json"),
               "plot": str(out / "calibration.png") if plot else None,
               "rows": data["rows"], "scans": data["scans"],
               "accepted_rate": data["accepted_rate"],
               "brier_held_out": cal["brier_held_out"],
               "brier_base_rate": cal["brier_base_rate"],
               "reliability_held_out": cal["reliability_held_out"]}
    emit_summary(summary, as_json,
                 f"detection model from {data['rows']} marker fates in {data['scans']} scans: "
                 f"accepted {data['accepted_rate']:.3f}, held-out Brier "
                 f"{cal['brier_held_out']:.4f} (base rate {cal['brier_base_rate']:.4f})\n"
                 f"wrote {out / 'detection_model.json'}"
                 + (f" and {out / 'calibration.png'}" if plot else ""))
