"""The calibration's emulator and fit against an analytic stand-in for the simulator, and the
field-summary readers against hand-computed statistics."""

import numpy as np
import pytest

import planner.studies.sensor_calibration as cal
from markerplan.errors import ConfigError
from planner.studies.field_summary import (
    FIELD_EXPERIMENT_CSV,
    FieldPosition,
    positions_from_marker_table,
    read_field_summary,
)
from visibility.sensor_profile import load_profile

A_M2 = {"0": 2e-6, "1": 1e-6, "2": 3e-6}  # per-position floor, m^2
B = {"0": 40.0, "1": 55.0, "2": 30.0}  # per-position growth, m^2 / rad^2
TRUE_P = 1.2e-3  # rad
PARAM = "turntable.encoder_noise_rad"


def analytic_stat(name, p, relative_noise, rng):
    return float(np.sqrt(A_M2[name] + B[name] * p ** 2) * (1 + relative_noise *
                                                            rng.standard_normal()))


def fake_simulation(relative_noise):
    def simulate(profile, position, index, replicate, settings):
        rng = np.random.default_rng([settings.seed, index, replicate])
        p = profile.value(PARAM)
        return {"position": position.name, "replicate": replicate,
                "statistic_m": analytic_stat(position.name, p, relative_noise, rng),
                "n_accepted": 11, "n_markers": 11}
    return simulate


def positions(p=TRUE_P):
    return [FieldPosition(k, np.linspace(3, 20, 11), float(np.sqrt(A_M2[k] + B[k] * p ** 2)))
            for k in A_M2]


def test_exact_emulator_recovers_the_parameter(monkeypatch):
    monkeypatch.setattr(cal, "simulate_position", fake_simulation(0.0))
    result = cal.calibrate(positions(), load_profile("datasheet"),
                           [cal.FreeParameter(PARAM, 0.0, 3e-3)],
                           cal.CalibrationSettings(replicates=2, resolution_m=0.0))
    assert result.values[PARAM] == pytest.approx(TRUE_P, rel=1e-4)
    assert all(e["max_rel_misfit"] < 1e-6 for e in result.emulator)
    assert [c["ratio"] for c in result.confirmation] == pytest.approx([1, 1, 1], rel=1e-4)
    assert [h["ratio"] for h in result.holdout] == pytest.approx([1, 1, 1], rel=1e-4)
    assert result.profile.turntable.encoder_noise_rad == pytest.approx(TRUE_P, rel=1e-4)
    assert result.warnings == []


def test_standard_error_covers_the_truth(monkeypatch):
    """Monte Carlo: with 5 % noise on every simulated statistic and on the measurements, the
    fitted value lies within 2 standard errors of the truth in most of 40 repeats."""
    monkeypatch.setattr(cal, "simulate_position", fake_simulation(0.05))
    rng = np.random.default_rng(7)
    inside = 0
    for seed in range(40):
        measured = [FieldPosition(p.name, p.distances_m, p.mean_abs_edge_residual_m
                                  * (1 + 0.05 * rng.standard_normal())) for p in positions()]
        r = cal.calibrate(measured, load_profile("datasheet"),
                          [cal.FreeParameter(PARAM, 0.0, 3e-3)],
                          cal.CalibrationSettings(replicates=3, resolution_m=0.0, seed=seed,
                                                  holdout=False))
        inside += abs(r.values[PARAM] - TRUE_P) <= 2 * r.sigmas[PARAM]
    assert inside >= 32  # ~95 % expected; 32/40 leaves room for the estimated weights


def test_fit_at_bound_warns(monkeypatch):
    monkeypatch.setattr(cal, "simulate_position", fake_simulation(0.0))
    result = cal.calibrate(positions(2.5e-3), load_profile("datasheet"),
                           [cal.FreeParameter(PARAM, 0.0, 1e-3)],
                           cal.CalibrationSettings(replicates=1, holdout=False))
    assert result.at_bound == [PARAM]
    assert "widen" in result.warnings[0]


def test_too_few_positions_refused():
    with pytest.raises(ConfigError, match="at least 3 positions"):
        cal.calibrate(positions()[:2], load_profile("datasheet"),
                      [cal.FreeParameter(PARAM, 0, 1e-3),
                       cal.FreeParameter("sensor.range_noise_m", 0, 0.05)])


def test_shipped_field_experiment_summary():
    pos = read_field_summary(FIELD_EXPERIMENT_CSV)
    assert [p.name for p in pos] == ["1", "2", "3"]
    assert [p.distances_m.size for p in pos] == [11, 11, 11]
    assert [p.mean_abs_edge_residual_m for p in pos] == [0.011, 0.010, 0.011]
    assert pos[1].distances_m[5] == pytest.approx(2.273)


def test_positions_from_marker_table(tmp_path):
    """Two stations whose marker D is 1 cm and 3 cm off along x: hand-computed statistics."""
    from pipeline.tables.marker_table import COLUMNS

    ref = {"A": (0, 0, 0), "B": (4, 0, 0), "C": (0, 3, 0), "D": (4, 3, 0)}
    (tmp_path / "ref.csv").write_text("id,x_m,y_m,z_m\n" + "".join(
        f"{k},{x},{y},{z}\n" for k, (x, y, z) in ref.items()))
    rows = []
    for station, shift in (("S1", 0.01), ("S2", 0.03)):
        for k, (x, y, z) in ref.items():
            x = x + (shift if k == "D" else 0.0)
            cells = dict.fromkeys(COLUMNS, "")
            cells.update(station_id=station, marker_id=k, x_m=x + 5, y_m=y + 1, z_m=z - 0.9,
                         distance_m=np.hypot(x + 5, y + 1), accepted="true")
            rows.append(",".join(str(cells[c]) for c in COLUMNS))
    (tmp_path / "markers.csv").write_text(",".join(COLUMNS) + "\n" + "\n".join(rows) + "\n")
    s1, s2 = positions_from_marker_table(tmp_path / "markers.csv", tmp_path / "ref.csv")
    def expected(dx):  # |AD| 5 -> hypot(4 + dx, 3), |BD| 3 -> hypot(dx, 3), |CD| 4 -> 4 + dx
        return (abs(np.hypot(4 + dx, 3) - 5) + abs(np.hypot(dx, 3) - 3) + dx) / 6

    assert s1.mean_abs_edge_residual_m == pytest.approx(expected(0.01), rel=1e-9)
    assert s2.mean_abs_edge_residual_m == pytest.approx(expected(0.03), rel=1e-9)
    assert s2.distances_m.size == 4
