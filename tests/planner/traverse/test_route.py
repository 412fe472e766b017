"""The route: PyVRP's tour against the brute-force optimum over every permutation, the route's
legs and polyline, determinism, and the one-line error for an untrafficable start."""

from itertools import permutations

import numpy as np
import pytest
import shapely

from markerplan.errors import ConfigError, DataError
from planner.traverse.route import plan_route, solve_tour
from planner.traverse.trafficability import TrafficSettings, trafficable_map
from visibility.dem import DEM

OPEN = TrafficSettings(footprint_m=0.5, grid_m=0.5, hazard_standoff_m=0.0)


def _brute_force(d):
    """Shortest closed tour from point 0 over every order of the others."""
    rest = range(1, len(d))
    return min(d[0, p[0]] + sum(d[a, b] for a, b in zip(p[:-1], p[1:], strict=True))
               + d[p[-1], 0] for p in permutations(rest))


def _tour_length(d, order):
    stops = np.r_[0, order, 0]
    return d[stops[:-1], stops[1:]].sum()


@pytest.mark.parametrize("seed", range(4))
def test_small_tours_are_the_brute_force_optimum(seed):
    rng = np.random.default_rng(seed)
    if seed % 2:  # Euclidean
        p = rng.uniform(0, 50, (8, 2))
        d = np.hypot(*(p[:, None] - p[None]).transpose(2, 0, 1))
    else:  # any symmetric lengths (not even metric)
        d = rng.uniform(1, 30, (8, 8))
        d = np.round(d + d.T, 3)
        np.fill_diagonal(d, 0)
    order, rec = solve_tour(d)
    assert sorted(order.tolist()) == list(range(1, 8))
    best = _brute_force(d)
    assert abs(_tour_length(d, order) - best) < 8e-3  # 8 legs rounded to the millimetre
    assert abs(rec["objective_m"] - _tour_length(d, order)) < 8e-3
    assert rec["name"] == "PyVRP" and rec["stop"].startswith("MaxIterations(")


def test_one_or_no_station():
    d = np.array([[0.0, 2.5], [2.5, 0.0]])
    order, rec = solve_tour(d)
    assert order.tolist() == [1] and rec["objective_m"] == 5.0 and rec["proven_optimal"]
    assert solve_tour(np.zeros((1, 1)))[0].tolist() == []


def _field():
    dem = DEM(np.zeros((201, 201)), (-10.0, -10.0), 0.1)
    wall = shapely.box(-0.1, -10.0, 0.1, 4.0)
    return dem, trafficable_map(dem, OPEN, keepouts=[wall])


STATIONS = np.array([[-6.0, -6.0], [6.0, -6.0], [6.0, 6.0], [-6.0, 6.0], [-3.0, 0.0]])


def test_route_follows_ground_paths_and_is_deterministic():
    dem, tm = _field()
    ids = [f"P{k:04d}" for k in range(1, 6)]
    route = plan_route(tm, (-8.0, -8.0), STATIONS, ids)
    again = plan_route(tm, (-8.0, -8.0), STATIONS, ids)
    assert route.order.tolist() == again.order.tolist()
    assert np.array_equal(route.polyline, again.polyline) and route.solver == again.solver
    assert sorted(route.order.tolist()) == list(range(5))
    assert route.polyline[0].tolist() == route.polyline[-1].tolist() == [-8.0, -8.0]
    seg = np.hypot(*np.diff(route.polyline, axis=0).T)
    assert np.isclose(seg.sum(), route.length_m) and np.isclose(route.leg_m.sum(),
                                                                route.length_m)
    for k in route.order:  # the polyline passes through every station
        assert np.hypot(*(route.polyline - STATIONS[k]).T).min() == 0.0
    assert shapely.LineString(route.polyline).intersects(shapely.box(-0.1, -10, 0.1, 4)) is False
    # the wall forces the two east stations into one visit: west-side stations, then east, back
    east = [k for k, s in enumerate(STATIONS) if s[0] > 0]
    pos = [route.order.tolist().index(k) for k in east]
    assert abs(pos[0] - pos[1]) == 1


def test_untrafficable_start_names_the_fix():
    dem, tm = _field()
    with pytest.raises(ConfigError, match=r"^`route_start` \(0\.00, 0\.00\) m is not on "
                                          r"trafficable ground \(keep-out\); move `route_start` "
                                          r"to trafficable ground; the nearest trafficable point "
                                          r"is \((-0\.50|0\.50), 0\.00\) m$"):
        plan_route(tm, (0.0, 0.0), STATIONS, list("ABCDE"))
    with pytest.raises(ConfigError, match=r"\(off the DEM\)"):
        plan_route(tm, (30.0, 0.0), STATIONS, list("ABCDE"))


def test_unreachable_station_names_it():
    dem, tm = _field()
    with pytest.raises(DataError, match=r"^station C at \(0\.00, -5\.00\) m is not on "
                                        r"trafficable ground \(keep-out\)"):
        plan_route(tm, (-8.0, -8.0), np.array([[1.0, 1.0], [-1.0, 1.0], [0.0, -5.0]]),
                   list("ABC"))
