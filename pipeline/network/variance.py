"""Variance components of observation groups: is the error model right for every station and
every range?

The adjustment's a-posteriori variance factor ``sigma0^2`` tests the error model as a whole.
Split into groups ``g`` (the observations of one station, or of one range band), each group
gets its own factor by the simplified Helmert / Förstner estimator (Förstner, *AVN* 86, 1979;
Koch, *Parameter estimation and hypothesis testing in linear models*, 1999, section 3.6.4):

    sigma_g^2 = v_g^T P_g v_g / r_g,    r_g = sum of the redundancy numbers of the group,

iterated: the group's weights are divided by its estimate and the network adjusted again
until the estimates no longer change (then the estimator is the best invariant quadratic
unbiased one). A factor of 1 means the group's sigmas are right; 4 means its errors are twice
what the error model says. An estimate heading for 0 is held at :data:`MIN_COMPONENT`. Under
the model an estimate scatters by about ``sigma_g^2 sqrt(2 / r_g)`` (chi-square with ``r_g``
degrees of freedom). A group's redundancy changes with its estimate (a group weighted up takes
less of it); below :data:`MIN_GROUP_REDUNDANCY` the group gets no estimate.

This module only sees the weighted squared residuals and redundancy numbers of each
observation; the adjustment (:mod:`pipeline.network.adjustment`) supplies them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from markerplan.errors import DataError

#: How observations can be grouped.
GROUPINGS = ("station", "range")

#: Upper limits of the range bands, m (distance from the LiDAR centre to the marker centre):
#: near (the range study's densest part), middle, far, and beyond the range study's 50 m.
RANGE_BANDS_M = (10.0, 20.0, 50.0)

#: Iterations end when no group's estimate changes by more than this share of its standard
#: deviation (the iteration converges linearly, slowly for a group of little redundancy whose
#: estimate heads for 0).
TOLERANCE = 1e-3
#: Most iterations.
MAX_ITERATIONS = 100
#: A group whose redundancy is below this has no estimate (nan): with less than one degree of
#: freedom its estimate scatters by more than 140 % and its iteration barely converges.
MIN_GROUP_REDUNDANCY = 1.0
#: An estimate that falls below this is held there: the iteration would drive it to 0
#: geometrically without converging (the unbiased estimate is then negative).
MIN_COMPONENT = 1e-3


@dataclass(frozen=True)
class VarianceComponent:
    """The estimated variance factor of one group of observations.

    Attributes
    ----------
    group : str
        A station id, or a range band such as ``"10-20 m"``.
    n_observations : int
        Point observations in the group (3 components each).
    redundancy : float
        ``r_g``, the group's share of the degrees of freedom.
    sigma0_squared : float
        The estimate ``sigma_g^2`` (nan when ``redundancy`` is below
        :data:`MIN_GROUP_REDUNDANCY`).
    sd : float
        Its standard deviation under the model, ``sigma_g^2 sqrt(2 / r_g)``.
    """

    group: str
    n_observations: int
    redundancy: float
    sigma0_squared: float
    sd: float


def observation_groups(station: np.ndarray, station_ids: tuple[str, ...],
                       distance_m: np.ndarray, by: str) -> tuple[np.ndarray, list[str]]:
    """Group of each observation.

    Parameters
    ----------
    station : (n,) int
        Station index of each observation.
    station_ids : tuple of str
    distance_m : (n,) float
        Station-to-marker distance of each observation, m.
    by : {"station", "range"}
        Group by observing station, or by :data:`RANGE_BANDS_M`.

    Returns
    -------
    group : (n,) int
        Index into ``names``.
    names : list of str
        The groups that hold observations, in station order or by range.

    Examples
    --------
    >>> observation_groups(np.array([0, 1, 1]), ("S1", "S2", "S3"), np.array([5, 15, 60]),
    ...                    "range")
    (array([0, 1, 2]), ['0-10 m', '10-20 m', '50+ m'])
    """
    if by == "station":
        used, group = np.unique(station, return_inverse=True)
        return group, [station_ids[i] for i in used]
    edges = (0.0, *RANGE_BANDS_M)
    labels = [f"{lo:g}-{hi:g} m" for lo, hi in zip(edges[:-1], edges[1:], strict=True)]
    labels.append(f"{edges[-1]:g}+ m")
    used, group = np.unique(np.searchsorted(RANGE_BANDS_M, distance_m, side="right"),
                            return_inverse=True)
    return group, [labels[i] for i in used]


def variance_components(solve: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                        group: np.ndarray, names: list[str]) -> list[VarianceComponent]:
    """Iterated variance-component estimates of the groups.

    Parameters
    ----------
    solve : callable
        ``solve(scale) -> (vpv, r)``: adjusts with the weights of each observation divided by
        ``scale`` ((n,) float) and returns its weighted squared residuals ``v_i^T P_i v_i``
        and redundancy numbers (the sum over its components), (n,) each, both with the scaled
        weights.
    group : (n,) int
        Group index of each observation (:func:`observation_groups`).
    names : list of str

    Returns
    -------
    components : list of VarianceComponent
        In the order of ``names``.

    Raises
    ------
    DataError
        The estimates still change after :data:`MAX_ITERATIONS` iterations.

    Examples
    --------
    Two groups of a mean of 1-D values; the second's scatter is twice the stated sigma (1):

    >>> y = np.array([0.9, -1.1, 1.0, -0.8, 2.1, -1.9, 2.0, -2.2])
    >>> g = np.repeat([0, 1], 4)
    >>> def solve(scale):
    ...     p = 1.0 / scale
    ...     v = y - np.sum(p * y) / np.sum(p)
    ...     return p * v**2, 1.0 - p / np.sum(p)
    >>> [round(c.sigma0_squared, 2) for c in variance_components(solve, g, ["a", "b"])]
    [1.14, 4.44]
    """
    scale = np.ones(len(names))
    for _ in range(MAX_ITERATIONS):
        vpv, r = solve(scale[group])
        r_g = np.bincount(group, weights=r, minlength=len(names))
        estimable = r_g > MIN_GROUP_REDUNDANCY
        ratio = np.where(estimable, np.bincount(group, weights=vpv, minlength=len(names))
                         / np.where(estimable, r_g, 1.0), 1.0)
        ratio = np.where(scale * ratio < MIN_COMPONENT, MIN_COMPONENT / scale, ratio)
        scale *= ratio
        if np.all(np.abs(ratio - 1.0) <= TOLERANCE * np.sqrt(2.0 / np.maximum(r_g, 1e-300))):
            break
    else:
        raise DataError(f"the variance components did not converge in {MAX_ITERATIONS} "
                        f"iterations (last change {np.abs(ratio - 1.0).max():.2g})")
    counts = np.bincount(group, minlength=len(names))
    return [VarianceComponent(name, int(counts[g]), float(r_g[g]),
                              float(scale[g]) if estimable[g] else float("nan"),
                              float(scale[g] * math.sqrt(2.0 / r_g[g])) if estimable[g]
                              else float("nan"))
            for g, name in enumerate(names)]
