import math

import numpy as np
import pytest
from scipy.stats import chi2

from markerplan.errors import ConfigError
from pipeline.network.association import associate_by_geometry, associate_with_plan
from pipeline.network.simulation import simulated_network
from pipeline.scans.rig import rot_z

ODOMETRY_M = 0.5
HEADING_RAD = math.radians(2.0)


def _sigma(distance_m):
    """Realistic centre error: 5 mm near the station, 20 mm at 30 m."""
    return 0.005 + 0.0005 * np.asarray(distance_m)


def _layout(rng, n, extent_m, min_spacing_m):
    """Random marker sites on gently rolling ground, no two closer than ``min_spacing_m``."""
    sites = []
    while len(sites) < n:
        p = rng.uniform(-extent_m, extent_m, 2)
        if all(np.hypot(*(p - q)) >= min_spacing_m for q in sites):
            sites.append(p)
    xy = np.array(sites)
    return np.column_stack([xy, 0.3 * np.sin(xy[:, 0] / 7.0) + 0.2 * np.cos(xy[:, 1] / 5.0)])


def _observe(rng, markers, position, heading, max_range_m=30.0):
    """Indices seen (shuffled), their noisy levelled-frame centres and sigmas."""
    d = np.linalg.norm(markers - position, axis=1)
    seen = rng.permutation(np.flatnonzero((d > 1.0) & (d <= max_range_m)))
    sigma = _sigma(d[seen])
    xyz = (markers[seen] - position) @ rot_z(heading)
    return seen, xyz + rng.normal(size=xyz.shape) * (sigma / math.sqrt(3.0))[:, None], sigma


def _plan_station(seed, n_markers=25, min_spacing_m=8.0):
    rng = np.random.default_rng(seed)
    markers = _layout(rng, n_markers, 35.0, min_spacing_m)
    position, heading = np.array([0.0, 0.0, 1.5]), rng.uniform(-np.pi, np.pi)
    seen, xyz, sigma = _observe(rng, markers, position, heading)
    nominal = position + rng.normal(0.0, ODOMETRY_M, 3)
    return markers, seen, xyz, sigma, nominal, heading + rng.normal(0.0, HEADING_RAD)


def _associate(markers, xyz, sigma, nominal, heading, ids=None, **kw):
    ids = [f"P{j}" for j in range(len(markers))] if ids is None else ids
    return associate_with_plan(xyz, nominal, heading, markers, ids, sigma, ODOMETRY_M,
                               HEADING_RAD, **kw)


def test_plan_association_recovers_every_true_id_inside_its_gate():
    inside = assigned = 0
    for seed in range(15):
        markers, seen, xyz, sigma, nominal, heading = _plan_station(seed)
        res = _associate(markers, xyz, sigma, nominal, heading)
        for i, j in enumerate(seen):
            own = _associate(markers[[j]], xyz[[i]], sigma[[i]], nominal, heading, ["own"])
            if own.mahalanobis_sq[0] <= res.gate:
                inside += 1
                assert res.ids[i] == f"P{j}", (seed, i, res.status[i])
            assert res.ids[i] in (f"P{j}", None)
            assigned += res.ids[i] is not None
    assert inside > 150 and assigned >= inside


@pytest.mark.parametrize("odometry_m, heading_rad", [(ODOMETRY_M, HEADING_RAD), (0.0, 0.0)])
def test_the_gate_holds_its_probability(odometry_m, heading_rad):
    """Squared Mahalanobis distances of the true marker follow chi-square(3), whether the
    odometry error (lever arm included) or the detection noise alone dominates."""
    rng = np.random.default_rng(7)
    trials, within = 500, 0
    for _ in range(trials):
        marker = np.array([[*rng.uniform(-30.0, 30.0, 2), 0.0]])
        seen, xyz, sigma = _observe(rng, marker, np.array([0.0, 0.0, 1.5]), 0.3, 60.0)
        nominal = np.array([0.0, 0.0, 1.5]) + rng.normal(0.0, odometry_m, 3)
        res = associate_with_plan(xyz, nominal, 0.3 + rng.normal(0.0, heading_rad), marker,
                                  ["A"], sigma, odometry_m, heading_rad, gate_probability=0.9)
        within += res.status[0] == "assigned"
    assert abs(within / trials - 0.9) < 0.04


def test_a_marker_missing_from_the_plan_stays_unassigned():
    markers, seen, xyz, sigma, nominal, heading = _plan_station(3)
    # a stray marker 4 m from its nearest planned one (8 m spacing): outside every gate
    stray = xyz[0] + [4.0, 0.0, 0.0]
    res = _associate(markers, np.vstack([xyz, stray]), np.r_[sigma, 0.01], nominal, heading)
    assert res.ids[-1] is None and res.status[-1] == "outside_gate"
    assert res.ids[:-1] == [f"P{j}" for j in seen]
    # a stray 0.3 m from a planned, detected marker: neither is given an id it may not own
    res = _associate(markers, np.vstack([xyz, xyz[0] + [0.3, 0.0, 0.0]]), np.r_[sigma, 0.01],
                     nominal, heading)
    assert res.ids[0] is None and res.ids[-1] is None
    assert res.status[0] == res.status[-1] == "ambiguous"
    assert res.ids[1:-1] == [f"P{j}" for j in seen[1:]]


def test_planned_markers_closer_than_the_odometry_error_are_ambiguous():
    plan = np.array([[10.0, 0.0, 0.0], [10.0, 0.4, 0.0], [0.0, 12.0, 0.0]])
    det = plan - [0.2, -0.1, 1.5]  # truth: station at (0.2, -0.1, 1.5), heading 0
    sigma = np.full(3, 0.01)
    res = associate_with_plan(det, [0.0, 0.0, 1.5], 0.0, plan, "ABC", sigma, ODOMETRY_M,
                              HEADING_RAD)
    assert res.ids == [None, None, "C"]
    assert res.status[:2] == ("ambiguous", "ambiguous")
    # the same markers are told apart once the pose is known to 2 cm
    res = associate_with_plan(det, [0.2, -0.1, 1.5], 0.0, plan, "ABC", sigma, 0.02, 1e-3)
    assert res.ids == ["A", "B", "C"]


def test_heading_error_that_swaps_nearest_markers_is_resolved_by_the_gate_shape():
    """A 5 deg heading error moves far marker A next to B's prediction; the gate is long
    across the line of sight (heading) but short along it (position), so A stays A."""
    plan = np.array([[30.0, 0.0, 0.0], [28.5, 2.2, 0.0]])
    true_heading = math.radians(-5.0)  # nominal heading 0, odometry wrong by 5 deg
    det = plan[[0]] @ rot_z(true_heading)  # Rz(h)^T m: A seen from the origin
    nearest = np.argmin(np.linalg.norm(plan - det, axis=1))
    assert nearest == 1  # nearest-neighbour on the nominal pose would take B
    res = associate_with_plan(det, [0.0, 0.0, 0.0], 0.0, plan, ["A", "B"], [0.02], 0.2,
                              math.radians(2.0))
    assert res.ids == ["A"] and res.mahalanobis_sq[0] < res.gate


def test_empty_plan_and_no_detections():
    res = associate_with_plan(np.ones((2, 3)), [0, 0, 0], 0.0, np.zeros((0, 3)), [],
                              [0.01, 0.01], 0.5, 0.03)
    assert res.ids == [None, None] and res.status == ("outside_gate", "outside_gate")
    assert np.all(np.isinf(res.mahalanobis_sq))


@pytest.mark.parametrize("change, match", [
    ({"detections_xyz": np.full((1, 3), np.nan)}, "detections_xyz.*finite"),
    ({"detections_xyz": np.zeros((1, 2))}, r"shape \(n, 3\), got \(1, 2\)"),
    ({"detection_sigma_m": [-0.01]}, "detection_sigma_m.*> 0"),
    ({"detection_sigma_m": [0.01, 0.01]}, r"shape \(1,\)"),
    ({"odometry_sigma_m": -1.0}, "odometry_sigma_m.*>= 0"),
    ({"odometry_heading_sigma_rad": -0.1}, "odometry_heading_sigma_rad"),
    ({"nominal_position_m": [0.0, np.nan, 0.0]}, "nominal_position_m"),
    ({"plan_ids": ["A", "A"]}, "unique"),
    ({"plan_ids": ["A"]}, "one id per row"),
    ({"gate_probability": 1.0}, "gate_probability"),
])
def test_plan_bad_input_is_one_line(change, match):
    args = {"detections_xyz": np.zeros((1, 3)), "nominal_position_m": [0.0, 0.0, 0.0],
            "nominal_heading_rad": 0.0, "plan_xyz": np.ones((2, 3)), "plan_ids": ["A", "B"],
            "detection_sigma_m": [0.01], "odometry_sigma_m": 0.5,
            "odometry_heading_sigma_rad": 0.03} | change
    with pytest.raises(ConfigError, match=match) as err:
        associate_with_plan(**args)
    assert "\n" not in str(err.value)


def _traverse(seed):
    """Six stations of a simulated network, detections shuffled within each station."""
    obs, _ = simulated_network(n_stations=6, seed=seed, sigma_m=_sigma)
    rng = np.random.default_rng(seed)
    stations, truth, sigmas = [], [], []
    for s, name in enumerate(obs.station_ids):
        rows = rng.permutation(np.flatnonzero(obs.station == s))
        stations.append((name, obs.xyz_m[rows]))
        truth.append(obs.marker[rows])
        sigmas.append(obs.sigma_m[rows])
    return stations, truth, sigmas


def _partition(labels):
    """The partition of (station, detection) given by per-station labels."""
    groups = {}
    for s, row in enumerate(labels):
        for d, label in enumerate(row):
            groups.setdefault(label, set()).add((s, d))
    return {frozenset(g) for g in groups.values()}


@pytest.mark.parametrize("seed", [1, 3, 5])
def test_geometry_recovers_the_true_partition_of_a_traverse(seed):
    stations, truth, sigmas = _traverse(seed)
    res = associate_by_geometry(stations, sigmas)
    assert _partition(res.ids) == _partition(truth)
    assert res.refused_merges == 0
    assert sum(p.status == "matched" for p in res.pairs) >= 5


def test_geometry_never_merges_markers_of_a_regular_grid():
    g = np.arange(-20.0, 40.1, 4.0)
    grid = np.array([[x, y, 0.0] for x in g for y in np.arange(-12.0, 12.1, 4.0)])
    rng = np.random.default_rng(0)
    stations, truth, sigmas = [], [], []
    for s in range(3):
        seen, xyz, sigma = _observe(rng, grid, np.array([5.0 * s, 0.5, 1.5]),
                                    rng.uniform(-np.pi, np.pi), 10.0)
        stations.append((f"S{s}", xyz))
        truth.append(seen)
        sigmas.append(sigma)
    res = associate_by_geometry(stations, sigmas)
    found, true = _partition(res.ids), _partition(truth)
    assert all(any(f <= t for t in true) for f in found)  # no false merge
    assert any(p.status == "ambiguous" for p in res.pairs)
    # the same grid placed with 0.3 m errors is no longer symmetric: its markers are linked
    rough = grid + np.c_[rng.normal(0.0, 0.3, (len(grid), 2)), np.zeros(len(grid))]
    seen = [_observe(np.random.default_rng(s), rough, np.array([5.0 * s, 0.5, 1.5]), 0.4 * s,
                     10.0) for s in range(3)]
    res = associate_by_geometry([(f"S{s}", o[1]) for s, o in enumerate(seen)],
                                [o[2] for o in seen])
    assert _partition(res.ids) == _partition([o[0] for o in seen])


def test_geometry_ids_are_deterministic_and_ordered():
    stations, _, sigmas = _traverse(2)
    first = associate_by_geometry(stations, sigmas)
    assert first.ids == associate_by_geometry(stations, sigmas).ids
    n0 = len(stations[0][1])
    assert first.ids[0] == [f"M{i + 1:03d}" for i in range(n0)]


def test_a_merge_that_would_join_two_detections_of_one_station_is_refused():
    """Markers T and U lie 5 cm apart. A sees T only, B sees U only, C sees both: A-B matches
    T with U, so C's T and U would become one marker; that merge is refused."""
    rng = np.random.default_rng(4)
    common = _layout(rng, 6, 12.0, 4.0)
    t, u = np.array([[3.0, -14.0, 0.0]]), np.array([[3.05, -14.0, 0.0]])
    sets = {"A": np.vstack([common, t]), "B": np.vstack([common, u]),
            "C": np.vstack([common, t, u])}
    stations = [(name, (m - [0.0, 0.0, 1.5]) @ rot_z(0.5 * i))
                for i, (name, m) in enumerate(sets.items())]
    res = associate_by_geometry(stations, 0.03)
    assert res.refused_merges >= 1
    for row in res.ids:
        assert len(set(row)) == len(row)  # no marker holds two detections of a station
    assert res.ids[2][6] != res.ids[2][7]


@pytest.mark.parametrize("stations, kw, match", [
    ([("S1", np.zeros((2, 3))), ("S1", np.zeros((2, 3)))], {}, "unique"),
    ([("S1", np.full((2, 3), np.nan))], {}, "station 'S1'.*finite"),
    ([("S1", np.zeros((2, 2)))], {}, r"shape \(n, 3\)"),
    ([("S1", np.zeros((2, 3)))], {"detection_sigma_m": -0.01}, "detection_sigma_m"),
    ([("S1", np.zeros((2, 3)))], {"detection_sigma_m": [np.ones(3)]}, r"shape \(2,\)"),
    ([("S1", np.zeros((2, 3)))], {"station_pairs": [("S1", "S9")]}, "unknown station.*S9"),
    ([("S1", np.zeros((2, 3)))], {"min_correspondences": 2}, "min_correspondences"),
    ([np.zeros((2, 3))], {}, "station_id, detections"),
])
def test_geometry_bad_input_is_one_line(stations, kw, match):
    with pytest.raises(ConfigError, match=match) as err:
        associate_by_geometry(stations, **kw)
    assert "\n" not in str(err.value)


def test_gate_value_is_the_chi_square_quantile():
    res = associate_with_plan(np.zeros((0, 3)), [0, 0, 0], 0.0, np.zeros((0, 3)), [],
                              np.zeros(0), 0.5, 0.03, gate_probability=0.99)
    assert res.gate == pytest.approx(chi2.ppf(0.99, 3))
