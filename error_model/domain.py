"""The region of predictor space a model was fitted on; queries outside it are flagged.

Distance: the fitted range. Elevation: per distance band (edges at distance quantiles) the
fitted elevation range (signed, station frame, z up) widened by a margin. Optional
predictors: their fitted ranges.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from markerplan.errors import InputFileError
from markerplan.reading import json_numbers, require_keys, require_type


@dataclass(frozen=True)
class Domain:
    """Fitted predictor ranges.

    Attributes
    ----------
    band_edges_m : (b + 1,) float
        Distance band edges, metres; ``[0]`` and ``[-1]`` are the fitted distance range.
    elevation_lo_rad, elevation_hi_rad : (b,) float
        Elevation range per band including the margin, radians.
    extras : dict of str -> (lo, hi)
        Fitted range of each optional predictor used.
    """

    band_edges_m: tuple[float, ...]
    elevation_lo_rad: tuple[float, ...]
    elevation_hi_rad: tuple[float, ...]
    extras: dict[str, tuple[float, float]] = field(default_factory=dict)

    @classmethod
    def from_data(cls, distance_m: np.ndarray, elevation_rad: np.ndarray,
                  extras: Mapping[str, np.ndarray], n_bands: int,
                  margin_rad: float) -> Domain:
        """Record the ranges of the fitted rows.

        Parameters
        ----------
        distance_m, elevation_rad : (n,) float
        extras : mapping of str -> (n,) float
        n_bands : int
            Wanted distance bands (fewer when distances repeat).
        margin_rad : float
            Widening of each band's elevation range, radians.
        """
        edges = np.unique(np.quantile(distance_m, np.linspace(0, 1, n_bands + 1),
                                      method="inverted_cdf"))
        if edges.size == 1:
            edges = np.r_[edges, edges]
        band = np.clip(np.searchsorted(edges, distance_m, side="right") - 1, 0, edges.size - 2)
        lo, hi = [], []
        for i in range(edges.size - 1):
            e = elevation_rad[band == i]
            if e.size == 0:  # band without rows: fall back to its neighbours' union below
                lo.append(np.nan)
                hi.append(np.nan)
            else:
                lo.append(max(float(e.min()) - margin_rad, -np.pi / 2))
                hi.append(min(float(e.max()) + margin_rad, np.pi / 2))
        lo_a, hi_a = _fill_empty(np.asarray(lo)), _fill_empty(np.asarray(hi))
        return cls(band_edges_m=tuple(float(v) for v in edges),
                   elevation_lo_rad=tuple(float(v) for v in lo_a),
                   elevation_hi_rad=tuple(float(v) for v in hi_a),
                   extras={k: (float(np.min(v)), float(np.max(v))) for k, v in extras.items()})

    @property
    def distance_range_m(self) -> tuple[float, float]:
        return self.band_edges_m[0], self.band_edges_m[-1]

    def contains(self, distance_m: np.ndarray, elevation_rad: np.ndarray,
                 extras: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        """Boolean mask (broadcast shape of the inputs): inside the fitted domain."""
        d, e = np.broadcast_arrays(np.asarray(distance_m, float), np.asarray(elevation_rad,
                                                                              float))
        edges = np.asarray(self.band_edges_m)
        inside = (d >= edges[0]) & (d <= edges[-1])
        band = np.clip(np.searchsorted(edges, d, side="right") - 1, 0, edges.size - 2)
        lo = np.asarray(self.elevation_lo_rad)[band]
        hi = np.asarray(self.elevation_hi_rad)[band]
        inside &= (e >= lo) & (e <= hi)
        for name, (vlo, vhi) in self.extras.items():
            v = np.asarray((extras or {})[name], float)
            inside &= (v >= vlo) & (v <= vhi)
        return inside

    def to_dict(self) -> dict:
        return {"distance_range_m": list(self.distance_range_m),
                "band_edges_m": list(self.band_edges_m),
                "elevation_lo_rad": list(self.elevation_lo_rad),
                "elevation_hi_rad": list(self.elevation_hi_rad),
                "elevation_lo_deg": [float(np.rad2deg(v)) for v in self.elevation_lo_rad],
                "elevation_hi_deg": [float(np.rad2deg(v)) for v in self.elevation_hi_rad],
                "extras": {k: list(v) for k, v in self.extras.items()}}

    @classmethod
    def from_dict(cls, d: Any, what: str = "error-model domain") -> Domain:
        """Rebuild from :meth:`to_dict` output (the ``*_deg`` and ``distance_range_m`` copies
        are informational, and checked against what they copy when present).

        Raises
        ------
        InputFileError
            Missing keys, wrong types, non-finite numbers, fewer than two band edges, edges
            negative or decreasing, elevation ranges of the wrong length, inverted or beyond
            +-90 deg, extra ranges that are not ``[lo, hi]`` with ``lo <= hi``, a copy that is
            inverted or differs from what it copies (:func:`_check_copies`).
        """
        require_type(d, dict, what)
        require_keys(d, ["band_edges_m", "elevation_lo_rad", "elevation_hi_rad", "extras"],
                     what, _REFIT)
        edges = json_numbers(d["band_edges_m"], f"{what} band_edges_m")
        lo = json_numbers(d["elevation_lo_rad"], f"{what} elevation_lo_rad")
        hi = json_numbers(d["elevation_hi_rad"], f"{what} elevation_hi_rad")
        n = len(edges) - 1
        if n < 1 or len(lo) != n or len(hi) != n:
            raise InputFileError(f"{what}: {len(edges)} band edges need {max(n, 1)} elevation "
                                 f"ranges and at least 2 edges, got {len(lo)} lo and {len(hi)} "
                                 f"hi; {_REFIT}")
        if edges[0] < 0 or any(np.diff(edges) < 0):
            raise InputFileError(f"{what} band_edges_m: distances must be >= 0 and "
                                 f"non-decreasing, got {edges}; {_REFIT}")
        for i, (a, b) in enumerate(zip(lo, hi, strict=True)):
            if not -np.pi / 2 - 1e-9 <= a <= b <= np.pi / 2 + 1e-9:
                raise InputFileError(f"{what}: band {i} elevation range [{a:g}, {b:g}] rad must "
                                     f"satisfy -pi/2 <= lo <= hi <= pi/2; {_REFIT}")
        _check_copies(d, edges, lo, hi, what)
        extras = {}
        require_type(d["extras"], dict, f"{what} extras")
        for name, pair in d["extras"].items():
            if not (isinstance(pair, list) and len(pair) == 2):
                raise InputFileError(f"{what} extras {name}: expected a [lo, hi] list of two "
                                     f"numbers, got {pair!r:.60}; {_REFIT}")
            vlo, vhi = json_numbers(pair, f"{what} extras {name}")
            if vlo > vhi:
                raise InputFileError(f"{what} extras {name}: range [{vlo:g}, {vhi:g}] is "
                                     f"inverted (lo > hi); {_REFIT}")
            extras[str(name)] = (vlo, vhi)
        return cls(band_edges_m=tuple(edges), elevation_lo_rad=tuple(lo),
                   elevation_hi_rad=tuple(hi), extras=extras)


_REFIT = "regenerate the model with `markerplan fit-error-model`"

#: How closely an informational copy must match (it is written rounded to 6 decimals).
_COPY_TOLERANCE = 1e-5


def _check_copies(d: Mapping[str, Any], edges: list[float], lo: list[float], hi: list[float],
                  what: str) -> None:
    """The copies :meth:`Domain.to_dict` writes, when present: ``distance_range_m`` (the first
    and last band edge, m) and ``elevation_lo_deg`` / ``elevation_hi_deg`` (the elevation
    ranges in degrees) must be ``[min, max]`` ranges (not inverted) equal to what they copy, so
    that no reader of the file sees another domain than the one used."""
    copies = {"distance_range_m": [edges[0], edges[-1]],
              "elevation_lo_deg": np.rad2deg(lo).tolist(),
              "elevation_hi_deg": np.rad2deg(hi).tolist()}
    found = {key: json_numbers(d[key], f"{what} {key}") for key in copies if key in d}
    ranges = {}
    if "distance_range_m" in found:
        ranges["distance_range_m"] = [found["distance_range_m"]]
    if "elevation_lo_deg" in found and "elevation_hi_deg" in found:
        ranges["elevation_lo_deg / elevation_hi_deg"] = list(
            zip(found["elevation_lo_deg"], found["elevation_hi_deg"], strict=False))
    for key, pairs in ranges.items():
        for band, pair in enumerate(pairs):
            if len(pair) == 2 and pair[0] > pair[1]:
                where = "" if key == "distance_range_m" else f" band {band}"
                raise InputFileError(f"{what} {key}{where}: range [{pair[0]:g}, {pair[1]:g}] is "
                                     f"inverted (min > max); {_REFIT}")
    for key, values in found.items():
        if len(values) != len(copies[key]) or not np.allclose(
                values, copies[key], rtol=_COPY_TOLERANCE, atol=_COPY_TOLERANCE):
            raise InputFileError(f"{what} {key} {values} differs from the values it copies "
                                 f"({np.round(copies[key], 6).tolist()}); {_REFIT}")


def _fill_empty(values: np.ndarray) -> np.ndarray:
    """Replace NaN bands by the nearest non-empty band's value."""
    ok = np.flatnonzero(np.isfinite(values))
    idx = np.arange(values.size)
    nearest = ok[np.abs(idx[:, None] - ok[None, :]).argmin(axis=1)]
    return values[nearest]
