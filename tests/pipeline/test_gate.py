import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.gate import RangeIndex, research, two_box_gate


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
