import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.chain.ground import (
    GROUND_MAX_SLOPE,
    SUPPORT_CELL_M,
    SUPPORT_RADIUS_M,
    local_ground_height,
    remove_ground,
    rise_over_slope,
)


def test_marker_on_sloped_ground_keeps_upper_part():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 10, (20000, 2))
    ground = np.column_stack([xy, 0.02 * xy[:, 0] - 1.0])  # ~1.1 deg slope
    u = rng.normal(size=(2000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    centre = np.array([5.1, 5.1, 0.02 * 5.1 - 1.0 + 0.1])
    sphere = centre + 0.1 * u
    pts = np.vstack([ground, sphere])
    above = remove_ground(pts, 0.5, 0.1)
    assert not above[:20000].any()
    # points >= 0.1 m above the ground = the sphere's upper half (minus a sliver)
    upper = sphere[:, 2] - (0.02 * sphere[:, 0] - 1.0) >= 0.105
    assert above[20000:][upper].all()
    np.testing.assert_allclose(local_ground_height(ground, 0.5), ground[:, 2], atol=0.011)


def test_ground_height_is_the_lowest_point_of_each_cell():
    """Against a plain per-cell minimum, on cells with negative indices and cell edges."""
    rng = np.random.default_rng(1)
    pts = rng.uniform(-3, 2, (3000, 3))
    pts[:50, :2] = rng.integers(-6, 4, (50, 2)) * 0.5  # on cell edges
    cells = [tuple(c) for c in np.floor(pts[:, :2] / 0.5)]
    lowest = {}
    for c, z in zip(cells, pts[:, 2], strict=True):
        lowest[c] = min(lowest.get(c, np.inf), z)
    np.testing.assert_array_equal(local_ground_height(pts, 0.5), [lowest[c] for c in cells])


@pytest.mark.parametrize("kwargs", [{"cell_m": 0}, {"min_height_m": -1}, {"max_slope": -1},
                                    {"steepness_tolerance_m": -0.01},
                                    {"support_radius_m": 0}])
def test_bad_parameters(kwargs):
    with pytest.raises(ConfigError):
        remove_ground(np.zeros((3, 3)), **kwargs)


def test_empty_cloud():
    assert remove_ground(np.zeros((0, 3))).shape == (0,)


def _profile(r_m, diameter_m):
    return pytest.importorskip("visibility.terrain").fresh_crater_profile(r_m, diameter_m)


def _crater_ground(rng, n=200_000, noise_m=0.005):
    """Returns on a fresh 8 m crater (bowl, rim crest, ejecta) centred at (0, 0)."""
    xy = rng.uniform(-6.0, 6.0, (n, 2))
    z = _profile(np.hypot(xy[:, 0], xy[:, 1]), 8.0) - 1.0
    return np.column_stack([xy, z + rng.normal(0, noise_m, n)])


def test_fresh_crater_rim_and_walls_are_ground():
    """The 38 deg inner wall and the rim crest of a fresh crater rise up to 0.4 m above the
    lowest return of their 0.5 m cells (the height test alone keeps thousands of them, which
    chain a nearby marker into a rim cluster); the steepness test takes them for ground, and
    a marker 0.45 m outside the rim, on the 8 deg ejecta, keeps its upper half."""
    rng = np.random.default_rng(2)
    ground = _crater_ground(rng)
    assert (ground[:, 2] - local_ground_height(ground, 0.5) >= 0.1).sum() > 5000
    u = rng.normal(size=(3000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    foot = np.array([4.45, 0.0])
    centre = np.array([*foot, _profile(np.array([4.45]), 8.0)[0] - 1.0 + 0.1])
    sphere = centre + 0.1 * u
    above = remove_ground(np.vstack([ground, sphere]), 0.5, 0.1)
    assert above[:len(ground)].sum() < 10
    upper = sphere[:, 2] - centre[2] >= 0.01
    assert above[len(ground):][upper].mean() > 0.99


def test_rise_over_slope_against_brute_force():
    """Rise over the cone on the lowest return of each support cell within the radius,
    negative coordinates included; a point with no position rises -inf."""
    rng = np.random.default_rng(4)
    xyz = np.column_stack([rng.uniform(-3, 2, 4000), rng.uniform(-2, 3, 4000),
                           rng.normal(0, 0.2, 4000)])
    xyz[5] = [np.nan, 0.0, 0.0]
    queries = np.arange(0, 4000, 7)
    got = rise_over_slope(xyz, queries)
    ok = np.isfinite(xyz[:, 0])
    cells = np.floor(xyz[ok, :2] / SUPPORT_CELL_M)
    _, inverse = np.unique(cells, axis=0, return_inverse=True)
    lowest = {}
    for i, c in zip(np.flatnonzero(ok), inverse.ravel(), strict=True):
        if c not in lowest or xyz[i, 2] < xyz[lowest[c], 2]:
            lowest[c] = i
    low = xyz[list(lowest.values())]
    for q, rise in zip(queries, got, strict=True):
        if not ok[q]:
            assert rise == -np.inf
            continue
        d = np.hypot(*(low[:, :2] - xyz[q, :2]).T)
        near = d <= SUPPORT_RADIUS_M
        assert rise == pytest.approx(np.max(xyz[q, 2] - low[near, 2] - GROUND_MAX_SLOPE * d[near]),
                                     abs=1e-12)
