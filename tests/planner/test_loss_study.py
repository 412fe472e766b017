"""The loss study's layouts, covariates and tables (analytic cases), and one scan through it."""

import numpy as np
import pytest

from pipeline.tables.fate_table import FATE_COLUMNS
from planner.problem.detection_odds import rim_distance
from planner.studies.loss_study import (
    level_layout,
    loss_jobs,
    loss_table,
    pair_covariates,
    relief_layout,
    run_loss_study,
)
from visibility.terrain import Crater


def test_level_layout_covariates_are_those_of_a_plane():
    layout = level_layout(np.array([3.0, 12.0]))
    cov = pair_covariates(layout, 0, 60.0)
    assert cov["marker"].tolist() == [0, 1]
    horiz = np.array([3.0, 12.0])
    np.testing.assert_allclose(cov["distance_m"], np.hypot(horiz, 0.9), rtol=1e-9)
    el = np.degrees(np.arctan2(-0.9, horiz))
    np.testing.assert_allclose(cov["elevation_deg"], el, rtol=1e-9)
    # a level plane: its normal is vertical, so incidence = 90 deg - |elevation|
    np.testing.assert_allclose(cov["incidence_deg"], 90.0 + el, atol=1e-6)
    np.testing.assert_allclose(cov["slope_deg"], 0.0, atol=1e-9)
    assert np.isinf(cov["rim_distance_m"]).all()
    np.testing.assert_allclose(cov["visible_fraction"], 1.0)
    assert cov["expected_points"][0] > 10 * cov["expected_points"][1]


def test_rim_distance_is_to_the_nearest_crest():
    craters = [Crater((0.0, 0.0), 8.0, 1.0, "fresh"), Crater((20.0, 0.0), 2.0, 0.2, "fresh")]
    xy = np.array([[4.45, 0.0], [0.0, 0.0], [18.5, 0.0]])
    np.testing.assert_allclose(rim_distance(craters, xy), [0.45, 4.0, 0.5])


def test_relief_layout_keeps_markers_off_stations_and_rocks():
    sites = pytest.importorskip("visibility.sites")
    site = sites.load_site("default")
    layout = relief_layout(site, spacing_m=4.0)
    xy = layout.marker_centres_m[:, :2]
    assert len(xy) > 80
    assert np.linalg.norm(xy[:, None] - site.station_xy_m[None], axis=2).min() >= 1.5
    gap = np.linalg.norm(xy[:, None] - site.rock_centres_m[None, :, :2], axis=2)
    assert (gap > site.rock_radii_m[None] + 0.1).all()
    np.testing.assert_allclose(layout.marker_centres_m[:, 2], site.dem.height_at(xy) + 0.1)


def test_jobs_split_the_markers_into_interleaved_sets():
    layout = level_layout(np.arange(2.0, 10.0))
    jobs = loss_jobs(layout, [5, 6, 7], groups=2)
    assert [j.seed for j in jobs] == [5, 6, 7]
    assert jobs[0].markers.tolist() == [0, 2, 4, 6] and jobs[1].markers.tolist() == [1, 3, 5, 7]
    assert jobs[2].markers.tolist() == jobs[0].markers.tolist()


def test_loss_table_rates_and_stage_counts():
    rows = [{"d": 1.0, "stage": "gate"}, {"d": 1.5, "stage": "accepted"},
            {"d": 1.7, "stage": "quality"}, {"d": 9.0, "stage": "ground"}]
    table = loss_table(rows, "d", [0.0, 2.0, 5.0, 10.0])
    assert [(t["lo"], t["n"]) for t in table] == [(0.0, 3), (5.0, 1)]
    assert table[0]["detected"] == pytest.approx(2 / 3)
    assert table[0]["accepted"] == pytest.approx(1 / 3)
    assert (table[0]["gate"], table[0]["quality"], table[1]["ground"]) == (1, 1, 1)


def test_one_scan_gives_a_row_per_marker_in_range():
    layout = level_layout(np.array([10.0]))
    (scan,) = run_loss_study(layout, loss_jobs(layout, [0], frames=range(0, 800, 8)))
    assert [r["marker_id"] for r in scan.rows] == ["D010.0"]
    (row,) = scan.rows
    assert tuple(row) == FATE_COLUMNS
    assert row["stage"] == "accepted" and row["n_points"] > 20
    assert scan.false_accepts == 0
