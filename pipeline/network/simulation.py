"""Synthetic networks with known truth, for tests, benchmarks and planning studies.

Stations lie along a traverse: each step is ``spacing_m`` long in a direction that turns by a
random amount (1-sigma ``turn_sigma_rad`` per step; 0 for a straight line), the rover faces
along it (the station's heading) and the ground height wanders.
Markers are scattered around the stations (uniform in a ring between 2 m and
``0.9 max_range_m`` around a random station, about a metre below the LiDAR centre). Each
station observes every marker within ``max_range_m`` (3D distance); the measurement is the true
centre in the station's levelled frame — the frame the inclinometer believes is level: the
local vertical of ``body`` (:mod:`pipeline.network.body`; the site frame is the tangent plane at
the first station, the site origin), so the station's true roll and pitch are the vertical's
deflection plus the inclinometer's error drawn from ``inclinometer_sigma_rad`` —
plus isotropic noise of per-axis variance ``sigma**2 / 3``. The nominal poses are odometry: the
reference (first) station at its true pose, then a random walk of position and heading errors.
This is the model of :mod:`pipeline.network.adjustment`, so with zero noise the adjustment
given the same body recovers the truth exactly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from markerplan.errors import ConfigError
from pipeline.network.aids import OdometryReadings
from pipeline.network.body import Body
from pipeline.network.observations import NetworkObservations, NominalPoses
from pipeline.scans.rig import station_to_site_matrix


@dataclass(frozen=True)
class NetworkTruth:
    """The truth behind a simulated network.

    Attributes
    ----------
    pose : (s, 6) float
        True station poses (``POSE_PARAMETERS``), site frame, m and rad.
    marker_xyz_m : (k, 3) float
        True marker centres, site frame, m (in ``NetworkObservations.marker_ids`` order).
    nominal : NominalPoses
        Odometry: the first station exact, the others with accumulated errors.
    odometry : OdometryReadings or None
        Measured relative poses between consecutive stations (station order), and the closing
        reading with ``odometry_loop_m``, when asked for (``odometry_ratio`` or
        ``odometry_heading_rad_per_m``).
    heading_reading_rad : (s,) float or None
        The heading reference's readings (true heading + one common bias + per-station
        noise), when asked for (``heading_sigma_rad``).
    heading_bias_rad : float
        The bias drawn (0 without readings).
    """

    pose: np.ndarray
    marker_xyz_m: np.ndarray
    nominal: NominalPoses
    odometry: OdometryReadings | None = None
    heading_reading_rad: np.ndarray | None = None
    heading_bias_rad: float = 0.0


def simulated_network(n_stations: int = 10, spacing_m: float = 15.0,
                      markers_per_station: float = 3.0, max_range_m: float = 30.0,
                      sigma_m: float | Callable[[np.ndarray], np.ndarray] = 0.01,
                      inclinometer_sigma_rad: float = math.radians(0.01),
                      odometry_sigma_m: float = 0.3, odometry_heading_sigma_rad: float = 0.02,
                      noise_scale: float = 1.0, seed: int = 0, noise_seed: int | None = None,
                      turn_sigma_rad: float = 0.4, body: Body = Body(),  # noqa: B008 (frozen)
                      odometry_ratio: float | None = None,
                      odometry_heading_rad_per_m: float | None = None,
                      heading_sigma_rad: float | None = None, heading_bias_sigma_rad: float = 0.0,
                      odometry_loop_m: float | None = None
                      ) -> tuple[NetworkObservations, NetworkTruth]:
    """A random traverse network, its observations and its truth.

    Parameters
    ----------
    n_stations : int
        Stations along the traverse (>= 1); ids ``S01``, ``S02``, ...
    spacing_m : float
        Distance between consecutive stations, m.
    markers_per_station : float
        Markers placed per station (``round(markers_per_station * n_stations)`` in all); ids
        ``M001``, ... in placement order, those no station sees dropped.
    max_range_m : float
        Largest 3D distance at which a station observes a marker, m.
    sigma_m : float or callable
        1-sigma 3D centre error, m, or a function of the (n,) distances (m) giving (n,) sigmas.
    inclinometer_sigma_rad : float
        1-sigma of each station's true roll and pitch error, rad (0 for none).
    odometry_sigma_m, odometry_heading_sigma_rad : float
        1-sigma per step of the odometry's position (per axis, m) and heading (rad) random walk.
    noise_scale : float
        Factor on the measurement noise drawn (0: exact measurements; ``sigma_m`` is still the
        stated sigma).
    seed : int
        Seed of the geometry (and of the noise when ``noise_seed`` is None).
    noise_seed : int or None
        Separate seed of the noise (measurements, tilts, odometry): the same network with new
        noise, e.g. for Monte-Carlo trials.
    turn_sigma_rad : float
        1-sigma of the traverse's turn at each station, rad (0: a straight line).
    body : Body
        The body whose local vertical the stations are levelled to (tangent point: the site
        origin, where the first station stands); default the plane.
    odometry_ratio, odometry_heading_rad_per_m : float or None
        Measure the relative poses of consecutive stations
        (:class:`~pipeline.network.aids.OdometryReadings`, from the true poses) with per-axis
        noise ``odometry_ratio * d`` and heading noise ``odometry_heading_rad_per_m * d`` (``d``
        the true 3D distance; None: exact); neither: no readings.
    heading_sigma_rad, heading_bias_sigma_rad : float or None, float
        Read each station's heading: true heading + one common bias (1-sigma
        ``heading_bias_sigma_rad``) + independent noise (``heading_sigma_rad``); None: no
        readings. All these draws come after the others, so asking for them changes nothing
        else.
    odometry_loop_m : float or None
        With odometry readings: the traverse is closed, the rover driving this far from the
        last station back to the first (> 0 m); the closing reading (the first station's true
        pose in the last's levelled frame) gets noise of ``odometry_ratio * odometry_loop_m``
        per axis and ``odometry_heading_rad_per_m * odometry_loop_m`` on the heading, drawn
        last of all (so closing the traverse changes no other draw).

    Returns
    -------
    obs : NetworkObservations
        Ordered by station, then by marker id.
    truth : NetworkTruth

    Examples
    --------
    >>> obs, truth = simulated_network(n_stations=3, seed=2)
    >>> obs.station_ids, truth.pose.shape
    (('S01', 'S02', 'S03'), (3, 6))
    >>> bool(np.allclose(truth.nominal.position_m[0], truth.pose[0, :3]))
    True
    """
    if not (isinstance(n_stations, int) and n_stations >= 1):
        raise ConfigError(f"`n_stations` must be an integer >= 1, got {n_stations!r}")
    for name, value in (("spacing_m", spacing_m), ("markers_per_station", markers_per_station),
                        ("max_range_m", max_range_m),
                        ("inclinometer_sigma_rad", inclinometer_sigma_rad),
                        ("noise_scale", noise_scale), ("turn_sigma_rad", turn_sigma_rad),
                        ("odometry_sigma_m", odometry_sigma_m),
                        ("odometry_heading_sigma_rad", odometry_heading_sigma_rad),
                        ("odometry_ratio", odometry_ratio or 0.0),
                        ("odometry_heading_rad_per_m", odometry_heading_rad_per_m or 0.0),
                        ("heading_sigma_rad", heading_sigma_rad or 0.0),
                        ("heading_bias_sigma_rad", heading_bias_sigma_rad)):
        if not (np.isfinite(value) and value >= 0):
            raise ConfigError(f"`{name}` must be a finite number >= 0, got {value!r}")
    if odometry_loop_m is not None and odometry_ratio is None \
            and odometry_heading_rad_per_m is None:
        raise ConfigError("`odometry_loop_m` closes the odometry, and none is read; set "
                          "odometry_ratio and/or odometry_heading_rad_per_m, or drop it")
    if not isinstance(body, Body):
        raise ConfigError(f"`body` must be a Body (Body.named('moon'|'earth'|'plane')), got "
                          f"{body!r:.40}")
    rng = np.random.default_rng(seed)
    noise = rng if noise_seed is None else np.random.default_rng(noise_seed)
    s = n_stations
    direction = np.cumsum(np.concatenate([[rng.uniform(-np.pi, np.pi)],
                                          rng.normal(0.0, turn_sigma_rad, s - 1)]))
    step = spacing_m * np.column_stack([np.cos(direction), np.sin(direction)])
    pose = np.zeros((s, 6))
    pose[1:, :2] = np.cumsum(step[:-1], axis=0)
    pose[:, 2] = 1.5 + np.cumsum(rng.normal(0.0, 0.3, s))
    pose[:, 3] = (direction + np.pi) % (2 * np.pi) - np.pi

    k = round(markers_per_station * s)
    host = rng.integers(0, s, k)
    radius = rng.uniform(2.0, 0.9 * max_range_m, k)
    bearing = rng.uniform(-np.pi, np.pi, k)
    markers = np.column_stack([pose[host, 0] + radius * np.cos(bearing),
                               pose[host, 1] + radius * np.sin(bearing),
                               pose[host, 2] - 1.2 + rng.normal(0.0, 0.2, k)])
    distance = np.linalg.norm(markers[None, :, :] - pose[:, None, :3], axis=2)
    station, marker = np.nonzero(distance <= max_range_m)
    seen = np.unique(marker)
    markers = markers[seen]
    marker = np.searchsorted(seen, marker)
    d = distance[station, seen[marker]]
    sigma = (np.asarray(sigma_m(d), dtype=float) if callable(sigma_m)
             else np.full(d.shape, float(sigma_m)))

    pose[:, 4:] = (noise.normal(0.0, inclinometer_sigma_rad, (s, 2))
                   + body.vertical_tilt(pose[:, :3], pose[:, 3]))
    rotation = np.stack([station_to_site_matrix(*p[3:]) for p in pose])
    levelled = np.einsum("nji,nj->ni", rotation[station], markers[marker] - pose[station, :3])
    per_axis = noise_scale * sigma / math.sqrt(3.0)
    xyz = levelled + noise.normal(size=levelled.shape) * per_axis[:, None]

    position_error = np.cumsum(noise.normal(0.0, odometry_sigma_m, (s, 3)), axis=0)
    heading_error = np.cumsum(noise.normal(0.0, odometry_heading_sigma_rad, s))
    nominal = NominalPoses(pose[:, :3] + position_error - position_error[0],
                           pose[:, 3] + heading_error - heading_error[0])
    obs = NetworkObservations(tuple(f"S{i + 1:02d}" for i in range(s)),
                              tuple(f"M{j + 1:03d}" for j in seen), station, marker, xyz, sigma)
    odometry = reading = None
    bias = 0.0
    measured = (odometry_ratio is not None or odometry_heading_rad_per_m is not None) and s > 1
    if measured:
        driven = np.linalg.norm(np.diff(pose[:, :3], axis=0), axis=1)
        exact = OdometryReadings.from_poses(np.arange(s), pose[:, :3], pose[:, 3],
                                            odometry_loop_m)
        dp = exact.delta_xyz_m.copy()
        dpsi = exact.delta_heading_rad.copy()
        dp[:s - 1] += noise.normal(size=(s - 1, 3)) * ((odometry_ratio or 0.0) * driven[:, None])
        dpsi[:s - 1] += noise.normal(size=s - 1) * ((odometry_heading_rad_per_m or 0.0) * driven)
    if heading_sigma_rad is not None:
        bias = float(noise.normal(0.0, heading_bias_sigma_rad))
        reading = pose[:, 3] + bias + noise.normal(0.0, heading_sigma_rad, s)
    if measured:
        if odometry_loop_m is not None:  # the closing reading, drawn last
            dp[s - 1] += noise.normal(size=3) * ((odometry_ratio or 0.0) * odometry_loop_m)
            dpsi[s - 1] += noise.normal() * ((odometry_heading_rad_per_m or 0.0)
                                             * odometry_loop_m)
        odometry = OdometryReadings(np.arange(s), dp, dpsi, odometry_loop_m)
    return obs, NetworkTruth(pose, markers, nominal, odometry, reading, bias)
