"""Network adjustment: truth recovery, hand-derived covariances, datum invariance, Monte-Carlo
coverage of the 95 % ellipsoids, bad inputs and speed."""

import time

import numpy as np
import pytest
from scipy.stats import chi2

from markerplan.errors import ConfigError, InputFileError
from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.observations import ControlPoint, Datum, NetworkObservations, NominalPoses
from pipeline.network.simulation import simulated_network

NO_SNOOPING = AdjustmentSettings(snooping=False)


def exact_network(**kwargs):
    """A network with exact measurements and no tilt, so the truth is the exact solution."""
    return simulated_network(noise_scale=0.0, inclinometer_sigma_rad=0.0, **kwargs)


def reference_pose(truth):
    return tuple(truth.pose[0, :4])


def relabel(obs, station_prefix, marker_prefix):
    return NetworkObservations(tuple(station_prefix + s for s in obs.station_ids),
                               tuple(marker_prefix + m for m in obs.marker_ids), obs.station,
                               obs.marker, obs.xyz_m, obs.sigma_m)


def merged(a, b):
    """Two networks as one set of observations (nothing shared between them)."""
    return NetworkObservations(a.station_ids + b.station_ids, a.marker_ids + b.marker_ids,
                               np.concatenate([a.station, b.station + len(a.station_ids)]),
                               np.concatenate([a.marker, b.marker + len(a.marker_ids)]),
                               np.vstack([a.xyz_m, b.xyz_m]),
                               np.concatenate([a.sigma_m, b.sigma_m]))


def test_exact_network_recovered_from_nominal_poses_off_by_metres():
    obs, truth = exact_network(n_stations=12, seed=4, odometry_sigma_m=1.5,
                               odometry_heading_sigma_rad=0.15)
    nominal = truth.nominal
    assert np.abs(nominal.position_m - truth.pose[:, :3]).max() > 3.0
    assert np.abs(nominal.heading_rad - truth.pose[:, 3]).max() > 0.3
    result = adjust(obs, settings=NO_SNOOPING, nominal=nominal)
    assert np.abs(result.pose - truth.pose).max() < 1e-9
    assert np.abs(result.marker_xyz_m - truth.marker_xyz_m).max() < 1e-9
    assert result.sigma0_squared < 1e-12
    assert result.rejected == []


def test_exact_network_recovered_without_nominal_poses():
    obs, truth = exact_network(n_stations=12, seed=6)
    result = adjust(obs, Datum(reference_pose=reference_pose(truth)), NO_SNOOPING)
    assert np.abs(result.pose - truth.pose).max() < 1e-9
    assert np.abs(result.marker_xyz_m - truth.marker_xyz_m).max() < 1e-9
    # without a reference pose, the site frame is the reference station's own frame
    own = adjust(obs, settings=NO_SNOOPING)
    assert np.abs(own.pose[0, :4]).max() == 0.0
    distance = np.linalg.norm(own.marker_xyz_m - own.pose[3, :3], axis=1)
    assert np.allclose(distance, np.linalg.norm(truth.marker_xyz_m - truth.pose[3, :3], axis=1),
                       atol=1e-9)


def test_exact_network_recovered_from_control_points_without_nominal_poses():
    obs, truth = exact_network(n_stations=8, seed=7)
    control = tuple(ControlPoint(obs.marker_ids[j], truth.marker_xyz_m[j], [0.002] * 3)
                    for j in (0, len(obs.marker_ids) - 1))
    result = adjust(obs, Datum(kind="control", control=control), NO_SNOOPING)
    assert np.abs(result.pose - truth.pose).max() < 1e-9
    assert np.abs(result.marker_xyz_m - truth.marker_xyz_m).max() < 1e-9


def test_single_station_marker_covariance_is_noise_plus_inclinometer():
    """One station fixes its x, y, z, heading; the tilt is known only from its prior, so each
    marker's covariance is ``sigma^2/3 I + s_incl^2 (d_roll d_roll^T + d_pitch d_pitch^T)`` with
    ``d_roll = (0, -p_z, p_y)``, ``d_pitch = (p_z, 0, -p_x)`` (heading 0), and two markers
    correlate through the shared tilt."""
    p = np.array([[10.0, 2.0, -1.0], [-3.0, 8.0, -1.5]])
    sigma, s_incl = 0.01, 1e-3
    obs = NetworkObservations(("S1",), ("A", "B"), [0, 0], [0, 1], p, [sigma, sigma])
    result = adjust(obs, settings=AdjustmentSettings(inclinometer_sigma_rad=s_incl,
                                                     snooping=False))
    d = np.stack([np.column_stack([np.zeros(2), -p[:, 2], p[:, 1]]),
                  np.column_stack([p[:, 2], np.zeros(2), -p[:, 0]])])  # (2 tilts, 2 markers, 3)
    for a in range(2):
        expected = sigma**2 / 3 * np.eye(3) + s_incl**2 * (d[:, a].T @ d[:, a])
        assert np.allclose(result.marker_covariance(a), expected, rtol=1e-9, atol=1e-15)
    assert np.allclose(result.covariance[6:9, 9:12], s_incl**2 * d[:, 0].T @ d[:, 1],
                       rtol=1e-9, atol=1e-15)
    assert result.dof == 0 and np.allclose(result.redundancy, 0.0, atol=1e-9)
    assert np.all(result.w_test == 0.0) and np.all(np.isinf(result.mdb_m))


def test_two_station_covariance_matches_hand_derivation():
    """S1 (reference) at the origin and S2 at (D, 0, 0), both heading 0, both see markers a, b at
    (D/2, +-Y, 0), each axis with variance v. Eliminating the markers, S2 sees two fixed points
    with variance 2v: var x2 = v, var y2 = v (1 + D^2 / 4Y^2), var heading = v / Y^2,
    cov(y2, heading) = v D / 2Y^2, var z2 = v; the heights give var z_a = 3v/4,
    cov(z_a, z_b) = v/4. The tilt is held by a near-zero inclinometer sigma."""
    d_, y_, sigma = 20.0, 6.0, 0.01
    v = sigma**2 / 3
    markers = np.array([[d_ / 2, y_, 0.0], [d_ / 2, -y_, 0.0]])
    stations = np.array([[0.0, 0.0, 0.0], [d_, 0.0, 0.0]])
    obs = NetworkObservations(("S1", "S2"), ("a", "b"), [0, 0, 1, 1], [0, 1, 0, 1],
                              np.vstack([markers - stations[0], markers - stations[1]]),
                              [sigma] * 4)
    result = adjust(obs, settings=AdjustmentSettings(inclinometer_sigma_rad=1e-9,
                                                     snooping=False))
    c2 = result.station_covariance("S2")
    assert c2[0, 0] == pytest.approx(v, rel=1e-6)
    assert c2[1, 1] == pytest.approx(v * (1 + d_**2 / (4 * y_**2)), rel=1e-6)
    assert c2[3, 3] == pytest.approx(v / y_**2, rel=1e-6)
    assert c2[1, 3] == pytest.approx(v * d_ / (2 * y_**2), rel=1e-6)
    assert c2[2, 2] == pytest.approx(v, rel=1e-6)
    assert abs(c2[0, 1]) < 1e-12 and abs(c2[0, 3]) < 1e-12
    assert result.marker_covariance("a")[2, 2] == pytest.approx(0.75 * v, rel=1e-6)
    assert result.covariance[12 + 2, 15 + 2] == pytest.approx(0.25 * v, rel=1e-6)
    assert np.all(result.station_covariance("S1")[:4, :4] == 0.0)
    assert result.dof == 3 * 4 + 2 * 2 - (6 * 2 + 3 * 2 - 4)


@pytest.mark.parametrize("datum_kind", ["station", "control"])
def test_redundancy_numbers_sum_to_degrees_of_freedom(datum_kind):
    """trace(Q_vv P) over all observations equals the redundancy; the priors' (and control
    points') share is ``1 - var_posterior / var_prior``."""
    obs, truth = simulated_network(n_stations=6, seed=5)
    control = tuple(ControlPoint(obs.marker_ids[j], truth.marker_xyz_m[j], [0.005] * 3)
                    for j in (0, 4, 9)) if datum_kind == "control" else ()
    settings = AdjustmentSettings(snooping=False)
    result = adjust(obs, Datum(kind=datum_kind, control=control), settings, truth.nominal)
    s = len(obs.station_ids)
    tilt = np.array([result.covariance[6 * i + a, 6 * i + a] for i in range(s) for a in (4, 5)])
    total = result.redundancy.sum() + np.sum(1 - tilt / settings.inclinometer_sigma_rad**2)
    for c in control:
        total += np.sum(1 - np.diag(result.marker_covariance(c.marker_id)) / c.sigma_m**2)
    unknowns = 6 * s + 3 * len(obs.marker_ids) - (4 if datum_kind == "station" else 0)
    assert result.dof == 3 * obs.n + 2 * s + 3 * len(control) - unknowns
    assert total == pytest.approx(result.dof, rel=1e-9)
    assert np.all((result.redundancy >= 0) & (result.redundancy <= 1))


def _distance_variances(result, obs):
    """Variances of some inter-marker and station-to-station distances (datum-free), m^2."""
    s, k = len(obs.station_ids), len(obs.marker_ids)
    points = [(6 * s + 3 * a, 6 * s + 3 * b) for a, b in ((0, 3), (1, k - 1), (2, k // 2))]
    points += [(6 * a, 6 * b) for a, b in ((1, s - 1), (0, 2))]
    params = np.concatenate([result.pose.ravel(), result.marker_xyz_m.ravel()])
    g = np.zeros((len(points), params.size))
    for row, (a, b) in enumerate(points):
        d = params[a:a + 3] - params[b:b + 3]
        g[row, a:a + 3], g[row, b:b + 3] = d / np.linalg.norm(d), -d / np.linalg.norm(d)
    return np.einsum("ij,jk,ik->i", g, result.covariance, g)


def test_relative_precision_is_the_same_under_any_datum():
    """Inter-marker distances and their variances do not depend on the datum: reference station
    S01, reference S04, or the free network with minimal constraints. On the free network the
    constrained quantities (the stations' centroid) have zero variance."""
    obs, truth = exact_network(n_stations=7, seed=8)
    results = [adjust(obs, Datum(), NO_SNOOPING, truth.nominal),
               adjust(obs, Datum(reference_station="S04"), NO_SNOOPING, truth.nominal),
               adjust(obs, Datum(kind="free"), NO_SNOOPING, truth.nominal)]
    variances = [_distance_variances(r, obs) for r in results]
    for var in variances[1:]:
        assert np.allclose(var, variances[0], rtol=1e-8)
    free = results[2]
    s = len(obs.station_ids)
    centroid = np.zeros((3, free.covariance.shape[0]))
    for axis in range(3):
        centroid[axis, 6 * np.arange(s) + axis] = 1.0 / s
    assert np.abs(centroid @ free.covariance @ centroid.T).max() < 1e-12 * np.trace(
        free.covariance)
    # station datum: the reference is exact, the far end least precise
    station = results[0]
    errors = [np.trace(station.station_covariance(i)[:3, :3]) for i in range(s)]
    assert errors[0] == 0.0 and errors[-1] > errors[1] > 0.0


def test_relative_precision_datum_invariance_holds_with_noise():
    obs, truth = simulated_network(n_stations=7, seed=8)
    station = adjust(obs, Datum(), NO_SNOOPING, truth.nominal)
    free = adjust(obs, Datum(kind="free"), NO_SNOOPING, truth.nominal)
    assert np.allclose(_distance_variances(free, obs), _distance_variances(station, obs),
                       rtol=1e-4)
    assert free.sigma0_squared == pytest.approx(station.sigma0_squared, rel=1e-9)
    assert free.dof == station.dof


def test_monte_carlo_ellipsoids_cover_95_percent_and_sigma0_is_one():
    """200 noise realisations of one network (reference station at its true pose): the true
    errors of the non-reference stations' positions and of the markers fall inside their 95 %
    ellipsoids (a-priori covariance) 93-97 % of the time; the mean sigma0^2 is 1."""
    k95 = chi2.ppf(0.95, 3)
    inside, sigma0 = [], []
    for trial in range(200):
        obs, truth = simulated_network(n_stations=5, seed=11, noise_seed=1000 + trial)
        result = adjust(obs, settings=NO_SNOOPING, nominal=truth.nominal)
        for i in range(1, 5):
            e = result.pose[i, :3] - truth.pose[i, :3]
            inside.append(e @ np.linalg.solve(result.station_covariance(i)[:3, :3], e) <= k95)
        for j in range(len(obs.marker_ids)):
            e = result.marker_xyz_m[j] - truth.marker_xyz_m[j]
            inside.append(e @ np.linalg.solve(result.marker_covariance(j), e) <= k95)
        sigma0.append(result.sigma0_squared)
    coverage = np.mean(inside)
    assert 0.93 <= coverage <= 0.97, coverage
    standard_error = np.sqrt(2.0 / result.dof / len(sigma0))
    assert abs(np.mean(sigma0) - 1.0) < 3 * standard_error, np.mean(sigma0)


def test_heading_prior_tightens_the_far_stations_and_fixes_the_free_rotation():
    obs, truth = simulated_network(n_stations=10, seed=12)
    rng = np.random.default_rng(0)
    sun = NominalPoses(truth.nominal.position_m, truth.pose[:, 3] + rng.normal(0, 0.002, 10))
    plain = adjust(obs, settings=NO_SNOOPING, nominal=sun)
    prior = adjust(obs, settings=AdjustmentSettings(heading_prior_sigma_rad=0.002,
                                                    snooping=False), nominal=sun)
    assert prior.station_covariance(9)[3, 3] < plain.station_covariance(9)[3, 3]
    assert np.trace(prior.station_covariance(9)[:3, :3]) < np.trace(
        plain.station_covariance(9)[:3, :3])
    assert prior.dof == plain.dof + 10
    # a free network with a sun sensor only lacks the translation
    free = adjust(obs, Datum(kind="free"), AdjustmentSettings(heading_prior_sigma_rad=0.002,
                                                              snooping=False), sun)
    assert free.dof == plain.dof + 10 - 1
    assert free.station_covariance(0)[3, 3] > 0


def test_point_covariance_and_ellipsoid_helpers():
    obs, truth = simulated_network(n_stations=4, seed=1)
    result = adjust(obs, settings=NO_SNOOPING, nominal=truth.nominal)
    cov = result.marker_covariance(obs.marker_ids[2])
    assert np.array_equal(cov, result.marker_covariance(2))
    semi, axes = result.ellipsoid(cov)
    assert np.allclose(axes @ np.diag(semi**2 / chi2.ppf(0.95, 3)) @ axes.T, cov)
    assert np.array_equal(result.station_covariance("S02"), result.station_covariance(1))
    assert result.datum.describe(obs.station_ids) == ("reference station S01 "
                                                      "(x, y, z, heading fixed)")


def test_disconnected_stations_are_named():
    a, _ = simulated_network(n_stations=4, seed=1)
    b, _ = simulated_network(n_stations=2, seed=2)
    obs = merged(a, relabel(b, "F", "N"))
    with pytest.raises(InputFileError, match=r"^stations FS01, FS02 share fewer than 2 markers "
                       r"with the part of the network holding the reference S01$"):
        adjust(obs)
    # a station sharing a single marker with the rest cannot be tied either
    k = len(a.marker_ids)
    lone = NetworkObservations(a.station_ids + ("X",), a.marker_ids + ("N1", "N2"),
                               np.append(a.station, [4, 4, 4]), np.append(a.marker, [0, k, k + 1]),
                               np.vstack([a.xyz_m, [[5, 0, -1], [0, 5, -1], [-5, 0, -1]]]),
                               np.append(a.sigma_m, [0.01] * 3))
    with pytest.raises(InputFileError, match="^stations X share fewer than 2 markers"):
        adjust(lone)


def test_datum_that_does_not_fix_the_network_names_the_free_defect():
    obs, truth = simulated_network(n_stations=5, seed=3)
    one = (ControlPoint(obs.marker_ids[0], truth.marker_xyz_m[0], [0.01] * 3),)
    with pytest.raises(ConfigError, match=r"leave heading \(rotation about the vertical\) free"):
        adjust(obs, Datum(kind="control", control=one), nominal=truth.nominal)
    # with a sun sensor one control point is enough
    sun = AdjustmentSettings(heading_prior_sigma_rad=0.01, snooping=False)
    assert adjust(obs, Datum(kind="control", control=one), sun, truth.nominal).dof > 0
    with pytest.raises(ConfigError, match="control points are needed by"):
        Datum(kind="control")
    with pytest.raises(ConfigError, match="datum kind must be one of"):
        Datum(kind="lander")


@pytest.mark.parametrize("offset", [[0.0, 0.0, 0.0], [0.0, 0.0, 5.0], [0.004, 0.0, 0.0]],
                         ids=["identical", "stacked", "within-sigma"])
def test_control_points_at_one_horizontal_position_leave_the_heading_free(offset):
    """Two control points at one x, y (identical, stacked vertically, or closer than their
    sigma) fix no heading, whatever the markers' estimated positions: refused like one point;
    points farther apart than their sigma fix it."""
    obs, truth = simulated_network(n_stations=5, seed=3)
    xyz = truth.marker_xyz_m[0]
    two = (ControlPoint(obs.marker_ids[0], xyz, [0.01] * 3),
           ControlPoint(obs.marker_ids[1], xyz + offset, [0.01] * 3))
    with pytest.raises(ConfigError, match=r"leave heading \(rotation about the vertical\) free: "
                       r"they stand at one horizontal position within their sigma"):
        adjust(obs, Datum(kind="control", control=two), NO_SNOOPING, truth.nominal)
    apart = (two[0], ControlPoint(obs.marker_ids[1], truth.marker_xyz_m[1], [0.01] * 3))
    assert Datum(kind="control", control=apart).control_heading_sigma_rad() < 0.01
    assert adjust(obs, Datum(kind="control", control=apart), NO_SNOOPING, truth.nominal).dof > 0


@pytest.mark.parametrize(("settings", "message"), [
    (dict(inclinometer_sigma_rad=1e-300), r"^inclinometer_sigma_rad must be a number > 0 \(at "
                                          r"least 8.6e-78"),
    (dict(heading_prior_sigma_rad=1e-200), "^heading_prior_sigma_rad must be a number > 0"),
    (dict(inclinometer_sigma_rad=0.0), "^inclinometer_sigma_rad must be a number > 0"),
])
def test_prior_sigmas_whose_weight_overflows_are_refused(settings, message):
    with pytest.raises(ConfigError, match=message):
        AdjustmentSettings(**settings)
    with pytest.raises(ConfigError, match=r"`sigma_m` must be > 0 \(at least"):
        ControlPoint("C", [0, 0, 0], [1e-300] * 3)


def test_smallest_sigmas_and_significance_level_still_adjust():
    """At the smallest accepted prior sigma the weights stay finite, and ``alpha0`` down to
    the smallest float has a finite critical value: the adjustment runs, and the exact tilt
    prior only adds information (no variance grows)."""
    from pipeline.network.observations import MIN_SIGMA
    from pipeline.network.reliability import critical_value

    obs, truth = simulated_network(n_stations=4, seed=1)
    settings = AdjustmentSettings(inclinometer_sigma_rad=MIN_SIGMA, alpha0=5e-324)
    result = adjust(obs, settings=settings, nominal=truth.nominal)
    plain = adjust(obs, settings=AdjustmentSettings(alpha0=5e-324), nominal=truth.nominal)
    assert np.isfinite(result.covariance).all() and np.isfinite(result.w_test).all()
    assert critical_value(5e-324) == pytest.approx(38.485, abs=1e-3)
    assert np.all(np.diag(result.covariance) <= np.diag(plain.covariance) * (1 + 1e-9))


@pytest.mark.parametrize(("datum", "settings", "message"), [
    (Datum(reference_station="S99"), AdjustmentSettings(),
     r"^`reference_station` 'S99' is not a station of the network; valid ids are S01, S02, "
     r"S03$"),
    (Datum(kind="control", control=(ControlPoint("X7", [0, 0, 0], [1, 1, 1]),)),
     AdjustmentSettings(), r"^control points X7 are not markers of the network$"),
    (Datum(), AdjustmentSettings(heading_prior_sigma_rad=0.01), "needs nominal poses"),
])
def test_bad_datum_or_settings_give_one_line_errors(datum, settings, message):
    obs, _ = simulated_network(n_stations=3, seed=1)
    with pytest.raises(ConfigError, match=message):
        adjust(obs, datum, settings)


@pytest.mark.parametrize(("field", "value", "message"), [
    ("sigma_m", -0.01, r"^`sigma_m` must be finite and > 0 \(at least 8.6e-78: .*\), got -0.01 "
                       r"\(station S01, marker "),
    ("sigma_m", np.nan, r"`sigma_m` must be finite and > 0 \(.*\), got nan"),
    ("sigma_m", 1e-300, r"`sigma_m` must be finite and > 0 \(at least 8.6e-78: a smaller "
                        r"sigma's weight 1/sigma\^2 overflows\), got 1e-300"),
    ("xyz_m", np.nan, r"^`xyz_m` must be finite, got \[nan, nan, nan\] \(station S01"),
    ("marker", 999, r"^`marker` indices must lie in \[0, "),
])
def test_bad_observations_give_one_line_errors(field, value, message):
    obs, _ = simulated_network(n_stations=3, seed=1)
    values = {name: np.array(getattr(obs, name), dtype=float if name in ("xyz_m", "sigma_m")
                             else int) for name in ("station", "marker", "xyz_m", "sigma_m")}
    values[field][1] = value
    with pytest.raises(InputFileError, match=message):
        NetworkObservations(obs.station_ids, obs.marker_ids, **values)


def test_malformed_observations_and_settings_are_refused():
    with pytest.raises(InputFileError, match=r"`xyz_m` must have shape \(2, 3\)"):
        NetworkObservations(("S1",), ("A",), [0, 0], [0, 0], np.zeros((2, 2)), [0.01, 0.01])
    with pytest.raises(InputFileError, match="every marker needs an observation; none of B"):
        NetworkObservations(("S1",), ("A", "B"), [0], [0], np.zeros((1, 3)), [0.01])
    with pytest.raises(InputFileError, match="`station_ids` must be unique, got S1 more"):
        NetworkObservations(("S1", "S1"), ("A",), [0], [0], np.zeros((1, 3)), [0.01])
    with pytest.raises(ConfigError, match="inclinometer_sigma_rad must be a number > 0"):
        AdjustmentSettings(inclinometer_sigma_rad=-1.0)
    with pytest.raises(ConfigError, match="alpha0 must lie in"):
        AdjustmentSettings(alpha0=1.5)
    with pytest.raises(ConfigError, match="control point M1: `sigma_m` must be > 0"):
        ControlPoint("M1", [0, 0, 0], [0.01, 0, 0.01])
    with pytest.raises(ConfigError, match="nominal poses must be finite"):
        NominalPoses(np.zeros((2, 3)), [0.0, np.nan])


def test_hundred_stations_thousand_observations_adjust_in_well_under_three_seconds():
    """The issue asks < 1 s (benchmarks/adjust_network.py prints the figure); the guard here is
    generous, and on the smaller of wall and CPU time, since on a machine busy with other work
    the wall time of threaded BLAS grows while the work does not. Data snooping is on, the data
    clean."""
    obs, truth = simulated_network(n_stations=100, markers_per_station=2.5, seed=3)
    assert 900 <= obs.n <= 1100
    adjust(obs, nominal=truth.nominal)  # warm-up (imports, BLAS threads)
    start, cpu = time.perf_counter(), time.process_time()
    result = adjust(obs, nominal=truth.nominal)
    elapsed = min(time.perf_counter() - start, time.process_time() - cpu)
    assert elapsed < 3.0, elapsed
    assert result.covariance.shape == (6 * 100 + 3 * len(obs.marker_ids),) * 2
    assert len(result.rejected) <= 6
