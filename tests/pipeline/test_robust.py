"""Robust estimation of the network (Huber, IGG-III) against simulated ground truth: three
gross errors of 0.5 m at once are down-weighted, exactly they are flagged, and the robust
solution holds the truth within its covariance where plain least squares does not."""

import numpy as np
import pytest
from scipy.stats import chi2

from markerplan.errors import ConfigError
from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.observations import NetworkObservations
from pipeline.network.reliability import critical_value
from pipeline.network.simulation import simulated_network

#: 99.9 % of chi2(3): a point outside is not explained by the covariance.
CHI2_3_999 = chi2.ppf(0.999, 3)


def blundered(seed: int):
    """A 10-station network whose clean adjustment flags nothing, with gross errors of 0.5 m
    (random directions) in three observations of markers at least three stations see."""
    obs, truth = simulated_network(n_stations=10, seed=40 + seed)
    rng = np.random.default_rng(seed)
    seen = np.bincount(obs.marker)[obs.marker]
    rows = np.sort(rng.choice(np.flatnonzero((seen >= 3) & (obs.station > 0)), 3,
                              replace=False))
    direction = rng.normal(size=(3, 3))
    xyz = obs.xyz_m.copy()
    xyz[rows] += 0.5 * direction / np.linalg.norm(direction, axis=1)[:, None]
    bad = NetworkObservations(obs.station_ids, obs.marker_ids, obs.station, obs.marker, xyz,
                              obs.sigma_m)
    return obs, bad, truth, rows


def mahalanobis(result, truth) -> np.ndarray:
    """Squared Mahalanobis distances of every marker and (non-datum) station position from
    the truth under the result's covariance."""
    d2 = [e @ np.linalg.solve(result.marker_covariance(j), e)
          for j, e in enumerate(result.marker_xyz_m - truth.marker_xyz_m)]
    d2 += [e @ np.linalg.solve(result.station_covariance(i)[:3, :3], e)
           for i, e in enumerate(result.pose[1:, :3] - truth.pose[1:, :3], start=1)]
    return np.array(d2)


@pytest.mark.parametrize("seed", [1, 2])
def test_robust_estimators_find_three_blunders_and_hold_the_truth(seed):
    obs, bad, truth, rows = blundered(seed)
    clean = adjust(obs, settings=AdjustmentSettings(snooping=False), nominal=truth.nominal)
    assert clean.point.w.max() < critical_value(0.001)  # nothing to flag without the blunders
    plain = adjust(bad, settings=AdjustmentSettings(snooping=False), nominal=truth.nominal)
    assert np.sum(mahalanobis(plain, truth) > CHI2_3_999) >= 3  # least squares is spoilt
    for estimator in ("huber", "igg3"):
        result = adjust(bad, settings=AdjustmentSettings(snooping=False, robust=estimator),
                        nominal=truth.nominal)
        assert result.observations.n == obs.n and result.rejected == []
        assert np.flatnonzero(result.point.w > critical_value(0.001)).tolist() == rows.tolist()
        assert sorted(np.argsort(result.robust_weight)[:3]) == rows.tolist()
        if estimator == "igg3":
            assert np.flatnonzero(result.robust_weight == 0.0).tolist() == rows.tolist()
        else:  # Huber: k / w, w in the tens
            assert result.robust_weight[rows].max() < 0.05
            assert np.sort(result.robust_weight)[3] > 0.1
        assert mahalanobis(result, truth).max() < CHI2_3_999, estimator
        assert result.robust_rounds > 1


def test_huber_on_clean_data_is_close_to_least_squares():
    obs, truth = simulated_network(n_stations=8, seed=43)
    plain = adjust(obs, settings=AdjustmentSettings(snooping=False), nominal=truth.nominal)
    huber = adjust(obs, settings=AdjustmentSettings(snooping=False, robust="huber"),
                   nominal=truth.nominal)
    assert np.mean(huber.robust_weight == 1.0) > 0.7  # w <= 1.5 for most
    sigma = np.sqrt(np.array([np.diag(plain.marker_covariance(j))
                              for j in range(len(obs.marker_ids))]))
    assert np.all(np.abs(huber.marker_xyz_m - plain.marker_xyz_m) < sigma)


def test_robust_settings_are_checked():
    with pytest.raises(ConfigError, match="^robust estimation replaces data snooping"):
        AdjustmentSettings(robust="huber")
    with pytest.raises(ConfigError, match="^robust must be None or one of huber, igg3"):
        AdjustmentSettings(robust="l1", snooping=False)
    with pytest.raises(ConfigError, match="^IGG-III needs robust_k0 < robust_k1"):
        AdjustmentSettings(robust="igg3", snooping=False, robust_k0=3.0, robust_k1=2.0)
    AdjustmentSettings(robust="huber", snooping=False, robust_k0=4.0)  # k1 unused by Huber
