"""The range noise of one LiDAR return: the one formula the simulator draws from and the
processing chain scales its gates and estimators with.

A return at range ``r`` whose beam meets the surface at incidence angle ``i`` (between the beam
and the surface normal) has a Gaussian range error of standard deviation

    sigma(r, i) = sqrt(sigma0^2 + (k_r r)^2 + (k_i min(tan i, 10))^2)

``sigma0`` (``range_noise_m``) is the noise at short range and normal incidence; ``k_r``
(``range_noise_per_m``) lets it grow with range (falling signal-to-noise ratio); ``k_i``
(``incidence_noise_m``) with incidence (the pulse is spread over a slanted footprint). The
reported range is then rounded to ``resolution_m`` (2 mm for the VLP-16), which adds a uniform
error of variance ``resolution^2 / 12``. The parameters are part of the scan's ``sensor``
metadata block (:mod:`pipeline.scans.scan_format`), so a scan carries the noise it was taken with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplan.checks import require_non_negative

#: tan(incidence) is capped here (grazing returns), about 84 degrees.
MAX_TAN_INCIDENCE = 10.0


#: The fields of :class:`RangeNoise`, as named in a scan's ``sensor`` metadata block.
_NAMES = ("range_noise_m", "range_noise_per_m", "incidence_noise_m", "range_resolution_m")


@dataclass(frozen=True)
class RangeNoise:
    """Parameters of :func:`sigma_m` (metres, metres per metre of range).

    Attributes
    ----------
    range_noise_m : float
        1-sigma range noise at short range and normal incidence, metres.
    range_noise_per_m : float
        Growth with range: adds ``range_noise_per_m * range`` in quadrature, metres per metre.
    incidence_noise_m : float
        Growth with incidence: adds ``incidence_noise_m * tan(i)`` in quadrature, metres.
    range_resolution_m : float
        Reported ranges are multiples of this, metres (0: not rounded).
    """

    range_noise_m: float = 0.015
    range_noise_per_m: float = 0.0
    incidence_noise_m: float = 0.0
    range_resolution_m: float = 0.002

    def __post_init__(self) -> None:
        require_non_negative(self, _NAMES)

    @classmethod
    def from_metadata(cls, sensor: dict) -> RangeNoise:
        """The range scatter the processing chain should expect of a sensor described by a
        scan's ``sensor`` metadata block (or a ``SensorConfig`` as a dict; missing keys:
        defaults).

        The unit's per-channel range offsets (``laser_range_bias_m``, constant per laser) are
        added in quadrature to the constant term: a marker's points come from several lasers,
        each shifted by its own offset, so for its fit and quality gate the offsets scatter
        them like noise.

        Examples
        --------
        >>> RangeNoise.from_metadata({"range_noise_m": 0.02, "model": "VLP-16"}).range_noise_m
        0.02
        >>> RangeNoise.from_metadata({"range_noise_m": 0.03, "laser_range_bias_m": 0.04}
        ...                          ).range_noise_m
        0.05
        """
        values = {k: float(sensor[k]) for k in _NAMES if sensor.get(k) is not None}
        bias = float(sensor.get("laser_range_bias_m") or 0.0)
        if bias:
            values["range_noise_m"] = float(np.hypot(values.get("range_noise_m",
                                                                cls.range_noise_m), bias))
        return cls(**values)

    @classmethod
    def recorded(cls, sensor: dict) -> RangeNoise | None:
        """The noise a scan's ``sensor`` block records, or ``None`` if it records none (real
        pcap scans: the user's sensor profile must supply it).

        Examples
        --------
        >>> RangeNoise.recorded({"model": "VLP-16"}) is None
        True
        """
        return cls.from_metadata(sensor) if sensor.get("range_noise_m") is not None else None

    def sigma_m(self, range_m, tan_incidence=0.0) -> np.ndarray:
        """1-sigma Gaussian range error, metres (before rounding), shape of the broadcast inputs.

        Parameters
        ----------
        range_m : array_like
            Range of the return, metres.
        tan_incidence : array_like
            tan of the incidence angle (capped at :data:`MAX_TAN_INCIDENCE`).

        Examples
        --------
        >>> float(RangeNoise(0.015, 0.001, 0.0).sigma_m(20.0))
        0.025
        """
        r = np.asarray(range_m, dtype=float)
        t = np.minimum(np.asarray(tan_incidence, dtype=float), MAX_TAN_INCIDENCE)
        return np.sqrt(self.range_noise_m ** 2 + (self.range_noise_per_m * r) ** 2
                       + (self.incidence_noise_m * t) ** 2)

    def total_sigma_m(self, range_m, tan_incidence=0.0) -> np.ndarray:
        """:meth:`sigma_m` with the rounding's ``resolution^2 / 12`` added in quadrature, metres."""
        s = self.sigma_m(range_m, tan_incidence)
        return np.sqrt(s ** 2 + self.range_resolution_m ** 2 / 12.0)
