import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.marker_table import MarkerRow
from pipeline.range_study import (
    RANGE_STUDY_DISTANCES_M,
    marker_layout,
    measure_markers,
    summarise,
)
from tests.pipeline.test_synthesis import synthetic_scan


def test_published_distances():
    d = RANGE_STUDY_DISTANCES_M
    assert d[:15].tolist() == list(range(1, 16))
    assert d[15:20].tolist() == [17, 19, 21, 23, 25]
    assert d[20:].tolist() == [30, 35, 40, 45, 50]


def test_layout_spreads_markers_on_the_ground():
    c = marker_layout(RANGE_STUDY_DISTANCES_M)
    np.testing.assert_allclose(np.hypot(c[:, 0], c[:, 1]), RANGE_STUDY_DISTANCES_M)
    np.testing.assert_allclose(c[:, 2], -0.9)
    az = np.sort(np.degrees(np.arctan2(c[:, 1], c[:, 0])) % 360)
    assert np.diff(az).min() > 3  # no marker directly behind another
    with pytest.raises(ConfigError):
        marker_layout(np.array([0.1]))


def _elevation_deg(c):
    return np.degrees(np.arctan2(c[:, 2], np.hypot(c[:, 0], c[:, 1])))


@pytest.mark.parametrize(("height", "slope_deg"), [(0.8, 15.0), (1.5, -15.0), (1.0, 20.0)])
def test_layout_rests_markers_on_the_slope(height, slope_deg):
    d, r, s = RANGE_STUDY_DISTANCES_M, 0.1, np.radians(slope_deg)
    c = marker_layout(d, r, height, s)
    np.testing.assert_allclose(np.hypot(c[:, 0], c[:, 1]), d)
    normal = np.array([-np.sin(s), 0.0, np.cos(s)])  # upward normal of z = x tan(s) - height
    contact = c - r * normal
    np.testing.assert_allclose(contact[:, 2], contact[:, 0] * np.tan(s) - height, atol=1e-12)
    # uphill markers are seen higher than on level ground, downhill ones lower, by up to ~slope
    # (less at 1-2 m, where the line of sight is steep on any ground)
    shift = _elevation_deg(c) - _elevation_deg(marker_layout(d, r, height))
    uphill = np.cos(np.arctan2(c[:, 1], c[:, 0])) * np.sign(slope_deg)
    assert np.all(shift[(uphill > 0.9) & (d >= 3)] > 10)
    assert np.all(shift[(uphill < -0.9) & (d >= 3)] < -10)
    assert np.all(np.abs(shift) < abs(slope_deg) + 1)


def test_layout_reaches_positive_and_steep_negative_elevations():
    near = RANGE_STUDY_DISTANCES_M[RANGE_STUDY_DISTANCES_M <= 15]
    up = _elevation_deg(marker_layout(near, 0.1, 0.8, np.radians(15)))
    down = _elevation_deg(marker_layout(near, 0.1, 1.5, np.radians(-15)))
    level = _elevation_deg(marker_layout(near))
    assert up.max() > 10 > level.max()
    assert (down - level).min() < -10 and down.min() < -55


@pytest.mark.parametrize(("kwargs", "needle"), [({"lidar_height_m": 0.0}, "lidar_height_m"),
                                                ({"slope_rad": np.radians(50)}, "slope_rad"),
                                                ({"slope_rad": np.nan}, "slope_rad")])
def test_layout_refuses_bad_relief(kwargs, needle):
    with pytest.raises(ConfigError, match=needle):
        marker_layout(np.array([2.0]), **kwargs)


def test_measure_both_estimators_on_synthetic_scan():
    centres = marker_layout(np.array([2.0, 4.0, 30.0]))
    scan = synthetic_scan(n_frames=200, spheres=[(c, 0.1) for c in centres], noise_m=0.005,
                          max_range_m=35.0, seed=1)
    rows = measure_markers(scan, centres, ["a", "b", "far"], replicate=2, seed=7)
    assert len(rows) == 6 and {r.estimator for r in rows} == {"fixed-radius", "hemisphere-icp"}
    near = [r for r in rows if r.marker_id in ("a", "b") and r.estimator == "fixed-radius"]
    assert all(r.accepted and r.error_m < 0.005 for r in near)
    far = [r for r in rows if r.marker_id == "far"]
    assert all(not r.accepted and r.reason == "too_few_points" for r in far)
    assert all(r.replicate == 2 and r.seed == 7 for r in rows)


def test_summarise_medians():
    rows = []
    for k, err in enumerate([0.001, 0.003, 0.002]):
        r = MarkerRow("S", "m1", 0, 0, 0, 1, 0, 0, 100, 10.0, 1.0, 0.01, 0.1, "fixed-radius",
                      True, "", replicate=k)
        r.error_m = err
        rows.append(r)
    rows.append(MarkerRow("S", "m2", 0, 0, 0, 9, 0, 0, 0, 0.0, 0.0, float("nan"), float("nan"),
                          "fixed-radius", False, "too_few_points"))
    s = summarise(rows, {"m1": 1.0, "m2": 9.0})
    assert s[0]["median_error_m"] == pytest.approx(0.002) and s[0]["n_accepted"] == 3
    assert s[1]["n_fitted"] == 0 and np.isnan(s[1]["median_error_m"])
