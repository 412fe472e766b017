"""The processing config of a survey's settings and the station loop over its scan files."""

import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.chain.evaluation import read_reference
from pipeline.chain.process import process_station
from pipeline.chain.stages import build_config, with_offsets
from pipeline.scans.rig import MountingOffsets
from pipeline.scans.scan_format import read_scan
from pipeline.scans.sensor_noise import RangeNoise
from pipeline.surveys.survey import ProcessingSettings, process_scans, processing_config
from tests.cli.bad_input import write_synthetic_station


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    d = tmp_path_factory.mktemp("scans")
    write_synthetic_station(d, n_frames=240, azimuth_step_deg=0.4)
    return d


def test_radius_only_is_the_chains_default_config_at_that_radius():
    for radius in (0.075, 0.1, 0.15):
        assert (processing_config(ProcessingSettings(marker_radius_m=radius))
                == build_config({"fit": {"radius_m": radius}}))
    assert processing_config(ProcessingSettings()) == build_config()


def test_settings_take_precedence_over_stage_options():
    offsets = MountingOffsets(0.001, -0.002, (0.003, 0.0))
    cfg = processing_config(ProcessingSettings(
        marker_radius_m=0.15, estimator="hemisphere-icp", offsets=offsets, calibrate=False,
        min_points=30, max_rms_m=0.02,
        stage_options={"fit": {"method": "fixed-radius", "radius_m": 0.2},
                       "quality": {"min_points": 10}, "gate": {"max_box_m": 0.5}}))
    assert (cfg.fit.method, cfg.fit.radius_m) == ("hemisphere-icp", 0.15)
    assert (cfg.quality.min_points, cfg.quality.max_rms_m, cfg.quality.max_rms_sigma) == (
        30, 0.02, 0.0)
    assert cfg.gate.max_box_m == 0.5 and cfg.research.radius_m == pytest.approx(0.45)
    assert not cfg.calibrate.enabled and cfg.calibrate.offsets() == offsets
    # the stage options alone give the radius when the settings do not
    assert processing_config(ProcessingSettings(
        stage_options={"fit": {"radius_m": 0.2}})).fit.radius_m == 0.2


def test_unknown_stage_option_refused_by_name():
    with pytest.raises(ConfigError, match="no option 'max_box'"):
        processing_config(ProcessingSettings(stage_options={"gate": {"max_box": 0.3}}))


def test_process_scans_is_process_station_per_scan(station):
    path = station / "station_S1.scan.npz"
    ref = read_reference(station / "station_S1.truth.json")
    cfg = with_offsets(build_config(), MountingOffsets(), enabled=False)
    fallback = RangeNoise(0.01)
    seen = []
    survey = process_scans([path], cfg, [ref], fallback, "sensor profile test",
                           each=lambda scan, result: seen.append((scan.station_id, result)))
    direct = process_station(read_scan(path), cfg, ref, noise=fallback)
    (res,) = survey.results
    assert [r.marker_id for r in res.rows] == [r.marker_id for r in direct.rows]
    np.testing.assert_array_equal([r.centre_m for r in res.rows],
                                  [r.centre_m for r in direct.rows])
    assert res.summary["n_matched_accepted"] == 4
    assert seen == [("S1", res)]
    (record,) = survey.inputs
    assert record["scan"] == str(path) and record["station_id"] == "S1"
    assert len(record["sha256"]) == 64
    # the synthetic scan records no range noise: the fallback is followed, and named
    assert record["range_noise"]["source"] == "sensor profile test"
    assert record["range_noise"]["range_noise_m"] == 0.01
