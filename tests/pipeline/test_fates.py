"""Marker fates against the simulator's truth: each known marker gets the stage that lost it."""

from dataclasses import replace

import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.chain.process import process_station
from pipeline.chain.quality import quality_gate
from pipeline.chain.stages import build_config
from pipeline.surveys.fates import false_accepts, marker_fates
from pipeline.tables.fate_table import FATE_STAGES

simulate = pytest.importorskip("visibility.simulate")
dem_mod = pytest.importorskip("visibility.dem")

#: Markers on a level field seen from (0, 0, 1): accepted at 8 m; a pair touching at 7 m (one
#: cluster of two spheres, too large for the gate); one out of the sensor's range.
CENTRES = np.array([[8.0, 0.0, 0.1], [0.0, 7.0, 0.1], [0.2, 7.0, 0.1], [0.0, -130.0, 0.1]])
IDS = ["A", "T1", "T2", "FAR"]


@pytest.fixture(scope="module")
def processed():
    dem = dem_mod.DEM(np.zeros((2801, 201)), (-10.0, -140.0), 0.1)
    scan, truth = simulate.simulate_markers(dem, [0.0, 0.0, 1.0], 0.0, CENTRES,
                                            marker_ids=IDS, frames=range(0, 800, 8))
    cfg = build_config()
    result = process_station(scan, cfg)
    centres = [m["centre_station_m"] for m in truth["markers"]]
    counts = [m["n_points"] for m in truth["markers"]]
    return result, centres, counts, cfg


def test_each_marker_gets_the_stage_that_lost_it(processed):
    result, centres, counts, cfg = processed
    assert counts[3] == 0 and min(counts[:3]) > 50
    fates = marker_fates(result, centres, IDS, 0.1, cfg.cluster.min_points, counts)
    got = {f.marker_id: (f.stage, f.reason) for f in fates}
    assert got["A"] == ("accepted", "")
    assert got["T1"] == ("gate", "too_large (one cluster with T2)")
    assert got["T2"] == ("gate", "too_large (one cluster with T1)")
    assert got["FAR"][0] == "not_in_view"
    assert all(f.stage in FATE_STAGES for f in fates)
    accepted = fates[0]
    assert result.rows[accepted.row_index].accepted
    assert np.linalg.norm(result.rows[accepted.row_index].centre_m - centres[0]) < 0.01
    # without the truth's counts an unseen marker keeps no point above the ground
    blind = marker_fates(result, centres, IDS, 0.1, cfg.cluster.min_points)
    assert blind[3].stage == "ground" and blind[3].n_above_ground == 0


def test_a_rejected_candidate_is_lost_at_quality(processed):
    result, centres, counts, _ = processed
    # the chain's quality gate with more points required than any marker has
    strict = build_config({"quality": {"min_points": 100000}}).quality
    rows = []
    for cand, row in zip(result.candidates, result.rows, strict=True):
        ok, reason = quality_gate(cand.fit, cand.metrics, strict)
        rows.append(replace(row, accepted=ok, reason=reason))
    rejected = replace(result, rows=rows)
    fates = marker_fates(rejected, centres, IDS, 0.1, 5, counts)
    assert fates[0].stage == "quality" and fates[0].reason == "too_few_points"
    assert false_accepts(rejected, centres, 0.1) == []


def test_false_accepts_are_accepted_rows_far_from_every_marker(processed):
    result, centres, _, _ = processed
    assert false_accepts(result, centres, 0.1) == []
    # with the accepted marker unknown, its row is a false accept
    assert false_accepts(result, centres[1:], 0.1) == [
        i for i, r in enumerate(result.rows) if r.accepted]


def test_mismatched_inputs_are_refused(processed):
    result, centres, counts, _ = processed
    with pytest.raises(ConfigError, match="one id"):
        marker_fates(result, centres, IDS[:2], 0.1, 5)
    with pytest.raises(ConfigError, match="radius"):
        marker_fates(result, centres, IDS, 0.0, 5)
