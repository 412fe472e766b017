"""P(visible) over a DEM's declared height error (planner.problem.terrain_uncertainty),
against the analytic ridge case: a knife ridge between a station and a marker, the error field
correlated over 4 m (independent at the station, the ridge and the marker 10 m apart, coherent
around each), so the pair is visible while the ridge's error minus the sight line's stays
below the clearance: a Gaussian tail."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import norm

from planner.problem.terrain_uncertainty import visible_probability
from visibility.dem import DEM
from visibility.orbital import HeightError
from visibility.visibility_matrix import tiled_visibility

CELL_M = 0.5
RIDGE_X_M = 10.0
MARKER_X_M = 20.0
RADIUS_M = 0.10
LIDAR_M = 1.0
#: Sight line (LiDAR 1 m above ground at x 0 -> marker centre 0.1 m above ground at x 20) at
#: the ridge, m.
SIGHT_AT_RIDGE_M = 0.5 * (LIDAR_M + RADIUS_M)
#: One pair per row: ridge crest heights (m) of the three pairs, 20 m apart along y.
RIDGES_M = (0.40, 0.55, 0.70)
ROWS_Y_M = (-20.0, 0.0, 20.0)
CONFIG = SimpleNamespace(min_visible_fraction=0.5, max_range_m=30.0, rays_per_marker=64)


def ridge_case(error: HeightError):
    """Flat ground with a one-cell knife ridge across each pair's sight line, the station
    at x 0 and the marker at x 20 (cell centres), and the planning visibility matrix."""
    x = np.arange(-4.0, 26.0 + 1e-9, CELL_M)
    y = np.arange(-32.0, 32.0 + 1e-9, CELL_M)
    heights = np.zeros((y.size, x.size))
    i = int(np.argmin(abs(x - RIDGE_X_M)))
    for h, row in zip(RIDGES_M, ROWS_Y_M, strict=True):
        band = np.abs(y - row) <= 8.0
        heights[band, i] = h
    dem = DEM(heights, (x[0], y[0]), CELL_M)
    stations = np.array([[0.0, r, LIDAR_M] for r in ROWS_Y_M])
    sites = np.array([[MARKER_X_M, r, RADIUS_M] for r in ROWS_Y_M])
    vis, _ = tiled_visibility(dem, stations, sites, RADIUS_M, CONFIG.max_range_m,
                              CONFIG.rays_per_marker, progress=False)
    keep = vis.station == vis.site  # each station's own marker (the others are > 20 m off)
    assert keep.sum() == 3
    inputs = SimpleNamespace(dem=dem, height_error=error, station_xyz=stations,
                             marker_radius_m=RADIUS_M)
    return inputs, vis, sites, keep


def analytic(error: HeightError) -> np.ndarray:
    """P(ridge error - sight-line error at the ridge < clearance): the line's error is the mean
    of the station's and the marker's (t = 1/2), all three independent."""
    sd = error.rms_m * np.sqrt(1.0 + 0.25 + 0.25)
    return norm.cdf((SIGHT_AT_RIDGE_M - np.array(RIDGES_M)) / sd)


def test_ridge_follows_the_gaussian_tail_of_the_height_error():
    error = HeightError(0.10, 4.0)
    inputs, vis, sites, keep = ridge_case(error)
    k = 120
    p = visible_probability(inputs, vis, sites, CONFIG, realisations=k, seed=3)[keep]
    expected = analytic(error)
    se = np.sqrt(expected * (1 - expected) / k)
    assert np.all(np.abs(p - expected) < 3 * se + 0.03), (p, expected)
    # the middle ridge is near the line: the answer is neither 0 nor 1
    assert 0.2 < p[1] < 0.8


def test_zero_error_gives_the_planning_dem_verdict():
    inputs, vis, sites, keep = ridge_case(HeightError(0.0, 4.0))
    p = visible_probability(inputs, vis, sites, CONFIG, realisations=3)
    assert set(np.unique(p)) <= {0.0, 1.0}
    np.testing.assert_array_equal(p, (vis.visible_fraction >= 0.5).astype(float))
    assert p[keep].tolist() == [1.0, 1.0, 0.0]  # crest below, on (half visible) and above the line


def test_no_declared_error_is_the_planning_verdict_and_seeds_repeat():
    inputs, vis, sites, _ = ridge_case(HeightError(0.10, 4.0))
    exact = SimpleNamespace(**{**vars(inputs), "height_error": None})
    np.testing.assert_array_equal(visible_probability(exact, vis, sites, CONFIG),
                                  (vis.visible_fraction >= 0.5).astype(float))
    a = visible_probability(inputs, vis, sites, CONFIG, realisations=6, seed=1)
    b = visible_probability(inputs, vis, sites, CONFIG, realisations=6, seed=1)
    np.testing.assert_array_equal(a, b)
    assert np.all((a * 6) == np.round(a * 6))


@pytest.mark.parametrize("k", [0, -1])
def test_realisations_below_one_refused(k):
    inputs, vis, sites, _ = ridge_case(HeightError(0.10, 4.0))
    with pytest.raises(ValueError, match="realisations"):
        visible_probability(inputs, vis, sites, CONFIG, realisations=k)


# --- verification on the truth terrain (planner.verify.known_control.on_truth_terrain) -----


def orbital_plan():
    """A two-station, three-marker plan of ``default`` made on its orbital DEM (heights as
    ``plan --terrain orbital`` writes them: ground of the planning DEM + rig / radius)."""
    from planner.outputs.plan_file import PlannedStation, SurveyPlan
    from visibility.sites import load_site, planning_dem

    site = load_site("default")
    orbital = planning_dem(site, "orbital")
    st_xy = np.array([[0.0, 0.0], [12.0, 0.0]])
    mk_xy = np.array([[5.0, 3.0], [-6.5, -12.5], [13.5, 0.5]])
    st_z = orbital.height_at(st_xy) + 1.0
    stations = tuple(PlannedStation(f"S{k + 1}", np.array([*xy, z]), 0.0, 0.03, ("A", "B"))
                     for k, (xy, z) in enumerate(zip(st_xy, st_z, strict=True)))
    markers = np.column_stack([mk_xy, orbital.height_at(mk_xy) + RADIUS_M])
    terrain = {"kind": "orbital", "cell_m": 2.0,
               "height_error": {"rms_m": 0.3, "correlation_m": 10.0}, "seed": 0}
    plan = SurveyPlan(dem=site.dem, stations=stations, marker_ids=("A", "B", "C"),
                      marker_xyz_m=markers, marker_radius_m=RADIUS_M, requirement_m=0.1,
                      working_radius_m=10.0,
                      provenance={"inputs": {"site": "default", "seed": 0, "terrain": terrain}})
    return plan, site, orbital


def test_orbital_plan_is_verified_on_the_truth_ground():
    from planner.verify.known_control import on_truth_terrain

    plan, site, orbital = orbital_plan()
    truth = on_truth_terrain(plan)
    assert truth.dem is site.dem
    mk = truth.marker_xyz_m
    np.testing.assert_allclose(mk[:, :2], plan.marker_xyz_m[:, :2])
    np.testing.assert_allclose(mk[:, 2], site.dem.height_at(mk[:, :2]) + RADIUS_M, atol=1e-9)
    # the orbital ground is off the truth's by decimetres: the re-seating moved them
    assert np.max(np.abs(mk[:, 2] - plan.marker_xyz_m[:, 2])) > 0.05
    for st in truth.stations:
        ground = site.dem.height_at(st.position_m[None, :2])[0]
        assert st.position_m[2] == pytest.approx(ground + 1.0, abs=1e-9)


def test_plan_on_its_own_terrain_is_verified_unchanged():
    from dataclasses import replace

    from planner.verify.known_control import on_truth_terrain

    plan, site, _ = orbital_plan()
    on_truth = replace(plan, provenance={"inputs": {"site": "default", "seed": 0}})
    assert on_truth_terrain(on_truth) is on_truth
    assert on_truth_terrain(on_truth, site.dem) is on_truth


def test_truth_dem_not_covering_names_every_uncovered_id():
    from markerplan.errors import DataError
    from planner.verify.known_control import on_truth_terrain

    plan, _, _ = orbital_plan()
    small = DEM(np.zeros((81, 81)), (-2.0, -2.0), 0.1)  # covers S1 (0, 0) and A (5, 3) only
    with pytest.raises(DataError, match=r"`truth_dem` does not cover S2, B, C of the plan"):
        on_truth_terrain(plan, small)


# --- planning inputs on the orbital DEM (planner.problem.inputs.load_inputs) ---------------


def test_orbital_inputs_record_their_terrain_and_verify_rebuilds_it():
    from planner.outputs.plan_file import SurveyPlan
    from planner.problem.inputs import load_inputs
    from planner.verify.known_control import planning_terrain
    from visibility.sites import load_site, planning_dem

    inputs = load_inputs("default", 0, terrain="orbital")
    site = load_site("default", 0)
    np.testing.assert_array_equal(inputs.dem.heights_m, planning_dem(site, "orbital").heights_m)
    assert inputs.height_error == HeightError(0.3, 10.0)
    assert inputs.sources["terrain"] == {"kind": "orbital", "cell_m": 2.0, "seed": 0,
                                         "height_error": {"rms_m": 0.3, "correlation_m": 10.0}}
    np.testing.assert_allclose(inputs.station_xyz[:, 2],
                               inputs.dem.height_at(inputs.station_xyz[:, :2]) + 1.0)
    assert all(c.diameter_m >= 4.0 for c in inputs.craters)
    # verify rebuilds the very planning DEM from plan.json's provenance
    plan = SurveyPlan(dem=site.dem, stations=(), marker_ids=(), marker_xyz_m=np.zeros((0, 3)),
                      marker_radius_m=RADIUS_M, requirement_m=0.1, working_radius_m=10.0,
                      provenance={"inputs": inputs.sources})
    np.testing.assert_array_equal(planning_terrain(plan).heights_m, inputs.dem.heights_m)
    truth = load_inputs("default", 0)
    assert truth.height_error is None and "terrain" not in truth.sources


def test_dem_file_declares_its_height_error(tmp_path):
    from markerplan.errors import ConfigError
    from planner.problem.inputs import load_inputs
    from visibility.dem import write_dem

    write_dem(tmp_path / "nac.npz", DEM(np.zeros((41, 41)), (-20.0, -20.0), 1.0))
    (tmp_path / "st.csv").write_text("id,x_m,y_m\nS1,0,0\nS2,5,5\n")
    inputs = load_inputs(dem_path=tmp_path / "nac.npz", stations_path=tmp_path / "st.csv",
                         dem_height_error=HeightError(0.5))
    assert inputs.height_error == HeightError(0.5, 10.0)
    assert inputs.sources["terrain"] == {"kind": "file", "cell_m": 1.0, "seed": None,
                                         "height_error": {"rms_m": 0.5, "correlation_m": 10.0}}
    with pytest.raises(ConfigError, match="`terrain` orbital is a site preset's orbital DEM"):
        load_inputs(dem_path=tmp_path / "nac.npz", stations_path=tmp_path / "st.csv",
                    terrain="orbital")
    with pytest.raises(ConfigError, match="the preset's truth terrain is exact"):
        load_inputs(dem_height_error=HeightError(0.5))
