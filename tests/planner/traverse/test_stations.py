"""Candidate stations: the grid clipped to the area, to trafficable ground and to the ground
the rover can reach; the guard against huge grids."""

import numpy as np
import pytest
import shapely

from markerplan.errors import ConfigError, DataError
from planner.traverse.stations import MAX_STATION_CANDIDATES, candidate_stations
from planner.traverse.trafficability import TrafficSettings, trafficable_map
from visibility.dem import DEM

OPEN = TrafficSettings(footprint_m=0.5, grid_m=0.5, hazard_standoff_m=0.0)


def _tilted():
    x = np.arange(201) * 0.1
    return DEM(np.tile(0.05 * x, (201, 1)), (0.0, 0.0), 0.1)  # 2.9 deg ramp along x


def test_grid_clipped_to_area_and_trafficable_ground():
    dem = _tilted()
    keep = shapely.box(9.0, 9.0, 13.0, 13.0)
    tm = trafficable_map(dem, OPEN, keepouts=[keep])
    area = shapely.Point(10.0, 10.0).buffer(7.0)
    ids, xy, pos = candidate_stations(tm, area, 2.0, 1.2, dem)
    gx, gy = np.meshgrid(np.arange(0, 21, 2.0), np.arange(0, 21, 2.0))
    grid = np.column_stack([gx.ravel(), gy.ravel()])  # row by row, x increasing
    want = grid[shapely.contains_xy(area, *grid.T) & ~shapely.intersects_xy(keep, *grid.T)]
    assert xy.tolist() == want.tolist()
    assert ids == [f"P{k:04d}" for k in range(1, len(want) + 1)]
    assert np.allclose(pos[:, 2], 0.05 * xy[:, 0] + 1.2)


def test_stations_cut_off_from_the_start_are_dropped():
    dem = DEM(np.zeros((201, 201)), (0.0, 0.0), 0.1)
    ring = shapely.box(10.0, 10.0, 18.0, 18.0).difference(shapely.box(11.0, 11.0, 17.0, 17.0))
    tm = trafficable_map(dem, OPEN, keepouts=[ring])
    area = shapely.box(1.0, 1.0, 19.0, 19.0)
    _, every, _ = candidate_stations(tm, area, 2.0, 1.0, dem)
    _, reached, _ = candidate_stations(tm, area, 2.0, 1.0, dem, start_xy=(2.0, 2.0))
    enclosed = (every[:, 0] > 11) & (every[:, 0] < 17) & (every[:, 1] > 11) & (every[:, 1] < 17)
    assert enclosed.sum() == 9
    assert reached.tolist() == every[~enclosed].tolist()


def test_huge_grid_and_empty_result_are_one_line_errors():
    dem = _tilted()
    tm = trafficable_map(dem, OPEN)
    assert 201 ** 2 > MAX_STATION_CANDIDATES
    with pytest.raises(ConfigError,
                       match=r"^`station_spacing_m` 0\.1 m lays 40401 candidate stations"):
        candidate_stations(tm, shapely.box(0, 0, 20, 20), 0.1, 1.0, dem)
    with pytest.raises(DataError, match=r"no candidate station is left \(dropped: 0 outside "
                                        r"the area, 1 not trafficable\)"):
        candidate_stations(tm, shapely.box(-1, -1, 1, 1), 2.0, 1.0, dem)
