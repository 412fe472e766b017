import numpy as np
import pytest

from markerplan.errors import DataError, InputFileError
from pipeline.chain.evaluation import (
    edge_residuals,
    kabsch,
    match_nearest,
    read_reference,
    register_reference,
)
from pipeline.scans.rig import rot_z


def _layout(seed=0, n=8):
    rng = np.random.default_rng(seed)
    return rng.uniform(-15, 15, (n, 3)) * [1, 1, 0.05]


def test_match_nearest_is_one_to_one_and_gated():
    ref = _layout()
    est = ref[[3, 1, 5]] + 0.01
    est = np.vstack([est, [[100.0, 0, 0]]])
    np.testing.assert_array_equal(match_nearest(est, ref, 0.5), [3, 1, 5, -1])


def test_registration_recovers_an_external_frame():
    station = _layout(1)
    rot = rot_z(0.7)
    ts_frame = station @ rot.T + [1000.0, 2000.0, 50.0]  # total-station frame
    order = np.random.default_rng(2).permutation(len(station))
    noisy = station[order] + np.random.default_rng(3).normal(0, 0.003, station.shape)
    match, r, t = register_reference(noisy, ts_frame, 0.05)
    np.testing.assert_array_equal(match, order)
    np.testing.assert_allclose(ts_frame @ r.T + t, station, atol=0.01)


def test_registration_needs_three_points():
    with pytest.raises(DataError, match=">= 3"):
        register_reference(np.zeros((2, 3)), _layout(), 0.1)


def test_kabsch_exact():
    a = _layout(4)
    r = rot_z(-1.2)
    rr, t = kabsch(a, a @ r.T + 5)
    np.testing.assert_allclose(rr, r, atol=1e-12)
    np.testing.assert_allclose(t, 5, atol=1e-9)


def test_edge_residuals_frame_free():
    a = _layout(5, 4)
    b = a @ rot_z(2.0).T + 7
    b[0] += [0.01, 0, 0]
    edges = edge_residuals(list("ABCD"), b, a)
    assert len(edges) == 6
    assert all(abs(e["residual_m"]) < 0.011 for e in edges)
    assert all(abs(e["residual_m"]) < 1e-9 for e in edges if "A" not in (e["marker_a"],
                                                                          e["marker_b"]))


def test_reference_csv_errors(tmp_path):
    f = tmp_path / "ts.csv"
    f.write_text("id,x_m,y_m\nA,1,2\n")
    with pytest.raises(InputFileError, match="z_m"):
        read_reference(f)
    f.write_text("id,x_m,y_m,z_m\nA,1,2,zz\n")
    with pytest.raises(InputFileError, match="numbers"):
        read_reference(f)
    f.write_text("id,x_m,y_m,z_m\n")
    with pytest.raises(DataError, match="no markers"):
        read_reference(f)
    f.write_text("id,x_m,y_m,z_m\nA,1,2,3\nB,4,5,6\n")
    ref = read_reference(f)
    assert ref.ids == ("A", "B") and ref.station_id is None
    with pytest.raises(InputFileError, match="does not exist"):
        read_reference(tmp_path / "none.csv")
