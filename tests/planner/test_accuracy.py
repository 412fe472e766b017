import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.scans.rig import rot_z
from planner.accuracy import known_control
from planner.accuracy.figure import MONOTONE_TOLERANCE, ErrorFigure
from planner.accuracy.known_control import CHI2_3_95, fit_pose, registration_error, station_error

ELLIPSOID, QUANTILE = ErrorFigure("ellipsoid"), ErrorFigure("quantile")


def test_symmetric_layout_matches_closed_form():
    # four markers at distance D in four directions, equal sigma: C_tt = s2/4 I, C_psi = s2/(4 D^2)
    d, r, sigma = 8.0, 10.0, 0.01
    xy = d * np.array([[1, 0], [0, 1], [-1, 0], [0, -1]], float)
    s2 = sigma**2 / 3.0
    lam = s2 / 4 + r**2 * s2 / (4 * d**2)
    expected = np.sqrt(CHI2_3_95 * lam)
    assert np.isclose(station_error([0, 0], xy, [sigma] * 4, r, figure=ELLIPSOID), expected,
                      rtol=1e-9)


def test_inclinometer_adds_vertical_error():
    xy = 8.0 * np.array([[1, 0], [0, 1], [-1, 0], [0, -1]], float)
    e0 = station_error([0, 0], xy, [0.01] * 4, 10.0, 0.0)
    e1 = station_error([0, 0], xy, [0.01] * 4, 10.0, np.radians(0.5))
    assert e1 > e0


def test_degenerate_layouts_are_infinite():
    assert station_error([0, 0], np.zeros((0, 2)), np.zeros(0), 10.0) == np.inf
    assert station_error([0, 0], [[5, 5], [5, 5]], [0.01, 0.01], 10.0) == np.inf


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(0.002, 0.05)),
                min_size=3, max_size=8),
       st.tuples(st.floats(-20, 20), st.floats(-20, 20), st.floats(0.002, 0.05)))
def test_adding_a_marker_never_worsens_a_station(markers, extra):
    m = np.array(markers)
    e = station_error([0, 0], m[:, :2], m[:, 2], 10.0, figure=QUANTILE)
    m2 = np.vstack([m, extra])
    e2 = station_error([0, 0], m2[:, :2], m2[:, 2], 10.0, figure=QUANTILE)
    assert e2 <= e * (1 + MONOTONE_TOLERANCE) or not np.isfinite(e)
    e = station_error([0, 0], m[:, :2], m[:, 2], 10.0, figure=ELLIPSOID)
    e2 = station_error([0, 0], m2[:, :2], m2[:, 2], 10.0, figure=ELLIPSOID)
    assert e2 <= e * (1 + 1e-9) or not np.isfinite(e)


def test_batch_errors_agree_with_single():
    rng = np.random.default_rng(3)
    xy = rng.uniform(-15, 15, (5, 2))
    sig = rng.uniform(0.005, 0.02, 5)
    j = known_control.pair_information([0, 0], xy, sig)
    batch = known_control.errors_from_information(np.stack([j[:3].sum(0), j.sum(0)]), 10.0,
                                                  0.0, ErrorFigure())
    assert np.isclose(batch[0], station_error([0, 0], xy[:3], sig[:3], 10.0))
    assert np.isclose(batch[1], station_error([0, 0], xy, sig, 10.0))


def test_fit_pose_recovers_a_known_pose_and_registration_error():
    rng = np.random.default_rng(0)
    site = np.column_stack([rng.uniform(-15, 15, (5, 2)), rng.uniform(-1, 1, 5)])
    t_true, psi_true = np.array([1.0, -2.0, 0.5]), 0.7
    station = (site - t_true) @ rot_z(psi_true)
    t, psi = fit_pose(station, site, np.full(5, 0.01), heading0_rad=0.6)
    assert np.allclose(t, t_true, atol=1e-9) and np.isclose(psi, psi_true, atol=1e-12)
    assert registration_error(t, psi, t_true, psi_true, 10.0) < 1e-8
    # a pure heading error of 1 mrad moves the rim by 10 mm at 10 m
    assert np.isclose(registration_error(t_true, psi_true + 1e-3, t_true, psi_true, 10.0),
                      10.0 * 2 * np.sin(0.5e-3), rtol=1e-6)


def test_closed_form_largest_eigenvalue():
    rng = np.random.default_rng(1)
    m = rng.normal(size=(500, 3, 3))
    s = m @ m.transpose(0, 2, 1)
    s[0] = np.eye(3) * 2.0  # repeated eigenvalues
    assert np.allclose(known_control.lambda_max_sym3(s), np.linalg.eigvalsh(s)[:, -1], rtol=1e-9,
                       atol=1e-12)
