"""How often a station's worst error over its working disc exceeds its 95 % figure, by
Monte-Carlo through the adjustment, not through the figure's own covariance arithmetic.

Each draw simulates the observations anew (:func:`pipeline.network.simulation.simulated_network`:
Gaussian marker-centre noise, true residual tilts from the inclinometer's sigma), estimates the
poses by the network adjustment (:func:`pipeline.network.adjustment.adjust`, Gauss-Newton on the
non-linear model) or a known-control 4-parameter fit
(:func:`planner.accuracy.known_control.fit_pose`) and measures each station's worst
registration error over its working disc: the estimated minus the true site position of 720
rim points and the station itself, mapped with the full rotations. The figures
(:mod:`planner.accuracy.figure`) are computed once, from the covariance the adjustment states
for the noise-free network. A calibrated 95 % figure is exceeded in 5 %
of station-draws; the ellipsoid figure, usually in fewer.

:func:`pair_calibration` does the same for the local requirement's pair figures
(:mod:`planner.accuracy.local`): each draw's worst relative error of two stations over both
discs (:func:`planner.verify.local_pairs.relative_error_m`, the quantity ``verify`` measures)
against the pair's 95 % figures from the stated joint covariance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.simulation import simulated_network
from pipeline.scans.rig import station_to_site_matrix
from planner.accuracy import known_control
from planner.accuracy.figure import N_DIRECTIONS, ErrorFigure
from planner.accuracy.known_control import CHI2_3_95, registration_differences
from planner.accuracy.local import pair_quantile, pair_worst
from planner.config import ERROR_FIGURES
from planner.verify.local_pairs import relative_error_m

#: Rim bearings of the measured worst error (ten times the figures' 72).
MEASURED_RIM = 720


@dataclass(frozen=True)
class FigureCalibration:
    """Exceedance of each 95 % figure over Monte-Carlo draws of one geometry.

    Attributes
    ----------
    case : str
        The geometry, in words.
    n_draws : int
    figures_m : dict of str to (s,) float
        Each figure (:data:`planner.config.ERROR_FIGURES`) of every judged station, m.
    worst_m : (n_draws, s) float
        Measured worst error over each judged station's disc in each draw, m.
    """

    case: str
    n_draws: int
    figures_m: dict
    worst_m: np.ndarray

    def exceeded(self, figure: str) -> float:
        """Fraction of station-draws whose worst error exceeds ``figure``'s value."""
        return float(np.mean(self.worst_m > self.figures_m[figure][None]))

    def draw_exceeded(self, figure: str) -> float:
        """Fraction of draws in which some judged station exceeds ``figure``'s value."""
        return float(np.mean(np.any(self.worst_m > self.figures_m[figure][None], axis=1)))

    def to_json(self) -> dict:
        """The case's figures (mean over stations) and exceedances, JSON-ready."""
        return {"case": self.case, "n_draws": self.n_draws,
                "n_station_draws": int(self.worst_m.size),
                **{f"{f}_mean_m": float(np.mean(self.figures_m[f])) for f in self.figures_m},
                **{f"{f}_exceeded": self.exceeded(f) for f in self.figures_m}}


def disc_points(working_radius_m: float) -> np.ndarray:
    """(MEASURED_RIM + 1, 3) the station and its rim points, levelled station frame, m."""
    phi = np.linspace(0.0, 2.0 * np.pi, MEASURED_RIM, endpoint=False)
    rim = working_radius_m * np.column_stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)])
    return np.vstack([np.zeros((1, 3)), rim])


def worst_disc_error(pose_est: np.ndarray, pose_true: np.ndarray, working_radius_m: float
                     ) -> np.ndarray:
    """(s,) largest distance between estimated and true site positions of each station's disc
    points (:func:`disc_points`), m, for poses (s, 6) (x, y, z, heading, roll, pitch)."""
    p = disc_points(working_radius_m)
    out = np.empty(len(pose_est))
    for i, (est, true) in enumerate(zip(pose_est, pose_true, strict=True)):
        r_est = station_to_site_matrix(*est[3:])
        r_true = station_to_site_matrix(*true[3:])
        diff = (est[:3] - true[:3]) + p @ (r_est - r_true).T
        out[i] = np.sqrt(np.max(np.einsum("ri,ri->r", diff, diff)))
    return out


def _figures(cov: np.ndarray, working_radius_m: float) -> dict:
    return {f: ErrorFigure(f).station_errors(cov, working_radius_m) for f in ERROR_FIGURES}


def _stated_traverse(n_stations: int, seed: int, spacing_m: float, sigma_m: float,
                     markers_per_station: float, inclinometer_sigma_rad: float):
    """The adjustment settings (no snooping), the simulator's keywords, the noise-free truth and
    the adjustment of the noise-free network (whose covariance the figures are computed
    from) of a simulated traverse (:func:`pipeline.network.simulation.simulated_network`)."""
    settings = AdjustmentSettings(inclinometer_sigma_rad=inclinometer_sigma_rad, snooping=False)
    kw = dict(n_stations=n_stations, spacing_m=spacing_m, sigma_m=sigma_m, seed=seed,
              markers_per_station=markers_per_station,
              inclinometer_sigma_rad=inclinometer_sigma_rad)
    obs, truth = simulated_network(noise_scale=0.0, **kw)
    return settings, kw, truth, adjust(obs, settings=settings, nominal=truth.nominal)


def network_calibration(n_stations: int, n_draws: int, seed: int = 0, spacing_m: float = 15.0,
                        sigma_m: float = 0.01, working_radius_m: float = 10.0,
                        markers_per_station: float = 3.0,
                        inclinometer_sigma_rad: float = math.radians(0.01)
                        ) -> FigureCalibration:
    """Exceedance of the figures over a simulated traverse network (the first station the
    datum; the others judged).

    Parameters
    ----------
    n_stations, seed, spacing_m, markers_per_station : as
        :func:`pipeline.network.simulation.simulated_network`.
    n_draws : int
        Noise draws (adjustments), each with its own noise seed.
    sigma_m : float
        1-sigma 3D marker-centre error, m.
    working_radius_m : float
    inclinometer_sigma_rad : float

    Returns
    -------
    FigureCalibration
    """
    settings, kw, truth, stated = _stated_traverse(n_stations, seed, spacing_m, sigma_m,
                                                   markers_per_station, inclinometer_sigma_rad)
    judged = np.arange(1, n_stations)
    cov = np.stack([stated.station_covariance(int(i)) for i in judged])
    # the figures take the translation along the station's own axes (heading 0 frame)
    turn = np.tile(np.eye(6), (judged.size, 1, 1))
    turn[:, :3, :3] = np.stack([station_to_site_matrix(h, 0.0, 0.0).T
                                for h in truth.pose[judged, 3]])
    figures = _figures(turn @ cov @ np.swapaxes(turn, 1, 2), working_radius_m)
    worst = np.empty((n_draws, judged.size))
    for d in range(n_draws):
        obs_d, truth_d = simulated_network(noise_seed=10_000 + d, **kw)
        res = adjust(obs_d, settings=settings, nominal=truth_d.nominal)
        worst[d] = worst_disc_error(res.pose[judged], truth_d.pose[judged], working_radius_m)
    return FigureCalibration(f"network traverse, {n_stations} stations {spacing_m:g} m apart "
                             f"(seed {seed})", n_draws, figures, worst)


def site_axes(pose_covariance: np.ndarray, heading_rad: np.ndarray) -> np.ndarray:
    """(6 s, 6 s) pose covariance with each station's roll and pitch turned from its own axes
    (the adjustment's ``Rz(heading) Ry(pitch) Rx(roll)``) to the site axes the planner's
    figures use: the small rotation ``roll Rz e_x + pitch Rz e_y`` has site components
    ``R2(heading) (roll, pitch)``. Translations and headings are site-frame already."""
    turn = np.eye(pose_covariance.shape[0])
    for k, h in enumerate(heading_rad):
        c, s = math.cos(h), math.sin(h)
        turn[6 * k + 4:6 * k + 6, 6 * k + 4:6 * k + 6] = [[c, -s], [s, c]]
    return turn @ pose_covariance @ turn.T


def pair_calibration(n_stations: int, n_draws: int, seed: int = 0, spacing_m: float = 15.0,
                     kind: str = "position", sigma_m: float = 0.01,
                     working_radius_m: float = 10.0, markers_per_station: float = 3.0,
                     inclinometer_sigma_rad: float = math.radians(0.01)) -> FigureCalibration:
    """Exceedance of the local requirement's pair figures over a simulated traverse: every
    pair of consecutive stations, its worst relative error over both discs
    (:func:`~planner.verify.local_pairs.relative_error_m`: position, or ``kind="distance"``
    along the line between them) in each draw against the figures from the joint covariance
    the adjustment states for the noise-free network (:func:`site_axes`).

    Parameters
    ----------
    n_stations, n_draws, seed, spacing_m, sigma_m, working_radius_m, markers_per_station,
    inclinometer_sigma_rad : as :func:`network_calibration`
    kind : {"position", "distance"}

    Returns
    -------
    FigureCalibration
        One column per pair (the stations ``k``, ``k + 1``).
    """
    settings, kw, truth, stated = _stated_traverse(n_stations, seed, spacing_m, sigma_m,
                                                   markers_per_station, inclinometer_sigma_rad)
    six = 6 * n_stations
    cov = site_axes(stated.covariance[:six, :six], truth.pose[:, 3])
    first, second = np.arange(n_stations - 1), np.arange(1, n_stations)
    idx = np.hstack([6 * first[:, None] + np.arange(6), 6 * second[:, None] + np.arange(6)])
    blocks = cov[idx[:, :, None], idx[:, None, :]]
    delta = truth.pose[second, :3] - truth.pose[first, :3]
    direction = delta / np.linalg.norm(delta, axis=1, keepdims=True)
    figures = {"quantile": pair_quantile(blocks, direction, working_radius_m, kind, N_DIRECTIONS),
               "ellipsoid": np.sqrt(CHI2_3_95 * pair_worst(blocks, direction, working_radius_m,
                                                      kind)[0])}
    worst = np.empty((n_draws, first.size))
    n_rim = MEASURED_RIM // 10  # the figures' rim
    for d in range(n_draws):
        obs_d, truth_d = simulated_network(noise_seed=10_000 + d, **kw)
        res = adjust(obs_d, settings=settings, nominal=truth_d.nominal)
        errors = [registration_differences(res.pose[k], truth_d.pose[k], working_radius_m,
                                           n_rim) for k in range(n_stations)]
        worst[d] = [relative_error_m(errors[a], errors[b], kind, direction[i])
                    for i, (a, b) in enumerate(zip(first, second, strict=True))]
    return FigureCalibration(f"network traverse, pairs of {n_stations} stations {spacing_m:g} m "
                             f"apart, {kind} (seed {seed})", n_draws, figures, worst)


def known_control_calibration(n_markers: int, n_draws: int, seed: int = 0,
                              max_range_m: float = 25.0, working_radius_m: float = 10.0,
                              sigma_per_m: float = 0.0008,
                              inclinometer_sigma_rad: float = math.radians(0.01)
                              ) -> FigureCalibration:
    """Exceedance of the figures for one station registered to ``n_markers`` known markers
    (random bearings and distances in [3, max_range_m] m, sigma growing with distance).

    Each draw tilts the station by the inclinometer's sigma, measures the markers in its
    levelled frame with Gaussian noise and fits x, y, z and heading
    (:func:`planner.accuracy.known_control.fit_pose`), roll and pitch taken as level.
    """
    rng = np.random.default_rng(seed)
    distance = rng.uniform(3.0, max_range_m, n_markers)
    bearing = rng.uniform(-np.pi, np.pi, n_markers)
    site = np.column_stack([distance * np.cos(bearing), distance * np.sin(bearing),
                            rng.normal(-1.0, 0.2, n_markers)])
    sigma = np.maximum(sigma_per_m * distance, 0.002)
    j = known_control.pair_information(np.zeros(2), site[:, :2], sigma).sum(axis=0)
    cov = known_control.pose_covariance(np.linalg.inv(j)[None], inclinometer_sigma_rad)
    figures = _figures(cov, working_radius_m)
    truth = np.zeros(6)
    truth[3] = rng.uniform(-np.pi, np.pi)
    noise = np.random.default_rng(seed + 1)
    worst = np.empty((n_draws, 1))
    for d in range(n_draws):
        true = truth.copy()
        true[4:] = noise.normal(0.0, inclinometer_sigma_rad, 2)
        levelled = (site - true[:3]) @ station_to_site_matrix(*true[3:])
        measured = levelled + noise.normal(size=site.shape) * (sigma / math.sqrt(3.0))[:, None]
        t, psi = known_control.fit_pose(measured, site, sigma, heading0_rad=true[3])
        est = np.r_[t, psi, 0.0, 0.0]
        worst[d] = worst_disc_error(est[None], true[None], working_radius_m)
    return FigureCalibration(f"known control, {n_markers} markers within {max_range_m:g} m "
                             f"(seed {seed})", n_draws, figures, worst)
