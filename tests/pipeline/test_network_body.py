"""The curvature of the local vertical: deflections, the simulator levelling to it and the
adjustment's tilt prior centred on it (a plane prior leaves the sagitta D^2 / 2R at the far
station, the curved prior removes it)."""

import math
import re

import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.body import BODY_RADIUS_M, Body
from pipeline.network.observations import Datum
from pipeline.network.simulation import simulated_network
from pipeline.scans.rig import station_to_site_matrix

MOON, EARTH = Body.named("moon"), Body.named("earth")


def up_axis(tilt, heading):
    """The levelled station's z axis in the site frame, (n, 3)."""
    return np.stack([station_to_site_matrix(h, r, p)[:, 2]
                     for h, (r, p) in zip(heading, tilt, strict=True)])


@pytest.mark.parametrize("body", [MOON, EARTH])
def test_deflection_is_d_over_r_away_from_the_tangent_point(body):
    rng = np.random.default_rng(0)
    d = np.array([1.0, 100.0, 381.0, 800.0])
    bearing = rng.uniform(-np.pi, np.pi, d.size)
    tangent = np.array([12.0, -7.0])
    position = np.column_stack([tangent[0] + d * np.cos(bearing),
                                tangent[1] + d * np.sin(bearing), np.zeros(d.size)])
    heading = rng.uniform(-np.pi, np.pi, d.size)
    tilt = body.vertical_tilt(position, heading, tangent)
    up = up_axis(tilt, heading)
    outward = np.column_stack([np.cos(bearing), np.sin(bearing)])
    # the vertical leans away from the tangent point by atan(d / R), and only that way
    np.testing.assert_allclose(np.einsum("ni,ni->n", up[:, :2], outward), np.sin(np.arctan(
        d / body.radius_m)), rtol=1e-9)
    across = up[:, 0] * outward[:, 1] - up[:, 1] * outward[:, 0]
    np.testing.assert_allclose(across, 0.0, atol=1e-15)
    np.testing.assert_allclose(np.hypot(*tilt.T), d / body.radius_m, rtol=1e-6)
    # 381 m on the Moon: the 0.0126 deg
    if body is MOON:
        assert math.degrees(np.hypot(*tilt[2])) == pytest.approx(0.012564, abs=1e-6)


def test_deflection_zero_at_the_tangent_point_and_on_the_plane():
    position = np.array([[5.0, 6.0, 1.5], [300.0, -400.0, 2.0]])
    heading = np.array([0.3, -2.0])
    assert np.array_equal(MOON.vertical_tilt(position[:1], heading[:1], (5.0, 6.0)),
                          np.zeros((1, 2)))
    assert np.array_equal(Body().vertical_tilt(position, heading), np.zeros((2, 2)))
    assert np.array_equal(Body.named("plane").vertical_tilt(position, heading), np.zeros((2, 2)))


def test_pitch_along_heading_roll_across():
    # ahead of the tangent point the station pitches up by d / R; to its left it rolls by -d / R
    tilt = MOON.vertical_tilt(np.array([[0.0, 500.0, 0.0], [-500.0, 0.0, 0.0]]),
                              np.full(2, np.pi / 2))
    r = math.atan(500.0 / BODY_RADIUS_M["moon"])
    np.testing.assert_allclose(tilt, [[0.0, r], [-r, 0.0]], atol=1e-12, rtol=1e-9)


@pytest.mark.parametrize("make, message", [
    (lambda: Body.named("mars"), "`body` must be one of moon, earth, plane, got 'mars'"),
    (lambda: Body("sphere", 0.0), "`radius_m` of the body must be a finite number > 0"),
    (lambda: Body("sphere", -5.0), "`radius_m` of the body must be a finite number > 0"),
    (lambda: Body("moon", 1000.0), "a radius of your own is Body('sphere', R)"),
    (lambda: Body("moon"), "needs a radius_m > 0"),
    (lambda: AdjustmentSettings(body="moon"), "body must be a Body"),
    (lambda: AdjustmentSettings(tangent_point_m=(1.0,)), "tangent_point_m must be None or 2"),
    (lambda: AdjustmentSettings(tangent_point_m=("a", 1.0)), "tangent_point_m must be None or 2"),
    (lambda: simulated_network(body="moon"), "`body` must be a Body"),
])
def test_bad_body_is_one_config_error(make, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        make()


def far_station_error(settings, noise_seed=None, **kw):
    """A straight 14-station traverse to ~390 m on the Moon, curvature the only error."""
    args = dict(n_stations=14, spacing_m=30.0, max_range_m=45.0, turn_sigma_rad=0.0,
                noise_scale=0.0, inclinometer_sigma_rad=0.0, seed=3, body=MOON)
    args.update(kw)
    obs, truth = simulated_network(noise_seed=noise_seed, **args)
    result = adjust(obs, settings=settings, nominal=truth.nominal)
    d = np.linalg.norm(truth.pose[-1, :2] - truth.pose[0, :2])
    return result.pose[-1, :3] - truth.pose[-1, :3], d, result


def test_plane_prior_leaves_the_sagitta_curved_prior_removes_it():
    plane = AdjustmentSettings(snooping=False)
    error, d, _ = far_station_error(plane, odometry_sigma_m=0.0, odometry_heading_sigma_rad=0.0)
    assert d > 350.0
    sagitta = d**2 / (2 * BODY_RADIUS_M["moon"])  # 39 mm at 381 m (module doc of the benchmark)
    assert error[2] == pytest.approx(sagitta, rel=0.05)
    assert np.hypot(*error[:2]) < 0.1 * sagitta
    curved = AdjustmentSettings(snooping=False, body=MOON)
    error, _, result = far_station_error(curved, odometry_sigma_m=0.0,
                                         odometry_heading_sigma_rad=0.0)
    assert np.abs(error).max() < 1e-9
    assert result.settings.body.to_dict() == {"name": "moon", "radius_m": 1_737_400.0}
    # odometry errors of metres move the prior's centre by microradians: still < 1 mm
    error, _, _ = far_station_error(curved, odometry_sigma_m=1.0, noise_seed=5)
    assert np.abs(error).max() < 1e-3


def test_curved_prior_without_nominal_poses_and_with_another_datum_station():
    obs, truth = simulated_network(n_stations=10, spacing_m=30.0, max_range_m=45.0, seed=8,
                                   noise_scale=0.0, inclinometer_sigma_rad=0.0, body=MOON)
    # the site frame's tangent point is the first station (the site origin); the datum
    # station S06 is ~150 m away, so the tangent point must be given
    datum = Datum(reference_station="S06", reference_pose=tuple(truth.pose[5, :4]))
    given = adjust(obs, datum, AdjustmentSettings(snooping=False, body=MOON,
                                                  tangent_point_m=(0.0, 0.0)))
    # chained initial values (tilts 0) move the prior's centre by nanoradians
    assert np.abs(given.pose - truth.pose).max() < 1e-6
    assert np.abs(given.marker_xyz_m - truth.marker_xyz_m).max() < 1e-6
    wrong = adjust(obs, datum, AdjustmentSettings(snooping=False, body=MOON))
    assert np.abs(wrong.marker_xyz_m - truth.marker_xyz_m).max() > 1e-3
