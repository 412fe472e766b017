"""Tiled visibility (stations in blocks, one DEM tile each) against one scene of the whole DEM."""

import numpy as np
import pytest

from visibility.dem import DEM
from visibility.scene import RayScene
from visibility.terrain import CraterSpec, TerrainSpec, generate_terrain
from visibility.visibility_matrix import (
    VisibilityGroup,
    group_visibility,
    station_groups,
    tile_rectangle,
    tiled_visibility,
    visibility_matrix,
)

FIELDS = ("station", "site", "distance_m", "elevation_rad", "bearing_rad", "visible_fraction",
          "expected_points")


@pytest.fixture(scope="module")
def rough_field():
    """A 40 m crater field at 0.1 m cells, 12 stations, ~700 sites: occlusion everywhere."""
    spec = TerrainSpec(extent_m=(-20.0, 20.0, -20.0, 20.0), cell_size_m=0.1, hurst=0.85,
                       roughness_1m_m=0.03, rolloff_m=10.0, crater_density=0.02,
                       crater_diameter_range_m=(0.5, 3.0), rock_abundance=0.02,
                       rock_diameter_range_m=(0.15, 0.5),
                       craters=(CraterSpec((3.0, 2.0), 6.0, 0.0),))
    dem = generate_terrain(spec, np.random.default_rng(5)).dem
    rng = np.random.default_rng(6)
    sxy = rng.uniform(-17.0, 17.0, (12, 2))
    st = np.column_stack([sxy, dem.height_at(sxy) + 0.4])
    g = np.arange(-18.5, 18.6, 1.4)
    gx, gy = np.meshgrid(g, g)
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    si = np.column_stack([xy, dem.height_at(xy) + 0.1])
    return dem, st, si


def test_tiled_equals_whole_dem(rough_field):
    dem, st, si = rough_field
    whole = visibility_matrix(RayScene(dem), st, si, 0.1, 8.0, 24, progress=False)
    tiled, stats = tiled_visibility(dem, st, si, 0.1, 8.0, 24, block_m=6.0, progress=False)
    assert stats["groups"] > 4  # really tiled
    assert stats["max_tile_triangles"] < 2 * (dem.shape[0] - 1) * (dem.shape[1] - 1) / 2
    assert 0.05 < np.mean(whole.visible_fraction < 1) < 0.95  # occlusion is exercised
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(tiled, name), getattr(whole, name), err_msg=name)
    assert tiled.n_rays == whole.n_rays


def test_map_groups_is_used_and_lazy(rough_field):
    dem, st, si = rough_field
    seen = []

    def spy_map(fn, groups):
        for g in groups:
            assert isinstance(g, VisibilityGroup)
            seen.append(len(g.station_index))
            yield fn(g)

    tiled, stats = tiled_visibility(dem, st, si, 0.1, 8.0, 24, block_m=6.0, map_groups=spy_map,
                                    progress=False)
    assert sum(seen) == len(st) and len(seen) == stats["groups"]
    whole, _ = tiled_visibility(dem, st, si, 0.1, 8.0, 24, block_m=100.0, progress=False)
    np.testing.assert_array_equal(tiled.visible_fraction, whole.visible_fraction)


def test_group_without_sites_builds_no_scene():
    dem = DEM(np.zeros((11, 11)), (0.0, 0.0), 1.0)
    st = np.array([[5.0, 5.0, 1.0]])
    group = VisibilityGroup(dem, np.array([3]), st, np.zeros(0, np.int64), np.zeros((0, 3)),
                            0.1, 5.0, 8, None)
    ans = group_visibility(group)
    assert len(ans.vis) == 0 and ans.n_triangles == 0


def test_station_groups_and_even_tiles():
    xy = np.array([[0.0, 0.0], [25.0, 0.0], [1.0, 1.0], [0.5, 41.0]])
    assert [g.tolist() for g in station_groups(xy, 20.0)] == [[0, 2], [1], [3]]
    dem = DEM(np.zeros((101, 101)), (-5.0, -5.0), 0.1)
    for x in (-1.23, 0.0, 0.05, 0.17):
        tile = dem.crop(*tile_rectangle(np.array([[x, x + 0.31], [x + 0.5, x]]), 1.0))
        i0 = round((tile.origin_m[0] + 5.0) / 0.1)
        j0 = round((tile.origin_m[1] + 5.0) / 0.1)
        assert i0 % 2 == 0 and j0 % 2 == 0
        assert tile.extent()[0] <= x - 1.0 and tile.extent()[1] >= x + 1.5
        assert tile.extent()[2] <= x - 1.0 and tile.extent()[3] >= x + 1.31
