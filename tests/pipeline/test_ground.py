import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.ground import local_ground_height, remove_ground


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


@pytest.mark.parametrize("kwargs", [{"cell_m": 0}, {"min_height_m": -1}])
def test_bad_parameters(kwargs):
    with pytest.raises(ConfigError):
        remove_ground(np.zeros((3, 3)), **kwargs)


def test_empty_cloud():
    assert remove_ground(np.zeros((0, 3))).shape == (0,)
