"""The reference a field experiment is evaluated against, with its own error.

In the published experiment each marker's reference centre was a total-station measurement of
the sphere's top minus its radius. Two errors enter it:

- the operator aims at the top but hits a point a horizontal distance ``d`` from it
  (``d`` per axis Gaussian with ``aim_sigma_m``); that point lies ``R - sqrt(R^2 - d^2)`` below
  the top, so the reference is off by ``d`` horizontally and low by about ``d^2 / (2 R)``;
- the instrument's own point error (reflectorless distance and angles), Gaussian per axis with
  ``point_sigma_m`` (a few millimetres at tens of metres).

Simulated evaluations that stand in for the field (``calibrate-sensor``) draw their reference
from :meth:`TotalStationReference.survey`; with both sigmas zero it is the simulator's truth.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from markerplan.checks import require_non_negative


@dataclass(frozen=True)
class TotalStationReference:
    """Errors of a top-minus-radius total-station reference (metres, 1 sigma per axis).

    Attributes
    ----------
    point_sigma_m : float
        Instrument point error, each axis.
    aim_sigma_m : float
        Horizontal miss of the sphere's top, each horizontal axis.
    """

    point_sigma_m: float = 0.0
    aim_sigma_m: float = 0.0

    def __post_init__(self) -> None:
        require_non_negative(self, asdict(self), "reference ")

    def survey(self, centres_m: np.ndarray, radius_m: float, rng: np.random.Generator
               ) -> np.ndarray:
        """Reference centres as the total station would give them.

        Parameters
        ----------
        centres_m : (n, 3) float
            True sphere centres, metres (any frame with z up).
        radius_m : float
            Sphere radius, metres.
        rng : numpy.random.Generator

        Returns
        -------
        reference_m : (n, 3) float
            Measured top minus the radius, metres.

        Examples
        --------
        >>> ts = TotalStationReference(0.0, 0.0)
        >>> ts.survey(np.array([[1.0, 2.0, 0.1]]), 0.1, np.random.default_rng(0)).tolist()
        [[1.0, 2.0, 0.1]]
        """
        c = np.asarray(centres_m, dtype=float).reshape(-1, 3)
        aim = rng.normal(0.0, self.aim_sigma_m, (len(c), 2)) if self.aim_sigma_m else \
            np.zeros((len(c), 2))
        d2 = np.minimum(np.sum(aim ** 2, axis=1), radius_m ** 2)
        top = c + np.column_stack([aim, np.sqrt(radius_m ** 2 - d2)])
        if self.point_sigma_m:
            top = top + rng.normal(0.0, self.point_sigma_m, top.shape)
        return top - np.array([0.0, 0.0, radius_m])
