"""Trafficability: slope and roughness against an independent least-squares plane fit, crater
interiors, keep-outs and the standoff's dilation distance."""

from types import SimpleNamespace

import numpy as np
import pytest
import shapely

from markerplan.errors import ConfigError
from planner.traverse.trafficability import REASONS, TrafficSettings, trafficable_map
from visibility.dem import DEM

FLAT = TrafficSettings(footprint_m=0.5, grid_m=0.5, hazard_standoff_m=0.0)


def _plane(slope_deg, azimuth_deg=30.0, n=41, cell=0.1):
    x = cell * np.arange(n)
    xx, yy = np.meshgrid(x, x)
    a = np.radians(azimuth_deg)
    h = np.tan(np.radians(slope_deg)) * (np.cos(a) * xx + np.sin(a) * yy)
    return DEM(h, (0.0, 0.0), cell)


def _inner(tm):
    """The nodes whose footprint lies on the DEM."""
    return tm.reason != REASONS.index("nodata or edge") + 1


@pytest.mark.parametrize(("slope_deg", "passes"), [(14.9, True), (15.1, False)])
def test_tilted_plane_just_under_and_over_the_slope_limit(slope_deg, passes):
    tm = trafficable_map(_plane(slope_deg), TrafficSettings(footprint_m=0.5, grid_m=0.5,
                                                            hazard_standoff_m=0.0))
    inner = _inner(tm)
    assert inner.sum() == 49
    assert tm.trafficable[inner].all() == passes
    if not passes:
        assert (tm.reason[inner] == REASONS.index("slope") + 1).all()


def test_slope_and_roughness_match_an_independent_plane_fit():
    dem = DEM(np.random.default_rng(3).normal(0, 0.05, (41, 41)), (0.0, 0.0), 0.1)
    r, c = 4, 3  # node -> DEM cell (20, 15); footprint 0.5 m = 5 x 5 cells
    z = dem.heights_m[18:23, 13:18].ravel()
    v, u = np.meshgrid(np.arange(-2, 3) * 0.1, np.arange(-2, 3) * 0.1, indexing="ij")
    a = np.column_stack([np.ones(25), u.ravel(), v.ravel()])
    coef, *_ = np.linalg.lstsq(a, z, rcond=None)
    rms = np.sqrt(np.mean((z - a @ coef) ** 2))
    slope = np.degrees(np.arctan(np.hypot(coef[1], coef[2])))
    for eps, ok in ((1e-6, True), (-1e-6, False)):
        s = TrafficSettings(footprint_m=0.5, grid_m=0.5, hazard_standoff_m=0.0,
                            max_slope_deg=89.0, max_roughness_m=rms * (1 + eps))
        assert trafficable_map(dem, s).trafficable[r, c] == ok
        s = TrafficSettings(footprint_m=0.5, grid_m=0.5, hazard_standoff_m=0.0,
                            max_slope_deg=slope * (1 + eps), max_roughness_m=1.0)
        assert trafficable_map(dem, s).trafficable[r, c] == ok


def test_crater_interior_excluded():
    dem = DEM(np.zeros((81, 81)), (-4.0, -4.0), 0.1)
    crater = SimpleNamespace(centre_xy_m=(0.2, -0.3), diameter_m=3.0)
    tm = trafficable_map(dem, FLAT, craters=[crater])
    xy = tm.node_xy()
    d = np.hypot(xy[:, 0] - 0.2, xy[:, 1] + 0.3)
    inner = _inner(tm).ravel()
    code = tm.reason.ravel()
    assert (code[inner & (d < 1.5)] == REASONS.index("crater interior") + 1).all()
    assert tm.trafficable.ravel()[inner & (d >= 1.5)].all()
    assert (inner & (d < 1.5)).sum() > 20


def test_keepout_polygon_excluded_and_standoff_dilates_by_its_distance():
    dem = DEM(np.zeros((101, 101)), (0.0, 0.0), 0.1)
    keep = shapely.box(4.8, 4.8, 5.2, 5.2)  # holds exactly the node (5, 5)
    s = TrafficSettings(footprint_m=0.5, grid_m=0.5, hazard_standoff_m=1.2)
    tm = trafficable_map(dem, s, keepouts=[keep])
    xy = tm.node_xy()
    d = np.hypot(xy[:, 0] - 5.0, xy[:, 1] - 5.0)
    code = tm.reason.ravel()
    inner = _inner(tm).ravel()
    assert code[d == 0].tolist() == [REASONS.index("keep-out") + 1]
    ring = (d > 0) & (d <= 1.2)
    assert ring.sum() == 20  # nodes within 1.2 m of a node on a 0.5 m grid
    assert (code[ring] == REASONS.index("standoff") + 1).all()
    # elsewhere only the DEM edge (footprint off the DEM) and its standoff fail
    edge_d = np.minimum.reduce([xy[:, 0], xy[:, 1], 10 - xy[:, 0], 10 - xy[:, 1]])
    far = (d > 1.2) & inner
    assert (tm.trafficable.ravel()[far] == (edge_d[far] > 1.2 + 1e-9)).all()
    assert tm.counts()["keep-out"] == 1


def test_points_report_their_reason_and_the_nearest_trafficable_point():
    dem = DEM(np.zeros((101, 101)), (0.0, 0.0), 0.1)
    tm = trafficable_map(dem, FLAT, keepouts=[shapely.box(3.0, 3.0, 7.0, 7.0)])
    assert tm.why_not(np.array([[5.0, 5.0], [1.0, 1.0], [20.0, 1.0]])) == [
        "keep-out", "", "off the DEM"]
    assert tm.nearest_trafficable(np.array([[5.0, 3.2]])).tolist() == [[5.0, 2.5]]


def test_grid_must_be_whole_dem_cells():
    dem = DEM(np.zeros((11, 11)), (0.0, 0.0), 0.2)
    with pytest.raises(ConfigError, match="`grid_m` 0.5 m must be a whole number"):
        trafficable_map(dem, TrafficSettings(grid_m=0.5))
