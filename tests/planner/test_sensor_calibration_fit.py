"""The calibration fit's identifiability diagnostics (parameter correlation, the Jacobian's
condition) and its per-position prediction intervals, on hand-made emulators whose answers are
known analytically."""

import numpy as np
import pytest

import planner.studies.sensor_calibration as cal
from planner.studies.field_summary import FieldPosition

FLAT = "reference.aim_sigma_m"  # range-independent: the same effect at every position
GROWING = "turntable.periodic_error_rad"  # grows with the markers' distances
SETTINGS = cal.CalibrationSettings(resolution_m=0.0)
FREE = [cal.FreeParameter(FLAT, 0.0, 0.02), cal.FreeParameter(GROWING, 0.0, 0.003)]
TRUTH = {FLAT: 0.004, GROWING: 0.0012}


def emulator(name, a_m2, b_flat, b_growing, rel_spread=0.1):
    return {"position": name, "index": 0, "a_m2": a_m2,
            "b": {FLAT: b_flat, GROWING: b_growing}, "max_rel_misfit": 0.0,
            "rel_spread": rel_spread, "n_design": 9}


def exact_positions(emulators):
    """Positions whose measurements are the emulators' values at :data:`TRUTH`."""
    return [FieldPosition(e["position"], np.array([5.0, 10.0, 15.0]), cal.emulate(e, TRUTH))
            for e in emulators]


def fit(emulators):
    return cal._fit_parameters(exact_positions(emulators), FREE, emulators, SETTINGS)


def test_distinct_distance_profiles_tell_the_terms_apart():
    """Positions whose growing term differs 1 : 4 : 16 against a flat term that is the same
    everywhere: the fit recovers both, with a modest condition number."""
    result = fit([emulator(k, 1e-6, 1.0, b) for k, b in (("1", 10.0), ("2", 40.0),
                                                         ("3", 160.0))])
    assert result["values"][FLAT] == pytest.approx(TRUTH[FLAT], rel=1e-4)
    assert result["values"][GROWING] == pytest.approx(TRUTH[GROWING], rel=1e-4)
    assert result["jacobian_condition"] < 10
    assert abs(result["correlation"][0][1]) < 0.99


def test_proportional_effects_are_flagged_as_inseparable():
    """Positions with nearly the same distances: both terms act on every position in nearly the
    same proportion, so the Jacobian's columns are almost parallel (condition >> 1, correlation
    near -1, standard errors far above the values); exactly parallel, the errors are
    infinite."""
    near = fit([emulator(k, 1e-6, 1.0, b) for k, b in (("1", 50.0), ("2", 50.5), ("3", 51.0))])
    assert near["jacobian_condition"] > 100
    assert near["correlation"][0][1] < -0.999
    assert near["sigmas"][FLAT] > TRUTH[FLAT]
    exact = fit([emulator(k, 1e-6, 1.0, 50.0) for k in ("1", "2", "3")])
    assert exact["jacobian_condition"] > 1e12
    assert exact["sigmas"] == {FLAT: np.inf, GROWING: np.inf}


def test_condition_ignores_the_parameters_units():
    """Rescaling one parameter's effect (another unit) changes the raw Jacobian, not the
    equilibrated condition number."""
    jac = np.array([[1.0, 2.0], [1.0, 5.0], [1.0, 9.0]])
    assert cal._equilibrated_condition(jac) == pytest.approx(
        cal._equilibrated_condition(jac * np.array([1e-3, 1e4])), rel=1e-9)
    assert cal._equilibrated_condition(np.eye(2)) == pytest.approx(1.0)
    assert cal._equilibrated_condition(np.array([[1.0, 0.0], [2.0, 0.0]])) == np.inf


def test_prediction_interval_one_parameter_analytic():
    """One parameter: the interval is the emulated value +- 1.96 * hypot(|ds/dp| sigma_p,
    spread * s), and with exact measurements it contains them."""
    free = [cal.FreeParameter(GROWING, 0.0, 0.003)]
    emulators = [{"position": k, "index": 0, "a_m2": 2e-6, "b": {GROWING: b},
                  "max_rel_misfit": 0.0, "rel_spread": 0.2, "n_design": 4}
                 for k, b in (("1", 30.0), ("2", 60.0), ("3", 90.0))]
    truth = {GROWING: 0.0012}
    positions = [FieldPosition(e["position"], np.array([5.0]), cal.emulate(e, truth))
                 for e in emulators]
    result = cal._fit_parameters(positions, free, emulators, SETTINGS)
    sigma_p = result["sigmas"][GROWING]
    for e, pred in zip(emulators, result["predictions"], strict=True):
        s = cal.emulate(e, result["values"])
        slope = e["b"][GROWING] * result["values"][GROWING] / s
        assert pred["emulated_m"] == pytest.approx(s)
        assert pred["fit_sd_m"] == pytest.approx(slope * sigma_p, rel=1e-9)
        assert pred["draw_sd_m"] == pytest.approx(0.2 * s, rel=1e-9)
        half = 1.959963984540054 * np.hypot(slope * sigma_p, 0.2 * s)
        assert pred["interval95_m"] == pytest.approx([s - half, s + half], rel=1e-9)
        assert pred["interval95_m"][0] < pred["measured_m"] < pred["interval95_m"][1]
