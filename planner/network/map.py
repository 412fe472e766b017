"""The network map (``network.png``) of ``markerplan adjust``: stations coloured by their 95 %
station error, markers, the ties (one line per kept observation; removed ones dashed red), and
every point's 95 % horizontal error ellipse drawn to scale, enlarged by one stated factor.

Site frame, metres (x to the right, y up), the style of the plan's map
(:mod:`planner.outputs.plan_map`): a figure of the view's aspect ratio, labels that cover no
other label and no symbol.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from planner.outputs.plan_map import (
    _nice_125,
    axis_frame,
    draw_stations,
    figure_size,
    map_labels,
    place_labels,
    station_colour_bar,
)

#: The largest ellipse is drawn at about this fraction of the map's width.
ELLIPSE_FRACTION = 0.06
#: Room above and below the axes, inches: the two-line title, the x label and the legend's rows.
TITLE_LEGEND_IN = 2.1
#: Text style of a marker's label.
MARKER_LABEL_STYLE = {"fontsize": 7, "color": "#b2182b", "zorder": 10}


def exaggeration(largest_semi_axis_m: float, extent_m: float) -> float:
    """Factor (1-2-5 x 10^k, >= 1) by which ellipses are enlarged on the map, so the largest
    reaches about :data:`ELLIPSE_FRACTION` of the map's extent.

    Examples
    --------
    >>> exaggeration(0.02, 100.0), exaggeration(5.0, 100.0), exaggeration(0.0, 100.0)
    (200.0, 1.0, 1.0)
    """
    if largest_semi_axis_m <= 0.0:
        return 1.0
    return max(1.0, _nice_125(ELLIPSE_FRACTION * extent_m / largest_semi_axis_m))


def draw_network_map(run, stations: list[dict], markers: list[dict], observations: list[dict],
                     path: Path, dpi: int = 150) -> Path:
    """Draw the map of an adjustment into ``path`` (PNG).

    Parameters
    ----------
    run : planner.network.record.AdjustmentRun
        Gives the covariances (ellipses), the datum and the requirement.
    stations, markers, observations : list of dict
        Rows of :mod:`planner.network.record` (positions, station errors, tie status).
    path : Path
    dpi : int

    Returns
    -------
    path : Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Ellipse
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    from planner.network.record import horizontal_ellipse

    res = run.result
    s_xy = np.array([[s["x_m"], s["y_m"]] for s in stations]).reshape(-1, 2)
    m_xy = np.array([[m["x_m"], m["y_m"]] for m in markers]).reshape(-1, 2)
    s_index = {s["station_id"]: i for i, s in enumerate(stations)}
    m_index = {m["marker_id"]: j for j, m in enumerate(markers)}
    pts = np.vstack([s_xy, m_xy])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    extent = float(max(hi[0] - lo[0], hi[1] - lo[1], 1.0))
    pad = 0.06 * extent
    ellipses = ([horizontal_ellipse(res.station_covariance(i)[:3, :3])
                 for i in range(len(stations))],
                [horizontal_ellipse(res.marker_covariance(j)) for j in range(len(markers))])
    largest = max((e[0] for group in ellipses for e in group), default=0.0)
    factor = exaggeration(largest, extent)

    xlim = (lo[0] - pad, hi[0] + pad)
    ylim = (lo[1] - 2 * pad, hi[1] + pad)  # room for the scale bars
    figsize, bar_at = figure_size(xlim[1] - xlim[0], ylim[1] - ylim[0], TITLE_LEGEND_IN)
    fig, ax = plt.subplots(figsize=figsize, dpi=dpi, layout="constrained")
    ties = {"kept": [], "removed": []}
    for o in observations:
        i, j = s_index.get(o["station_id"]), m_index.get(o["marker_id"])
        if i is not None and j is not None:
            ties["removed" if o["status"] == "removed" else "kept"].append((s_xy[i], m_xy[j]))
    ax.add_collection(LineCollection(ties["kept"], colors="#ffbf00", linewidths=0.8, alpha=0.7,
                                     zorder=3))
    ax.add_collection(LineCollection(ties["removed"], colors="#d62728", linestyles="--",
                                     linewidths=1.4, alpha=0.9, zorder=4))
    for group, xy, colour in ((ellipses[0], s_xy, "#1f3b73"), (ellipses[1], m_xy, "#e41a1c")):
        for (a, b, angle), (x, y) in zip(group, xy, strict=True):
            ax.add_patch(Ellipse((x, y), 2 * a * factor, 2 * b * factor, angle=angle,
                                 fill=False, ec=colour, lw=1.0, zorder=6))
    control = [m["control"] for m in markers]
    symbols = [ax.scatter(m_xy[:, 0], m_xy[:, 1], s=36,
                          c=["#7b3294" if c else "#e41a1c" for c in control], marker="o",
                          edgecolors="white", linewidths=0.8, zorder=7)]
    err_mm = np.array([1e3 * s["station_error_95_m"] for s in stations])
    req_mm = 1e3 * run.requirement_m
    failing = np.array([not s["meets_requirement"] for s in stations], dtype=bool)
    sc, station_symbols = draw_stations(ax, s_xy, err_mm, req_mm, failing)
    symbols += station_symbols
    ref = [i for i, s in enumerate(stations) if s["reference"]]
    if ref:
        symbols.append(ax.scatter(s_xy[ref, 0], s_xy[ref, 1], marker="s", s=260,
                                  facecolors="none", edgecolors="black", linewidths=1.6,
                                  zorder=9))
    labels = map_labels(s_xy, [s["station_id"] for s in stations], err_mm,
                        [m["marker_id"] for m in markers], m_xy, MARKER_LABEL_STYLE)
    station_colour_bar(fig, ax, sc, bar_at, failing,
                       f"station error, 95 % over {run.working_radius_m:g} m (mm); "
                       f"requirement {req_mm:g} mm")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    frame = "site frame" if run.crs is None else axis_frame(run.crs)
    ax.set_xlabel(f"x (m, {frame})")
    ax.set_ylabel(f"y (m, {frame})")
    bar = _nice_125(extent / 5)
    ell_bar = _nice_125(2.0 * largest) if largest > 0.0 else bar  # the largest axis
    bars = [AnchoredSizeBar(ax.transData, bar, f"{bar:g} m (positions)", "lower right",
                            pad=0.5, color="black", frameon=True, size_vertical=extent / 300),
            AnchoredSizeBar(ax.transData, ell_bar * factor,
                            f"{1e3 * ell_bar:g} mm (ellipses, ×{factor:g})", "lower left",
                            pad=0.5, color="#1f3b73", frameon=True, size_vertical=extent / 300)]
    for b in bars:
        ax.add_artist(b)
    handles = [
        Line2D([], [], marker="^", ls="", mfc="#3b528b", mec="black", ms=10,
               label="station (colour: station error)"),
        Line2D([], [], marker="o", ls="", mfc="#e41a1c", mec="white", ms=8,
               label=f"marker ({len(markers)})"),
        Line2D([], [], color="#ffbf00", lw=1.2, label="tie (kept observation)"),
        Line2D([], [], color="#1f3b73", lw=1.0,
               label=f"95 % horizontal error ellipse ×{factor:g} (station blue, marker red)"),
    ]
    if ref:
        handles.append(Line2D([], [], marker="s", ls="", mfc="none", mec="black", ms=12,
                              label="datum: reference station"))
    if any(control):
        handles.append(Line2D([], [], marker="o", ls="", mfc="#7b3294", mec="white", ms=8,
                              label="control point"))
    if ties["removed"]:
        handles.append(Line2D([], [], color="#d62728", ls="--", lw=1.4,
                              label="removed by data snooping"))
    if failing.any():
        handles.append(Line2D([], [], marker="^", ls="", mfc="none", mec="#d62728", mew=2,
                              ms=13, label="station failing the requirement"))
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 3),
               fontsize=8, frameon=False)
    n_ok = int((~failing).sum())
    ax.set_title(f"markerplan adjust — {len(stations)} stations, {len(markers)} markers; "
                 f"{n_ok}/{len(stations)} ≤ {run.requirement_m:g} m\n"
                 f"datum: {res.datum.describe(res.observations.station_ids)}; "
                 f"ellipses 95 % ×{factor:g}", fontsize=10)
    place_labels(fig, ax, labels, symbols, bars)
    path = Path(path)
    fig.savefig(path, dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    return path
