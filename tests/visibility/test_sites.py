"""Site presets: layout, reproducibility, and the three-direction visibility of the default."""

import time

import numpy as np
import pytest

from markerplan.errors import ConfigError, DataError
from visibility.dem import DEM
from visibility.scene import RayScene
from visibility.sites import load_site, site_with_dem


@pytest.fixture(scope="module")
def default_site():
    return load_site("default")


def test_default_layout(default_site):
    site = default_site
    assert len(site.station_ids) == 7 and len(site.marker_ids) == 11
    assert site.marker_radius_m == 0.10
    ground = site.dem.height_at(site.marker_centres_m[:, :2])
    np.testing.assert_allclose(site.marker_centres_m[:, 2], ground + 0.10)
    np.testing.assert_allclose(site.station_position_m[:, 2],
                               site.dem.height_at(site.station_xy_m) + 1.0)
    xmin, xmax, ymin, ymax = site.dem.extent()
    bx, by = site.boundary_xy_m[:, 0], site.boundary_xy_m[:, 1]
    assert xmax - xmin == pytest.approx(60) and bx.max() - bx.min() == pytest.approx(40)
    assert xmin <= bx.min() - 10 and xmax >= bx.max() + 10 and ymin <= by.min() - 10
    assert ymax >= by.max() + 10
    diam = [c.diameter_m for c in site.craters]
    assert sum(2 <= d <= 8 for d in diam) >= 5
    assert {c.kind for c in site.craters} == {"fresh", "degraded"}
    assert len(site.rock_radii_m) >= 3


def test_every_default_station_sees_markers_in_three_directions(default_site):
    site = default_site
    scene = RayScene(site.dem, site.marker_centres_m, site.marker_radius_m)
    centres = site.marker_centres_m
    for s, origin in enumerate(site.station_position_m):
        o = np.broadcast_to(origin, centres.shape)
        hits = scene.intersect(o, centres - o)
        seen = hits.sphere_index == np.arange(len(centres))
        az = np.arctan2(centres[:, 1] - origin[1], centres[:, 0] - origin[0])
        sectors = set(np.floor(np.mod(az[seen], 2 * np.pi) / (np.pi / 3)).astype(int))
        assert seen.sum() >= 3, site.station_ids[s]
        assert len(sectors) >= 3, (site.station_ids[s], sectors)


def test_presets_are_reproducible_and_seeded(default_site):
    again = load_site("default", seed=0)
    np.testing.assert_array_equal(again.dem.heights_m, default_site.dem.heights_m)
    other = load_site("default", seed=1)
    assert not np.array_equal(other.dem.heights_m, default_site.dem.heights_m)
    np.testing.assert_array_equal(other.station_xy_m, default_site.station_xy_m)


def test_large_preset_is_big_and_fast():
    t0 = time.perf_counter()
    site = load_site("large")
    assert time.perf_counter() - t0 < 10.0
    assert len(site.station_ids) >= 100
    xmin, xmax, ymin, ymax = site.dem.extent()
    assert xmax - xmin >= 300 and ymax - ymin >= 300
    assert site.dem.contains(site.station_xy_m).all()
    assert site.dem.contains(site.marker_centres_m[:, :2]).all()


def test_unknown_preset_lists_valid_names():
    with pytest.raises(ConfigError, match="default, large"):
        load_site("moon")


def test_site_on_another_dem(default_site):
    small = DEM(np.zeros((11, 11)), (-5.0, -5.0), 1.0)
    with pytest.raises(DataError, match="station S2 .* outside the DEM"):
        site_with_dem(default_site, small)
    big = DEM(np.full((61, 61), 3.0), (-30.0, -30.0), 1.0)
    moved = site_with_dem(default_site, big)
    np.testing.assert_allclose(moved.marker_centres_m[:, 2], 3.1)
    assert moved.craters == [] and len(moved.rock_radii_m) == 0
