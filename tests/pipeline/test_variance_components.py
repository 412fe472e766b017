"""Variance components per observation group against simulated ground truth: one station
whose noise is twice the stated sigma gets a factor of about 4, the others about 1; the same
for a range band; and the estimates scatter as their stated standard deviation says."""

import numpy as np
import pytest

from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.observations import NetworkObservations
from pipeline.network.simulation import simulated_network

GEOMETRY = dict(n_stations=6, markers_per_station=5.0, seed=7)


def louder(where, noise_seed: int):
    """The simulated network with the noise of the observations ``where(obs)`` doubled: the
    same draws at noise_scale 2 (same geometry, tilts and odometry), sigmas as stated."""
    obs, truth = simulated_network(**GEOMETRY, noise_seed=noise_seed)
    loud, _ = simulated_network(**GEOMETRY, noise_seed=noise_seed, noise_scale=2.0)
    xyz = np.where(where(obs)[:, None], loud.xyz_m, obs.xyz_m)
    return NetworkObservations(obs.station_ids, obs.marker_ids, obs.station, obs.marker, xyz,
                               obs.sigma_m), truth


@pytest.mark.parametrize("by, loud_group, where", [
    ("station", "S03", lambda obs: obs.station == 2),
    ("range", "10-20 m", lambda obs: (np.linalg.norm(obs.xyz_m, axis=1) >= 10)
     & (np.linalg.norm(obs.xyz_m, axis=1) < 20)),
])
def test_a_group_with_twice_the_noise_gets_a_factor_of_four(by, loud_group, where):
    settings = AdjustmentSettings(snooping=False, variance_components=by)
    estimates, sds = [], []
    for trial in range(12):
        obs, truth = louder(where, 300 + trial)
        result = adjust(obs, settings=settings, nominal=truth.nominal)
        components = result.variance_components
        names = [c.group for c in components]
        estimates.append([c.sigma0_squared for c in components])
        sds.append([c.sd for c in components])
    assert loud_group in names
    # a group whose iterated redundancy fell below one has no estimate (nan) in that trial
    estimates, sds = np.array(estimates), np.array(sds)
    assert np.isfinite(estimates).sum(axis=0).min() >= 10
    mean = np.nanmean(estimates, axis=0)
    spread = np.nanmean(sds, axis=0) / np.sqrt(np.isfinite(estimates).sum(axis=0))
    loud = names.index(loud_group)
    expected = np.where(np.arange(len(names)) == loud, 4.0, 1.0)
    assert np.all(np.abs(mean - expected) < 4 * spread), (names, mean, spread)
    # the stated sd is the estimates' scatter (within a factor for 12 trials)
    scatter = np.nanstd(estimates, axis=0, ddof=1)
    stated = np.nanmean(sds, axis=0)
    assert np.all((scatter > 0.4 * stated) & (scatter < 2.0 * stated)), (scatter, stated)


def test_components_leave_the_adjustment_as_it_was():
    obs, truth = simulated_network(**GEOMETRY)
    plain = adjust(obs, settings=AdjustmentSettings(snooping=False), nominal=truth.nominal)
    both = adjust(obs, settings=AdjustmentSettings(snooping=False, variance_components="range"),
                  nominal=truth.nominal)
    assert np.array_equal(plain.marker_xyz_m, both.marker_xyz_m)
    assert np.array_equal(plain.covariance, both.covariance)
    assert sum(c.n_observations for c in both.variance_components) == obs.n
    # the groups' redundancies add up to the observations' share of the degrees of freedom
    assert sum(c.redundancy for c in both.variance_components) < both.dof
