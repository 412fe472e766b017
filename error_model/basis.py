"""The error model's basis: monotone piecewise-linear in distance, piecewise-linear in
``|elevation|``, plus optional non-negative terms for visible fraction and point count.

A model is ``f(x) = b @ phi(x)`` with

- ``intercept``: the value at distance 0 and elevation 0;
- distance ramps ``clip(d - t[j], 0, t[j+1] - t[j])`` over knots ``0 = t[0] < ... < t[K-1]``,
  the last one unbounded; their coefficients are the segment slopes and are constrained
  ``>= 0``, so ``f`` is non-decreasing in distance whatever the other terms;
- ``|elevation|`` ramps over knots ``0 = s[0] < ...`` with free-sign slopes;
- ``visible_fraction`` enters as ``1 - visible_fraction`` and ``expected_points`` as
  ``1 / sqrt(max(points, 1))``, both with coefficients ``>= 0`` (less of the marker seen,
  fewer points: never a smaller error).

Non-negativity everywhere then reduces to a few linear constraints: distance and extra terms
are ``>= 0``, so ``f`` is smallest at distance 0 with the extra features at 0, where it is
piecewise linear in ``|elevation|`` and only needs checking at the knots and at 90 deg.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from markerplan.errors import ConfigError, InputFileError
from markerplan.reading import (
    json_numbers,
    require_keys,
    require_type,
)


@dataclass(frozen=True)
class Basis:
    """Feature map of the error model.

    Attributes
    ----------
    distance_knots_m : tuple of float
        Interior distance knots ``t[1:]`` (``t[0] = 0``), metres, increasing.
    elevation_knots_rad : tuple of float
        Interior ``|elevation|`` knots ``s[1:]`` (``s[0] = 0``), radians, increasing.
    extras : tuple of str
        Optional predictors used (``visible_fraction``, ``expected_points``).
    """

    distance_knots_m: tuple[float, ...] = ()
    elevation_knots_rad: tuple[float, ...] = ()
    extras: tuple[str, ...] = ()

    @classmethod
    def from_data(cls, distance_m: np.ndarray, elevation_rad: np.ndarray,
                  distance_segments: int, elevation_segments: int,
                  extras: tuple[str, ...] = ()) -> Basis:
        """Place knots at quantiles of the data (duplicates merged).

        Parameters
        ----------
        distance_m, elevation_rad : (n,) float
            Fitted rows (metres, radians).
        distance_segments, elevation_segments : int
            Number of linear segments wanted (fewer if the data has fewer distinct values).
        extras : tuple of str
        """
        return cls(distance_knots_m=_quantile_knots(distance_m, distance_segments),
                   elevation_knots_rad=_quantile_knots(np.abs(elevation_rad),
                                                       elevation_segments),
                   extras=tuple(extras))

    @property
    def names(self) -> list[str]:
        """Feature names, in coefficient order."""
        d_edges = (0.0, *self.distance_knots_m)
        e_edges = (0.0, *np.rad2deg(self.elevation_knots_rad))
        names = ["intercept"]
        names += [f"distance_slope_from_{t:.4g}m" for t in d_edges]
        names += [f"abs_elevation_slope_from_{s:.4g}deg" for s in e_edges]
        names += [f"extra_{x}" for x in self.extras]
        return names

    @property
    def n_features(self) -> int:
        return 1 + len(self.distance_knots_m) + 1 + len(self.elevation_knots_rad) + 1 \
            + len(self.extras)

    @property
    def nonneg(self) -> np.ndarray:
        """(p,) bool: coefficients constrained ``>= 0`` (distance slopes and extras)."""
        n_d = len(self.distance_knots_m) + 1
        n_e = len(self.elevation_knots_rad) + 1
        return np.r_[False, np.ones(n_d, bool), np.zeros(n_e, bool),
                     np.ones(len(self.extras), bool)]

    def design(self, distance_m: np.ndarray, elevation_rad: np.ndarray,
               extras: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        """Feature matrix.

        Parameters
        ----------
        distance_m, elevation_rad : (n,) float
            Metres; radians (station frame, z up).
        extras : mapping of str -> (n,) float
            Values of every predictor in :attr:`extras`.

        Returns
        -------
        phi : (n, p) float
        """
        d = np.asarray(distance_m, float).ravel()
        a = np.abs(np.asarray(elevation_rad, float).ravel())
        cols = [np.ones_like(d), _ramps(d, self.distance_knots_m),
                _ramps(a, self.elevation_knots_rad)]
        for name in self.extras:
            cols.append(transform_extra(name, np.asarray(extras[name], float).ravel()))
        return np.column_stack(cols)

    def nonneg_rows(self) -> np.ndarray:
        """(k, p) float: ``rows @ b >= 0`` makes the model ``>= 0`` over the whole space."""
        a = np.r_[0.0, self.elevation_knots_rad, np.pi / 2]
        rows = np.zeros((a.size, self.n_features))
        rows[:, 0] = 1.0
        n_d = len(self.distance_knots_m) + 1
        n_e = len(self.elevation_knots_rad) + 1
        rows[:, 1 + n_d:1 + n_d + n_e] = _ramps(a, self.elevation_knots_rad)
        return rows

    def to_dict(self) -> dict:
        return {"distance_knots_m": list(self.distance_knots_m),
                "elevation_knots_rad": list(self.elevation_knots_rad),
                "extras": list(self.extras), "feature_names": self.names}

    @classmethod
    def from_dict(cls, d: Any, what: str = "error-model basis") -> Basis:
        """Rebuild from :meth:`to_dict` output (``feature_names`` is informational).

        Raises
        ------
        InputFileError
            Missing keys, wrong types, non-finite knots, knots not positive and increasing,
            an ``|elevation|`` knot beyond 90 deg, unknown or repeated extra predictors.
        """
        require_type(d, dict, what)
        require_keys(d, ["distance_knots_m", "elevation_knots_rad", "extras"], what, _REFIT)
        dk = json_numbers(d["distance_knots_m"], f"{what} distance_knots_m")
        ek = json_numbers(d["elevation_knots_rad"], f"{what} elevation_knots_rad")
        extras = [require_type(x, str, f"{what} extras[{i}]")
                  for i, x in enumerate(require_type(d["extras"], list, f"{what} extras"))]
        for name, knots in (("distance_knots_m", dk), ("elevation_knots_rad", ek)):
            if any(k <= 0 for k in knots) or any(np.diff(knots) <= 0):
                raise InputFileError(f"{what} {name}: knots must be positive and increasing, got "
                                     f"{list(knots)}; {_REFIT}")
        if ek and ek[-1] > np.pi / 2:
            raise InputFileError(f"{what} elevation_knots_rad: |elevation| knots must be <= "
                                 f"pi/2 (90 deg), got {ek[-1]:g}; {_REFIT}")
        bad = sorted(set(extras) - set(_EXTRA_TRANSFORMS))
        if bad:
            raise InputFileError(f"{what}: unknown extra predictor(s) {bad} (known: "
                                 f"{sorted(_EXTRA_TRANSFORMS)}); {_REFIT}")
        if len(set(extras)) != len(extras):
            raise InputFileError(f"{what}: extras {extras} name a predictor twice; {_REFIT}")
        return cls(distance_knots_m=tuple(dk), elevation_knots_rad=tuple(ek),
                   extras=tuple(extras))


_REFIT = "regenerate the model with `markerplan fit-error-model`"


_EXTRA_TRANSFORMS = {
    "visible_fraction": lambda v: 1.0 - np.clip(v, 0.0, 1.0),
    "expected_points": lambda n: 1.0 / np.sqrt(np.maximum(n, 1.0)),
}


def transform_extra(name: str, values: np.ndarray) -> np.ndarray:
    """Feature of an optional predictor (``>= 0``, larger means a worse marker)."""
    if name not in _EXTRA_TRANSFORMS:
        raise ConfigError(f"unknown extra predictor {name!r}; known: {sorted(_EXTRA_TRANSFORMS)}")
    return _EXTRA_TRANSFORMS[name](values)


def _ramps(x: np.ndarray, knots: tuple[float, ...]) -> np.ndarray:
    """(n, len(knots) + 1) ramps over ``[0, k1], [k1, k2], ..., [k_last, inf)``."""
    lo = np.r_[0.0, knots]
    width = np.r_[np.diff(lo), np.inf]
    return np.clip(x[:, None] - lo[None, :], 0.0, width[None, :])


def _quantile_knots(x: np.ndarray, segments: int) -> tuple[float, ...]:
    if segments <= 1:
        return ()
    q = np.quantile(x, np.arange(1, segments) / segments)
    q = np.unique(np.round(q, 9))
    span = float(x.max() - max(x.min(), 0.0)) or 1.0
    knots: list[float] = []
    for k in q:
        if k > 1e-3 * span and k < x.max() and (not knots or k - knots[-1] > 1e-3 * span):
            knots.append(float(k))
    return tuple(knots)
