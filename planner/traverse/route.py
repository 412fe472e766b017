"""The traverse: a closed tour from the route start (the lander) through the chosen stations
and back, over trafficable ground, and the mission time it costs.

The order is a travelling-salesman tour on the ground-path drive lengths
(:mod:`planner.traverse.ground_paths`), solved by PyVRP's iterated local search on the lengths
in whole millimetres, with a fixed seed and a fixed number of iterations (so the same inputs
give the same tour on any machine). PyVRP is a heuristic: the tour is not proven optimal in
general; on small instances (up to about ten stations) it finds the optimum (the tests hold it
against every permutation).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib.metadata import version

import numpy as np

from markerplan.errors import ConfigError

__all__ = ["MissionCosts", "MissionTime", "Route", "RouteSettings", "mission_time_s",
           "plan_route", "route_start", "solve_tour"]


@dataclass(frozen=True)
class RouteSettings:
    """How the tour is solved.

    Attributes
    ----------
    max_iterations : int
        PyVRP's stopping criterion (``pyvrp.stop.MaxIterations``). Default 2000: on random
        instances of 30, 100 and 300 stations the tour is then within 0 %, 0.9 % and 2 % of the
        best found with 25 times as many iterations, in about 0.5, 1 and 2 s (a run-time limit
        would make the tour depend on the machine).
    seed : int
        PyVRP's random seed.
    units_per_m : int
        Drive lengths are handed to PyVRP as integers in these units. Default 1000 (mm).
    """

    max_iterations: int = 2000
    seed: int = 0
    units_per_m: int = 1000

    def __post_init__(self) -> None:
        for name in ("max_iterations", "units_per_m"):
            v = getattr(self, name)
            if not (isinstance(v, int | np.integer) and v >= 1):
                raise ConfigError(f"`{name}` must be a positive integer, got {v!r}")


@dataclass(frozen=True)
class Route:
    """A closed tour over trafficable ground, site frame.

    Attributes
    ----------
    order : (n,) int
        The stations in driving order (indices into the stations given).
    leg_m : (n + 1,) float
        Drive length of each leg: start -> first station, ..., last station -> start, metres.
    length_m : float
        Total drive length, metres.
    polyline : (p, 2) float
        The drive along the ground paths, from the start back to the start, metres.
    solver : dict
        Name, version, stopping criterion, seed and objective (integer units and metres); no
        timings, so equal inputs give equal records.
    """

    order: np.ndarray
    leg_m: np.ndarray
    length_m: float
    polyline: np.ndarray
    solver: dict


def solve_tour(distance_m: np.ndarray, settings: RouteSettings = RouteSettings()
               ) -> tuple[np.ndarray, dict]:
    """The shortest closed tour from point 0 through every other point, by PyVRP.

    Parameters
    ----------
    distance_m : (k, k) float
        Drive lengths, metres; point 0 is the start.
    settings : RouteSettings

    Returns
    -------
    order : (k - 1,) int
        The other points in visiting order (indices into ``distance_m``, 1..k-1).
    solver : dict
        See :attr:`Route.solver`.

    Examples
    --------
    >>> d = np.array([[0, 1, 2, 1], [1, 0, 1, 2], [2, 1, 0, 1], [1, 2, 1, 0]], float)
    >>> order, rec = solve_tour(d)
    >>> sorted([order.tolist(), order[::-1].tolist()])[0], rec["objective_m"]
    ([1, 2, 3], 4.0)
    """
    d = np.asarray(distance_m, dtype=float)
    if d.ndim != 2 or d.shape[0] != d.shape[1] or len(d) < 1 or not np.isfinite(d).all():
        raise ConfigError(f"`distance_m` must be a finite (k, k) matrix with k >= 1, got shape "
                          f"{d.shape}")
    units = np.rint(d * settings.units_per_m).astype(np.int64)
    record = {"name": "PyVRP", "version": version("pyvrp"),
              "stop": f"MaxIterations({settings.max_iterations})", "seed": settings.seed,
              "units_per_m": settings.units_per_m, "proven_optimal": False}
    if len(d) <= 2:  # nothing to order
        order = np.arange(1, len(d))
        objective = int(units[0, 1] + units[1, 0]) if len(d) == 2 else 0
        return order, {**record, "objective": objective,
                       "objective_m": objective / settings.units_per_m, "proven_optimal": True}
    from pyvrp import Model
    from pyvrp.stop import MaxIterations

    model = Model()
    locations = [model.add_location(x=0, y=0) for _ in range(len(d))]
    depot = model.add_depot(locations[0])
    for loc in locations[1:]:
        model.add_client(loc)
    model.add_vehicle_type(1, start_depot=depot, end_depot=depot)
    for i, a in enumerate(locations):
        for j, b in enumerate(locations):
            if i != j:
                model.add_edge(a, b, int(units[i, j]))
    result = model.solve(MaxIterations(settings.max_iterations), seed=settings.seed,
                         collect_stats=False, display=False)
    order = np.array([a.idx + 1 for a in result.best.routes()[0] if a.is_client()])
    objective = int(result.cost())
    return order, {**record, "objective": objective,
                   "objective_m": objective / settings.units_per_m}


def route_start(traffic_map, start_xy) -> np.ndarray:
    """The route start as a point on trafficable ground.

    Parameters
    ----------
    traffic_map : planner.traverse.trafficability.TrafficMap
    start_xy : (2,) float
        Site frame, metres.

    Returns
    -------
    start : (2,) float

    Raises
    ------
    ConfigError
        Not one finite point, off the map or on ground that is not trafficable (naming the
        reason and the nearest trafficable point).
    """
    start = np.asarray(start_xy, dtype=float).reshape(-1)
    if start.shape != (2,) or not np.isfinite(start).all():
        raise ConfigError(f"`route_start` must be one finite (x, y) point, got {start_xy!r}")
    if not traffic_map.trafficable_at(start[None])[0]:
        why = traffic_map.why_not(start[None])[0]
        near = traffic_map.nearest_trafficable(start[None])[0]
        raise ConfigError(f"`route_start` ({start[0]:.2f}, {start[1]:.2f}) m is not on "
                          f"trafficable ground ({why}); move `route_start` to trafficable "
                          f"ground; the nearest trafficable point is ({near[0]:.2f}, "
                          f"{near[1]:.2f}) m")
    return start


def plan_route(traffic_map, start_xy, station_xy, station_ids, dem=None,
               settings: RouteSettings = RouteSettings(), graph=None,
               order: np.ndarray | None = None, order_solver: dict | None = None) -> Route:
    """The traverse from ``start_xy`` through every station and back, over trafficable ground.

    Parameters
    ----------
    traffic_map : planner.traverse.trafficability.TrafficMap
    start_xy : (2,) float
        Route start and end (the lander), site frame, metres.
    station_xy : (n, 2) float
        The chosen stations, metres.
    station_ids : sequence of str
    dem : visibility.dem.DEM, optional
        With it, drive lengths include the height change
        (:func:`planner.traverse.ground_paths.ground_paths`).
    settings : RouteSettings
    graph : planner.traverse.ground_paths.GroundGraph, optional
        ``traffic_map``'s graph, built with ``dem`` (default built here).
    order : (n,) int, optional
        The driving order (indices into the stations), when already chosen; default PyVRP's
        tour (:func:`solve_tour`).
    order_solver : dict, optional
        The route's solver record when ``order`` is given (who chose it, whether proven).

    Returns
    -------
    route : Route

    Raises
    ------
    ConfigError
        ``start_xy`` off the map or on ground that is not trafficable (naming the reason and
        the nearest trafficable point).
    DataError
        A station not on trafficable ground, or cut off from the start.
    """
    from planner.traverse.ground_paths import ground_paths

    start = route_start(traffic_map, start_xy)
    xy = np.vstack([start, np.asarray(station_xy, dtype=float).reshape(-1, 2)])
    paths = ground_paths(traffic_map, xy, ["route_start", *station_ids], dem=dem,
                         label="station", graph=graph)
    if order is None:
        order, solver = solve_tour(paths.distance_m, settings)
    else:
        order = np.asarray(order, np.int64) + 1
        solver = order_solver or {"name": "given", "proven_optimal": False}
    stops = np.r_[0, order, 0]
    legs = paths.distance_m[stops[:-1], stops[1:]]
    lines = [paths.polyline(a, b) for a, b in zip(stops[:-1], stops[1:], strict=True)]
    polyline = np.vstack([lines[0][:1]] + [line[1:] for line in lines]) if lines else start[None]
    return Route(order=order - 1, leg_m=legs, length_m=float(legs.sum()), polyline=polyline,
                 solver=solver)


@dataclass(frozen=True)
class MissionCosts:
    """What a mission costs in time.

    Attributes
    ----------
    station_s : float
        One station: stop, level and localise the rover, one full turntable scan, pack up,
        seconds. Default 300 s: the scan is 800 VLP-16 frames per turntable turn at 10 Hz
        (600 rpm) = 80 s; about 220 s more for stopping, levelling the rig, a localisation fix
        and checking the scan on the ground (an assumption; no flight data).
    marker_s : float
        Placing one marker with the rover's arm at a stop on the way, seconds. Default 180 s
        (an assumption: unstow, place, release, image to confirm; the drive to it is not
        counted, markers lie beside the traverse).
    drive_m_per_s : float
        Average drive speed including hazard-avoidance stops, m/s. Default 0.05 m/s: Yutu-2
        averaged well under 0.1 m/s over a day's drive; VIPER's 0.2 m/s top speed drops to
        about a quarter in stop-and-go autonomous driving.
    """

    station_s: float = 300.0
    marker_s: float = 180.0
    drive_m_per_s: float = 0.05

    def __post_init__(self) -> None:
        for name in ("station_s", "marker_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"`{name}` must be zero or a positive number of seconds, "
                                  f"got {v!r}")
        if not (np.isfinite(self.drive_m_per_s) and self.drive_m_per_s > 0):
            raise ConfigError(f"`drive_m_per_s` must be a positive speed, got "
                              f"{self.drive_m_per_s!r}")


@dataclass(frozen=True)
class MissionTime:
    """Mission time and its parts, seconds."""

    stations_s: float
    markers_s: float
    drive_s: float

    @property
    def total_s(self) -> float:
        return self.stations_s + self.markers_s + self.drive_s


def mission_time_s(route: Route, n_stations: int, n_markers: int,
                   costs: MissionCosts = MissionCosts()) -> MissionTime:
    """Time to drive the route, scan every station and place every marker.

    Parameters
    ----------
    route : Route
    n_stations, n_markers : int
    costs : MissionCosts

    Returns
    -------
    time : MissionTime

    Examples
    --------
    >>> r = Route(np.arange(2), np.array([10.0, 5.0, 5.0]), 20.0, np.zeros((1, 2)), {})
    >>> t = mission_time_s(r, 2, 3)
    >>> t.stations_s, t.markers_s, t.drive_s, t.total_s
    (600.0, 540.0, 400.0, 1540.0)
    """
    if n_stations < 0 or n_markers < 0:
        raise ConfigError(f"station and marker counts must be >= 0, got {n_stations} and "
                          f"{n_markers}")
    return MissionTime(stations_s=n_stations * costs.station_s,
                       markers_s=n_markers * costs.marker_s,
                       drive_s=route.length_m / costs.drive_m_per_s)
