"""Candidate station positions: where the rover could stop and scan.

A regular grid at ``spacing_m`` (on multiples of the spacing in the site frame, so the same
area gives the same grid whatever its outline), kept where it lies inside the area and on
trafficable ground (and, given a route start, on ground the rover can drive to from there).
Ids ``P0001``, ``P0002``, ... run row by row (rows along +y, x increasing within a row).
"""

from __future__ import annotations

import numpy as np
import shapely

from markerplan.errors import ConfigError, DataError
from planner.problem.candidates import GridPoints
from planner.traverse.trafficability import LIMITS

__all__ = ["MAX_STATION_CANDIDATES", "candidate_stations"]

#: Most candidate stations accepted (each is a column block of the joint program and a
#: Dijkstra source of the route).
MAX_STATION_CANDIDATES = 5000


def candidate_stations(traffic_map, area_polygon, spacing_m: float, lidar_height_m: float,
                       dem, start_xy=None) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Candidate stations on a grid over trafficable ground.

    Parameters
    ----------
    traffic_map : planner.traverse.trafficability.TrafficMap
    area_polygon : shapely Polygon or MultiPolygon
        Where stations may go (e.g. the AOI buffered by the coverage range), site frame.
    spacing_m : float
        Grid spacing, metres.
    lidar_height_m : float
        LiDAR centre above the ground at a station, metres.
    dem : visibility.dem.DEM
        Terrain the stations stand on.
    start_xy : (2,) float, optional
        Route start (the lander); stations the rover cannot drive to from it are dropped.

    Returns
    -------
    ids : list of str
        ``"P0001"``, ... (at least four digits).
    xy : (n, 2) float
        Station ground positions, site frame, metres.
    position_m : (n, 3) float
        LiDAR centres: ground height + ``lidar_height_m``.

    Raises
    ------
    ConfigError
        A spacing or height that is not a positive number, or a grid of more than
        :data:`MAX_STATION_CANDIDATES` points inside the area's bounds.
    DataError
        No candidate left (with the count dropped for each reason).

    Examples
    --------
    >>> from visibility.dem import DEM
    >>> from planner.traverse.trafficability import TrafficSettings, trafficable_map
    >>> dem = DEM(np.zeros((101, 101)), (0.0, 0.0), 0.1)
    >>> tm = trafficable_map(dem, TrafficSettings(hazard_standoff_m=0.0))
    >>> ids, xy, pos = candidate_stations(tm, shapely.box(0, 0, 10, 10), 4.0, 1.0, dem)
    >>> ids, pos[:, 2].tolist()
    (['P0001', 'P0002', 'P0003', 'P0004'], [1.0, 1.0, 1.0, 1.0])
    >>> xy.tolist()  # the edge row and column fail "nodata or edge" (footprint off the DEM)
    [[4.0, 4.0], [8.0, 4.0], [4.0, 8.0], [8.0, 8.0]]
    """
    for name, v in (("spacing_m", spacing_m), ("lidar_height_m", lidar_height_m)):
        if not (np.isfinite(v) and v > 0):
            raise ConfigError(f"`{name}` must be a positive number of metres, got {v!r}")
    x0, y0, x1, y1 = area_polygon.bounds
    gx = spacing_m * np.arange(np.ceil(x0 / spacing_m), np.floor(x1 / spacing_m) + 1)
    gy = spacing_m * np.arange(np.ceil(y0 / spacing_m), np.floor(y1 / spacing_m) + 1)
    if len(gx) * len(gy) > MAX_STATION_CANDIDATES:
        raise ConfigError(f"`station_spacing_m` {spacing_m:g} m lays {len(gx) * len(gy)} "
                          f"candidate stations over the {x1 - x0:.0f} x {y1 - y0:.0f} m area, "
                          f"more than the {MAX_STATION_CANDIDATES} accepted; raise "
                          "`station_spacing_m` or shrink the area")
    points = GridPoints(gx, gy)
    points.drop(~shapely.contains_xy(area_polygon, points.xy[:, 0], points.xy[:, 1]),
                "outside the area")
    points.drop(~(dem.valid_at(points.xy) & traffic_map.trafficable_at(points.xy)),
                "not trafficable")
    if start_xy is not None and len(points.xy):
        from planner.traverse.ground_paths import reachable_nodes

        flat, _ = traffic_map.node_of(points.xy)
        points.drop(~reachable_nodes(traffic_map, start_xy).ravel()[flat],
                    "cut off from the start")
    xy = points.xy
    if not len(xy):
        raise DataError("no candidate station is left (dropped: " + points.dropped_text()
                        + "); enlarge the area, lower `station_spacing_m` or relax the "
                        f"{LIMITS}")
    width = max(4, len(str(len(xy))))
    ids = [f"P{k + 1:0{width}d}" for k in range(len(xy))]
    z = dem.height_at(xy) + lidar_height_m
    return ids, xy, np.column_stack([xy, z])
