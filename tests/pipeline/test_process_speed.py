"""The station chain's speed-ups give the results of the straightforward code they replaced.

Each faster step is compared with a plain reference implementation (the code it replaced), and
the whole chain on a small simulated scan with the marker table and offsets that revision
6391827 (before the speed-ups) produced.
"""

import math

import numpy as np
import pytest

from markerplan.errors import DataError
from pipeline.gate import RangeIndex, within_range_bands
from pipeline.process import detection_subset
from pipeline.rig import MountingOffsets, frame_poses, sensor_to_station


def test_range_bands_keep_every_research_point():
    """Indexing only the range bands finds exactly the points indexing everything finds,
    including points on the search sphere itself."""
    gen = np.random.default_rng(5)
    pts = gen.uniform(-12, 12, (60000, 3))
    pts[:, 2] *= 0.1
    centres = np.array([[3.0, 4.0, 0.0], [0.05, 0.0, 0.0], [-9.0, 0.2, 0.1], [0.0, 11.0, 0]])
    radius = 0.3
    u = gen.normal(size=(40, 3))
    on_sphere = centres[[1, 2]].repeat(20, 0) + radius * u / np.linalg.norm(u, axis=1)[:, None]
    pts = np.vstack([pts, on_sphere, centres[2] * (1 - radius / np.linalg.norm(centres[2]))])
    rng = np.sqrt(np.einsum("ij,ij->i", pts, pts))
    full = RangeIndex(pts, rng)
    for bin_m in (0.05, 1e-4):  # fine bins: the bands themselves, not the bins, must hold
        near = within_range_bands(rng, centres, radius, bin_m)
        assert np.all(np.diff(near) > 0) and near.size < pts.shape[0] // 2
        part = RangeIndex(pts[near], rng[near])
        for c in centres:
            want = full.within(c, radius)
            assert want.size > 0
            np.testing.assert_array_equal(near[part.within(c, radius)], want)
    assert within_range_bands(rng, np.zeros((0, 3)), radius).size == 0


def test_detection_subset_matches_the_formula():
    """Same indices as ``i % clip((4 / r)^2, 1, 64) == 0`` in int64, at the stride edges too."""
    gen = np.random.default_rng(6)
    r = np.r_[0.0, 1e-4, 0.5, 0.5 + 1e-12, 1.0, 2.0, 4.0 - 1e-12, 4.0, 4.0 + 1e-12, 100.0,
              gen.uniform(0, 8, 20000)]
    for dtype in (np.float64, np.float32):
        rd = r.astype(dtype)
        stride = np.clip((4.0 / np.maximum(rd, 1e-3)) ** 2, 1, 64)
        want = np.flatnonzero(np.arange(rd.size) % stride.astype(np.int64) == 0)
        np.testing.assert_array_equal(detection_subset(rd), want)


def test_sensor_to_station_matches_per_frame_products():
    """The per-frame ``p @ R.T + t`` (up to round-off), with unsorted runs of frames, from
    float32 and float64 points; a frame without a turntable angle is an error, not a read
    past the poses."""
    gen = np.random.default_rng(7)
    angles = np.linspace(0, 2 * np.pi, 9)[:-1]
    fi = np.repeat(gen.permutation(8), gen.integers(1, 50, 8))
    fi = np.r_[fi, fi[:5]].astype(np.uint32)
    p = gen.uniform(-20, 20, (fi.size, 3)).astype(np.float32)
    off = MountingOffsets(0.004, -0.003, (0.015, -0.002))
    rot, trans = frame_poses(angles, off)
    want = np.array([p[k] @ rot[f].T + trans[f] for k, f in enumerate(fi)])
    for points in (p, p.astype(np.float64)):
        got = sensor_to_station(points, fi, angles, off)
        assert got.dtype == np.float64
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert sensor_to_station(p[:0], fi[:0], angles, off).shape == (0, 3)
    with pytest.raises(DataError, match="8 turntable angles"):
        sensor_to_station(p, np.r_[fi[:-1], 8].astype(np.uint32), angles, off)


#: Revision 6391827 (before the speed-ups) on default-site station 0, every 16th of 800 frames,
#: offsets 0.3 deg, 0.3 deg, 15 mm, seed 0: the estimated offsets and, per marker-table row,
#: (marker_id, x, y, z, n_points, fit_rms_m, radius_fit_m, visible_fraction, accepted, reason).
BASELINE_OFFSETS = (0.005240265240765853, 0.005305064757486782,
                    (0.015069952962744167, -0.0008272535793548076))
BASELINE_ROWS = [
    ("M10", -14.55797527902285, -10.580352263545128, -0.39137897917845615, 7,
     0.008912306234472245, 0.10845322191890965, 1.0, False, "too_few_points"),
    ("M09", -14.557188092314393, 10.58870599384414, -0.6862321173110154, 6,
     0.005032193500601391, 0.07056295264671575, 1.0, False, "too_few_points"),
    ("", -6.382379438759864, 6.319904086092785, -0.9318242849124698, 7,
     0.01313391106170435, 0.08613653161769076, 0.5, False, "too_few_points"),
    ("", -5.75758705077668, -17.872471026910567, -0.8558612351526191, 18,
     0.11839850137172027, math.nan, 0.25, False, "too_few_points"),
    ("M04", -5.194727707091048, -3.0083599081950188, -0.693256321297134, 39,
     0.011258837149644001, 0.09286570743734934, 1.0, True, ""),
    ("M03", -5.190970140353136, 3.0115293628907644, -0.8284435956954693, 37,
     0.011241288537543978, 0.09121911425825646, 1.0, True, ""),
    ("M02", -0.0029126387158686976, 5.997222965379252, -1.0001933445483193, 39,
     0.01121637518174199, 0.1025287973558947, 1.0, True, ""),
    ("M05", 0.004272446855000911, -5.998391597185211, -0.7785711951640664, 46,
     0.012835388807811886, 0.11696328278518522, 1.0, True, ""),
    ("M06", 5.192421258197312, -3.003323355911473, -0.9670090652437244, 40,
     0.00944064411379547, 0.10260469781471346, 1.0, True, ""),
    ("M01", 5.193204518532522, 2.9980666801977063, -1.000800618280614, 43,
     0.009659513374068998, 0.09395560107987261, 1.0, True, ""),
    ("M08", 5.555898738925132, 17.129568445423214, -1.197809114359205, 6,
     0.008616257965635437, 0.14783935278665128, 1.0, False, "too_few_points"),
    ("M11", 5.562289592075678, -17.117094599004037, -0.7320073941296913, 8,
     0.009584832590878667, 14.19925612315455, 1.0, False, "too_few_points"),
]


@pytest.mark.slow
def test_chain_reproduces_the_baseline_marker_table():
    """Self-calibration (ICP, axis offset, re-detection), detection, re-search, fits and
    verdicts as before the speed-ups, which changed the arithmetic at round-off level: the
    offsets and the accepted markers' columns within 1e-9 relative; rejected candidates keep
    their ids, counts and reasons, but their fits (a handful of points, or not a sphere) are
    so ill-conditioned that a 1e-14 m change of the points moves them by millimetres (as
    does a bit-identical chain on another machine), so their centres are held to 1 cm only."""
    sites = pytest.importorskip("visibility.sites")
    simulate = pytest.importorskip("visibility.simulate")
    sensor = pytest.importorskip("visibility.sensor")
    from pipeline.evaluation import reference_from_truth
    from pipeline.process import process_station
    from pipeline.stages import build_config

    rig = sensor.RigConfig(offsets=MountingOffsets(np.radians(0.3), np.radians(0.3),
                                                   (0.015, 0.0)))
    scan, truth = simulate.simulate_station(sites.load_site("default"), 0, rig=rig, seed=0,
                                            frames=range(0, 800, 16))
    res = process_station(scan, build_config(), reference_from_truth(truth, "truth"))
    o = res.offsets
    got = [o.vertical_axis_error_rad, o.lframe_tilt_rad, *o.axis_offset_m]
    np.testing.assert_allclose(got, [*BASELINE_OFFSETS[:2], *BASELINE_OFFSETS[2]], rtol=1e-9)
    rows = [(r.marker_id, r.x_m, r.y_m, r.z_m, r.n_points, r.fit_rms_m, r.radius_fit_m,
             r.visible_fraction, r.accepted, r.reason) for r in res.rows]
    assert [(r[0], r[4], r[8], r[9]) for r in rows] == [
        (r[0], r[4], r[8], r[9]) for r in BASELINE_ROWS]
    ok = [r[8] for r in BASELINE_ROWS]
    np.testing.assert_allclose([r[1:4] + r[5:8] for r, a in zip(rows, ok, strict=True) if a],
                               [r[1:4] + r[5:8] for r in BASELINE_ROWS if r[8]], rtol=1e-9,
                               atol=1e-12)
    np.testing.assert_allclose([r[1:4] for r, a in zip(rows, ok, strict=True) if not a],
                               [r[1:4] for r in BASELINE_ROWS if not r[8]], rtol=0, atol=1e-2)
