"""The files of ``markerplan calibrate-sensor``: the fitted profile, the numbers, a report and a
plot (:func:`write_calibration`)."""

from __future__ import annotations

import json
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from markerplan.provenance import provenance
from markerplan.writing import json_default, write_csv
from planner.studies.sensor_calibration import CalibrationResult, emulate
from visibility.sensor_profile import save_profile

FILES = ("sensor_profile.json", "calibration.json", "runs.csv", "report.md", "calibration.png")


def calibration_record(result: CalibrationResult) -> dict:
    """The calibration block stored in the profile and in ``calibration.json``."""
    return {
        "free": [asdict(f) for f in result.free],
        "values": result.values, "standard_errors": result.sigmas,
        "at_bound": result.at_bound, "chi2": result.chi2, "dof": result.dof,
        "correlation": result.correlation, "jacobian_condition": result.jacobian_condition,
        "predictions": result.predictions,
        "measured_m": result.measured,
        "confirmation": result.confirmation, "holdout": result.holdout,
        "emulator": result.emulator, "settings": asdict(result.settings),
        "warnings": result.warnings,
    }


def write_calibration(result: CalibrationResult, folder: Path, config: dict) -> dict:
    """Write :data:`FILES` into ``folder``.

    Parameters
    ----------
    result : CalibrationResult
    folder : Path
        Existing, empty folder.
    config : dict
        The command's resolved configuration (recorded in every file's provenance).

    Returns
    -------
    record : dict
        The content of ``calibration.json``.
    """
    folder = Path(folder)
    record = calibration_record(result)
    prov = provenance(config, command="calibrate-sensor")
    save_profile(replace(result.profile, calibration=record), folder / "sensor_profile.json",
                 prov)
    (folder / "calibration.json").write_text(
        json.dumps({**record, "provenance": prov}, indent=1, sort_keys=True,
                   default=json_default) + "\n")
    names = [f.name for f in result.free]
    write_csv(folder / "runs.csv", (*names, "position", "replicate", "statistic_m",
                                    "n_accepted", "n_markers"), result.runs)
    (folder / "report.md").write_text(report_markdown(result, config))
    _plot(result, folder / "calibration.png")
    return record


def report_markdown(result: CalibrationResult, config: dict) -> str:
    """A short Markdown report: fitted values, per-position ratios, hold-out."""
    lines = ["# Sensor calibration", "",
             f"Profile `{result.profile.name}` fitted to {len(result.measured)} position(s) of "
             f"`{config.get('data')}`; base profile `{config.get('base_profile')}`.", "",
             "| parameter | fitted | standard error | searched |", "|---|---|---|---|"]
    for f in result.free:
        flag = " (at the bound: widen the range)" if f.name in result.at_bound else ""
        lines.append(f"| {f.name} | {result.values[f.name]:.6g}{flag} | "
                     f"{result.sigmas[f.name]:.2g} | {f.low:g}-{f.high:g} |")
    lines += ["", f"chi^2 = {result.chi2:.2f} on {result.dof} degree(s) of freedom.", ""]
    if len(result.free) > 1:
        lines += [f"Correlation of the fitted parameters {result.correlation[0][1]:+.3f}; "
                  f"condition number of the Jacobian (unit-norm columns) "
                  f"{result.jacobian_condition:.3g}.", ""]
    lines += ["## Fitted statistic with its 95 % interval for one field measurement", "",
              "| position | measured mm | fitted mm | 95 % interval mm |", "|---|---|---|---|"]
    for p in result.predictions:
        lo, hi = p["interval95_m"]
        lines.append(f"| {p['position']} | {p['measured_m'] * 1e3:.2f} | "
                     f"{p['emulated_m'] * 1e3:.2f} | {lo * 1e3:.2f}-{hi * 1e3:.2f} |")
    lines += ["",
              "## Predicted against measured (fresh seeds)", "",
              "| position | measured mm | predicted mm | ratio | accepted markers |",
              "|---|---|---|---|---|"]
    for c in result.confirmation:
        lines.append(_ratio_row(c))
    if result.holdout:
        lines += ["", "## Hold-out: fit on the other positions, predict this one", "",
                  "| position | measured mm | predicted mm | ratio | accepted markers | "
                  "fitted values |", "|---|---|---|---|---|---|"]
        for h in result.holdout:
            values = ", ".join(f"{k} {v:.4g}" for k, v in h["values"].items())
            lines.append(_ratio_row(h) + f" {values} |")
    worst = max(e["max_rel_misfit"] for e in result.emulator)
    lines += ["", f"Emulator (s^2 = a + sum b p^2 per position): largest relative misfit on the "
              f"design {worst:.1%}."]
    lines += ["", *[f"**Warning:** {w}." for w in result.warnings]] if result.warnings else []
    return "\n".join(lines) + "\n"


def _ratio_row(c: dict) -> str:
    accepted = "/".join(str(a) for a in c["n_accepted"])
    if c["predicted_m"] is None:
        predicted = "none (no markers accepted) | -"
    else:
        predicted = f"{c['predicted_m'] * 1e3:.2f} | {c['ratio']:.2f}"
    return (f"| {c['position']} | {c['measured_m'] * 1e3:.2f} | {predicted} | {accepted} of "
            f"{c['n_markers']} |")


def _plot(result: CalibrationResult, path: Path) -> None:
    """Statistic against the (first) free parameter per position: runs, emulator, measured."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    first = result.free[0]
    fixed = {f.name: result.values[f.name] for f in result.free[1:]}
    grid = np.linspace(first.low, first.high, 100)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for k, e in enumerate(result.emulator):
        colour = f"C{k}"
        runs = [r for r in result.runs if r["position"] == e["position"]
                and all(np.isclose(r[n], v) for n, v in fixed.items())]
        ax.plot([r[first.name] for r in runs], [r["statistic_m"] * 1e3 for r in runs], "o",
                color=colour, alpha=0.6)
        ax.plot(grid, [emulate(e, {first.name: g, **fixed}) * 1e3 for g in grid], "-",
                color=colour, label=f"position {e['position']}")
        ax.axhline(result.measured[e["position"]] * 1e3, color=colour, ls=":")
    ax.axvline(result.values[first.name], color="k", lw=1)
    ax.axvspan(result.values[first.name] - result.sigmas[first.name],
               result.values[first.name] + result.sigmas[first.name], color="k", alpha=0.1)
    ax.set_xlabel(first.name)
    ax.set_ylabel("mean |edge residual|, mm")
    ax.set_title("Simulated runs (dots), emulator (lines), measured (dotted); fit +- 1 s.e.")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120, metadata={"Software": None})
    plt.close(fig)
