import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.chain.gate import RangeIndex, gate_verdicts, research, two_box_gate


def test_two_box_gate_keeps_marker_sized_clusters():
    rng = np.random.default_rng(2)
    marker = rng.uniform(-0.1, 0.1, (100, 3)) + [3, 0, -0.9]       # 0.2 m
    speck = rng.uniform(-0.01, 0.01, (20, 3)) + [5, 0, -0.9]        # 0.02 m
    boulder = rng.uniform(-0.3, 0.3, (300, 3)) + [8, 0, -0.7]        # 0.6 m
    pts = np.vstack([marker, speck, boulder])
    labels = np.r_[np.zeros(100), np.ones(20), np.full(300, 2)].astype(int)
    ids, centroids = two_box_gate(pts, labels)
    assert ids.tolist() == [0]
    np.testing.assert_allclose(centroids[0], marker.mean(axis=0))
    with pytest.raises(ConfigError):
        two_box_gate(pts, labels, max_box_m=0.05, min_box_m=0.3)


def test_range_index_matches_brute_force():
    rng = np.random.default_rng(3)
    pts = rng.uniform(-20, 20, (50000, 3))
    pts[:, 2] *= 0.05
    index = RangeIndex(pts)
    centres = np.array([[3.0, 4.0, 0.0], [-10.0, 0.1, 0.2], [0.05, 0.0, 0.0], [-15, -0.01, 0]])
    for c, got in zip(centres, research(index, centres, 0.5), strict=True):
        want = np.flatnonzero(np.linalg.norm(pts - c, axis=1) <= 0.5)
        np.testing.assert_array_equal(got, want)


def _cap(rng, centre, radius, n, sensor=(0.0, 0.0, 0.0), noise_m=0.005):
    """n points of the sensor-facing half of a sphere, with range noise."""
    u = rng.normal(size=(4 * n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    los = np.subtract(centre, sensor) / np.linalg.norm(np.subtract(centre, sensor))
    u = u[u @ los < 0][:n]
    return centre + (radius + rng.normal(0, noise_m, (n, 1))) * u


def test_gate_leaves_out_a_thin_tail_but_not_a_boulder():
    """The mixed returns at a near sphere's silhouette trail behind it along the line of sight
    (here 5 % of the points, up to 0.45 m): the bounding box grows past the 0.30 m cube, but
    the cube placed on the sphere holds all but the tail. A boulder, a 0.4 m rock and a slab
    of crater wall spill far more than 10 % of their points out of any 0.30 m cube."""
    rng = np.random.default_rng(5)
    centre = np.array([2.0, 0.5, -0.9])
    los = centre / np.linalg.norm(centre)
    sphere = _cap(rng, centre, 0.1, 950)
    tail = centre + 0.1 * rng.uniform(-0.7, 0.7, (50, 3)) + rng.uniform(0.1, 0.45, (50, 1)) * los
    marker = np.vstack([sphere, tail])
    boulder = _cap(rng, [6.0, 0, -0.6], 0.3, 1000)
    rock = _cap(rng, [9.0, 0, -0.8], 0.2, 1000)
    s, t = rng.uniform(0, 1, (2, 1000))
    wall = np.column_stack([12 + s, t, -1 + 0.78 * s])
    pts = np.vstack([marker, boulder, rock, wall])
    labels = np.repeat(np.arange(4), 1000)
    assert np.ptp(marker, axis=0).max() > 0.4
    assert gate_verdicts(pts, labels).tolist() == ["passed", "too_large", "too_large",
                                                  "too_large"]
    ids, centroids = two_box_gate(pts, labels)
    assert ids.tolist() == [0]


@pytest.mark.parametrize(("n_out", "verdict"), [(10, "passed"), (11, "too_large")])
def test_gate_lets_a_tenth_of_the_points_spill(n_out, verdict):
    rng = np.random.default_rng(6)
    cap = rng.uniform(0, 0.2, (100 - n_out, 3))
    far = rng.uniform(0.5, 0.9, (n_out, 3))
    assert gate_verdicts(np.vstack([cap, far]), np.zeros(100, dtype=int)).tolist() == [verdict]


def test_gate_judges_a_cluster_that_fits_the_cube_by_its_bounding_box():
    """Nothing spills out of a cube that holds the bounding box: the verdicts are the
    bounding box's (edge > max_box: too large, <= min_box: too small), clusters in any
    order and position."""
    rng = np.random.default_rng(7)
    sizes = rng.uniform(0.01, 0.6, 40)
    pts = np.vstack([rng.uniform(-20, 20, 3) + rng.uniform(0, s, (30, 3)) for s in sizes])
    labels = rng.permutation(np.repeat(np.arange(40), 30))
    shuffled = np.empty_like(pts)
    shuffled[np.argsort(labels, kind="stable")] = pts  # cluster k's points under label k
    pts = shuffled
    edge = np.array([np.ptp(pts[labels == k], axis=0).max() for k in range(40)])
    got = gate_verdicts(pts, labels)
    fits = edge <= 0.30
    want = np.where(edge > 0.05, "passed", "too_small")
    assert got[fits].tolist() == want[fits].tolist()
    spill = np.array([1 - _best_cube_share(pts[labels == k]) for k in range(40)])
    assert (got[~fits] == np.where(spill > 0.1, "too_large", "passed")[~fits]).all()


def _best_cube_share(points, edge=0.30):
    """Share of the points held by the 0.30 m cube the gate places (brute force: per axis the
    window starting at a point that holds the most, lowest start on ties)."""
    lo = []
    for axis in range(3):
        v = np.sort(points[:, axis])
        count = [(np.sum((v >= a) & (v <= a + edge)), -a) for a in v]
        lo.append(-max(count)[1])
    inside = np.all((points >= lo) & (points <= np.add(lo, edge)), axis=1)
    return inside.mean()


def test_gate_on_no_clusters_and_bad_spill():
    assert gate_verdicts(np.zeros((3, 3)), np.full(3, -1)).shape == (0,)
    pts = np.vstack([np.zeros((9, 3)), [[0.2, 0, 0], [0.9, 0, 0]]])
    assert gate_verdicts(pts, np.zeros(11, dtype=int), spill_fraction=0.0).tolist() == [
        "too_large"]  # nothing may spill: the bounding box must fit
    with pytest.raises(ConfigError, match="spill_fraction"):
        gate_verdicts(pts, np.zeros(11, dtype=int), spill_fraction=0.5)
