import numpy as np
import pytest
from scipy.optimize import least_squares

from markerplan.errors import ConfigError, DataError
from pipeline.scans.pointsets import read_points
from pipeline.scans.sensor_noise import RangeNoise
from pipeline.sphere_centres import sphere_fit
from pipeline.sphere_centres.geometric_sphere_fit import fit_free_radius
from pipeline.sphere_centres.sphere_fit import METHODS, fit_sphere, hemisphere_model


def noisy_cap(centre, radius, sensor, n, noise, rng, half_angle_deg=80.0):
    """Points on the sensor-facing cap of a sphere, range noise along the line of sight."""
    centre = np.asarray(centre, float)
    sensor = np.asarray(sensor, float)
    axis = (sensor - centre) / np.linalg.norm(sensor - centre)
    u = rng.normal(size=(4 * n, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    u = u[u @ axis > np.cos(np.radians(half_angle_deg))][:n]
    p = centre + radius * u
    los = (p - sensor) / np.linalg.norm(p - sensor, axis=1)[:, None]
    return p + los * rng.normal(0, noise, size=(len(p), 1))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("distance", [2.0, 10.0])
def test_noisy_cap_recovers_known_centre(method, distance):
    rng = np.random.default_rng(4)
    centre = np.array([distance * 0.8, distance * 0.6, -0.9])
    pts = noisy_cap(centre, 0.1, (0, 0, 0), 800, 0.003, rng)
    fit = fit_sphere(pts, 0.1, method=method)
    assert fit.converged
    assert np.linalg.norm(fit.centre_m - centre) < 1.5e-3
    assert 0.001 < fit.rms_m < 0.0033  # range noise projected on the surface normal
    assert fit.method == method


def test_fixed_radius_ignores_mount_and_background_icp_does_not():
    rng = np.random.default_rng(7)
    centre = np.array([0.0, 6.0, 0.0])
    cap = noisy_cap(centre, 0.05, (0, 0, 0), 1500, 0.0005, rng)
    # a mount post below the sphere and a wall behind it
    post = np.column_stack([rng.uniform(-0.01, 0.01, 300), rng.uniform(5.95, 5.97, 300),
                            rng.uniform(-0.2, -0.05, 300)])
    wall = np.column_stack([rng.uniform(-0.1, 0.1, 600), np.full(600, 6.1),
                            rng.uniform(-0.1, 0.1, 600)])
    pts = np.vstack([cap, post, wall])
    fixed = fit_sphere(pts, 0.05, method="fixed-radius")
    icp = fit_sphere(pts, 0.05, method="hemisphere-icp")
    assert np.linalg.norm(fixed.centre_m - centre) < 3e-4
    assert np.linalg.norm(icp.centre_m - centre) > np.linalg.norm(fixed.centre_m - centre)


def test_free_radius_recovers_radius():
    rng = np.random.default_rng(1)
    pts = noisy_cap([3, 0, 0], 0.3, (0, 0, 0), 2000, 0.001, rng)
    c, r, rms = fit_free_radius(pts, np.array([3.2, 0, 0]), 0.1)
    assert r == pytest.approx(0.3, abs=0.005)
    np.testing.assert_allclose(c, [3, 0, 0], atol=0.005)
    assert rms < 0.002


def test_hemisphere_model_faces_minus_x():
    m = hemisphere_model(0.1)
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), 0.1)
    assert (m[:, 0] <= 0).all() and len(m) > 1000


@pytest.mark.parametrize("kwargs, err", [
    ({"radius_m": 0.0}, ConfigError), ({"radius_m": -1.0}, ConfigError),
    ({"radius_m": 0.1, "method": "ransac"}, ConfigError),
    ({"radius_m": 0.1, "sensor_m": (0, 0)}, ConfigError),
])
def test_bad_arguments_raise(kwargs, err):
    pts = noisy_cap([2, 0, 0], 0.1, (0, 0, 0), 50, 0.001, np.random.default_rng(0))
    with pytest.raises(err, match="`"):
        fit_sphere(pts, **kwargs)


def test_too_few_points_raise():
    with pytest.raises(DataError, match="at least 4"):
        fit_sphere(np.zeros((3, 3)), 0.1)


def _nist_reference(data, radius, iterations=6):
    """Literal transcription of NIST's coneCylAlgoE57 (6 passes, scipy least squares)."""

    def fit(pts, c0):
        return least_squares(lambda c: np.linalg.norm(pts - c, axis=1) - radius, c0,
                             xtol=1e-14, ftol=1e-14, gtol=1e-14).x

    rng = np.linalg.norm(data, axis=1)
    n = len(data)
    k = int(np.floor(min(500, 0.05 * n)))
    start = np.median(np.sort(rng)[:k])
    first = data[rng < start + 0.5 * radius]
    c0 = first.mean(axis=0) * (1 + radius / np.linalg.norm(first.mean(axis=0)))
    centre = fit(first, c0)
    for _ in range(iterations - 1):
        co = -centre
        cp = data - centre
        ang = np.arctan2(np.linalg.norm(np.cross(co, cp), axis=1), cp @ co)
        unit = co / np.linalg.norm(co)
        dof = data @ -unit
        dpf = np.sqrt(np.maximum((data ** 2).sum(1) - dof ** 2, 0))
        sel = data[(np.degrees(ang) < 60) & (dpf < radius * np.sin(np.radians(60)))]
        c1 = fit(sel, centre)
        res = np.linalg.norm(sel - c1, axis=1) - radius
        final = sel[np.abs(res) < 3 * np.std(res)]
        centre = fit(final, c1)
    return centre


@pytest.mark.realdata
def test_nist_scans_match_astm_e3125_reference(real_data):
    folder = real_data / "nist_spheres"
    files = sorted(folder.glob("SPH*.xyz"))
    assert len(files) == 11
    for f in files:
        pts = read_points(f)
        fit = fit_sphere(pts, 0.05, method="fixed-radius")
        ref = _nist_reference(pts, 0.05)
        assert np.linalg.norm(fit.centre_m - ref) < 1e-3, f.name
        # the trimmed points are a clean sphere: free-radius fit gives ~50 mm, rms well < 1 mm
        _, r, rms = fit_free_radius(pts[fit.used], fit.centre_m, 0.05)
        assert abs(r - 0.05) < 2e-3, f.name
        assert fit.rms_m < 5e-4, f.name


@pytest.mark.parametrize("noise", [None, RangeNoise(0.045, range_resolution_m=0.0)])
def test_a_cycling_fit_stops_where_the_full_loop_would(monkeypatch, noise):
    """Noisy caps whose ASTM loop cycles (6 of these 8 do): stopping once the point sets
    repeat gives the sets, iterations and (to the Gauss-Newton tolerance) the centre that
    running all 100 iterations gives."""
    caps = [noisy_cap([5.0, 1.0, -0.9], 0.1, (0, 0, 0), 300, 0.045, np.random.default_rng(s))
            for s in range(8)]
    short = [fit_sphere(p, 0.1, centre0_m=[5.05, 1.0, -0.9], noise=noise) for p in caps]
    monkeypatch.setattr(sphere_fit, "_cycle_period", lambda states: 0)
    full = [fit_sphere(p, 0.1, centre0_m=[5.05, 1.0, -0.9], noise=noise) for p in caps]
    assert sum(f.iterations == 100 for f in full) == 6  # the cycles were met
    for a, b in zip(short, full, strict=True):
        assert (a.iterations, a.converged, a.n_used) == (b.iterations, b.converged, b.n_used)
        np.testing.assert_array_equal(a.used, b.used)
        np.testing.assert_allclose(a.centre_m, b.centre_m, rtol=0, atol=1e-10)
        assert a.rms_m == pytest.approx(b.rms_m, rel=0, abs=1e-10)
