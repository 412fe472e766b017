"""Site presets: layout, reproducibility, and the three-direction visibility of the default."""

import time

import numpy as np
import pytest

from markerplan.errors import ConfigError, DataError
from visibility.dem import DEM
from visibility.scene import RayScene
from visibility.sites import KM_STATION_STEP_M, km_traverse, load_site, points_along, site_with_dem


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


def test_km_traverse_gives_a_few_hundred_stations_along_the_legs():
    xy, heading = points_along(km_traverse(), KM_STATION_STEP_M)
    path = km_traverse()
    length = np.sum(np.hypot(*np.diff(path, axis=0).T))
    assert length == pytest.approx(6 * 900 + 5 * 160)
    assert len(xy) == int(length // KM_STATION_STEP_M) + 1 == 311
    step = np.hypot(*np.diff(xy, axis=0).T)
    assert np.all(step <= KM_STATION_STEP_M + 1e-9) and np.median(step) == pytest.approx(20.0)
    assert np.all(np.abs(xy) <= 450.0)
    np.testing.assert_allclose(np.abs(np.cos(heading[:40])), 1.0)  # first leg: east-west


@pytest.mark.slow
def test_km_preset_extent_cells_stations_and_crater_sfd():
    site = load_site("km")
    assert site.dem.shape == (4001, 4001) and site.dem.cell_size_m == 0.25
    assert site.dem.extent() == (-500.0, 500.0, -500.0, 500.0)
    assert len(site.station_ids) == 311 and len(site.marker_ids) == 96
    assert site.dem.contains(site.station_xy_m).all()
    d = np.array([c.diameter_m for c in site.craters])
    assert d.min() >= 1.0 and 20.0 < d.max() <= 40.0
    # cumulative SFD N(>D) ~ D^-2: ten times the diameter, a hundred times fewer craters
    assert 50 < np.sum(d >= 1.0) / np.sum(d >= 10.0) < 200
    assert len(site.rock_radii_m) > 100 and site.rock_radii_m.max() <= 0.75


def test_unknown_preset_lists_valid_names():
    with pytest.raises(ConfigError, match="default, large, km"):
        load_site("moon")


def test_site_on_another_dem(default_site):
    small = DEM(np.zeros((11, 11)), (-5.0, -5.0), 1.0)
    with pytest.raises(DataError, match="station S2 .* outside the DEM"):
        site_with_dem(default_site, small)
    big = DEM(np.full((61, 61), 3.0), (-30.0, -30.0), 1.0)
    moved = site_with_dem(default_site, big)
    np.testing.assert_allclose(moved.marker_centres_m[:, 2], 3.1)
    assert moved.craters == [] and len(moved.rock_radii_m) == 0
