"""The placement map (``map.png``): hillshaded terrain, craters, stations coloured by predicted
error, chosen markers, the lines of sight each station uses, legend and scale bar.

Site frame (x to the right, y up), metres: the DEM's CRS, named on the axes, when it has one.
The figure takes the view's aspect ratio (:func:`figure_size`), and the labels are placed where
they cover no other label and no symbol (:func:`place_labels`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Above this many stations (or markers) the map leaves out their text labels.
MAX_LABELS = 30
#: Colour covering the DEM's nodata cells (no measured terrain).
NODATA_COLOUR = "#e8d9c5"
#: Label positions tried around a point, in order: distance (points) and direction (degrees,
#: counter-clockwise from +x). Beyond the first ring a thin leader line joins label and point.
LABEL_RADII_PT = (9.0, 18.0, 30.0)
LABEL_DIRECTIONS_DEG = (45.0, -45.0, 0.0, 135.0, -135.0, 180.0, 90.0, -90.0)
#: Clearance kept around each label and symbol, pixels (covers a label's rounded box).
LABEL_PAD_PX = 2.0
#: Largest side of a map figure, and the room it keeps around the axes (inches): the y axis's
#: label and ticks, the colour bar with its label, and (height) title, x label and legend.
MAX_FIGURE_IN = 9.0
AXIS_LABELS_IN = 1.0
COLOUR_BAR_IN = {"right": 1.1, "bottom": 0.5}
#: Length over thickness of the colour bar, beside the axes (``right``) or under them.
COLOUR_BAR_ASPECT = {"right": 20, "bottom": 40}
TITLE_LEGEND_IN = 1.7


def draw_plan_map(outcome, path: Path, dpi: int = 150) -> Path:
    """Draw the map of a :class:`~planner.run.PlanOutcome` into ``path`` (PNG)."""
    # lazy: pyplot takes ~1 s to import, paid only once a figure is drawn (not by a refused input)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LightSource, ListedColormap
    from matplotlib.lines import Line2D
    from matplotlib.patches import Circle, Patch, Polygon
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    inp, prob, res, cfg = outcome.inputs, outcome.problem, outcome.result, outcome.config
    dem = inp.dem
    xmin, xmax, ymin, ymax = _view(inp, prob, outcome.design)
    figsize, bar_at = figure_size(xmax - xmin, ymax - ymin)
    fig, ax = plt.subplots(figsize=figsize, dpi=dpi, layout="constrained")
    # hillshade of the DEM, cropped to the view
    gx, gy = dem.grid_xy()
    ci = (gx >= xmin - 1) & (gx <= xmax + 1)
    cj = (gy >= ymin - 1) & (gy <= ymax + 1)
    # the view is a contiguous block of cells: stride it as a view, never copy the whole DEM
    cols = slice(int(np.argmax(ci)), int(np.flatnonzero(ci)[-1]) + 1)
    rows = slice(int(np.argmax(cj)), int(np.flatnonzero(cj)[-1]) + 1)
    step = max(1, int(np.ceil(max(rows.stop - rows.start, cols.stop - cols.start) / 1200)))
    view = (slice(rows.start, rows.stop, step), slice(cols.start, cols.stop, step))
    h = dem.heights_m[view]
    ls = LightSource(azdeg=315, altdeg=35)
    # LightSource expects row 0 at the top (north); our rows run along +y, so flip and back
    shade = ls.hillshade(h[::-1], vert_exag=3.0, dx=dem.cell_size_m * step,
                         dy=dem.cell_size_m * step)[::-1]
    extent = (gx[ci][0], gx[ci][-1], gy[cj][0], gy[cj][-1])
    ax.imshow(shade, cmap="gray", origin="lower", extent=extent, vmin=0, vmax=1,
              interpolation="bilinear")
    # nodata: its filled heights are no terrain, so cover them
    nodata = ~dem.valid_mask()[view]
    if nodata.any():
        ax.imshow(np.ma.masked_where(~nodata, nodata), cmap=ListedColormap([NODATA_COLOUR]),
                  origin="lower", extent=extent, interpolation="nearest", zorder=1)
    for c in inp.craters:
        ax.add_patch(Circle(c.centre_xy_m, 0.5 * c.diameter_m, fill=False, ec="#8c6d31",
                            lw=1.0, ls="--", alpha=0.9))
    if inp.boundary_xy is not None:
        ax.add_patch(Polygon(np.asarray(inp.boundary_xy), closed=True, fill=False, ec="#1f77b4",
                             lw=1.2, ls=":"))
    for poly in inp.exclusions:
        ax.add_patch(Polygon(np.asarray(poly.exterior.coords), closed=True, fc="#d62728",
                             alpha=0.15, ec="#d62728", lw=0.8))
    design_handles = [] if outcome.design is None else draw_design(ax, outcome.design)
    # lines of sight each station uses
    for s in range(prob.n_stations):
        for j in prob.pair_site[prob.selected_pairs(s, res.selected)]:
            ax.plot([prob.station_xyz[s, 0], prob.site_xyz[j, 0]],
                    [prob.station_xyz[s, 1], prob.site_xyz[j, 1]], color="#ffbf00", lw=0.9,
                    alpha=0.8, zorder=3)
    if len(inp.as_built_ids):
        symbols = [ax.scatter(inp.as_built_xyz[:, 0], inp.as_built_xyz[:, 1], marker="x",
                              s=30, c="#444444", lw=1.0, zorder=4)]
    else:
        symbols = []
    sel = np.flatnonzero(res.selected)
    symbols.append(ax.scatter(prob.site_xyz[sel, 0], prob.site_xyz[sel, 1], s=90, c="#e41a1c",
                              edgecolors="white", linewidths=1.2, zorder=10))
    err_mm = 1e3 * res.check.error_m
    req_mm = 1e3 * cfg.requirement_m
    failing = ~res.check.ok
    sc, station_symbols = draw_stations(ax, prob.station_xyz[:, :2], err_mm, req_mm, failing)
    symbols += station_symbols
    labels = map_labels(prob.station_xyz[:, :2], prob.station_ids, err_mm,
                        [prob.site_ids[j] for j in sel], prob.site_xyz[sel, :2])
    station_colour_bar(fig, ax, sc, bar_at, failing,
                       f"predicted station error, 95 % (mm); requirement {req_mm:g} mm")
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal")
    frame = axis_frame(dem.crs)
    ax.set_xlabel(f"x (m, {frame})")
    ax.set_ylabel(f"y (m, {frame})")
    ax.ticklabel_format(useOffset=False, style="plain")  # CRS coordinates in full, no "+5e5"
    bar = _nice_125((xmax - xmin) / 5)
    scale_bar = AnchoredSizeBar(ax.transData, bar, f"{bar:g} m", "lower right", pad=0.5,
                                color="black", frameon=True, size_vertical=(ymax - ymin) / 200)
    ax.add_artist(scale_bar)
    handles = [
        Line2D([], [], marker="^", ls="", mfc="#3b528b", mec="black", ms=10,
               label="station (colour: predicted error)"),
        Line2D([], [], marker="o", ls="", mfc="#e41a1c", mec="white", ms=10,
               label=f"planned marker ({len(sel)})"),
        Line2D([], [], color="#ffbf00", lw=1.2, label="line of sight used"),
    ]
    if failing.any():
        handles.append(Line2D([], [], marker="^", ls="", mfc="none", mec="#d62728", mew=2,
                              ms=13, label="station failing the requirement"))
    if len(inp.as_built_ids):
        handles.append(Line2D([], [], marker="x", ls="", color="#444444", ms=7,
                              label=f"as-built marker ({len(inp.as_built_ids)})"))
    if inp.craters:
        handles.append(Line2D([], [], color="#8c6d31", ls="--", label="crater rim"))
    if inp.boundary_xy is not None:
        handles.append(Line2D([], [], color="#1f77b4", ls=":", label="site boundary"))
    if nodata.any():
        handles.append(Patch(fc=NODATA_COLOUR, ec="none", label="DEM nodata"))
    handles += design_handles
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4),
               fontsize=8, frameon=False)
    sol = res.solution
    ax.set_title(f"markerplan — site '{inp.site_name}': {len(sel)} markers, "
                 f"{int(res.check.ok.sum())}/{prob.n_stations} stations ≤ "
                 f"{cfg.requirement_m:g} m ({sol.status})", fontsize=11)
    place_labels(fig, ax, labels, symbols, [scale_bar])
    path = Path(path)
    fig.savefig(path, dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    return path


def draw_design(ax, design) -> list:
    """Draw a survey design's area of interest, the cells no station could cover and the
    traverse (with its start) on ``ax``; return their legend handles."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, Polygon

    for part in getattr(design.aoi, "geoms", [design.aoi]):
        ax.add_patch(Polygon(np.asarray(part.exterior.coords), closed=True, fill=False,
                             ec="#2ca02c", lw=1.4, ls="-", zorder=2))
    handles = [Line2D([], [], color="#2ca02c", lw=1.4, label="area of interest")]
    if len(design.uncoverable):
        xy = design.grid.centre_xy_m[design.uncoverable.cell]
        ax.scatter(xy[:, 0], xy[:, 1], marker="s", s=12, c="#9467bd", lw=0, zorder=2)
        handles.append(Patch(fc="#9467bd", ec="none",
                             label=f"cell no station can cover ({len(design.uncoverable)})"))
    line = design.route.polyline
    ax.plot(line[:, 0], line[:, 1], color="#08306b", lw=1.3, alpha=0.85, zorder=5)
    ax.scatter(*design.route_start_xy, marker="*", s=180, c="#08306b", edgecolors="white",
               zorder=11)
    handles += [Line2D([], [], color="#08306b", lw=1.3,
                       label=f"traverse ({design.route.length_m:.0f} m)"),
                Line2D([], [], marker="*", ls="", mfc="#08306b", mec="white", ms=13,
                       label="route start and end")]
    return handles


def axis_frame(crs: str | None) -> str:
    """The frame named on a map's axes: the DEM's CRS by name, or the local site frame.

    >>> axis_frame(None)
    'site frame — local metres'
    """
    from planner.outputs.gis import crs_name

    return "site frame — local metres" if crs is None else crs_name(crs)


#: Text style of a station's label (id and error) and of a marker's label (id).
STATION_LABEL_STYLE = {"fontsize": 8, "weight": "bold", "zorder": 11,
                       "bbox": {"boxstyle": "round,pad=0.15", "fc": "white", "alpha": 0.7,
                                "lw": 0}}
MARKER_LABEL_STYLE = {"fontsize": 8, "color": "#e41a1c", "weight": "bold", "zorder": 11}


def draw_stations(ax, xy: np.ndarray, error_mm: np.ndarray, requirement_mm: float,
                  failing: np.ndarray):
    """Stations as triangles coloured by their 95 % error (viridis from 0 to the requirement,
    or tighter when every station is far inside it), failing ones ringed in red.

    Parameters
    ----------
    ax : matplotlib Axes
    xy : (s, 2) float
        Station positions, site frame, m.
    error_mm : (s,) float
        95 % station errors, mm (non-finite: unregistrable).
    requirement_mm : float
    failing : (s,) bool

    Returns
    -------
    scatter : PathCollection
        The triangles, for the colour bar.
    symbols : list of PathCollection
        Everything drawn (triangles and rings), for :func:`place_labels`.
    """
    from matplotlib.colors import Normalize

    finite = error_mm[np.isfinite(error_mm)]
    # colour range: up to the requirement, or tighter when every station is far inside it, so
    # that stations stay distinguishable (their errors are also written beside them)
    top = (requirement_mm if not finite.size else
           min(requirement_mm, _nice_125(1.2 * finite.max(), up=True)))
    sc = ax.scatter(xy[:, 0], xy[:, 1],
                    c=np.where(np.isfinite(error_mm), error_mm, 2 * requirement_mm),
                    cmap="viridis", norm=Normalize(vmin=0.0, vmax=top), marker="^", s=140,
                    edgecolors="black", linewidths=0.8, zorder=8)
    symbols = [sc]
    if failing.any():
        symbols.append(ax.scatter(xy[failing, 0], xy[failing, 1], marker="^", s=320,
                                  facecolors="none", edgecolors="#d62728", linewidths=2.0,
                                  zorder=8))
    return sc, symbols


def station_labels(xy: np.ndarray, ids, error_mm: np.ndarray) -> list[tuple]:
    """One :func:`place_labels` label per station: its id and error in mm (or
    ``unregistrable``), in :data:`STATION_LABEL_STYLE`.

    >>> station_labels(np.zeros((2, 2)), ["S1", "S2"], np.array([12.4, np.inf]))[1][0]
    'S2 unregistrable'
    """
    return [(f"{ids[s]} {error_mm[s]:.0f} mm" if np.isfinite(error_mm[s])
             else f"{ids[s]} unregistrable", xy[s], STATION_LABEL_STYLE)
            for s in range(len(ids))]


def map_labels(station_xy: np.ndarray, station_ids, error_mm: np.ndarray, marker_ids,
               marker_xy: np.ndarray, marker_style: dict = MARKER_LABEL_STYLE) -> list[tuple]:
    """The :func:`place_labels` labels of a map: the stations' (:func:`station_labels`), then
    the markers' ids in ``marker_style``; either group is left out above :data:`MAX_LABELS`
    (ids beside every symbol read well up to a few dozen; beyond that they hide the map, and the
    colour and the CSV tables carry the same information).

    Parameters
    ----------
    station_xy : (s, 2) float
    station_ids : sequence of str
    error_mm : (s,) float
        Each station's error, mm.
    marker_ids : sequence of str
    marker_xy : (k, 2) float
        Site frame, m.
    marker_style : dict
        Text properties of the marker labels.

    Returns
    -------
    labels : list of (text, (2,) float, dict)
    """
    labels = (station_labels(station_xy, station_ids, error_mm)
              if len(station_ids) <= MAX_LABELS else [])
    if len(marker_ids) <= MAX_LABELS:
        labels += [(m, xy, marker_style) for m, xy in zip(marker_ids, marker_xy, strict=True)]
    return labels


def station_colour_bar(fig, ax, scatter, bar_at: str, failing: np.ndarray, label: str):
    """The colour bar of the stations' error, at ``bar_at`` (:func:`figure_size`), extended
    upwards when a station fails the requirement.

    Returns
    -------
    colorbar : matplotlib.colorbar.Colorbar
    """
    cb = fig.colorbar(scatter, ax=ax, shrink=0.8, pad=0.01, location=bar_at,
                      aspect=COLOUR_BAR_ASPECT[bar_at],
                      extend="max" if failing.any() else "neither")
    cb.set_label(label)
    return cb


def figure_size(width_m: float, height_m: float, extra_height_in: float = TITLE_LEGEND_IN
                ) -> tuple[tuple[float, float], str]:
    """Figure size (inches) whose axes take the view's aspect ratio, and where the colour bar
    goes: ``"right"`` or, when that leaves the axes larger, ``"bottom"`` (wide views).

    The axes' larger side is as large as :data:`MAX_FIGURE_IN` allows after the room for the
    axis labels (:data:`AXIS_LABELS_IN`), the colour bar (:data:`COLOUR_BAR_IN`, its width
    beside the axes or its height under them) and ``extra_height_in`` (title, x label,
    legend).

    >>> figure_size(40.0, 40.0), figure_size(40.0, 10.0)
    (((9.0, 8.6), 'right'), ((9.0, 4.2), 'bottom'))
    """
    ratio = width_m / max(height_m, 1e-9)
    best = None
    for where, extra_w, extra_h in (
            ("right", AXIS_LABELS_IN + COLOUR_BAR_IN["right"], extra_height_in),
            ("bottom", AXIS_LABELS_IN, extra_height_in + COLOUR_BAR_IN["bottom"])):
        axes_w = min(MAX_FIGURE_IN - extra_w, (MAX_FIGURE_IN - extra_h) * ratio)
        size = (round(axes_w + extra_w, 2), round(axes_w / ratio + extra_h, 2))
        if best is None or axes_w > best[0]:
            best = (axes_w, size, where)
    return best[1], best[2]


def symbol_boxes(ax, collection) -> list:
    """Display-space boxes (pixels) of the markers of a scatter ``collection``: a square of
    the marker's size plus its edge line around each point."""
    from matplotlib.transforms import Bbox

    xy = ax.transData.transform(collection.get_offsets())
    sizes = np.broadcast_to(collection.get_sizes(), (len(xy),))
    widths = np.broadcast_to(collection.get_linewidths(), (len(xy),))
    px = ax.figure.dpi / 72.0
    half = 0.5 * (np.sqrt(sizes) + widths) * px
    return [Bbox.from_extents(x - h, y - h, x + h, y + h)
            for (x, y), h in zip(xy, half, strict=True)]


def label_offsets() -> list[tuple[float, float, str, str]]:
    """The tried offsets (points) with the text's alignment there, nearest first:
    :data:`LABEL_RADII_PT` x :data:`LABEL_DIRECTIONS_DEG`.

    >>> label_offsets()[0]
    (6.36, 6.36, 'left', 'bottom')
    """
    out = []
    for r in LABEL_RADII_PT:
        for a in np.radians(LABEL_DIRECTIONS_DEG):
            c, s = np.cos(a), np.sin(a)
            out.append((round(float(r * c), 2), round(float(r * s), 2),
                        "left" if c > 0.3 else "right" if c < -0.3 else "center",
                        "bottom" if s > 0.3 else "top" if s < -0.3 else "center"))
    return out


def place_labels(fig, ax, labels: list[tuple], symbols: list, obstacles: list = ()) -> list:
    """Write each label beside its point where its text covers no label placed before it, no
    symbol and no obstacle, inside the axes; a label that fits nowhere is left out.

    Tries :func:`label_offsets` in order (greedy, so the same figure gives the same
    placement); beyond the first ring a thin leader line joins label and point. Freezes the
    figure's layout first (the boxes are measured in it).

    Parameters
    ----------
    fig, ax : matplotlib Figure and Axes
        Drawn completely except for the labels.
    labels : list of (str, (x, y), dict)
        Text, point (data coordinates) and text style, in order of priority.
    symbols : list of PathCollection
        Scatters whose markers no label may cover (:func:`symbol_boxes`).
    obstacles : list of Artist
        Further artists no label may cover (e.g. the scale bar).

    Returns
    -------
    placed : list of Annotation
        The labels drawn (gid ``"label"``).
    """
    fig.canvas.draw()
    fig.set_layout_engine("none")
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    taken = [b.padded(LABEL_PAD_PX) for sc in symbols for b in symbol_boxes(ax, sc)]
    taken += [a.get_window_extent(renderer).padded(LABEL_PAD_PX) for a in obstacles]
    placed = []
    first_ring = len(LABEL_DIRECTIONS_DEG)
    for text, xy, style in labels:
        for k, (dx, dy, ha, va) in enumerate(label_offsets()):
            ann = ax.annotate(text, xy, xytext=(dx, dy), textcoords="offset points", ha=ha,
                              va=va, gid="label", **style)
            box = ann.get_window_extent(renderer).padded(LABEL_PAD_PX)
            inside = (box.x0 >= frame.x0 and box.y0 >= frame.y0 and box.x1 <= frame.x1
                      and box.y1 <= frame.y1)
            if inside and not any(box.overlaps(t) for t in taken):
                taken.append(box)
                placed.append(ann)
                if k >= first_ring:
                    ax.annotate("", xy, xytext=(dx, dy), textcoords="offset points",
                                arrowprops={"arrowstyle": "-", "lw": 0.5, "shrinkA": 0,
                                            "shrinkB": 0, "color": style.get("color", "black")},
                                zorder=style["zorder"] - 1)
                break
            ann.remove()
    return placed


def _view(inp, prob, design=None) -> tuple[float, float, float, float]:
    pts = [prob.station_xyz[:, :2]]
    if design is not None:
        pts += [design.route.polyline, np.array(design.aoi.bounds).reshape(2, 2)]
    if inp.boundary_xy is not None:
        pts.append(np.asarray(inp.boundary_xy))
    else:
        pts.append(prob.site_xyz[:, :2])
    p = np.vstack(pts)
    pad = 0.05 * max(np.ptp(p[:, 0]), np.ptp(p[:, 1]), 1.0)
    xmin, xmax, ymin, ymax = inp.dem.extent()
    return (max(p[:, 0].min() - pad, xmin), min(p[:, 0].max() + pad, xmax),
            max(p[:, 1].min() - pad, ymin), min(p[:, 1].max() + pad, ymax))


def _nice_125(x: float, up: bool = False) -> float:
    """Largest 1-2-5 x 10^k not above ``x`` (> 0), or with ``up`` the smallest not below it.

    >>> _nice_125(7.3), _nice_125(7.3, up=True), _nice_125(20.0), _nice_125(11.0, up=True)
    (5.0, 10.0, 20.0, 20.0)
    """
    k = 10 ** np.floor(np.log10(x))
    steps = [m * k for m in (1, 2, 5, 10)]
    return float(min(v for v in steps if v >= x) if up else max(v for v in steps if v <= x))
