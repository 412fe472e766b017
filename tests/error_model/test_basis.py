"""The basis: monotone ramps, and the constraints that make any admissible model >= 0."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from error_model.basis import Basis


def test_ramps_reproduce_a_piecewise_linear_function():
    basis = Basis(distance_knots_m=(5.0, 20.0), elevation_knots_rad=())
    b = np.array([1.0, 0.1, 0.0, 0.3, 0.0])  # intercept, 3 distance slopes, 1 elevation slope
    d = np.array([0.0, 5.0, 10.0, 20.0, 30.0])
    f = basis.design(d, np.zeros_like(d)) @ b
    np.testing.assert_allclose(f, [1.0, 1.5, 1.5, 1.5, 4.5])


def test_quantile_knots_merge_repeated_distances():
    d = np.repeat([1.0, 2.0, 3.0], 100)
    basis = Basis.from_data(d, np.zeros_like(d), 8, 2)
    assert len(basis.distance_knots_m) <= 2
    assert basis.n_features == len(basis.names)


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_d=st.integers(0, 4), n_e=st.integers(0, 3),
       n_x=st.integers(0, 2))
def test_coefficients_meeting_the_constraints_give_non_negative_monotone_models(seed, n_d,
                                                                                n_e, n_x):
    rng = np.random.default_rng(seed)
    basis = Basis(distance_knots_m=tuple(np.sort(rng.uniform(1, 40, n_d)).round(3)
                                         + np.arange(n_d)),
                  elevation_knots_rad=tuple(np.sort(rng.uniform(0.05, 1.0, n_e)).round(3)
                                            + 0.01 * np.arange(n_e)),
                  extras=("visible_fraction", "expected_points")[:n_x])
    # draw coefficients, then project onto the constraints by raising the intercept
    b = rng.normal(0, 1, basis.n_features)
    b[basis.nonneg] = np.abs(b[basis.nonneg])
    b[0] += max(0.0, -(basis.nonneg_rows() @ b).min())
    d = rng.uniform(0, 100, 500)
    e = rng.uniform(-np.pi / 2, np.pi / 2, 500)
    extras = {"visible_fraction": rng.uniform(0, 1, 500),
              "expected_points": rng.uniform(0, 1e4, 500)}
    f = basis.design(d, e, extras) @ b
    assert (f >= -1e-9).all()
    f2 = basis.design(d + rng.uniform(0, 10, 500), e, extras) @ b
    assert (f2 >= f - 1e-9).all()
