"""Ground paths: the detour around a wall against its analytic length, height change, and the
one-line errors for points the rover cannot reach."""

import numpy as np
import pytest
import shapely

from markerplan.errors import DataError
from planner.traverse.ground_paths import ground_paths, reachable_nodes
from planner.traverse.trafficability import TrafficSettings, trafficable_map
from visibility.dem import DEM

OPEN = TrafficSettings(footprint_m=0.5, grid_m=0.5, hazard_standoff_m=0.0)
WALL = shapely.box(-0.1, -10.0, 0.1, 5.0)  # blocks the x = 0 nodes for y in [-10, 5]


def _field(heights=None):
    h = np.zeros((301, 301)) if heights is None else heights
    return DEM(h, (-15.0, -15.0), 0.1)


def test_path_around_a_wall_is_the_analytic_detour():
    dem = _field()
    tm = trafficable_map(dem, OPEN, keepouts=[WALL])
    a, b = np.array([-5.5, 0.0]), np.array([5.5, 0.0])
    p = ground_paths(tm, np.array([a, b]), ["A", "B"])
    # shortest path in the plane: A -> both corners of the wall's tip -> B
    detour = 2 * np.hypot(5.4, 5.0) + 0.2
    grid = OPEN.grid_m
    assert detour <= p.distance_m[0, 1] <= detour + 4 * grid
    # on the grid: diagonals to the free nodes beside the tip, (-0.5, 5) and (0.5, 5), and four
    # side steps over it (the diagonal past the blocked tip node (0, 5) is not cut)
    assert np.isclose(p.distance_m[0, 1], 2 * 5 * np.sqrt(2) + 4 * grid)
    line = p.polyline(0, 1)
    assert line[0].tolist() == a.tolist() and line[-1].tolist() == b.tolist()
    seg = np.hypot(*np.diff(line, axis=0).T)
    assert np.isclose(seg.sum(), p.distance_m[0, 1])
    assert seg.max() <= grid * np.sqrt(2) + 1e-9  # node to node, no jumps
    assert not shapely.LineString(line).intersects(WALL)
    assert line[:, 1].max() >= 5.0  # it went round the tip
    # without the wall: the straight line
    straight = ground_paths(trafficable_map(dem, OPEN), np.array([a, b]), ["A", "B"])
    assert np.isclose(straight.distance_m[0, 1], 11.0)


def test_height_change_counts_in_the_length():
    x = -15.0 + 0.1 * np.arange(301)
    dem = _field(np.tile(0.1 * x, (301, 1)))  # 5.7 deg ramp along x
    tm = trafficable_map(dem, OPEN)
    xy = np.array([[-5.0, 1.0], [5.0, 1.0]])
    flat = ground_paths(tm, xy, ["A", "B"])
    ramp = ground_paths(tm, xy, ["A", "B"], dem=dem)
    assert np.isclose(flat.distance_m[0, 1], 10.0)
    assert np.isclose(ramp.distance_m[0, 1], 10.0 * np.hypot(1.0, 0.1))


def test_distance_matrix_is_symmetric_and_snaps_points_onto_nodes():
    tm = trafficable_map(_field(), OPEN, keepouts=[WALL])
    xy = np.array([[-5.3, 0.1], [5.6, -0.2], [0.0, 8.0], [-2.0, -12.0]])
    p = ground_paths(tm, xy, list("ABCD"))
    assert np.allclose(p.distance_m, p.distance_m.T)
    assert (np.diag(p.distance_m) == 0).all()
    # the snap steps are counted: A's node (-5.5, 0) is 0.2236 m away
    direct = ground_paths(tm, np.array([[-5.5, 0.0], [0.0, 8.0]]), ["A", "C"])
    assert np.isclose(p.distance_m[0, 2], direct.distance_m[0, 1] + np.hypot(0.2, 0.1))
    # the triangle inequality holds for shortest paths
    d = p.distance_m
    assert (d[:, None, :] <= d[:, :, None] + d[None, :, :] + 1e-9).all()


def test_unreachable_points_are_one_line_errors_naming_them():
    ring = shapely.box(4.0, 4.0, 8.0, 8.0).difference(shapely.box(5.0, 5.0, 7.0, 7.0))
    tm = trafficable_map(_field(), OPEN, keepouts=[ring])
    with pytest.raises(DataError, match=r"^station S2 at \(6\.00, 6\.00\) m stands on a "
                                        r"trafficable patch cut off from S1") as err:
        ground_paths(tm, np.array([[0.0, 0.0], [6.0, 6.0]]), ["S1", "S2"], label="station")
    assert "\n" not in str(err.value)
    with pytest.raises(DataError, match=r"station S2 at \(4\.50, 6\.00\) m is not on "
                                        r"trafficable ground \(keep-out\)"):
        ground_paths(tm, np.array([[0.0, 0.0], [4.5, 6.0]]), ["S1", "S2"], label="station")
    inside = reachable_nodes(tm, (6.0, 6.0))
    outside = reachable_nodes(tm, (0.0, 0.0))
    assert inside.sum() == 9 and not (inside & outside).any()
    assert not reachable_nodes(tm, (4.5, 6.0)).any()
