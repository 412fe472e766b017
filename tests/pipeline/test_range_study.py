from dataclasses import asdict

import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.chain.evaluation import reference_from_truth
from pipeline.chain.process import process_station
from pipeline.surveys.range_study import (
    NOT_DETECTED,
    RANGE_STUDY_DISTANCES_M,
    chain_markers,
    marker_layout,
    measure_markers,
    summarise,
    unmatched_counts,
)
from pipeline.surveys.survey import ProcessingSettings, processing_config
from pipeline.tables.marker_table import MarkerRow
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
    assert s[0]["n_detected"] == 3 and s[1]["n_detected"] == 1  # too_few_points: detected


def test_summary_counts_lost_markers_and_leaves_out_unmatched_detections():
    """A ``not_detected`` row is a row of its distance but not a detection; a detection that
    matched no laid-out marker is no row of any distance, only of :func:`unmatched_counts`."""
    lost = MarkerRow("S", "m1", 1, 0, -0.9, 1.3, -40, 0, 0, 0.0, 0.0, float("nan"),
                     float("nan"), "fixed-radius", False, NOT_DETECTED)
    found = MarkerRow("S", "m1", 1, 0, -0.9, 1.3, -40, 0, 90, 3e3, 0.9, 0.002, 0.1,
                      "fixed-radius", True, "", replicate=1)
    found.error_m = 0.001
    clutter = MarkerRow("S", "", 5, 5, -0.9, 7.1, -7, 45, 40, 1e3, 0.5, 0.003, 0.1,
                        "fixed-radius", True, "")
    (s,) = summarise([lost, found, clutter], {"m1": 1.0})
    assert (s["n_rows"], s["n_detected"], s["n_accepted"], s["n_fitted"]) == (2, 1, 1, 1)
    assert unmatched_counts([lost, found, clutter], {"m1": 1.0}) == {
        "fixed-radius": {"n_rows": 1, "n_accepted": 1}}


# --- the full-chain extraction, on simulated scans ----------------------------------------

#: Horizontal distances of the small layout, m: 1-2 m (mixed returns near the sphere), mid
#: range, and 45 m (too few returns to detect with :data:`FRAMES` frames).
SMALL_LAYOUT_M = np.array([1.0, 2.0, 5.0, 9.0, 13.0, 45.0])
#: Frames of the small layout's scan (a full turn: the chain self-calibrates).
FRAMES = 40


@pytest.fixture(scope="module")
def layout_scan():
    """A :data:`FRAMES`-frame scan of :data:`SMALL_LAYOUT_M` on level ground with the
    calibrated sensor: scan, truth, true centres (station frame), ids, expected noise."""
    simulate = pytest.importorskip("visibility.simulate")
    from visibility.dem import DEM
    from visibility.sensor_profile import default_profile

    profile = default_profile()
    sensor = profile.sensor_config(600)
    rig = profile.rig_config(frames_per_turn=FRAMES, lidar_height_m=1.0)
    dem = DEM(np.zeros((111, 111)), (-55.0, -55.0), 1.0)
    centres = marker_layout(SMALL_LAYOUT_M)
    ids = [f"R{d:04.1f}" for d in SMALL_LAYOUT_M]
    station = np.array([0.0, 0.0, 1.0])
    scan, truth = simulate.simulate_markers(dem, station, 0.0, centres + station, sensor, rig,
                                            seed=3, marker_ids=ids, station_id="RANGE")
    return scan, truth, centres, ids, sensor.expected_scatter()


@pytest.fixture(scope="module")
def fixed_radius_rows(layout_scan):
    """The full-chain rows of :func:`layout_scan` with the fixed-radius estimator (replicate
    2, seed 3)."""
    scan, truth, _, _, noise = layout_scan
    return chain_markers(scan, truth, 0.1, methods=("fixed-radius",), replicate=2, seed=3,
                         noise=noise)


@pytest.mark.parametrize("method", ["fixed-radius",
                                    pytest.param("hemisphere-icp", marks=pytest.mark.slow)])
def test_full_chain_rows_are_the_chains_own_rows(layout_scan, fixed_radius_rows, method):
    """Each laid-out marker's row is the row ``process_station`` itself gives it on the same
    scan (configured as ``process`` / ``verify``, ``fit.method`` = the estimator); a marker it
    gave none is ``not_detected`` at its true centre, without points or error; the chain's
    unmatched detections follow. So the table's acceptance, reasons and errors are the
    chain's, estimator by estimator."""
    scan, truth, centres, ids, noise = layout_scan
    rows = (fixed_radius_rows if method == "fixed-radius" else
            chain_markers(scan, truth, 0.1, methods=(method,), replicate=2, seed=3,
                          noise=noise))
    cfg = processing_config(ProcessingSettings(marker_radius_m=0.1, estimator=method))
    own = process_station(scan, cfg, reference_from_truth(truth), noise=noise, replicate=2,
                          seed=3).rows
    assert {r.estimator for r in rows} == {method}
    assert [r.marker_id for r in rows[:len(ids)]] == ids
    np.testing.assert_equal([asdict(r) for r in rows[len(ids):]],
                            [asdict(r) for r in own if not r.marker_id])  # NaN == NaN
    matched = {r.marker_id: r for r in own if r.marker_id}
    lost = []
    for row, centre in zip(rows, centres, strict=False):
        if row.marker_id in matched:
            np.testing.assert_equal(asdict(row), asdict(matched[row.marker_id]))
            continue
        lost.append(row.marker_id)
        assert (row.accepted, row.reason, row.n_points, row.error_m) == (
            False, NOT_DETECTED, 0, None)
        np.testing.assert_allclose(row.centre_m, centre)
        assert (row.replicate, row.seed) == (2, 3)
    assert any(r.accepted and r.marker_id for r in own), "the chain accepted no marker"
    assert sum(r.accepted for r in rows) == sum(r.accepted for r in own)
    assert "R45.0" in lost


def test_full_chain_differs_from_truth_seeded_where_the_chain_loses_a_marker(
        layout_scan, fixed_radius_rows):
    """The truth-seeded diagnostic fits the 45 m marker's few returns at its true position
    (rejected for too few points); the chain never detects it. Where both accept a marker
    they agree on its centre."""
    scan, _, centres, ids, noise = layout_scan
    chain = {r.marker_id: r for r in fixed_radius_rows}
    seeded = {r.marker_id: r for r in measure_markers(scan, centres, ids,
                                                      methods=("fixed-radius",), noise=noise)}
    assert chain["R45.0"].reason == NOT_DETECTED
    assert seeded["R45.0"].reason == "too_few_points"
    for mid in ids:
        if chain[mid].accepted and seeded[mid].accepted:
            assert np.linalg.norm(chain[mid].centre_m - seeded[mid].centre_m) < 0.01, mid
