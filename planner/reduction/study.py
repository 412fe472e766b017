"""A marker-reduction study on a site: the layout, its integer-program input and the three studies.

The layout comes from a plan (``plan.json``), a markers CSV (``id, x_m, y_m[, z_m]``, site
frame) or the site preset's as-built layout (``"as-built"``), on the site inputs of
:func:`planner.problem.inputs.load_inputs`. :func:`layout_problem` ray-casts the stations against
the layout's markers (:func:`planner.problem.sight.sight_problem`, as a plan does) or, with
``free``, against every candidate site plus the layout (:func:`planner.run.build_problem`); the
studies are :mod:`planner.reduction.curve`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import shapely

from markerplan.errors import DataError, InputFileError
from planner.config import PlanConfig, config_from_dict
from planner.outputs import plan_file
from planner.problem.inputs import known_ids, load_inputs, read_markers
from planner.problem.sight import sight_problem
from planner.problem.usability import PlanProblem
from planner.reduction.curve import Curve, tradeoff_curve
from planner.reduction.losses import DropStep, MarkerLoss, drop_order, marker_losses
from planner.run import build_problem

AS_BUILT = "as-built"


@dataclass(frozen=True)
class Layout:
    """Markers in the field, site frame.

    Attributes
    ----------
    ids : tuple of str, (m,)
    xyz : (m, 3) float
        Marker centres, m.
    source : str
        ``"as-built"``, or the file it was read from.
    control_sigma_m : dict of str -> float
        The layout's control points (a network plan's datum, ``plan --control``): id -> the
        1-sigma of each coordinate, m. They stay in every subset.
    """

    ids: tuple[str, ...]
    xyz: np.ndarray
    source: str
    control_sigma_m: dict = field(default_factory=dict)


@dataclass
class ReductionStudy:
    """Everything ``markerplan reduce`` reports.

    Attributes
    ----------
    problem : PlanProblem
        Candidate sites are the layout (or, with ``free``, every candidate site and the layout).
    config : PlanConfig
    layout : (n,) bool
        Which candidate sites are the layout's markers.
    free : bool
    curve : Curve
    drop : list of DropStep
    losses : list of MarkerLoss
    timings_s : dict
    layout_curve : Curve or None
        With ``free``: the exact curve over the layout's own markers (the free curve starts
        from it and is never worse).
    """

    problem: PlanProblem
    config: object
    layout: np.ndarray
    free: bool
    curve: Curve
    drop: list[DropStep]
    losses: list[MarkerLoss]
    timings_s: dict = field(default_factory=dict)
    layout_curve: Curve | None = None

    @property
    def n_layout(self) -> int:
        return int(self.layout.sum())

    @property
    def markers_that_can_go(self) -> int | None:
        """Layout markers that can be removed with every station still passing."""
        k = self.curve.k_feasible
        return None if k is None else self.n_layout - k


def read_layout(spec: str, inputs) -> Layout:
    """The layout named by ``spec`` on a site.

    Parameters
    ----------
    spec : str
        ``"as-built"``, a ``plan.json`` written by ``markerplan plan`` or a markers CSV.
    inputs : planner.problem.inputs.PlanInputs

    Raises
    ------
    InputFileError, DataError
        Missing or malformed file, duplicate ids, or a marker outside the site.
    """
    if spec == AS_BUILT:
        if not len(inputs.as_built_ids):
            raise InputFileError("INPUT as-built: this site has no as-built layout; give a plan "
                                 "or a markers CSV")
        layout = Layout(tuple(inputs.as_built_ids), np.asarray(inputs.as_built_xyz, float),
                        AS_BUILT)
    elif is_plan(spec):
        layout = _plan_layout(_read_plan(Path(spec)), spec)
    else:
        ids, xyz = read_markers(spec, inputs.dem, inputs.marker_radius_m, option="INPUT")
        layout = Layout(tuple(ids), xyz, str(spec))
    _inside_site_iv(layout, inputs)
    return layout


def resolve_inputs(spec: str, site_name: str | None = None, site_seed: int | None = None,
                   dem_path=None, stations_path=None, station_ids=None, boundary_path=None,
                   exclude_paths=(), marker_radius_m: float | None = None,
                   config=None, reproject: bool = False,
                   control_path=None) -> tuple[object, Layout, object]:
    """Site inputs, layout and plan configuration of a reduction study.

    A ``plan.json`` supplies its own site, terrain seed, DEM and stations files, stations,
    marker radius and configuration unless they are given here. Unless ``stations_path`` is
    given, the study is of the plan's own stations (``station_ids`` picks among them), which
    must stand on the site where the plan put them (:func:`_planned_stations`). The plan-only
    settings ``budget``, ``existing``, ``forbidden`` and ``redundant`` are reset: the study
    decides which markers stay. A plan made in network mode (``plan --network``) is studied in
    network mode, the mode its errors are for, even with another ``config``: its
    ``reference_station`` and ``heading_prior_sigma_deg`` apply unless ``config`` sets them (as
    ``verify`` follows a network plan's mode).

    Parameters
    ----------
    spec : str
        ``"as-built"``, a ``plan.json`` or a markers CSV (``id, x_m, y_m[, z_m]``).
    site_name, site_seed, dem_path, stations_path, boundary_path, exclude_paths, marker_radius_m
        As for :func:`planner.problem.inputs.load_inputs` (``site``, ``site_seed``, ...).
    station_ids : sequence of str, optional
        Only these stations (:func:`planner.problem.inputs.select_stations`; of a plan's own
        stations, those it lists).
    config : PlanConfig, optional
        Default: the plan's configuration, else ``PlanConfig()``.
    reproject : bool
        As for :func:`~planner.problem.inputs.load_inputs` (default: as the plan's DEM was read).
        The DEM is read as far as the stations see (``config.max_range_m``).
    control_path : path, optional
        A layout other than a plan: control points CSV (``id,x_m,y_m,z_m,sigma_m``,
        :func:`planner.problem.inputs.read_control_points`), network mode's datum, added to the
        layout as its control points (:attr:`Layout.control_sigma_m`; a plan records its own).

    Returns
    -------
    inputs : PlanInputs
    layout : Layout
    config : PlanConfig
    """
    plan = _read_plan(Path(spec)) if is_plan(spec) else None
    own_stations = plan is not None and stations_path is None and "stations" in plan
    chosen = own_stations and bool(plan.get("provenance", {}).get("inputs", {})
                                   .get("stations_chosen"))
    given_site = site_name
    if plan is not None:
        recorded = plan.get("provenance", {}).get("inputs", {})
        # the preset that supplied the defaults (a plan on a DEM is named after the DEM file)
        site_name = site_name or recorded.get("site") or plan.get("site", {}).get("name")
        site_seed = plan.get("site", {}).get("seed") if site_seed is None else site_seed
        if dem_path is None:
            dem_path, reproject = recorded.get("dem"), reproject or recorded.get("reproject")
        stations_path = stations_path or recorded.get("stations")
        if marker_radius_m is None:
            marker_radius_m = plan.get("site", {}).get("marker_radius_m")
        recorded = plan.get("provenance", {}).get("config", {})
        own_config = config is None
        if own_config:
            config = config_from_dict(recorded, where=f"INPUT {spec} (its configuration)")
        elif recorded.get("network") is True and not config.network:
            datum = {k: recorded[k] for k in ("reference_station", "heading_prior_sigma_deg")
                     if getattr(config, k) is None and recorded.get(k) is not None}
            config = config_from_dict({"network": True, **datum}, base=config,
                                      where=f"INPUT {spec} (its network settings)")
    config = (config or PlanConfig()).replace(budget=None, existing=(), forbidden=(),
                                              redundant=False)
    inputs = load_inputs(site_name or "default", site_seed, dem_path=dem_path,
                         stations_path=stations_path, boundary_path=boundary_path,
                         exclude_paths=exclude_paths, marker_radius_m=marker_radius_m,
                         station_ids=None if own_stations else station_ids,
                         reproject=bool(reproject),
                         sight_radius_m=None if chosen else config.max_range_m,
                         control=None if plan is not None else control_path,
                         stations_chosen=chosen)
    if plan is None:
        layout = _with_control_points(read_layout(spec, inputs), inputs.control)
        return replace(inputs, control=()), layout, config
    if chosen:
        inputs = _chosen_stations(plan, inputs, station_ids)
    elif own_stations:
        inputs = _planned_stations(plan, spec, inputs, station_ids, given_site)
    if own_config and config.odometry_loop_m is not None:
        config = config.replace(odometry_loop_m=_closing_of(plan, inputs.station_ids,
                                                            config.odometry_loop_m))
    layout = _plan_layout(plan, spec)
    _inside_site_iv(layout, inputs)
    return inputs, layout, config


#: How far a plan's station may stand from where its site puts it, m (a plan records them as
#: read; this only absorbs rounding).
STATION_MATCH_M = 1e-3


def _closing_of(plan: dict, station_ids, loop_m: float) -> float | None:
    """The closing legs' distance of the plan's closed traverse for the stations studied
    (:func:`planner.accuracy.aids.closing_distance_m`: longer when stations at its ends are
    left out); ``None`` (an open traverse) for stations that are not the plan's in its drive
    order, whose traverse the plan did not close."""
    from planner.accuracy.aids import closing_distance_m

    planned = [s["id"] for s in plan["stations"]]
    if not set(station_ids) <= set(planned):
        return None
    kept = np.array([planned.index(i) for i in station_ids])
    if kept.size < 2 or np.any(np.diff(kept) <= 0):
        return None
    xyz = np.array([[s["x_m"], s["y_m"], s["z_m"]] for s in plan["stations"]], float)
    return closing_distance_m(xyz, loop_m, kept)


def _chosen_stations(plan: dict, inputs, wanted):
    """``inputs`` with the stations a plan chose over its area of interest (``plan --aoi``),
    as the plan has them (``wanted`` of them; default all): no site or file holds them."""
    planned = {s["id"]: s for s in plan["stations"]}
    ids = list(known_ids(wanted, planned, "`station_ids`", "planned station") if wanted
               else planned)
    xyz = np.array([[planned[i]["x_m"], planned[i]["y_m"], planned[i]["z_m"]] for i in ids],
                   float).reshape(-1, 3)
    heading = np.array([planned[i].get("heading_rad") or 0.0 for i in ids], float)
    return replace(inputs, station_ids=ids, station_xyz=xyz, station_heading_rad=heading,
                   sources={**inputs.sources, "station_ids": ids})


def _planned_stations(plan: dict, spec, inputs, wanted, given_site: str | None):
    """``inputs`` for the plan's own stations (``wanted`` of them; default all it lists).

    Parameters
    ----------
    plan : dict
        A checked ``plan.json`` with ``stations``.
    spec : str
        The plan's path (for messages).
    inputs : PlanInputs
        The site read for it, with all its stations.
    wanted : sequence of str or None
        ``station_ids`` (among the plan's stations).
    given_site : str or None
        The ``site_name`` given for the study, if any (for the advice).

    Raises
    ------
    ConfigError
        A ``wanted`` id the plan lacks.
    DataError
        A plan's station the site lacks, or that it puts more than :data:`STATION_MATCH_M`
        (across) from where the plan has it: the plan was made on another site or stations.
    """
    planned = {s["id"]: (float(s["x_m"]), float(s["y_m"])) for s in plan["stations"]}
    ids = list(known_ids(wanted, planned, "`station_ids`", "planned station") if wanted
               else planned)
    recorded = plan.get("provenance", {}).get("inputs", {})
    planned_site = recorded.get("site") or plan.get("site", {}).get("name")
    where = (f"stations file {inputs.sources['stations']}" if "stations" in inputs.sources
             else f"site preset {inputs.site_name!r}")
    if given_site is not None and planned_site is not None and given_site != planned_site:
        fix = (f"the plan was made on site preset {planned_site!r}: drop `site_name` or set it "
               f"to {planned_site!r}")
    else:
        fix = ("the plan was made with other stations: re-plan, or give the stations to study "
               "with `stations_path`")
    for sid in ids:
        if sid not in inputs.station_ids:
            raise DataError(f"station {sid} of INPUT {spec} is not among the stations of "
                            f"{where}; {fix}")
        got = inputs.station_xyz[inputs.station_ids.index(sid), :2]
        x, y = planned[sid]
        if np.hypot(got[0] - x, got[1] - y) > STATION_MATCH_M:
            raise DataError(f"station {sid} of INPUT {spec} is planned at ({x:.2f}, {y:.2f}) m "
                            f"but {where} puts it at ({got[0]:.2f}, {got[1]:.2f}) m; {fix}")
    return inputs.with_stations(ids)


def _with_control_points(layout: Layout, control) -> Layout:
    """``layout`` with control points (:class:`pipeline.network.observations.ControlPoint`,
    each with its largest sigma: the planner's prior is isotropic) appended as its control
    points.

    Raises
    ------
    InputFileError
        A control point id the layout already uses.
    """
    if not control:
        return layout
    clash = sorted(set(layout.ids) & {c.marker_id for c in control})
    if clash:
        raise InputFileError(f"control point id(s) {', '.join(clash)} are also marker ids of "
                             f"INPUT {layout.source}; rename them in one of the files")
    return Layout(layout.ids + tuple(c.marker_id for c in control),
                  np.vstack([layout.xyz] + [c.xyz_m[None] for c in control]), layout.source,
                  {c.marker_id: float(c.sigma_m.max()) for c in control})


def is_plan(spec: str) -> bool:
    """Whether a layout ``spec`` (``INPUT`` of ``reduce``) names a ``plan.json`` (which brings
    its own site, DEM and stations) rather than ``"as-built"`` or a markers CSV."""
    return spec != AS_BUILT and Path(spec).suffix.lower() == ".json"


def _read_plan(path: Path) -> dict:
    """A ``plan.json`` or a hand-written layout with ``schema`` and ``markers``
    (:func:`planner.outputs.plan_file.read_plan`, ``INPUT``)."""
    return plan_file.read_plan(path, "INPUT", full=False)


def _plan_layout(data: dict, path) -> Layout:
    """The selected markers of a checked ``plan.json`` (``markers``: ``{id, x_m, y_m, z_m}``),
    with the control points of its network datum."""
    markers = data["markers"]
    ids = tuple(m["id"] for m in markers)
    xyz = np.array([[m["x_m"], m["y_m"], m["z_m"]] for m in markers], float)
    control = (data.get("network") or {}).get("datum", {}).get("control") or []
    return Layout(ids, xyz, str(path), {c["marker_id"]: float(c["sigma_m"]) for c in control})


def _inside_site_iv(layout: Layout, inputs) -> None:
    """Refuse a marker off the DEM's measured terrain or outside the site boundary (control
    points, on the lander, need only be on the DEM)."""
    xy = layout.xyz[:, :2]
    inside = inputs.dem.valid_at(xy)
    where = "the DEM's measured terrain"
    if inputs.boundary_xy is not None:
        poly = shapely.Polygon(np.asarray(inputs.boundary_xy, float))
        control = np.isin(layout.ids, list(layout.control_sigma_m))
        inside &= shapely.intersects_xy(poly, xy[:, 0], xy[:, 1]) | control
        where = "the site boundary"
    if not inside.all():
        k = int(np.flatnonzero(~inside)[0])
        raise DataError(f"marker {layout.ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m lies "
                        f"outside {where}; give markers in the site frame inside the site")


def layout_problem(inputs, layout: Layout, config, error_model, free: bool = False,
                   progress: bool = True) -> tuple[PlanProblem, np.ndarray, dict]:
    """The integer program's input for a reduction study.

    Parameters
    ----------
    inputs : planner.problem.inputs.PlanInputs
    layout : Layout
    config : PlanConfig
    error_model : ErrorModel
    free : bool
        Candidate sites are every candidate site of the planner plus the layout (else only
        the layout).
    progress : bool

    Returns
    -------
    problem : PlanProblem
        No site is marked existing: the study may drop any marker.
    layout_mask : (n,) bool
    timings_s : dict
    """
    if free:
        with_layout = replace(inputs, existing_ids=list(layout.ids), existing_xyz=layout.xyz)
        problem, _, _, timings = build_problem(with_layout, config, error_model, progress)
        problem = replace(problem, site_existing=np.zeros(problem.n_sites, bool),
                          site_cost=np.ones(problem.n_sites))
        mask = problem.site_mask(layout.ids, "layout")
        return _with_control(problem, layout), mask, timings
    sight = sight_problem(inputs, layout.ids, layout.xyz, config, error_model,
                          progress=progress)
    return (_with_control(sight.problem, layout), np.ones(sight.problem.n_sites, bool),
            sight.timings_s)


def _with_control(problem: PlanProblem, layout: Layout) -> PlanProblem:
    """``problem`` with the layout's control points (:attr:`Layout.control_sigma_m`) as its
    control sites (unchanged without any)."""
    if not layout.control_sigma_m:
        return problem
    sigma = np.array([layout.control_sigma_m.get(i, 0.0) for i in problem.site_ids])
    return replace(problem, site_control_sigma_m=sigma)


def run_study(problem: PlanProblem, config, layout: np.ndarray, free: bool = False,
              k_min: int | None = None, time_limit_s: float | None = None) -> ReductionStudy:
    """Trade-off curve (from the layout's size down), drop order and per-marker losses.

    Parameters
    ----------
    problem : PlanProblem
    config : PlanConfig
        ``existing``: markers always kept; ``forbidden``: markers never kept.
    layout : (n,) bool
    free : bool
        ``problem`` holds every candidate site, not only the layout: the curve is then optimal
        within ``tol_m`` (0.1 mm) instead of exactly, to keep the large programs tractable.
    k_min : int, optional
        Smallest count on the curve (default: the fewest meeting the direction rows).
    time_limit_s : float, optional
        Limit of the curve's integer programming, s (default ``config.time_limit_s``).
    """
    layout = np.asarray(layout, dtype=bool)
    start = layout & ~problem.site_mask(config.forbidden, "forbidden")
    n_allowed = int(start.sum())
    t = time.perf_counter()
    layout_curve = None
    incumbents = None
    limit = config.time_limit_s if time_limit_s is None else float(time_limit_s)
    if free:  # the layout's own (exact, cheap) optimum is a valid start for every count
        layout_curve = tradeoff_curve(problem.restrict(layout), config, time_limit_s=limit)
        limit = max(limit - (time.perf_counter() - t), 1.0)
        idx = np.flatnonzero(layout)
        incumbents = {}
        for p in layout_curve.points:
            full = np.zeros(problem.n_sites, bool)
            full[idx[p.selected]] = True
            incumbents[p.k] = full
    curve = tradeoff_curve(problem, config, k_max=n_allowed, k_min=k_min,
                           time_limit_s=limit, exact=not free, start=start,
                           incumbents=incumbents)
    timings = {"curve": time.perf_counter() - t}
    t = time.perf_counter()
    drop = drop_order(problem, config, layout)
    losses = marker_losses(problem, config, layout)
    timings["drop_order_and_losses"] = time.perf_counter() - t
    return ReductionStudy(problem=problem, config=config, layout=layout, free=free, curve=curve,
                          drop=drop, losses=losses, timings_s=timings, layout_curve=layout_curve)
