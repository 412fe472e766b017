import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.chain.clustering import euclidean_clusters


def test_two_blobs_and_noise():
    rng = np.random.default_rng(1)
    a = rng.normal([0, 0, 0], 0.03, (200, 3))
    b = rng.normal([2, 0, 0], 0.03, (150, 3))
    noise = np.array([[10.0, 10, 10], [20, 20, 20]])
    labels = euclidean_clusters(np.vstack([a, b, noise]), 0.2, 5)
    assert (labels[:200] == 0).all() and (labels[200:350] == 1).all()
    assert (labels[350:] == -1).all()


def test_chain_links_and_gap_splits():
    x = np.r_[np.arange(0, 1.0, 0.1), np.arange(1.5, 2.5, 0.1)]
    pts = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    labels = euclidean_clusters(pts, 0.15, 2)
    assert len(set(labels.tolist())) == 2


def test_bad_input():
    with pytest.raises(ConfigError):
        euclidean_clusters(np.zeros((3, 2)))
    with pytest.raises(ConfigError):
        euclidean_clusters(np.zeros((3, 3)), tolerance_m=0)
    assert euclidean_clusters(np.zeros((0, 3))).shape == (0,)
