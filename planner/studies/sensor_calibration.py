"""Calibrate a sensor profile's free parameters against a field experiment, by simulation.

The statistic is what the field experiment measured at each LiDAR position: the mean absolute
edge-length residual of its markers against the reference (:mod:`planner.studies.field_summary`).
The simulator predicts it through the project's own chain: a level field with the position's
markers at the observed distances (azimuths spread by the golden angle, since only the
distances are known) is scanned with the profile (:func:`visibility.simulate.simulate_markers`),
processed by :func:`pipeline.chain.process.process_station` exactly as ``markerplan process`` does
(self-calibration, detection, fit, quality gate), and evaluated against a reference drawn with
the profile's total-station error (:class:`visibility.total_station.TotalStationReference`).

Method
------
1. **Design.** Each free parameter takes ``design_points`` values evenly spread over its range
   (a full grid for two); every design point is simulated ``replicates`` times per position
   with the same seeds at every design point (common random numbers, so differences between
   design points come from the parameters, not the noise draw). A replicate is also another
   sensor unit (its per-channel offsets, drawn anew), shared by all positions of the replicate
   as the field's positions shared one LiDAR.
2. **Emulator.** Edge residuals add independent error sources in quadrature, and a noise
   parameter's contribution to a variance grows as its square, so per position
   ``s_k(p)^2 = a_k + sum_i b_ki p_i^2`` with ``a, b >= 0`` (non-negative least squares on the
   design means). Its largest relative misfit on the design is reported.
3. **Fit.** Weighted least squares of measured against emulated statistics over the bounded
   parameters. The weight of a position is the uncertainty of one field measurement of its
   statistic: the pooled relative spread of the replicates (a field position is one draw),
   with the rounding of the published figures (uniform over their last digit) added in
   quadrature. The parameters' standard errors and correlation come from the Jacobian, scaled
   up by ``chi^2 / dof`` when that exceeds one; the condition number of the Jacobian with
   unit-norm columns says whether the positions tell two parameters apart (near 1: yes; large:
   their effects on the positions are nearly proportional). Each position's fitted statistic
   gets a 95 % interval for one field measurement: the fit's uncertainty through the emulator
   and one field draw's spread, in quadrature.
4. **Confirmation.** The fitted profile is simulated again with fresh seeds; the
   predicted/measured ratio per position is reported (what a calibration must reproduce), and a
   hold-out: for each position, fit on the others and predict it by simulation.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares, nnls

from markerplan.errors import ConfigError, DataError
from pipeline.chain.evaluation import Reference
from pipeline.chain.process import process_station
from pipeline.surveys.range_study import marker_layout
from pipeline.surveys.survey import ProcessingSettings, processing_config
from planner.studies.field_summary import FieldPosition
from planner.studies.range_experiment import ground_dem
from visibility.sensor_profile import SensorProfile, parameter_names
from visibility.simulate import simulate_markers

#: Parameters ``calibrate-sensor`` fixes by default (``--fix`` replaces them all): values taken
#: from instrument documentation and practice, not from the field data. Sources:
#: reference — a reflectorless total station at <= 30 m measures a point to about 2 mm + 2 ppm
#: in distance and 1-2 arc seconds in angle (0.3 mm at 30 m): 2 mm per axis; aiming by eye at the
#: top of a 0.20 m sphere misses it by a few millimetres: 3 mm per horizontal axis.
#: turntable — a geared stepper table with a 0.01 deg encoder: encoder noise 0.1 mrad, backlash
#: 0.02 deg (0.35 mrad), axis wobble 0.05 mrad, a 1 ms timestamp jitter between table and LiDAR.
#: sensor — range noise growing by 0.3 mm per metre of range (weaker echoes) and 5 mm times
#: tan(incidence) (a slanted footprint spreads the pulse); per-channel angular offsets of
#: 0.2 mrad (the residual of the factory calibration, Glennie and Lichti 2010).
FIELD_PRIORS: dict[str, float] = {
    "reference.point_sigma_m": 0.002, "reference.aim_sigma_m": 0.003,
    "turntable.encoder_noise_rad": 1e-4, "turntable.backlash_rad": 3.5e-4,
    "turntable.wobble_rad": 5e-5, "turntable.sync_jitter_s": 1e-3,
    "sensor.range_noise_per_m": 3e-4, "sensor.incidence_noise_m": 0.005,
    "sensor.laser_angle_bias_rad": 2e-4,
}
#: The parameter ``calibrate-sensor`` fits by default: the amplitude of the turntable's
#: periodic angle error (second harmonic of the table angle). It stands for the errors of the
#: rig that are the same for all frames that see a marker and grow with its distance. Random
#: per-return and per-frame errors average over the hundreds of returns and tens of frames that
#: see a marker, and every marker is seen by all 16 lasers, so per-channel offsets act almost
#: alike on all markers: tried as free parameters, range noise up to 5 cm, range noise growing
#: 4 mm per metre, per-frame encoder noise of 1.5 mrad and per-channel range offsets of 3 cm
#: each left the field statistic at 4-8 mm, or made the quality gate reject the far markers,
#: where the field measured 10-11 mm with all of them accepted.
DEFAULT_FREE = ("turntable.periodic_error_rad=0:0.003",)
#: Relative uncertainty of a position's statistic when one replicate gives no spread, and the
#: floor under any estimated spread (an emulator is not better than this).
DEFAULT_REL_SPREAD = 0.1
MIN_REL_UNCERTAINTY = 0.01
#: Largest relative misfit of the emulator on the design that passes without a warning.
MAX_EMULATOR_MISFIT = 0.2
#: Replicate numbers of the confirmation and hold-out runs start here (fresh seeds).
CONFIRM_REPLICATE0 = 1000
HOLDOUT_REPLICATE0 = 2000


@dataclass(frozen=True)
class FreeParameter:
    """A profile parameter to fit (``block.field``) and the range to search, in its units."""

    name: str
    low: float
    high: float

    @classmethod
    def parse(cls, text: str) -> FreeParameter:
        """``block.field=LOW:HIGH``.

        Examples
        --------
        >>> FreeParameter.parse("sensor.range_noise_m=0.01:0.05")
        FreeParameter(name='sensor.range_noise_m', low=0.01, high=0.05)
        """
        name, _, span = text.partition("=")
        lo, _, hi = span.partition(":")
        try:
            low, high = float(lo), float(hi)
        except ValueError:
            raise ConfigError(f"free parameter {text!r}: expected NAME=LOW:HIGH, e.g. "
                              "sensor.range_noise_m=0.01:0.05") from None
        if name.strip() not in parameter_names():
            raise ConfigError(f"free parameter {name.strip()!r} is not a sensor-profile "
                              f"parameter; parameters are {', '.join(parameter_names())}")
        if not (np.isfinite(low) and np.isfinite(high) and 0 <= low < high):
            raise ConfigError(f"free parameter {text!r}: need 0 <= LOW < HIGH, got {low:g}, "
                              f"{high:g}")
        return cls(name.strip(), low, high)


def parse_setting(text: str) -> tuple[str, float]:
    """``block.field=VALUE`` -> (name, value), the name checked.

    Examples
    --------
    >>> parse_setting("reference.aim_sigma_m=0.003")
    ('reference.aim_sigma_m', 0.003)
    """
    name, _, value = text.partition("=")
    name = name.strip()
    if name not in parameter_names():
        raise ConfigError(f"`fixed` {text!r}: {name!r} is not a sensor-profile parameter; "
                          f"parameters are {', '.join(parameter_names())}")
    try:
        number = float(value)
    except ValueError:
        raise ConfigError(f"`fixed` {text!r}: expected NAME=VALUE with a number, e.g. "
                          "reference.aim_sigma_m=0.003") from None
    if not np.isfinite(number):
        raise ConfigError(f"`fixed` {text!r}: the value must be a finite number")
    return name, number


@dataclass(frozen=True)
class CalibrationSettings:
    """How the field is simulated and the design laid out.

    Attributes
    ----------
    frames : int
        Frames per turntable revolution of each simulated position (the rig's 800).
    replicates : int
        Simulations per design point and position (different seeds).
    check_replicates : int
        Simulations per position of the confirmation and of each hold-out prediction (a field
        position is one noisy draw of the statistic; their mean is the prediction).
    design_points : int
        Values per free parameter.
    marker_radius_m, lidar_height_m : float
        Marker radius and LiDAR height above the level field, metres.
    seed : int
    rpm : int
    resolution_m : float
        Last digit of the measured statistics (their rounding), metres; 0 if exact.
    holdout : bool
        Also run the leave-one-position-out check.
    """

    frames: int = 800
    replicates: int = 2
    check_replicates: int = 6
    design_points: int = 4
    marker_radius_m: float = 0.1
    lidar_height_m: float = 1.0
    seed: int = 0
    rpm: int = 600
    resolution_m: float = 0.001
    holdout: bool = True


@dataclass
class CalibrationResult:
    """Everything :func:`calibrate` found (plain numbers, for JSON and the report)."""

    free: list[FreeParameter]
    values: dict[str, float]
    sigmas: dict[str, float]
    at_bound: list[str]
    chi2: float
    dof: int
    emulator: list[dict]
    runs: list[dict]
    confirmation: list[dict]
    holdout: list[dict]
    profile: SensorProfile
    settings: CalibrationSettings
    measured: dict[str, float] = field(default_factory=dict)
    #: Correlation matrix of the free parameters (in ``free`` order).
    correlation: list[list[float]] = field(default_factory=list)
    #: Condition number of the fit's Jacobian with unit-norm columns (1: the positions tell the
    #: parameters apart perfectly; large: their effects are nearly proportional).
    jacobian_condition: float = float("nan")
    #: Per position: the fitted (emulated) statistic with its 95 % interval for one field
    #: measurement (``emulated_m``, ``fit_sd_m``, ``draw_sd_m``, ``interval95_m``).
    predictions: list[dict] = field(default_factory=list)

    @property
    def warnings(self) -> list[str]:
        """What makes the result doubtful: a fit at its range's bound, a poor emulator."""
        out = [f"{n} hit the bound of its range; widen it (--fit NAME=LOW:HIGH)"
               for n in self.at_bound]
        worst = max(self.emulator, key=lambda e: e["max_rel_misfit"])
        if worst["max_rel_misfit"] > MAX_EMULATOR_MISFIT:
            out.append(f"the emulator misses the simulated statistic of position "
                       f"{worst['position']} by {worst['max_rel_misfit']:.0%} on the design; "
                       "narrow the range or use more frames and replicates")
        return out


def simulate_position(profile: SensorProfile, position: FieldPosition, index: int,
                      replicate: int, settings: CalibrationSettings) -> dict:
    """Simulate, process and evaluate one field position with ``profile``.

    Parameters
    ----------
    profile : SensorProfile
    position : FieldPosition
    index : int
        The position's index (part of the seed).
    replicate : int
        Replicate number (part of the seed).
    settings : CalibrationSettings

    Returns
    -------
    run : dict
        ``position``, ``replicate``, ``statistic_m`` (mean |edge residual|, NaN when fewer than
        two markers were accepted), ``n_accepted``, ``n_markers``.
    """
    seeds = np.random.SeedSequence([settings.seed, index, replicate]).generate_state(2)
    # one sensor unit per replicate, shared by its positions (the field had one LiDAR)
    unit = int(np.random.SeedSequence([settings.seed, replicate]).generate_state(1)[0])
    radius = settings.marker_radius_m
    d = position.distances_m
    centres = marker_layout(d, radius, settings.lidar_height_m)
    dem = ground_dem(float(d.max()))
    station = np.array([0.0, 0.0, settings.lidar_height_m])
    sensor = profile.sensor_config(settings.rpm, unit_seed=unit)
    rig = profile.rig_config(lidar_height_m=settings.lidar_height_m,
                             frames_per_turn=settings.frames)
    ids = [f"M{k + 1:02d}" for k in range(len(d))]
    scan, _ = simulate_markers(dem, station, 0.0, centres + station, sensor, rig,
                               seed=int(seeds[0]), marker_radius_m=radius, marker_ids=ids,
                               station_id=f"P{position.name}")
    surveyed = profile.reference.survey(centres, radius, np.random.default_rng(seeds[1]))
    reference = Reference(tuple(ids), surveyed, scan.station_id, "simulated total station",
                          radius)
    result = process_station(scan, processing_config(ProcessingSettings(marker_radius_m=radius)),
                             reference)
    stat = result.summary.get("mean_abs_edge_residual_m")
    return {"position": position.name, "replicate": replicate,
            "statistic_m": float("nan") if stat is None else float(stat),
            "n_accepted": int(result.summary["n_accepted"]), "n_markers": len(d)}


def calibrate(positions: Sequence[FieldPosition], base: SensorProfile,
              free: Sequence[FreeParameter], settings: CalibrationSettings = CalibrationSettings(),
              progress: Callable[[int], object] | None = None) -> CalibrationResult:
    """Fit ``free`` parameters of ``base`` to the positions' measured statistics.

    Parameters
    ----------
    positions : sequence of FieldPosition
        At least ``len(free) + 1`` positions (so that the fit has a degree of freedom).
    base : SensorProfile
        Profile whose other parameters stay fixed.
    free : sequence of FreeParameter
        One or two parameters.
    settings : CalibrationSettings
    progress : callable, optional
        Called with 1 after each simulated run.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    ConfigError
        No or more than two free parameters, a parameter given twice, too few positions.
    DataError
        The design never gives an edge residual at some position (no markers accepted).
    """
    free = list(free)
    _calibrate_iv(positions, free, settings)
    grids = [np.linspace(f.low, f.high, settings.design_points) for f in free]
    design = [dict(zip([f.name for f in free], map(float, vals), strict=True))
              for vals in itertools.product(*grids)]
    runs = []
    for values in design:
        profile = base.with_values(values)
        for k, pos in enumerate(positions):
            for rep in range(settings.replicates):
                runs.append({**values, **simulate_position(profile, pos, k, rep, settings)})
                if progress is not None:
                    progress(1)
    emulator = [_fit_emulator(pos, k, free, design, runs) for k, pos in enumerate(positions)]
    fit = _fit_parameters(positions, free, emulator, settings)
    fitted = base.with_values(fit["values"])
    confirmation = [_predict(fitted, pos, k, settings, CONFIRM_REPLICATE0, progress)
                    for k, pos in enumerate(positions)]
    holdout = []
    if settings.holdout:
        for k, pos in enumerate(positions):
            keep = [j for j in range(len(positions)) if j != k]
            sub = _fit_parameters([positions[j] for j in keep], free,
                                  [emulator[j] for j in keep], settings)
            pred = _predict(base.with_values(sub["values"]), pos, k, settings,
                            HOLDOUT_REPLICATE0, progress)
            holdout.append({**pred, "fitted_on": [positions[j].name for j in keep],
                            "values": sub["values"]})
    measured = {p.name: p.mean_abs_edge_residual_m for p in positions}
    return CalibrationResult(free, fit["values"], fit["sigmas"], fit["at_bound"], fit["chi2"],
                             fit["dof"], emulator, runs, confirmation, holdout, fitted, settings,
                             measured, fit["correlation"], fit["jacobian_condition"],
                             fit["predictions"])


def _calibrate_iv(positions, free, settings) -> None:
    if not 1 <= len(free) <= 2:
        raise ConfigError(f"give one or two free parameters (`free`), got {len(free)}")
    names = [f.name for f in free]
    if len(set(names)) != len(names):
        raise ConfigError(f"free parameter {names[0]!r} is given twice; give each once")
    if len(positions) < len(free) + 1:
        raise ConfigError(f"{len(free)} free parameter(s) need at least {len(free) + 1} "
                          f"positions, got {len(positions)}")
    if settings.design_points < 3 or settings.replicates < 1 or settings.check_replicates < 1:
        raise ConfigError("the design needs >= 3 points per parameter and >= 1 replicate, and "
                          f"the checks >= 1 replicate, got {settings.design_points}, "
                          f"{settings.replicates} and {settings.check_replicates}")


def _fit_emulator(pos: FieldPosition, k: int, free: list[FreeParameter], design: list[dict],
                  runs: list[dict]) -> dict:
    """Per position: ``s^2 = a + sum_i b_i p_i^2`` on the design means (non-negative)."""
    rows, means, spreads = [], [], []
    for values in design:
        stats = np.array([r["statistic_m"] for r in runs if r["position"] == pos.name
                          and all(r[n] == v for n, v in values.items())])
        stats = stats[np.isfinite(stats)]
        if stats.size == 0:
            continue
        rows.append([1.0, *[values[f.name] ** 2 for f in free]])
        means.append(stats.mean())
        if stats.size > 1:
            spreads.append(stats.std(ddof=1) / stats.mean())
    if len(means) < len(free) + 1:
        raise DataError(f"position {pos.name!r}: the simulated field gave an edge residual at "
                        f"only {len(means)} design point(s); no markers were accepted — narrow "
                        "the free parameters' ranges, or simulate more `frames` (the rig "
                        "takes 800: markers far out need them)")
    a_matrix, target = np.array(rows), np.array(means) ** 2
    coef, _ = nnls(a_matrix, target)
    emulated = np.sqrt(a_matrix @ coef)
    return {"position": pos.name, "index": k, "a_m2": float(coef[0]),
            "b": {f.name: float(c) for f, c in zip(free, coef[1:], strict=True)},
            "max_rel_misfit": float(np.max(np.abs(emulated / np.array(means) - 1))),
            "rel_spread": float(np.sqrt(np.mean(np.square(spreads)))) if spreads else None,
            "n_design": len(means)}


def emulate(emulator: dict, values: dict[str, float]) -> float:
    """The emulated statistic of one position at parameter ``values``, metres."""
    return float(np.sqrt(emulator["a_m2"] + sum(b * values[n] ** 2
                                                for n, b in emulator["b"].items())))


def _fit_parameters(positions: Sequence[FieldPosition], free: list[FreeParameter],
                    emulator: list[dict], settings: CalibrationSettings) -> dict:
    """Bounded weighted least squares of measured against emulated statistics."""
    names = [f.name for f in free]
    measured = np.array([p.mean_abs_edge_residual_m for p in positions])
    spread = np.array([max(e["rel_spread"] if e["rel_spread"] is not None else
                           DEFAULT_REL_SPREAD, MIN_REL_UNCERTAINTY) for e in emulator])
    rounding = settings.resolution_m / np.sqrt(12.0)

    def uncertainty(pred: np.ndarray) -> np.ndarray:
        return np.hypot(spread * pred, rounding)

    def residuals(p: np.ndarray) -> np.ndarray:
        values = dict(zip(names, p, strict=True))
        pred = np.array([emulate(e, values) for e in emulator])
        return (pred - measured) / uncertainty(pred)

    lo = np.array([f.low for f in free])
    hi = np.array([f.high for f in free])
    best = min((least_squares(residuals, x0, bounds=(lo, hi), x_scale=hi - lo)
                for x0 in (lo + 0.25 * (hi - lo), lo + 0.75 * (hi - lo))),
               key=lambda r: r.cost)
    chi2 = float(2 * best.cost)
    dof = len(positions) - len(free)
    values = dict(zip(names, map(float, best.x), strict=True))
    cov = _covariance(best.jac, max(1.0, chi2 / dof if dof else 1.0))
    sig = np.sqrt(np.diag(cov))
    at_bound = [n for n, x, a, b in zip(names, best.x, lo, hi, strict=True)
                if min(x - a, b - x) < 1e-3 * (b - a)]
    return {"values": values,
            "sigmas": {n: float(s) for n, s in zip(names, sig, strict=True)},
            "chi2": chi2, "dof": dof, "at_bound": at_bound,
            "correlation": _correlation(cov).tolist(),
            "jacobian_condition": _equilibrated_condition(best.jac),
            "predictions": [_prediction(p, e, values, cov, uncertainty)
                            for p, e in zip(positions, emulator, strict=True)]}


def _covariance(jac: np.ndarray, scale: float) -> np.ndarray:
    """``scale * (J^T J)^-1``, all ``inf`` when ``J`` has lost rank (the data cannot fix the
    parameters)."""
    try:
        return np.linalg.inv(jac.T @ jac) * scale
    except np.linalg.LinAlgError:
        return np.full((jac.shape[1],) * 2, np.inf)


def _correlation(cov: np.ndarray) -> np.ndarray:
    """Correlation matrix of ``cov`` (NaN where a standard error is infinite or zero)."""
    sd = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        return cov / np.outer(sd, sd)


def _equilibrated_condition(jac: np.ndarray) -> float:
    """Condition number of the Jacobian with unit-norm columns: independent of the parameters'
    units, 1 for orthogonal effects, growing without bound as two parameters' effects on the
    positions become proportional (infinite when a column is zero)."""
    norms = np.linalg.norm(jac, axis=0)
    if np.any(norms == 0):
        return float("inf")
    return float(np.linalg.cond(jac / norms))


#: Two-sided 95 % normal quantile of the prediction intervals.
Z95 = 1.959963984540054


def _prediction(position: FieldPosition, emulator: dict, values: dict[str, float],
                cov: np.ndarray, uncertainty: Callable[[np.ndarray], np.ndarray]) -> dict:
    """The fitted statistic of one position with its 95 % interval for one field measurement:
    the fit's uncertainty (the emulator's gradient through the parameters' covariance) and one
    field draw's spread plus the rounding (``uncertainty``), in quadrature."""
    pred = emulate(emulator, values)
    # d s / d p_i = b_i p_i / s for s^2 = a + sum b_i p_i^2
    grad = np.array([emulator["b"][n] * v / pred if pred > 0 else 0.0
                     for n, v in values.items()])
    fit_sd = float(np.sqrt(grad @ cov @ grad)) if np.all(np.isfinite(cov)) else float("inf")
    draw_sd = float(uncertainty(np.array([pred]))[0])
    half = Z95 * float(np.hypot(fit_sd, draw_sd))
    return {"position": position.name, "measured_m": position.mean_abs_edge_residual_m,
            "emulated_m": pred, "fit_sd_m": fit_sd, "draw_sd_m": draw_sd,
            "interval95_m": [max(pred - half, 0.0), pred + half]}


def _predict(profile: SensorProfile, pos: FieldPosition, k: int, settings: CalibrationSettings,
             replicate0: int, progress) -> dict:
    """Simulate ``pos`` with ``profile`` (fresh seeds) and compare with its measurement."""
    stats, accepted = [], []
    for rep in range(settings.check_replicates):
        run = simulate_position(profile, pos, k, replicate0 + rep, settings)
        stats.append(run["statistic_m"])
        accepted.append(run["n_accepted"])
        if progress is not None:
            progress(1)
    s = np.array(stats)
    s = s[np.isfinite(s)]
    pred = float(s.mean()) if s.size else None
    return {"position": pos.name, "measured_m": pos.mean_abs_edge_residual_m,
            "predicted_m": pred,
            "ratio": None if pred is None else pred / pos.mean_abs_edge_residual_m,
            "replicate_statistics_m": [float(v) if np.isfinite(v) else None for v in stats],
            "n_accepted": accepted, "n_markers": int(pos.distances_m.size)}
