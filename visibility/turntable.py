"""The simulated turntable's per-frame errors (:func:`turntable_errors`): encoder noise,
backlash, synchronisation jitter, a periodic error and the wobble of its axis, each drawn from
its own seeded stream so that switching one term off leaves the others unchanged."""

from __future__ import annotations

import numpy as np

from visibility.sensor import RigConfig

#: Third entry of the turntable-error seed ``[seed, f, _TURNTABLE_STREAM]``.
_TURNTABLE_STREAM = 1
#: Second entry of the periodic turntable error's phase seed ``[seed, _PERIODIC_STREAM]``.
_PERIODIC_STREAM = 3


def turntable_errors(rig: RigConfig, rpm: int, seed: int, frames: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame turntable errors of :class:`visibility.sensor.TurntableErrors`.

    Parameters
    ----------
    rig : RigConfig
        ``rig.turntable`` gives the sigmas; ``rig.frames_per_turn`` the table rate.
    rpm : int
        LiDAR spin rate (one frame per LiDAR revolution).
    seed : int
        Frame ``f`` draws from ``default_rng([seed, f, 1])``.
    frames : (F,) int
        Frame indices.

    Returns
    -------
    angle_error_rad : (F,) float
        True minus nominal turntable angle (encoder + backlash + rate x sync jitter + the
        periodic error ``A sin(2 theta + phi)``, ``phi`` drawn from ``default_rng([seed, 3])``),
        radians.
    wobble_rad : (F, 2) float
        Tilt of the turntable axis about the turntable frame's x and y axes, radians.

    Examples
    --------
    >>> angle, wobble = turntable_errors(RigConfig(), 600, 0, np.arange(3))
    >>> angle.tolist(), wobble.shape
    ([0.0, 0.0, 0.0], (3, 2))
    """
    errors = rig.turntable
    if not errors.enabled:
        return np.zeros(len(frames)), np.zeros((len(frames), 2))
    rate = 2 * np.pi / (rig.frames_per_turn * 60.0 / rpm)
    draws = np.array([_turntable_draws(np.random.default_rng([seed, int(f), _TURNTABLE_STREAM]))
                      for f in frames]).reshape(-1, 5)
    angle = (errors.encoder_noise_rad * draws[:, 0] + errors.backlash_rad * draws[:, 1]
             + rate * errors.sync_jitter_s * draws[:, 2])
    if errors.periodic_error_rad:
        phase = np.random.default_rng([seed, _PERIODIC_STREAM]).uniform(0.0, 2 * np.pi)
        theta = 2 * np.pi * np.asarray(frames, dtype=float) / rig.frames_per_turn
        angle = angle + errors.periodic_error_rad * np.sin(2 * theta + phase)
    return angle, errors.wobble_rad * draws[:, 3:5]


def _turntable_draws(rng: np.random.Generator) -> list[float]:
    """One frame's draws: encoder N(0, 1), backlash U(-1/2, 1/2), sync N(0, 1), wobble x, y
    N(0, 1) (always all five, so switching a term off leaves the others unchanged)."""
    return [rng.standard_normal(), rng.uniform(-0.5, 0.5), *rng.standard_normal(3)]
