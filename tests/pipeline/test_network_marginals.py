"""Sparse marginal covariances (pipeline.network.marginals) against the dense inverse: the same
blocks, the same reliability, under every datum, data snooping, robust weights and variance
components."""

import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.marginals import MarginalCovariance
from pipeline.network.observations import ControlPoint, Datum, NetworkObservations
from pipeline.network.simulation import simulated_network

RELIABILITY = ("residuals_m", "redundancy", "w_test", "mdb_m", "mdb_effect_m", "mdb_point_m")


def both(obs, datum, nominal, **settings):
    return [adjust(obs, datum, AdjustmentSettings(covariance=kind, **settings), nominal)
            for kind in ("dense", "sparse")]


def assert_same(dense, sparse):
    assert isinstance(sparse.covariance, MarginalCovariance)
    assert isinstance(dense.covariance, np.ndarray)
    full = dense.covariance
    scale = np.abs(full).max()
    u = full.shape[0]
    # every entry, through the on-demand columns
    assert np.abs(sparse.covariance.columns(np.arange(u)) - full).max() < 1e-9 * scale
    assert np.abs(sparse.covariance.diagonal() - np.diag(full)).max() < 1e-9 * scale
    obs = sparse.observations
    s = len(obs.station_ids)
    for i in range(s):
        assert np.allclose(sparse.station_covariance(i), dense.station_covariance(i),
                           rtol=1e-9, atol=1e-9 * scale)
    for j in range(len(obs.marker_ids)):
        assert np.allclose(sparse.marker_covariance(j), dense.marker_covariance(j),
                           rtol=1e-9, atol=1e-9 * scale)
    # the observed station-marker blocks held ready
    st = 6 * obs.station[:, None, None] + np.arange(6)[None, :, None]
    mk = 6 * s + 3 * obs.marker[:, None, None] + np.arange(3)[None, None, :]
    assert np.abs(sparse.covariance[st, mk] - full[st, mk]).max() < 1e-9 * scale
    assert np.abs(sparse.covariance[mk.transpose(0, 2, 1), st.transpose(0, 2, 1)]
                  - full[mk.transpose(0, 2, 1), st.transpose(0, 2, 1)]).max() < 1e-9 * scale
    for name in RELIABILITY:
        a, b = getattr(dense, name), getattr(sparse, name)
        assert np.array_equal(np.isfinite(a), np.isfinite(b)), name
        assert np.allclose(a[np.isfinite(a)], b[np.isfinite(b)], rtol=1e-9, atol=1e-12), name
    assert np.allclose(dense.point.statistic, sparse.point.statistic, rtol=1e-9, atol=1e-12)
    assert np.allclose(dense.marker_xyz_m, sparse.marker_xyz_m, atol=1e-12)
    assert [(r.station_id, r.marker_id) for r in dense.rejected] == [
        (r.station_id, r.marker_id) for r in sparse.rejected]


@pytest.mark.parametrize("kind", ["station", "control", "free"])
def test_sparse_blocks_equal_the_dense_inverse_under_each_datum(kind):
    obs, truth = simulated_network(n_stations=9, seed=5)
    control = ()
    if kind == "control":
        control = tuple(ControlPoint(obs.marker_ids[j], truth.marker_xyz_m[j], [0.003] * 3)
                        for j in (0, len(obs.marker_ids) // 2, len(obs.marker_ids) - 1))
    assert_same(*both(obs, Datum(kind, control=control), truth.nominal))


def test_sparse_under_snooping_robust_and_variance_components():
    obs, truth = simulated_network(n_stations=9, seed=6)
    seen = np.bincount(obs.marker)[obs.marker]
    row = int(np.flatnonzero((seen >= 3) & (obs.station > 0))[2])
    xyz = obs.xyz_m.copy()
    xyz[row] += [0.4, -0.2, 0.1]
    bad = NetworkObservations(obs.station_ids, obs.marker_ids, obs.station, obs.marker, xyz,
                              obs.sigma_m)
    dense, sparse = both(bad, Datum(), truth.nominal, variance_components="station")
    assert dense.rejected  # the blunder is found, by both
    assert_same(dense, sparse)
    assert [c.sigma0_squared for c in dense.variance_components] == pytest.approx(
        [c.sigma0_squared for c in sparse.variance_components], rel=1e-9, nan_ok=True)
    assert_same(*both(bad, Datum(), truth.nominal, snooping=False, robust="huber"))


def test_covariance_setting_is_checked_and_auto_follows_size():
    with pytest.raises(ConfigError, match="covariance must be one of"):
        AdjustmentSettings(covariance="cholmod")
    obs, truth = simulated_network(n_stations=4, seed=1)
    small = adjust(obs, settings=AdjustmentSettings(snooping=False), nominal=truth.nominal)
    assert isinstance(small.covariance, np.ndarray)


def test_sparse_downdate_equals_the_dense_one():
    """Two observations removed in turn (Sherman-Morrison-Woodbury, as data snooping does):
    every entry, the blocks held and the products stay those of the dense downdate."""
    from pipeline.network.design import axis_weight
    from pipeline.network.normals import downdated, linearise

    obs, truth = simulated_network(n_stations=9, seed=5)
    dense, sparse = both(obs, Datum(), truth.nominal, snooping=False)
    blocks, columns, _ = linearise(sparse.observations, sparse.pose, sparse.marker_xyz_m)
    q, m = dense.covariance, sparse.covariance
    for i in (3, 17):
        weight = np.full(3, axis_weight(obs.sigma_m[i]))
        q = downdated(q, blocks[i], columns[i], weight)
        m = downdated(m, blocks[i], columns[i], weight)
    scale = np.abs(q).max()
    assert np.abs(m.columns(np.arange(q.shape[0])) - q).max() < 1e-9 * scale
    assert np.abs(m.diagonal() - np.diag(q)).max() < 1e-9 * scale
    st = 6 * obs.station[:, None, None] + np.arange(6)[None, :, None]
    mk = 6 * len(obs.station_ids) + 3 * obs.marker[:, None, None] + np.arange(3)[None, None, :]
    assert np.abs(m[st, mk] - q[st, mk]).max() < 1e-9 * scale
    assert np.abs(m[mk, np.swapaxes(mk, 1, 2)] - q[mk, np.swapaxes(mk, 1, 2)]).max() < 1e-9 * scale
