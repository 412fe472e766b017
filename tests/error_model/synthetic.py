"""Synthetic marker tables with a known error law, for testing the error-model fit.

Truth: the 3D RMS centre error is ``sigma(d, e) = 2 mm + 0.6 mm/m * d + 10 mm/rad * |e|``
(+ ``vf_effect_m * (1 - visible_fraction)`` when asked). Each axis error is Student-t with
5 degrees of freedom (heavy-ish tails), scaled so ``E[error_m^2] = sigma^2``. Distances
follow the range study's grid (1-15 m every 1 m, 15-25 m every 2 m, 25-50 m every 5 m) and a
uniform spread; elevations are drawn independently of distance in [-30, 10] deg so the two
effects are separable. Some rows are rejected by the "quality gate" or lack an error.
"""

from __future__ import annotations

import numpy as np

from markerplan import writing
from pipeline.tables.marker_table import COLUMNS

SIGMA0_M = 0.002
SLOPE_D = 0.0006  # m per m
SLOPE_E = 0.010  # m per rad of |elevation|
DOF = 5
RANGE_GRID_M = np.r_[np.arange(1, 16), np.arange(17, 26, 2), np.arange(30, 51, 5)].astype(float)


def true_sigma(distance_m, elevation_rad, visible_fraction=1.0, vf_effect_m=0.0):
    """3D RMS error of the generator, metres."""
    return (SIGMA0_M + SLOPE_D * np.asarray(distance_m) + SLOPE_E * np.abs(elevation_rad)
            + vf_effect_m * (1.0 - np.asarray(visible_fraction)))


def true_q95_factor(n: int = 400_000, seed: int = 1) -> float:
    """95 % quantile of the 3D error divided by sigma (Monte Carlo)."""
    rng = np.random.default_rng(seed)
    t = rng.standard_t(DOF, (n, 3)) / np.sqrt(DOF / (DOF - 2)) / np.sqrt(3)
    return float(np.quantile(np.linalg.norm(t, axis=1), 0.95))


def synthetic_table(n: int, seed: int, vf_effect_m: float = 0.0,
                    reject_fraction: float = 0.05) -> dict[str, np.ndarray]:
    """A marker table (dict of column -> array) with the columns of ``markerplan process``."""
    rng = np.random.default_rng(seed)
    half = n // 2
    d = np.r_[rng.choice(RANGE_GRID_M, half), rng.uniform(1.0, 50.0, n - half)]
    d = d[rng.permutation(n)]
    elev = np.deg2rad(rng.uniform(-30.0, 10.0, n))
    vf = rng.uniform(0.4, 1.0, n)
    n_points = rng.poisson(4000.0 * vf / d**2 + 5).astype(float)
    sigma = true_sigma(d, elev, vf, vf_effect_m)
    axis = rng.standard_t(DOF, (n, 3)) / np.sqrt(DOF / (DOF - 2)) * (sigma / np.sqrt(3))[:, None]
    err = np.linalg.norm(axis, axis=1)
    accepted = rng.random(n) >= reject_fraction
    err_out = np.where(accepted, err, err + 0.5)  # rejected markers: gross errors, not fitted
    err_out[rng.random(n) < 0.01] = np.nan  # no reference for a few markers
    station = np.array([f"S{i:03d}" for i in rng.integers(0, max(n // 40, 5), n)])
    az = rng.uniform(-180, 180, n)
    cols = {
        "station_id": station, "marker_id": np.array([f"M{i:05d}" for i in range(n)]),
        "x_m": d * np.cos(np.deg2rad(az)), "y_m": d * np.sin(np.deg2rad(az)),
        "z_m": d * np.tan(elev), "distance_m": d, "elevation_deg": np.rad2deg(elev),
        "azimuth_deg": az, "n_points": n_points, "point_density_per_m2": n_points / 0.0628,
        "visible_fraction": vf, "fit_rms_m": np.full(n, 0.003), "radius_fit_m": np.full(n, 0.1),
        "estimator": np.full(n, "hemisphere_icp"), "accepted": accepted,
        "reason": np.where(accepted, "", "sparse"), "error_m": err_out,
        "error_x_m": axis[:, 0], "error_y_m": axis[:, 1], "error_z_m": axis[:, 2],
        "replicate": np.zeros(n), "seed": np.full(n, float(seed)),
    }
    assert tuple(cols) == COLUMNS
    return cols


def write_csv(path, table: dict[str, np.ndarray]) -> None:
    """Write a table dict as ``markerplan process`` writes a marker table."""
    rows = [dict(zip(table, row, strict=True)) for row in zip(*table.values(), strict=True)]
    writing.write_csv(path, tuple(table), rows)
