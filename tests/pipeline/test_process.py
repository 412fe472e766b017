import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.chain.evaluation import Reference
from pipeline.chain.process import detection_subset, process_station
from pipeline.chain.stages import build_config, with_offsets
from pipeline.scans.rig import MountingOffsets
from tests.pipeline.test_synthesis import synthetic_scan


def test_build_config_rejects_unknown_names_and_bad_values():
    with pytest.raises(ConfigError, match="unknown stage 'grond'"):
        build_config({"grond": {}})
    with pytest.raises(ConfigError, match="has no option 'min_height'"):
        build_config({"ground": {"min_height": 0.1}})
    with pytest.raises(ConfigError, match="must be a int"):
        build_config({"quality": {"min_points": 2.5}})
    with pytest.raises(ConfigError, match="radius_m"):
        build_config({"fit": {"radius_m": 0}})
    with pytest.raises(ConfigError, match="method"):
        build_config({"fit": {"method": "ransac"}})
    cfg = build_config({"gate": {"max_box_m": 0.4}})
    assert cfg.gate.max_box_m == 0.4 and cfg.gate.min_box_m == 0.05
    assert set(cfg.to_dict()) == {"calibrate", "ground", "cluster", "gate", "research", "fit",
                                  "quality", "evaluate"}


def test_detection_subset_caps_near_density():
    r = np.r_[np.full(1000, 1.0), np.full(1000, 8.0)]
    sub = detection_subset(r, 4.0)
    assert (sub < 1000).sum() == 1000 // 16 + (1000 % 16 > 0)
    assert (sub >= 1000).sum() == 1000


def test_detection_subset_keeps_the_whole_array_formula():
    """Exactly the indices the whole-array formula ``i % clip((4 / r)^2, 1, 64) == 0`` keeps,
    from float64 and integer ranges."""
    r = np.random.default_rng(2).uniform(0, 6, 5003)
    want = np.flatnonzero(np.arange(r.size) % np.clip((4.0 / np.maximum(r, 1e-3)) ** 2, 1, 64)
                          .astype(np.int64) == 0)
    np.testing.assert_array_equal(detection_subset(np.round(r).astype(int)),
                                  detection_subset(np.round(r)))
    got = detection_subset(r)
    assert got.dtype == np.intp
    np.testing.assert_array_equal(got, want)
    assert detection_subset(r[:0]).shape == (0,)


@pytest.fixture(scope="module")
def synthetic():
    markers = np.array([[3.0, 1.0, -0.9], [-2.5, 2.0, -0.9], [0.5, -4.0, -0.9],
                        [-3.0, -2.5, -0.9]])
    block = ((1.8, 2.6, -1.0), (2.3, 3.2, -0.6))  # a 0.5 x 0.6 x 0.4 m block
    boulder = (np.array([0.0, 3.2, -1.05]), 0.25)  # partly buried rock, 0.2 m proud
    scan = synthetic_scan(MountingOffsets(), n_frames=240, azimuth_step_deg=0.4,
                          spheres=[(c, 0.1) for c in markers] + [boulder], boxes=[block],
                          noise_m=0.01, max_range_m=8.0, seed=2)
    ref = Reference(("A", "B", "C", "D"), markers, "S1", "synthetic")
    return scan, ref


def test_chain_on_synthetic_station(synthetic):
    scan, ref = synthetic
    cfg = with_offsets(build_config(), MountingOffsets(), enabled=False)
    res = process_station(scan, cfg, ref)
    accepted = [r for r in res.rows if r.accepted]
    assert sorted(r.marker_id for r in accepted) == ["A", "B", "C", "D"]
    assert all(r.error_m < 0.006 for r in accepted)
    rejected = [r for r in res.rows if not r.accepted]
    assert all(r.reason and r.marker_id == "" for r in rejected)
    assert res.summary["n_matched_accepted"] == 4 and res.summary["n_edges"] == 6
    assert res.summary["mean_abs_edge_residual_m"] < 0.006
    assert set(res.timings_s) >= {"synthesis", "ground+cluster+gate", "research+fit+quality"}


def test_both_estimators_find_the_markers(synthetic):
    scan, ref = synthetic
    cfg = with_offsets(build_config({"fit": {"method": "hemisphere-icp"}}), MountingOffsets(),
                       enabled=False)
    res = process_station(scan, cfg, ref)
    assert sorted(r.marker_id for r in res.rows if r.accepted) == ["A", "B", "C", "D"]
    assert all(r.estimator == "hemisphere-icp" for r in res.rows)
