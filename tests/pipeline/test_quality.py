import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.chain.quality import QualityConfig, marker_metrics, quality_gate, visible_fraction
from pipeline.sphere_centres.sphere_fit import fit_sphere
from tests.pipeline.test_sphere_fit import noisy_cap

CENTRE = np.array([6.0, 0.0, -0.9])


def _cap(n=400, seed=0):
    return noisy_cap(CENTRE, 0.1, (0, 0, 0), n, 0.005, np.random.default_rng(seed), 85.0)


def test_full_cap_scores_high_at_any_density():
    for n in (30, 100, 1000):
        pts = _cap(n)
        assert visible_fraction(pts, CENTRE, 0.1) > 0.85, n


def test_occluded_lower_half_scores_low_and_is_rejected():
    pts = _cap(600)
    # a crater rim between sensor and marker hides every ray below the centre's elevation
    elevation = np.arctan2(pts[:, 2], np.hypot(pts[:, 0], pts[:, 1]))
    upper = pts[elevation > np.arctan2(CENTRE[2], np.hypot(*CENTRE[:2]))]
    frac = visible_fraction(upper, CENTRE, 0.1)
    assert frac < 0.6
    fit = fit_sphere(upper, 0.1, centre0_m=CENTRE)
    ok, reason = quality_gate(fit, marker_metrics(upper, fit), QualityConfig())
    assert not ok and reason == "incomplete_cloud"


def test_clean_marker_accepted_and_metrics_defined():
    pts = _cap(500)
    fit = fit_sphere(pts, 0.1, centre0_m=CENTRE)
    m = marker_metrics(pts, fit)
    assert m.point_density_per_m2 == pytest.approx(fit.n_used / (np.pi * 0.01))
    assert abs(m.radius_fit_m - 0.1) < 0.02
    assert quality_gate(fit, m, QualityConfig()) == (True, "")


def test_reasons_in_order():
    pts = _cap(500)
    fit = fit_sphere(pts, 0.1, centre0_m=CENTRE)
    m = marker_metrics(pts, fit)
    assert quality_gate(fit, m, QualityConfig(min_points=10_000))[1] == "too_few_points"
    assert quality_gate(fit, m, QualityConfig(min_visible_fraction=1.01))[1] == "incomplete_cloud"
    assert quality_gate(fit, m, QualityConfig(max_rms_m=1e-4))[1] == "high_rms"
    # a 0.3 m boulder cap fitted as a 0.1 m marker fails the radius check
    boulder = noisy_cap([6.0, 0, -0.7], 0.3, (0, 0, 0), 800, 0.005, np.random.default_rng(1),
                        40.0)
    fb = fit_sphere(boulder, 0.1, centre0_m=[5.8, 0, -0.7])
    assert quality_gate(fb, marker_metrics(boulder, fb), QualityConfig())[1] in (
        "radius_mismatch", "high_rms")


def test_config_validation():
    with pytest.raises(ConfigError, match="min_visible_fraction"):
        QualityConfig(min_visible_fraction=2).validate()
