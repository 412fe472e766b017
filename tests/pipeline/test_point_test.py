"""The test of each point observation as one 3-dimensional group (the decision statistic of
data snooping and of the robust weights), against independent computations: refitting without
the observation, Monte-Carlo draws from the simulator under the null hypothesis, and a bias of
one 3-D minimal detectable bias on exact data."""

import numpy as np
import pytest
from scipy.stats import binom, chi2

from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.normals import linearise
from pipeline.network.observations import Datum, NetworkObservations
from pipeline.network.reliability import (
    critical_value,
    point_non_centrality,
    residual_blocks,
)
from pipeline.network.simulation import simulated_network
from pipeline.scans.rig import rot_z

NO_SNOOPING = AdjustmentSettings(snooping=False)


def test_point_statistic_is_the_drop_of_the_weighted_squares_without_the_observation():
    """``T_i`` equals ``Omega - Omega_without_i`` (the 3-D outlier model is the observation
    left out), refitted by brute force for every tenth observation."""
    obs, truth = simulated_network(n_stations=8, seed=5)
    full = adjust(obs, settings=NO_SNOOPING, nominal=truth.nominal)
    omega = full.sigma0_squared * full.dof
    checked = 0
    for i in np.flatnonzero(full.point.dof == 3)[::10]:
        keep = np.ones(obs.n, dtype=bool)
        keep[i] = False
        without = adjust(obs.subset(keep), settings=NO_SNOOPING, nominal=truth.nominal)
        drop = omega - without.sigma0_squared * without.dof
        assert full.point.statistic[i] == pytest.approx(drop, rel=1e-3, abs=1e-4)
        checked += 1
    assert checked >= 5
    once = np.bincount(obs.marker)[obs.marker] == 1
    assert np.all(full.point.dof[once] == 0) and np.all(full.point.statistic[once] == 0.0)


def test_rejection_rate_under_the_null_hypothesis_is_alpha0():
    """Noise drawn by the simulator (not by the adjustment's model): the share of point
    observations whose test rejects at alpha0 = 0.05 lies within binomial bounds of 0.05, and
    the statistics' mean is the chi2(3) mean."""
    alpha = 0.05
    settings = AdjustmentSettings(snooping=False, alpha0=alpha)
    statistics, rejected = [], 0
    for trial in range(200):
        obs, truth = simulated_network(n_stations=5, seed=11, noise_seed=9000 + trial)
        result = adjust(obs, settings=settings, nominal=truth.nominal)
        tested = result.point.dof == 3
        statistics.append(result.point.statistic[tested])
        rejected += int(np.sum(result.point.w[tested] > critical_value(alpha)))
    t = np.concatenate(statistics)
    lo, hi = binom.ppf([0.0005, 0.9995], t.size, alpha)
    assert lo <= rejected <= hi, (rejected, t.size)
    # the decision on w is the chi2(3) test on T
    assert rejected == int(np.sum(t > chi2.isf(alpha, 3)))
    # (the statistics of one network are correlated: a loose 5-sigma bound on their mean)
    assert t.mean() == pytest.approx(3.0, abs=5 * np.sqrt(6.0 / t.size))


def test_a_bias_of_the_point_mdb_gives_the_non_centrality():
    """Exact data plus a bias of the 3-D MDB along the observation's worst direction:
    ``T = lambda0(alpha0, beta0, 3)`` (the linear model's non-centrality)."""
    obs, truth = simulated_network(n_stations=6, seed=9, noise_scale=0.0,
                                   inclinometer_sigma_rad=0.0)
    datum = Datum(reference_pose=tuple(truth.pose[0, :4]))
    base = adjust(obs, datum, NO_SNOOPING)
    i = int(np.argmin(np.where(base.point.dof == 3, base.mdb_point_m, np.inf)))
    # the worst direction: the eigenvector of the smallest eigenvalue of I - w A Q A^T
    weight = 3.0 / obs.sigma_m[i] ** 2
    blocks, columns = base_blocks(base, obs)
    aqa = residual_blocks(blocks[i:i + 1], columns[i:i + 1], base.covariance)[0]
    lam, vec = np.linalg.eigh(np.eye(3) - weight * aqa)
    bias = base.mdb_point_m[i] * vec[:, 0]
    xyz = obs.xyz_m.copy()
    xyz[i] += rot_z(np.array([truth.pose[obs.station[i], 3]]))[0].T @ bias
    biased = adjust(NetworkObservations(obs.station_ids, obs.marker_ids, obs.station,
                                        obs.marker, xyz, obs.sigma_m), datum, NO_SNOOPING)
    assert biased.point.statistic[i] == pytest.approx(point_non_centrality(0.001, 0.8),
                                                      rel=1e-3)
    assert base.mdb_point_m[i] == pytest.approx(
        np.sqrt(point_non_centrality(0.001, 0.8) / (weight * lam[0])), rel=1e-9)


def base_blocks(result, obs):
    """Design blocks and columns of ``obs`` at the adjusted poses."""
    blocks, columns, _ = linearise(obs, result.pose, result.marker_xyz_m)
    return blocks, columns
