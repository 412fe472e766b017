"""Choose where the rover stops over an area of interest, its markers and its traverse.

:func:`design_survey` runs the steps in order:

1. the AOI's cells (:func:`planner.coverage.grid.aoi_grid`) and where the rover can drive
   (:func:`planner.traverse.trafficability.trafficable_map`);
2. candidate stations on trafficable ground within reach of the AOI
   (:func:`planner.traverse.stations.candidate_stations`), and which cells each covers
   (:func:`planner.coverage.sight.coverage_matrix`, ray cast on tiles, mapped like the marker
   visibility);
3. what each candidate station could do with each candidate marker site
   (:func:`planner.run.build_problem`, the marker plan's own visibility and error model);
4. the drive lengths over trafficable ground between the route start and every candidate
   station (:func:`planner.traverse.ground_paths.ground_paths`, one graph for every drive of
   the design), and the joint program of stations, markers and the tour, the drive priced
   at ``1 / drive_speed_m_s`` s/m (:func:`planner.program.joint.plan_stations_and_sites`),
   started from the best of three layouts, each costed with its PyVRP tour: two baselines
   (:mod:`planner.program.joint_baselines`) and the program of stops and markers alone
   (:data:`STOPS_TIME_SHARE` of the time limit, started from the better baseline);
5. the traverse through the chosen stations from the route start and back: the program's tour
   or PyVRP's (:func:`planner.traverse.route.plan_route`), whichever is shorter, and each
   baseline's;
6. on a site preset, its published hand layout (stations and as-built markers) judged the same
   way.

The caller then plans the markers of the chosen stations, in route order, with the ordinary
plan (:func:`planner.design.plan.design_plan`), so every output and ``verify`` treat the
result like any other plan.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from markerplan.errors import ConfigError, DataError, InfeasiblePlanError
from planner.accuracy.checks import evaluate_layout, station_infos
from planner.coverage.grid import AoiGrid, aoi_grid
from planner.coverage.raster import Uncovered, uncovered_summary
from planner.coverage.sight import CoverageMatrix, CoverageSettings, coverage_matrix
from planner.problem.inputs import PlanInputs
from planner.problem.sight import sight_problem
from planner.problem.usability import PlanProblem
from planner.program.joint import (
    JointCosts,
    JointResult,
    StationCover,
    eligible_stations,
    plan_stations_and_sites,
    shortest_tour,
    tour_units,
)
from planner.program.joint_baselines import (
    JointBaseline,
    greedy_viewpoints,
    grid_viewpoints,
    joint_baseline,
)
from planner.program.joint_tour import leg_lengths_m
from planner.run import build_problem
from planner.traverse.ground_paths import ground_graph, ground_paths
from planner.traverse.route import MissionCosts, Route, mission_time_s, plan_route, route_start
from planner.traverse.stations import candidate_stations
from planner.traverse.trafficability import TrafficMap, TrafficSettings, trafficable_map


@dataclass(frozen=True)
class SurveyOption:
    """One way to survey the AOI (the plan, a baseline, the hand layout), with its cost.

    Attributes
    ----------
    name : str
        "plan", "greedy", "grid" or "hand".
    station_xy : (k, 2) float
        Its stations in route order, site frame, m.
    n_markers : int
        New markers it places.
    covered_fraction : float
        Fraction of the AOI's cells covered ``cover_min_stations`` times.
    meets_requirement : bool
        Whether its markers meet every station's requirement (the marker program's rules).
    route : Route or None
        Its traverse (None when it has no station or the drive failed, see ``note``).
    time_s : dict
        Mission time: ``stations``, ``markers``, ``drive``, ``total``, s.
    note : str or None
        Why it falls short, when it does.
    spacing_m : float or None
        Grid spacing (grid baseline only), m.
    """

    name: str
    station_xy: np.ndarray
    n_markers: int
    covered_fraction: float
    meets_requirement: bool
    route: Route | None
    time_s: dict
    note: str | None = None
    spacing_m: float | None = None

    @property
    def n_stations(self) -> int:
        return int(len(self.station_xy))


@dataclass(frozen=True)
class SurveyDesign:
    """The stations, markers and traverse chosen over an AOI.

    Attributes
    ----------
    aoi : shapely Polygon or MultiPolygon
        Site frame.
    grid : AoiGrid
    traffic : TrafficMap
        Where the rover drives: the site's trafficability cut to the drives' window
        (:data:`DRIVE_MARGIN_M`).
    candidate_ids : tuple of str, (s,)
    candidate_position_m : (s, 3) float
        LiDAR centres of the candidate stations, m.
    coverage : CoverageMatrix
        Candidate stations x AOI cells.
    problem : PlanProblem
        Every candidate station and candidate marker site.
    joint : JointResult
    order : (k,) int
        The chosen candidate stations in route order.
    route : Route
    route_start_xy : (2,) float
        Where the traverse starts and ends, m.
    route_start_source : str
        Where that point came from.
    uncoverable : planner.coverage.raster.Uncovered
        AOI cells no candidate station can cover (left out of the requirement), and why.
    options : tuple of SurveyOption
        The plan first, then the baselines and (on a preset) the hand layout.
    costs : MissionCosts
    timings_s : dict
    """

    aoi: object
    grid: AoiGrid
    traffic: TrafficMap
    candidate_ids: tuple
    candidate_position_m: np.ndarray
    coverage: CoverageMatrix
    problem: PlanProblem
    joint: JointResult
    order: np.ndarray
    route: Route
    route_start_xy: np.ndarray
    route_start_source: str
    uncoverable: Uncovered
    options: tuple
    costs: MissionCosts
    timings_s: dict

    @property
    def station_ids(self) -> list[str]:
        """Ids of the chosen stations in route order: S1, S2, ..."""
        return [f"S{k + 1}" for k in range(self.order.size)]

    @property
    def station_position_m(self) -> np.ndarray:
        """(k, 3) LiDAR centres of the chosen stations in route order, m."""
        return self.candidate_position_m[self.order]

    @property
    def station_heading_rad(self) -> np.ndarray:
        """(k,) heading of the rover at each chosen station: the direction it arrived from the
        previous stop (the first: from the route start), straight-line, rad."""
        xy = np.vstack([self.route_start_xy, self.station_position_m[:, :2]])
        step = np.diff(xy, axis=0)
        return np.arctan2(step[:, 1], step[:, 0])


def coverage_settings(config) -> CoverageSettings:
    """The coverage requirement of a :class:`~planner.config.PlanConfig`."""
    return CoverageSettings(cell_m=config.aoi_cell_m, max_range_m=config.cover_max_range_m,
                            max_incidence_deg=config.cover_max_incidence_deg,
                            min_density_per_m2=config.cover_min_density_per_m2,
                            min_stations=config.cover_min_stations)


def traffic_settings(config) -> TrafficSettings:
    """The rover's trafficability limits of a :class:`~planner.config.PlanConfig`."""
    return TrafficSettings(footprint_m=config.rover_footprint_m,
                           max_slope_deg=config.rover_max_slope_deg,
                           max_roughness_m=config.rover_max_roughness_m,
                           hazard_standoff_m=config.rover_hazard_standoff_m,
                           grid_m=config.traffic_grid_m)


def mission_costs(config) -> MissionCosts:
    """The mission-time costs of a :class:`~planner.config.PlanConfig`."""
    return MissionCosts(station_s=config.station_time_s, marker_s=config.marker_time_s,
                        drive_m_per_s=config.drive_speed_m_s)


def flat_reach_m(config, lidar_height_m: float) -> float:
    """How far from a station a cell of flat ground can count as covered, m: the incidence
    limit's ``h tan(incidence)``, at most the range limit.

    >>> from planner.config import PlanConfig
    >>> round(flat_reach_m(PlanConfig(), 1.0), 2)
    11.43
    """
    incidence = math.radians(min(config.cover_max_incidence_deg, 89.9))
    return min(config.cover_max_range_m, lidar_height_m * math.tan(incidence))


def design_survey(inputs: PlanInputs, config, error_model, aoi, keepouts=(),
                  route_start_xy=None, route_start_source: str = "given",
                  progress: bool = True, map_groups=map, detection_model=None,
                  hand_layout: bool = True) -> SurveyDesign:
    """Choose stations, markers and traverse over ``aoi`` (see the module docstring).

    Parameters
    ----------
    inputs : PlanInputs
        The terrain, marker-site boundary, exclusions, craters, LiDAR height and marker radius;
        its stations are the hand layout (judged when ``hand_layout``), not candidates.
    config : PlanConfig
        The marker program's settings and the AOI plan's (``aoi_cell_m``, ``cover_*``,
        ``rover_*``, ``traffic_grid_m``, ``station_spacing_m``, ``*_time_s``,
        ``drive_speed_m_s``).
    error_model : ErrorModel
    aoi : shapely Polygon or MultiPolygon
        The area of interest, site frame (:func:`planner.coverage.aoi.read_aoi`).
    keepouts : sequence of shapely Polygon
        Where the rover must not drive.
    route_start_xy : (2,) float, optional
        Where the traverse starts and ends (the lander); default the trafficable point
        nearest the AOI's centroid.
    route_start_source : str
        How the report names where the start came from.
    progress : bool
    map_groups : callable
        How the ray casting's station blocks are mapped (see
        :func:`planner.problem.sight.sight_problem`).
    detection_model : DetectionModel, optional
    hand_layout : bool
        Judge ``inputs``' stations and as-built markers as the "hand" option.

    Returns
    -------
    design : SurveyDesign

    Raises
    ------
    InfeasiblePlanError
        Part of the AOI no trafficable candidate station covers (where, and why), or no
        choice meets the requirement.
    ConfigError
        A route start on ground the rover cannot drive.
    """
    timings: dict = {}
    t = time.perf_counter()
    dem = inputs.dem
    grid = aoi_grid(dem, aoi, config.aoi_cell_m)
    traffic = trafficable_map(dem, traffic_settings(config), craters=inputs.craters,
                              keepouts=keepouts)
    if route_start_xy is None:
        centroid = np.array(aoi.centroid.coords[0])
        route_start_xy = traffic.nearest_trafficable(centroid[None])[0]
        route_start_source = "the trafficable point nearest the AOI's centroid"
    start = route_start(traffic, route_start_xy)
    reach = flat_reach_m(config, inputs.lidar_height_m)
    traffic = _drive_window(traffic, aoi, reach, start)
    graph = ground_graph(traffic, dem)
    ids, _, position = candidate_stations(traffic, aoi.buffer(reach), config.station_spacing_m,
                                          inputs.lidar_height_m, dem, start_xy=start)
    timings["candidate_stations"] = time.perf_counter() - t
    cover_settings = coverage_settings(config)
    coverage = coverage_matrix(dem, position, grid, cover_settings, map_groups=map_groups,
                               progress=progress)
    timings["coverage"] = coverage.elapsed_s
    uncoverable = uncovered_summary(coverage, grid, position, cover_settings)
    if uncoverable.area_m2 > (1.0 - config.cover_min_fraction) * len(grid) * grid.cell_area_m2 \
            + 1e-9:
        raise InfeasiblePlanError(
            f"no trafficable candidate station covers part of the AOI: {uncoverable.text}; "
            f"more than `cover_min_fraction` ({config.cover_min_fraction:g}) of the AOI must "
            "be coverable: move the AOI, relax the coverage or rover limits, or lower "
            "`cover_min_fraction`")
    useful = np.unique(coverage.station)
    ids, position, coverage = _only(useful, ids, position, coverage)

    candidates = replace(inputs, station_ids=list(ids), station_xyz=position,
                         station_heading_rad=np.zeros(len(ids)))
    problem, _, _, sight_t = build_problem(candidates, config, error_model, progress,
                                           map_groups, detection_model, clear_of_stations=False)
    timings.update({f"marker_{k}": v for k, v in sight_t.items()})
    cover = _required_cover(coverage, len(grid), uncoverable.cell, config.cover_min_stations)
    t = time.perf_counter()
    drive = ground_paths(traffic, np.vstack([start, position[:, :2]]), ["route_start", *ids],
                         dem, label="candidate station", graph=graph).distance_m
    timings["drive_lengths"] = time.perf_counter() - t
    costs = mission_costs(config)
    jcosts = JointCosts(station=costs.station_s, marker=costs.marker_s,
                        drive_per_m=1.0 / costs.drive_m_per_s)
    clashes = _clashes(problem, config.min_station_distance_m)
    t = time.perf_counter()
    infos = station_infos(problem, config)
    eligible, _ = eligible_stations(problem, config, infos)
    greedy = _baseline("greedy", greedy_viewpoints(cover, eligible), problem, config, cover,
                       jcosts, clashes)
    xmin, ymin, xmax, ymax = aoi.bounds
    grid_stations, spacing = grid_viewpoints(cover, problem.station_xyz[:, :2], eligible,
                                             (xmin, xmax, ymin, ymax),
                                             _grid_spacings(reach, config.station_spacing_m))
    gridded = _baseline("grid", grid_stations, problem, config, cover, jcosts, clashes, spacing)
    timings["baselines"] = time.perf_counter() - t
    passing = [(b.stations, b.selected) for b in (greedy, gridded)
               if b.covered and b.meets_requirement]
    # stops and markers first (the program without the drive solves fast), its layout a
    # third candidate start of the full program
    t = time.perf_counter()
    stops = plan_stations_and_sites(
        problem, config.replace(time_limit_s=config.time_limit_s * STOPS_TIME_SHARE), cover,
        JointCosts(jcosts.station, jcosts.marker), clashes=clashes, infos=infos,
        incumbent=min(passing, key=lambda b: _cost(b, problem, jcosts)) if passing else None)
    passing.append((stops.stations, stops.selected))
    best = min(passing, key=lambda b: _cost(b, problem, jcosts, drive))
    remaining = config.time_limit_s - (time.perf_counter() - t)
    joint = plan_stations_and_sites(problem, config.replace(time_limit_s=max(remaining, 1.0)),
                                    cover, jcosts, incumbent=best, clashes=clashes, infos=infos,
                                    drive_m=drive)
    timings["joint_program"] = stops.solve_time_s + joint.solve_time_s
    t = time.perf_counter()
    route = _plan_route(joint, traffic, start, position, ids, dem, graph, drive)
    order = np.flatnonzero(joint.stations)[route.order]
    plan_option = _option("plan", problem, cover, len(grid), costs, joint.stations, joint.selected,
                          True, route, None)
    options = [plan_option]
    for b in (greedy, gridded):
        options.append(_baseline_option(b, problem, cover, len(grid), costs, traffic, start,
                                        ids, dem, graph))
    if hand_layout and len(inputs.station_ids):
        options.append(_hand_option(inputs, config, error_model, grid, cover_settings,
                                    costs, traffic, start, map_groups, graph))
    timings["routes"] = time.perf_counter() - t
    return SurveyDesign(aoi=aoi, grid=grid, traffic=traffic, candidate_ids=tuple(ids),
                        candidate_position_m=position, coverage=coverage, problem=problem,
                        joint=joint, order=order, route=route, route_start_xy=start,
                        route_start_source=route_start_source, uncoverable=uncoverable,
                        options=tuple(options),
                        costs=costs, timings_s=timings)


#: Drives stay within the candidate stations' area (the AOI buffered by the reach) and the
#: route start, widened by this much, m: room to go round obstacles at the edge, while the
#: ground-path graph stays small on a large site.
DRIVE_MARGIN_M = 20.0


def _drive_window(traffic: TrafficMap, aoi, reach_m: float, start: np.ndarray) -> TrafficMap:
    """The trafficability map cut to where the rover drives (see :data:`DRIVE_MARGIN_M`)."""
    xmin, ymin, xmax, ymax = aoi.buffer(reach_m + DRIVE_MARGIN_M).bounds
    m = DRIVE_MARGIN_M
    return traffic.window(min(xmin, start[0] - m), max(xmax, start[0] + m),
                          min(ymin, start[1] - m), max(ymax, start[1] + m))


def _only(keep: np.ndarray, ids, position: np.ndarray, coverage: CoverageMatrix):
    """The candidate stations ``keep`` (indices), their coverage re-indexed."""
    new = np.full(len(ids), -1, np.int64)
    new[keep] = np.arange(keep.size)
    return ([ids[k] for k in keep], position[keep],
            replace(coverage, station=new[coverage.station]))


def _required_cover(coverage: CoverageMatrix, n_cells: int, uncoverable: np.ndarray,
                    min_stations: int) -> StationCover:
    """The coverage rows' view: every AOI cell but the uncoverable ones (left out, reported)."""
    required = np.ones(n_cells, bool)
    required[uncoverable] = False
    keep = required[coverage.cell]
    new = np.cumsum(required) - 1
    return StationCover(coverage.station[keep], new[coverage.cell[keep]], int(required.sum()),
                        min_stations)


def _clashes(problem: PlanProblem, clearance_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(candidate station, site) pairs closer than ``clearance_m`` horizontally."""
    tree = cKDTree(problem.site_xyz[:, :2])
    hits = tree.query_ball_point(problem.station_xyz[:, :2], clearance_m)
    st = np.repeat(np.arange(problem.n_stations), [len(h) for h in hits])
    site = np.concatenate([np.asarray(h, np.int64) for h in hits] or [np.zeros(0, np.int64)])
    order = np.lexsort((site, st))
    return st[order], site[order]


def _baseline(name: str, stations: np.ndarray, problem: PlanProblem, config,
              cover: StationCover, costs: JointCosts, clashes, spacing_m=None
              ) -> JointBaseline:
    """A baseline's stations with their markers, no marker on a site too near one of them."""
    st, site = clashes
    near = {problem.site_ids[j] for j in site[stations[st]]}
    config = config.replace(forbidden=tuple(sorted(set(config.forbidden) | near)))
    return joint_baseline(name, problem, config, cover, costs, stations, spacing_m)


def _grid_spacings(reach_m: float, station_spacing_m: float) -> np.ndarray:
    """Grid spacings tried, widest first: from twice the flat reach down to the candidate
    spacing, 10 % narrower each step, m."""
    out, s = [], 2.0 * reach_m
    while s > station_spacing_m:
        out.append(s)
        s *= 0.9
    return np.array(out + [station_spacing_m])


def mission_time_record(costs: MissionCosts, route: Route | None, n_stations: int,
                        n_markers: int) -> dict:
    """Mission time of a way to survey, by part: ``stations``, ``markers``, ``drive``,
    ``total``, s (drive and total ``None`` without a route)."""
    if route is None:
        return {"stations": costs.station_s * n_stations, "markers": costs.marker_s * n_markers,
                "drive": None, "total": None}
    t = mission_time_s(route, n_stations, n_markers, costs)
    return {"stations": t.stations_s, "markers": t.markers_s, "drive": t.drive_s,
            "total": t.total_s}


def _option(name, problem, cover, n_aoi_cells, costs, stations, selected, meets, route, note,
            spacing_m=None) -> SurveyOption:
    idx = np.flatnonzero(stations)
    xy = problem.station_xyz[idx, :2]
    if route is not None:
        xy = xy[route.order]
    n_markers = int(problem.site_cost[selected].sum())
    frac = float(np.sum(cover.counts(stations) >= cover.min_stations) / max(n_aoi_cells, 1))
    return SurveyOption(name=name, station_xy=xy, n_markers=n_markers, covered_fraction=frac,
                        meets_requirement=bool(meets), route=route,
                        time_s=mission_time_record(costs, route, idx.size, n_markers), note=note,
                        spacing_m=spacing_m)


#: Share of ``time_limit_s`` the program of stops and markers alone may take before the full
#: program (drive priced) starts from its layout.
STOPS_TIME_SHARE = 0.4


def _cost(layout: tuple, problem: PlanProblem, costs: JointCosts, drive_m=None) -> float:
    """Stated cost of a layout ``(stations, selected)``: its stops and markers and, with
    ``drive_m``, PyVRP's closed tour through its stations, in the program's rounding."""
    stations, selected = layout
    units = 0.0 if drive_m is None else tour_units(drive_m, shortest_tour(drive_m, stations)[0],
                                                   costs)
    return costs.of(int(stations.sum()), int(problem.site_cost[selected].sum()), units)


def _plan_route(joint: JointResult, traffic: TrafficMap, start: np.ndarray,
                position: np.ndarray, ids, dem, graph, drive_m: np.ndarray) -> Route:
    """The traverse of the chosen stations: PyVRP's tour over the candidates' drive lengths
    ``drive_m``, or the joint program's when it is shorter (proven shortest for those stations
    when the program proved its optimum over every edge, up to the rounding of each leg's
    cost)."""
    chosen = np.flatnonzero(joint.stations)
    tour, solver = shortest_tour(drive_m, joint.stations)
    if joint.tour is not None:
        proven = joint.status == "optimal" and bool(joint.tour_complete)
        if leg_lengths_m(drive_m, joint.tour).sum() < leg_lengths_m(drive_m, tour).sum() - 1e-6:
            tour, solver = joint.tour, {"name": "joint program (HiGHS)", "proven_optimal": proven}
        elif proven:
            solver = {**solver, "proven_optimal": True}
    return plan_route(traffic, start, position[chosen, :2], [ids[k] for k in chosen], dem,
                      graph=graph, order=np.searchsorted(chosen, tour), order_solver=solver)


def _baseline_option(b: JointBaseline, problem, cover, n_aoi_cells, costs, traffic, start,
                     ids, dem, graph) -> SurveyOption:
    idx = np.flatnonzero(b.stations)
    route, note = None, b.note
    if idx.size:
        route = plan_route(traffic, start, problem.station_xyz[idx, :2],
                           [ids[k] for k in idx], dem, graph=graph)
    return _option(b.name, problem, cover, n_aoi_cells, costs, b.stations, b.selected,
                   b.meets_requirement, route, note, b.spacing_m)


def _hand_option(inputs: PlanInputs, config, error_model, grid: AoiGrid,
                 cover_settings: CoverageSettings, costs: MissionCosts, traffic, start,
                 map_groups, graph) -> SurveyOption:
    """The inputs' own stations with the site's as-built markers, judged like the plan."""
    position = inputs.station_xyz
    cov = coverage_matrix(inputs.dem, position, grid, cover_settings, map_groups=map_groups)
    counts = np.bincount(cov.cell, minlength=len(grid))
    frac = float(np.mean(counts >= cover_settings.min_stations)) if len(grid) else 1.0
    meets, note = False, None
    if len(inputs.as_built_ids):
        sight = sight_problem(inputs, list(inputs.as_built_ids), inputs.as_built_xyz, config,
                              error_model, progress=False, map_groups=map_groups)
        check = evaluate_layout(sight.problem, np.ones(len(inputs.as_built_ids), bool), config)
        meets = bool(check.ok.all())
        if not meets:
            note = f"{int((~check.ok).sum())} of {len(check.ok)} stations fail the requirement"
    else:
        note = "no as-built markers known"
    route = None
    outside = ~traffic.node_of(position[:, :2])[1]
    if outside.any():
        note = (note + "; " if note else "") + (
            f"{int(outside.sum())} of its stations lie beyond the drive window around the AOI: "
            "no route")
    else:
        try:
            route = plan_route(traffic, start, position[:, :2], list(inputs.station_ids),
                               inputs.dem, graph=graph)
        except (ConfigError, DataError) as exc:
            note = (note + "; " if note else "") + str(exc)
    xy = position[:, :2] if route is None else position[route.order, :2]
    n_markers = len(inputs.as_built_ids)
    return SurveyOption(name="hand", station_xy=xy, n_markers=n_markers, covered_fraction=frac,
                        meets_requirement=meets, route=route, note=note,
                        time_s=mission_time_record(costs, route, len(position), n_markers))
