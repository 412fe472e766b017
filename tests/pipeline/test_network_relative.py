"""Relative accuracy between stations (pipeline.network.relative): the pair covariance is
``D Sigma D^T`` of the full covariance, and the 95 % horizontal relative ellipse holds about
95 % of simulated networks' errors."""

import numpy as np
import pytest
from scipy.stats import chi2

from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.observations import Datum
from pipeline.network.relative import HORIZONTAL_SCALE_95, pair_covariances, relative_figures
from pipeline.network.simulation import simulated_network


@pytest.mark.parametrize("kind", ["station", "free"])
def test_pair_covariance_is_the_difference_operator_on_the_full_covariance(kind):
    obs, truth = simulated_network(n_stations=7, seed=8)
    s = len(obs.station_ids)
    first, second = np.triu_indices(s, k=1)
    for covariance in ("dense", "sparse"):
        result = adjust(obs, Datum(kind), AdjustmentSettings(snooping=False,
                                                             covariance=covariance),
                        truth.nominal)
        dense = adjust(obs, Datum(kind), AdjustmentSettings(snooping=False,
                                                            covariance="dense"),
                       truth.nominal).covariance
        # D: (3p, u), +1 on the second station's x, y, z and -1 on the first's
        p, u = first.size, dense.shape[0]
        d = np.zeros((3 * p, u))
        rows = 3 * np.arange(p)[:, None] + np.arange(3)
        d[rows, 6 * second[:, None] + np.arange(3)] = 1.0
        d[rows, 6 * first[:, None] + np.arange(3)] = -1.0
        full = d @ dense @ d.T
        expected = np.stack([full[3 * i:3 * i + 3, 3 * i:3 * i + 3] for i in range(p)])
        got = pair_covariances(result.covariance, first, second)
        assert np.allclose(got, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())


def test_horizontal_ellipse_holds_95_percent_of_simulated_errors():
    """200 noisy networks of one geometry (new noise, tilts and odometry each): the error of
    the adjusted horizontal vector between two neighbouring stations lies in its 95 % relative
    ellipse about 95 % of the time (3-sigma binomial band: 181..199 of 200)."""
    n, inside = 200, 0
    settings = AdjustmentSettings(snooping=False, covariance="sparse")
    first, second = np.array([2]), np.array([3])
    for draw in range(n):
        obs, truth = simulated_network(n_stations=5, seed=21, noise_seed=1000 + draw)
        result = adjust(obs, settings=settings, nominal=truth.nominal)
        fig = relative_figures(pair_covariances(result.covariance, first, second),
                               np.array([[1.0, 0.0, 0.0]]))
        error = ((result.pose[3, :2] - result.pose[2, :2])
                 - (truth.pose[3, :2] - truth.pose[2, :2]))
        h = fig.covariance[0, :2, :2]
        inside += float(error @ np.linalg.solve(h, error)) <= HORIZONTAL_SCALE_95**2
    band = 3 * np.sqrt(n * 0.95 * 0.05)
    assert abs(inside - 0.95 * n) <= band, inside
    assert HORIZONTAL_SCALE_95**2 == pytest.approx(chi2.ppf(0.95, 2))
