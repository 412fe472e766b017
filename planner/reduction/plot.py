"""``tradeoff.png``: markers kept against worst-station and mean predicted error, the requirement
line, the drop order for comparison and, after ``--verify``, the achieved errors beside the
predicted ones. Reads a ``reduce.json`` document."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_tradeoff(doc: dict, path: str | Path) -> Path:
    """Write the trade-off figure of a ``reduce.json`` document.

    Parameters
    ----------
    doc : dict
        ``reduce.json`` document.
    path : str or Path
        PNG to write.

    Returns
    -------
    path : Path
    """
    # lazy: pyplot takes ~1 s to import, paid only once a figure is drawn (not by a refused input)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    curve = doc["curve"]
    req = doc["requirement"]["requirement_m"]
    verify = doc.get("verify")
    ncols = 2 if verify else 1
    fig, axes = plt.subplots(1, ncols, figsize=(7.5 * ncols, 4.8), squeeze=False)
    ax = axes[0, 0]
    k = [p["k"] for p in curve]
    cm = [100 * (p["worst_error_m"] or float("nan")) for p in curve]
    mean = [100 * (p["mean_error_m"] or float("nan")) for p in curve]
    network = "network" in doc
    ax.plot(k, cm, "o-", color="C3", label=("worst station or kept marker" if network else
                                            "worst station") + " (minimax optimum)")
    ax.plot(k, mean, "s--", color="C0", label="mean over stations (same subsets)")
    unproven = [i for i, p in enumerate(curve) if not p["proven_optimal"]]
    if unproven:
        ax.plot([k[i] for i in unproven], [cm[i] for i in unproven], "o", mfc="white",
                color="C3", ms=11, label="time limit: not proven optimal")
    fail = [i for i, p in enumerate(curve) if not p["meets_requirement"]]
    if fail:
        ax.plot([k[i] for i in fail], [cm[i] for i in fail], "x", color="k", ms=10, mew=2,
                label="some station fails (error or directions)")
    drop = doc.get("drop_order", [])
    if drop:
        ax.plot([d["k"] for d in drop], [100 * d["worst_error_m"] for d in drop], ":",
                color="0.4", label="drop order, worst " + ("station or kept marker" if network
                                                           else "station") + " (nested)")
    ax.axhline(100 * req, color="k", lw=1.2, ls="-.", label=f"requirement {100 * req:g} cm")
    if doc["k_feasible"] is not None:
        ax.axvline(doc["k_feasible"], color="C2", lw=1, alpha=0.6,
                   label=f"fewest markers meeting it: {doc['k_feasible']}")
    if verify:
        done = [v for v in verify["points"] if v["achieved_worst_error_m"] is not None]
        ax.plot([v["k"] for v in done], [100 * v["achieved_worst_error_m"] for v in done], "D",
                color="C1", ms=8, label="achieved worst (simulator + pipeline)")
    ax.set_xlabel("markers kept")
    _log_error_axis(ax, "predicted 95 % error relative to the datum (cm, log scale)"
                    if network else "predicted 95 % station error (cm, log scale)")
    ax.invert_xaxis()
    ax.set_xticks(k)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    from planner.reduction.report import accuracy_mode

    ax.set_title(f"site {doc['site']['name']}: {doc['layout']['n_markers']} markers "
                 f"({doc['layout']['mode']}; {accuracy_mode(doc)})")
    if verify:
        _plot_verify(axes[0, 1], verify, req)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _log_error_axis(ax, label: str) -> None:
    """Log-scale error axis with plain-number ticks: errors of a few millimetres and the 10 cm
    requirement line stay readable in one panel."""
    # lazy, as in plot_tradeoff: only when a figure is drawn
    from matplotlib.ticker import FuncFormatter

    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.yaxis.set_minor_formatter(FuncFormatter(
        lambda v, _: f"{v:g}" if round(v / 10 ** np.floor(np.log10(v))) in (2, 5) else ""))
    ax.set_ylabel(label)


def _plot_verify(ax, verify: dict, req: float) -> None:
    pts = verify["points"]
    stations = [s["id"] for s in pts[0]["stations"]]
    x = np.arange(len(stations))
    width = 0.8 / (2 * len(pts))
    for i, v in enumerate(pts):
        pred = [100 * (s["predicted_error_m"] or np.nan) for s in v["stations"]]
        ach = [100 * (s["achieved_error_m"] if s["achieved_error_m"] is not None else np.nan)
               for s in v["stations"]]
        off = (2 * i - len(pts)) * width
        ax.bar(x + off, pred, width, color=f"C{i}", alpha=0.45,
               label=f"{v['k']} markers: predicted")
        ax.bar(x + off + width, ach, width, color=f"C{i}", hatch="//", edgecolor="k",
               label=f"{v['k']} markers: achieved")
    ax.axhline(100 * req, color="k", lw=1.2, ls="-.")
    ax.set_xticks(x, stations)
    _log_error_axis(ax, "station error (cm, log scale)")
    ax.set_title("verification: achieved beside predicted")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="y")
