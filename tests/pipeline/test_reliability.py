"""Reliability of the network adjustment: w-test levels, data snooping of a swapped marker id,
false alarms on clean data, minimal detectable biases and their effect."""

import numpy as np
import pytest
from scipy.stats import binom, norm

from markerplan.errors import DataError
from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.observations import Datum, NetworkObservations
from pipeline.network.reliability import critical_value, non_centrality
from pipeline.network.simulation import simulated_network


def test_critical_value_and_non_centrality_of_baarda():
    k = critical_value(0.001)
    assert k == pytest.approx(3.2905, abs=1e-4)
    delta0 = non_centrality(0.001, 0.80)
    assert delta0 == pytest.approx(4.13, abs=0.005)
    # the two-sided test detects a bias of delta0 (in sigmas of its residual) with power beta0
    power = norm.sf(k - delta0) + norm.cdf(-k - delta0)
    assert power == pytest.approx(0.80, abs=1e-6)


def swapped(obs, row_a, row_b):
    """The observations with the marker ids of two detections swapped (a mis-association)."""
    marker = obs.marker.copy()
    marker[[row_a, row_b]] = marker[[row_b, row_a]]
    return NetworkObservations(obs.station_ids, obs.marker_ids, obs.station, marker, obs.xyz_m,
                               obs.sigma_m)


def test_swapped_marker_ids_are_flagged_and_removed():
    obs, truth = simulated_network(n_stations=10, seed=21)
    rows = np.flatnonzero(obs.station == 5)[:2]  # S06's detections of M002 and M006
    assert [obs.marker_ids[j] for j in obs.marker[rows]] == ["M002", "M006"]
    assert np.linalg.norm(obs.xyz_m[rows[0]] - obs.xyz_m[rows[1]]) > 5.0
    blunder = swapped(obs, *rows)
    result = adjust(blunder, nominal=truth.nominal)
    assert [(r.station_id, r.marker_id, r.round) for r in result.rejected] == [
        ("S06", "M002", 1), ("S06", "M006", 2)]
    assert abs(result.rejected[0].w) > 100 * critical_value(0.001)
    assert np.abs(result.w_test).max() <= critical_value(0.001)
    # the result is the adjustment without the two observations, and close to the clean one
    keep = np.ones(obs.n, dtype=bool)
    keep[rows] = False
    without = adjust(obs.subset(keep), settings=AdjustmentSettings(snooping=False),
                     nominal=truth.nominal)
    assert np.abs(result.marker_xyz_m - without.marker_xyz_m).max() < 1e-8
    assert np.abs(result.pose - without.pose).max() < 1e-8
    assert np.allclose(result.covariance, without.covariance, rtol=1e-6, atol=1e-14)
    clean = adjust(obs, nominal=truth.nominal)
    assert clean.rejected == []
    sigma = np.sqrt(np.diag(clean.covariance)).reshape(-1)
    shift = np.concatenate([(result.pose - clean.pose).ravel(),
                            (result.marker_xyz_m - clean.marker_xyz_m).ravel()])
    assert np.all(np.abs(shift) <= sigma + 1e-12)
    # without snooping the blunder spoils the variance factor
    plain = adjust(blunder, settings=AdjustmentSettings(snooping=False), nominal=truth.nominal)
    assert plain.sigma0_squared > 1000


def test_swapped_marker_ids_are_found_in_many_networks():
    """In 12 random networks, two detections of a station (not the last) whose markers at least
    three stations see get each other's ids; data snooping removes those two first, with |w| in
    the tens or more, and otherwise at most a false alarm or two (|w| just above 3.29, as clean
    data gives at alpha0), with and without nominal poses. The contaminated adjustment
    converges slowly: its w-tests at the last iterate already point at the blunder."""
    for seed in range(12):
        obs, truth = simulated_network(n_stations=10, seed=100 + seed)
        rng = np.random.default_rng(seed)
        station = int(rng.integers(1, 9))
        seen = np.bincount(obs.marker)
        rows = rng.choice([r for r in np.flatnonzero(obs.station == station)
                           if seen[obs.marker[r]] >= 3], 2, replace=False)
        nominal = truth.nominal if seed % 2 else None
        datum = Datum(reference_pose=None if nominal else tuple(truth.pose[0, :4]))
        result = adjust(swapped(obs, *rows), datum, nominal=nominal)
        swaps = {(obs.station_ids[station], obs.marker_ids[obs.marker[r]]) for r in rows}
        first = {(r.station_id, r.marker_id) for r in result.rejected[:2]}
        assert first == swaps, seed
        assert min(abs(r.w) for r in result.rejected[:2]) > 20
        assert len(result.rejected) <= 4 and all(abs(r.w) < 5 for r in result.rejected[2:])
        assert np.abs(result.marker_xyz_m - truth.marker_xyz_m).max() < 0.1


def test_unresolvable_blunder_is_named_when_the_adjustment_cannot_converge():
    """A swap at the last station between markers few stations see: the worst observation
    cannot be removed without untying a station, the contaminated adjustment does not
    converge, and the one-line error names where the largest point-test statistic is."""
    obs, truth = simulated_network(n_stations=10, seed=120)
    rng = np.random.default_rng(20)
    rows = rng.choice(np.flatnonzero(obs.station == int(rng.integers(1, 10))), 2, replace=False)
    with pytest.raises(DataError, match=r"^the adjustment did not converge in 20 iterations "
                       r"after 0 removals by data snooping; the largest point-test w \(.*\) is at "
                       r"station S10, marker M017$"):
        adjust(swapped(obs, *rows), nominal=truth.nominal)


def test_max_rejections_limits_data_snooping():
    obs, truth = simulated_network(n_stations=10, seed=21)
    blunder = swapped(obs, *np.flatnonzero(obs.station == 5)[:2])
    result = adjust(blunder, settings=AdjustmentSettings(max_rejections=1),
                    nominal=truth.nominal)
    assert len(result.rejected) == 1
    assert np.abs(result.w_test).max() > critical_value(0.001)


def test_clean_data_false_alarms_match_alpha0():
    """200 clean networks with data snooping: most lose no observation, and the rejections per
    tested point observation are consistent with alpha0 = 0.001 (one test per point)."""
    trials, untouched, rejections, tested = 200, 0, 0, 0
    for trial in range(trials):
        obs, truth = simulated_network(n_stations=5, seed=11, noise_seed=5000 + trial)
        result = adjust(obs, nominal=truth.nominal)
        untouched += not result.rejected
        rejections += len(result.rejected)
        tested += int(np.sum(np.bincount(obs.marker)[obs.marker] > 1))
    assert untouched / trials >= 0.8
    lo, hi = binom.ppf([0.0005, 0.9995], tested, 0.001)
    assert lo <= rejections <= hi, (rejections, tested)


def test_bias_of_one_mdb_gives_w_of_delta0_and_shifts_coordinates_by_the_effect():
    """Exact data plus a bias of one MDB in one component: that component's |w| is delta0
    (the linear model's expectation), and the largest position shift over the three components'
    biases is the reported MDB effect."""
    obs, truth = simulated_network(n_stations=6, seed=9, noise_scale=0.0,
                                   inclinometer_sigma_rad=0.0)
    settings = AdjustmentSettings(snooping=False)
    datum = Datum(reference_pose=tuple(truth.pose[0, :4]))
    base = adjust(obs, datum, settings)
    i = int(np.argmax(base.redundancy.min(axis=1)))
    shifts = []
    for axis in range(3):
        xyz = obs.xyz_m.copy()
        bias = np.zeros(3)
        bias[axis] = base.mdb_m[i, axis]
        # the residual axes are the site frame: bias the measurement by R^T bias
        heading = truth.pose[obs.station[i], 3]
        c, s = np.cos(heading), np.sin(heading)
        xyz[i] += np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) @ bias
        biased = adjust(NetworkObservations(obs.station_ids, obs.marker_ids, obs.station,
                                            obs.marker, xyz, obs.sigma_m), datum, settings)
        assert abs(biased.w_test[i, axis]) == pytest.approx(non_centrality(0.001, 0.8),
                                                            rel=1e-4)
        shifts.append(max(np.linalg.norm(biased.pose[:, :3] - base.pose[:, :3], axis=1).max(),
                          np.linalg.norm(biased.marker_xyz_m - base.marker_xyz_m, axis=1).max()))
    assert max(shifts) == pytest.approx(base.mdb_effect_m[i], rel=1e-4)


def test_uncontrolled_observations_have_zero_redundancy_and_infinite_mdb():
    obs, truth = simulated_network(n_stations=6, seed=9)
    result = adjust(obs, nominal=truth.nominal)
    once = np.bincount(result.observations.marker)[result.observations.marker] == 1
    assert once.any() and (~once).any()
    assert np.allclose(result.redundancy[once], 0.0, atol=1e-9)
    assert np.all(result.w_test[once] == 0.0) and np.all(np.isinf(result.mdb_m[once]))
    assert np.all(np.isinf(result.mdb_effect_m[once]))
    assert np.all(result.redundancy[~once] > 0.01)
    assert np.all(np.isfinite(result.mdb_m[~once]) & (result.mdb_m[~once] > 0))
    assert np.all(result.mdb_effect_m[~once] >= result.mdb_m[~once].min(axis=1) * 0.01)


def test_an_observation_whose_removal_would_untie_a_station_is_kept():
    """Station X shares exactly two markers with the network; a 10 cm bias on one of them is
    flagged (|w| > k) but not removed, since X could no longer be tied."""
    a, truth = simulated_network(n_stations=4, seed=1, noise_scale=0.0,
                                 inclinometer_sigma_rad=0.0)
    k = len(a.marker_ids)
    x = truth.pose[3, :3] + [3.0, 0.0, 0.0]
    shared = np.argsort(np.linalg.norm(truth.marker_xyz_m - x, axis=1))[:2]
    p = np.vstack([truth.marker_xyz_m[shared] - x, [[4.0, 0.0, -1.0], [0.0, 4.0, -1.0]]])
    p[0, 0] += 0.10
    obs = NetworkObservations(a.station_ids + ("X",), a.marker_ids + ("N1", "N2"),
                              np.append(a.station, [4] * 4),
                              np.append(a.marker, [*shared, k, k + 1]),
                              np.vstack([a.xyz_m, p]), np.append(a.sigma_m, [0.01] * 4))
    result = adjust(obs, Datum(reference_pose=tuple(truth.pose[0, :4])))
    assert result.rejected == []
    worst = np.unravel_index(np.argmax(np.abs(result.w_test)), result.w_test.shape)[0]
    assert result.observations.station_ids[result.observations.station[worst]] == "X"
    assert np.abs(result.w_test).max() > critical_value(0.001)
