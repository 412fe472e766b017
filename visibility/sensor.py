"""The Velodyne VLP-16 and the turntable rig it is mounted on.

Sensor constants are from the Velodyne VLP-16 user manual (63-9243, section 9 "Data packet
format" and appendix "firing timing") and datasheet (63-9229):

- 16 lasers; channel ``i`` has elevation ``VLP16_ELEVATION_DEG[i]``
  (-15, +1, -13, +3, ..., -1, +15 deg) and fires ``i``-th in each firing sequence;
- one firing every 2.304 us, a sequence of 16 firings plus recharge every 55.296 us, so the
  spin azimuth advances ``rpm * 6 deg/s * 55.296 us`` per sequence (0.1/0.2/0.4 deg at
  5/10/20 Hz) and each laser within a sequence is offset by ``i * 2.304 / 55.296`` of that step;
- 300-1200 rpm in 60 rpm steps; range up to 100 m; distance resolution 2 mm;
- range accuracy "+-3 cm (typical)". We read this as a ~95 % band and use a 1-sigma Gaussian
  range noise of **1.5 cm** (``DEFAULT_RANGE_NOISE_M``); pass ``range_noise_m=0.03`` to treat
  the datasheet figure as 1 sigma instead;
- beam divergence 3.0 mrad (horizontal, along the spin) x 1.5 mrad (vertical); optional: where
  that elliptical footprint straddles a marker's silhouette the return is a mixed return of the
  sub-rays inside it (:mod:`visibility.simulate`), while the reported direction stays the
  nominal one;
- minimum range: the datasheet gives none; the ROS ``velodyne_pointcloud`` driver discards
  VLP-16 returns closer than 0.4 m (``VLP16_points.launch``), which we follow.

Not modelled: the per-laser vertical offsets of the optical centres (a few mm; the scan format's
sensor frame puts every beam through one origin, see :mod:`pipeline.scans.rig`), intensity, dual
returns.

The rig (:class:`RigConfig`): the LiDAR tilted 90 deg on an L-bracket on a turntable, its centre
``lidar_height_m`` above the ground, ``frames_per_turn`` frames per turntable revolution, and the
three mounting offsets of :class:`pipeline.scans.rig.MountingOffsets`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from markerplan.checks import require_non_negative
from markerplan.errors import ConfigError
from pipeline.scans.rig import VLP16_ELEVATION_DEG, MountingOffsets
from pipeline.scans.scan_format import sensor_metadata
from pipeline.scans.sensor_noise import RangeNoise

VLP16_ELEVATION_RAD = np.radians(VLP16_ELEVATION_DEG)
#: Channel fired at each position of a firing sequence.
FIRING_ORDER = tuple(range(16))
FIRING_INTERVAL_S = 2.304e-6
FIRING_CYCLE_S = 55.296e-6
RPM_MIN, RPM_MAX, RPM_STEP = 300, 1200, 60
MIN_RANGE_M = 0.4
MAX_RANGE_M = 100.0
RANGE_RESOLUTION_M = 0.002
DATASHEET_RANGE_ACCURACY_M = 0.03
DEFAULT_RANGE_NOISE_M = DATASHEET_RANGE_ACCURACY_M / 2
BEAM_DIVERGENCE_RAD = (3.0e-3, 1.5e-3)
#: Second entry of the per-channel offset seed ``[unit_seed, LASER_BIAS_STREAM]``.
LASER_BIAS_STREAM = 2


def azimuth_step_rad(rpm: float) -> float:
    """Spin-azimuth advance per firing sequence, radians: ``rpm/60 * 2 pi * 55.296 us``.

    Examples
    --------
    >>> [round(float(np.degrees(azimuth_step_rad(r))), 4) for r in (300, 600, 1200)]
    [0.0995, 0.1991, 0.3981]
    """
    return rpm / 60.0 * 2 * np.pi * FIRING_CYCLE_S


@dataclass(frozen=True)
class SensorConfig:
    """VLP-16 simulation settings (SI units).

    Attributes
    ----------
    rpm : int
        Spin rate, 300-1200 in steps of 60.
    range_noise_m, range_noise_per_m, incidence_noise_m, range_resolution_m : float
        The range noise of :class:`pipeline.scans.sensor_noise.RangeNoise`: 1-sigma at short range
        and normal incidence (m), growth with range (m/m) and with ``tan(incidence)`` (m), and
        the rounding of reported ranges (m).
    min_range_m, max_range_m : float
        Returns outside are dropped, metres.
    beam_divergence : bool
        Model the 3 x 1.5 mrad beam footprint and the mixed returns where it straddles an edge
        (see :mod:`visibility.simulate`).
    footprint_samples : int
        Sub-rays cast inside the footprint of a beam that passes near a marker's silhouette.
    dropout_prob : float
        Probability that a return is lost at random.
    laser_range_bias_m : float
        1-sigma of each laser channel's constant range offset (the factory calibration's
        residual), metres; one draw per channel and unit.
    laser_angle_bias_rad : float
        1-sigma of each channel's constant elevation and azimuth offsets, radians.
    unit_seed : int
        Which sensor unit: the channels' offsets are drawn from ``default_rng([unit_seed,
        LASER_BIAS_STREAM])``, the same for every station scanned with these settings.
    """

    rpm: int = 600
    range_noise_m: float = DEFAULT_RANGE_NOISE_M
    range_noise_per_m: float = 0.0
    incidence_noise_m: float = 0.0
    range_resolution_m: float = RANGE_RESOLUTION_M
    min_range_m: float = MIN_RANGE_M
    max_range_m: float = MAX_RANGE_M
    beam_divergence: bool = False
    footprint_samples: int = 7
    dropout_prob: float = 0.0
    laser_range_bias_m: float = 0.0
    laser_angle_bias_rad: float = 0.0
    unit_seed: int = 0

    def __post_init__(self) -> None:
        if not (RPM_MIN <= self.rpm <= RPM_MAX and (self.rpm - RPM_MIN) % RPM_STEP == 0):
            raise ConfigError(f"rpm must be {RPM_MIN}-{RPM_MAX} in steps of {RPM_STEP} "
                              f"(VLP-16), got {self.rpm}")
        self.range_noise()  # validates the noise parameters
        if not 0 <= self.min_range_m < self.max_range_m:
            raise ConfigError(f"need 0 <= min_range_m < max_range_m, got {self.min_range_m}, "
                              f"{self.max_range_m}")
        if not 0 <= self.dropout_prob < 1:
            raise ConfigError(f"dropout_prob must be in [0, 1), got {self.dropout_prob}")
        require_non_negative(self, ("laser_range_bias_m", "laser_angle_bias_rad"))
        if not (isinstance(self.unit_seed, int | np.integer) and self.unit_seed >= 0):
            raise ConfigError(f"unit_seed must be an integer >= 0, got {self.unit_seed!r}")
        if not (isinstance(self.footprint_samples, int) and 1 <= self.footprint_samples <= 64):
            raise ConfigError(f"footprint_samples must be an integer in 1..64, got "
                              f"{self.footprint_samples!r}")

    def laser_biases(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """This unit's constant per-channel offsets (always 48 draws, so either term can be off).

        Returns
        -------
        range_bias_m, elevation_bias_rad, azimuth_bias_rad : (16,) float
            Indexed by channel.

        Examples
        --------
        >>> r, e, a = SensorConfig(laser_range_bias_m=0.01).laser_biases()
        >>> r.shape, bool(np.all(e == 0))
        ((16,), True)
        """
        draws = np.random.default_rng([self.unit_seed, LASER_BIAS_STREAM]).standard_normal(
            (3, len(VLP16_ELEVATION_RAD)))
        return (self.laser_range_bias_m * draws[0], self.laser_angle_bias_rad * draws[1],
                self.laser_angle_bias_rad * draws[2])

    def expected_scatter(self) -> RangeNoise:
        """The range scatter the processing chain should expect of this sensor: the noise with
        the per-channel offsets folded in (:meth:`RangeNoise.from_metadata`)."""
        return RangeNoise.from_metadata(asdict(self))

    def range_noise(self) -> RangeNoise:
        """The random range noise the simulator draws (per return)."""
        return RangeNoise(self.range_noise_m, self.range_noise_per_m, self.incidence_noise_m,
                          self.range_resolution_m)

    @property
    def azimuth_step_rad(self) -> float:
        return azimuth_step_rad(self.rpm)

    def to_metadata(self) -> dict:
        """The ``sensor`` block of the scan metadata (:mod:`pipeline.scans.scan_format`)."""
        return {**sensor_metadata(), **asdict(self),
                "firing_order": list(FIRING_ORDER),
                "azimuth_step_rad": self.azimuth_step_rad,
                "firing_interval_s": FIRING_INTERVAL_S, "firing_cycle_s": FIRING_CYCLE_S,
                "beam_divergence_rad": list(BEAM_DIVERGENCE_RAD) if self.beam_divergence else None}


@dataclass(frozen=True)
class TurntableErrors:
    """Random errors of the turntable, drawn independently for every frame (SI units).

    Attributes
    ----------
    encoder_noise_rad : float
        1-sigma Gaussian error of the frame's turntable angle read by the encoder, radians.
    backlash_rad : float
        Full width of the gear backlash: the angle error is uniform in ``+-backlash / 2``.
    sync_jitter_s : float
        1-sigma timing error between the LiDAR revolution and the turntable angle stamped on
        it, seconds; at the table's mean rate ``2 pi / (frames * 60 / rpm)`` it is an angle error.
    wobble_rad : float
        1-sigma tilt of the turntable axis (bearing wobble) about each horizontal axis, radians.
    periodic_error_rad : float
        Amplitude of the periodic angle error ``A sin(2 theta + phi)`` (second harmonic of the
        table angle ``theta``: an elliptical bearing race or encoder disc), radians.
    """

    encoder_noise_rad: float = 0.0
    backlash_rad: float = 0.0
    sync_jitter_s: float = 0.0
    wobble_rad: float = 0.0
    periodic_error_rad: float = 0.0

    def __post_init__(self) -> None:
        require_non_negative(self, asdict(self), "turntable ")

    @property
    def enabled(self) -> bool:
        """True if any term is non-zero."""
        return any(v > 0 for v in asdict(self).values())


@dataclass(frozen=True)
class RigConfig:
    """Turntable rig settings.

    Attributes
    ----------
    lidar_height_m : float
        LiDAR centre above the ground at the station, metres.
    frames_per_turn : int
        Frames (one LiDAR revolution each) per turntable revolution; frame ``f`` is taken at
        turntable angle ``2 pi f / frames_per_turn``.
    offsets : MountingOffsets
        True mounting errors (recorded in the truth file only).
    turntable : TurntableErrors
        Per-frame random errors of the turntable (none by default).
    """

    lidar_height_m: float = 1.0
    frames_per_turn: int = 800
    offsets: MountingOffsets = field(default_factory=MountingOffsets)
    turntable: TurntableErrors = field(default_factory=TurntableErrors)

    def __post_init__(self) -> None:
        if not (isinstance(self.frames_per_turn, int | np.integer) and self.frames_per_turn > 0):
            raise ConfigError(f"frames_per_turn must be a positive integer (e.g. 800), got "
                              f"{self.frames_per_turn}")
        if not (np.isfinite(self.lidar_height_m) and self.lidar_height_m > 0):
            raise ConfigError(f"lidar_height_m must be > 0, got {self.lidar_height_m}")

    def turntable_angles_rad(self) -> np.ndarray:
        """(frames_per_turn,) turntable angle of every frame, radians."""
        return 2 * np.pi * np.arange(self.frames_per_turn) / self.frames_per_turn

    def to_metadata(self) -> dict:
        """The ``rig`` block of the scan metadata (no mounting offsets: those are truth)."""
        return {"lidar_height_m": float(self.lidar_height_m),
                "frames_per_turn": int(self.frames_per_turn),
                "turntable_errors": asdict(self.turntable)}


def firing_pattern(rpm: float, phase_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Laser channels and spin azimuths of one LiDAR revolution.

    Parameters
    ----------
    rpm : float
    phase_rad : float
        Azimuth of the first firing sequence, radians.

    Returns
    -------
    laser_id : (n,) uint8
        Channel of each firing, in firing order, ``n = 16 * floor(2 pi / step)``.
    azimuth_rad : (n,) float64
        Spin azimuth of each firing (interpolated within the sequence), in [0, 2 pi).
    """
    step = azimuth_step_rad(rpm)
    n_cycles = int(np.floor(2 * np.pi / step))
    order = np.asarray(FIRING_ORDER)
    offset = order * (FIRING_INTERVAL_S / FIRING_CYCLE_S) * step
    az = phase_rad + step * np.arange(n_cycles)[:, None] + offset[None, :]
    laser = np.broadcast_to(order[None, :], az.shape)
    return laser.ravel().astype(np.uint8), np.mod(az.ravel(), 2 * np.pi)


def sensor_directions(laser_id: np.ndarray, azimuth_rad: np.ndarray) -> np.ndarray:
    """Unit beam directions in the sensor frame (:mod:`pipeline.scans.rig`), shape (n, 3)."""
    return beam_directions(VLP16_ELEVATION_RAD[np.asarray(laser_id, dtype=np.int64)],
                           azimuth_rad)


def beam_directions(elevation_rad: np.ndarray, azimuth_rad: np.ndarray) -> np.ndarray:
    """Unit sensor-frame directions of elevation ``elevation_rad`` and spin azimuth
    ``azimuth_rad`` (clockwise from +y), both (n,) radians; shape (n, 3).

    Examples
    --------
    >>> beam_directions(np.array([0.0]), np.array([np.pi / 2])).round(12)
    array([[1., 0., 0.]])
    """
    w = np.asarray(elevation_rad, dtype=float)
    cw = np.cos(w)
    return np.column_stack([cw * np.sin(azimuth_rad), cw * np.cos(azimuth_rad), np.sin(w)])
