"""The stage configuration of the processing chain (PDAL-style declared stages).

Each stage is a small typed config; :func:`build_config` validates every option before anything
runs and rejects unknown stages/options by name. The chain that runs them is
:mod:`pipeline.chain.process`.

=============  ==========================================================================
stage          job (module)
=============  ==========================================================================
``calibrate``  direct/reverse self-calibration of the mounting offsets (:mod:`.calibration`),
               or known offsets with ``enabled = false``
``ground``     grid ground removal, keep points >= ``min_height_m`` above ground (:mod:`.ground`)
``cluster``    Euclidean clustering with a minimum cluster size (:mod:`.clustering`)
``gate``       two-box gate: fits a ``max_box_m`` cube, not a ``min_box_m`` cube (:mod:`.gate`)
``research``   all points within ``radius_m`` of each candidate centroid (:mod:`.gate`)
``fit``        sphere-centre estimator and marker radius (:mod:`.sphere_fit`)
``quality``    quality gate with a reason (:mod:`.quality`)
``evaluate``   matching against reference coordinates, errors, edge residuals (:mod:`.evaluation`)
=============  ==========================================================================

Lengths that follow the marker's size scale with the fit's ``radius_m`` ``R`` unless they are
given (:data:`RADIUS_SCALED`): ground ``min_height_m`` = R (the upper half of a sphere resting
on the ground stands above it), cluster ``tolerance_m`` = 2 R, gate ``max_box_m`` = 3 R and
``min_box_m`` = R / 2, research ``radius_m`` = 3 R. The class defaults are these values for the
0.20 m markers of the published experiment (R = 0.1 m).

Scales that follow the sensor's range noise (:class:`~pipeline.scans.sensor_noise.RangeNoise`, from
the scan's ``sensor`` block or the user's sensor profile; ``sigma`` = its total sigma at the
ground stage's ``max_range_m``, the largest a candidate can have) are applied by
:func:`noise_widened` when the chain knows the noise:

=======================  ======================================================================
option                   with the noise known
=======================  ======================================================================
gate ``max_box_m``       ``max(max_box_m, R + max_box_sigma * sigma)``: the cube holds the
                         sphere's cap (``R`` deep) smeared by +-3 sigma along the line of sight
                         (``max_box_sigma = 6``); at 15 mm the 3 R default still rules
research ``radius_m``    ``max(radius_m, 2 R + radius_sigma * sigma)``: every noisy point
                         (``R + 3 sigma`` from the centre) around a start up to ``R`` off
                         (``radius_sigma = 3``)
fit                      fixed-radius fit on line-of-sight residuals (:mod:`.sphere_fit`)
quality ``high_rms``     ``max_rms_sigma`` times the marker's expected RMS (:mod:`.quality`)
quality radius check     tolerance plus ``radius_sigma`` standard errors of the free radius
                         (held in [R/4, 4R]; one-sided beyond the footprint limit)
=======================  ======================================================================

The cluster ``tolerance_m`` (2 R) is not widened: range noise moves points along the line of
sight, across the sphere's 2 R extent, so neighbouring returns of one sphere stay within
``3 sqrt(2) sigma`` of each other, below 2 R up to ``sigma = 47 mm``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from markerplan.errors import ConfigError
from pipeline.chain.calibration import CalibrationConfig
from pipeline.chain.gate import GATE_SPILL_FRACTION
from pipeline.chain.ground import GROUND_MAX_SLOPE, STEEPNESS_TOLERANCE_M, SUPPORT_RADIUS_M
from pipeline.chain.quality import QualityConfig
from pipeline.scans.rig import MountingOffsets
from pipeline.scans.sensor_noise import RangeNoise
from pipeline.sphere_centres.sphere_fit import METHODS


@dataclass(frozen=True)
class CalibrateStage(CalibrationConfig):
    """``calibrate``: self-calibration settings plus the start / known offsets.

    With ``enabled = False`` the given offsets are applied as known values.
    ``axis_offset_rounds``: estimate the axis offset, (first round) re-estimate the angles with
    it, re-fit the spheres (new inlier sets); repeat this many times.
    ``redetect_shift_m``: the first detection runs before the axis offset is known, on a
    cloud whose direct and reverse faces are ``2 |d|`` apart; when the first round's offsets
    move any return within the ground stage's ``max_range_m`` by more than this (metres,
    :func:`pipeline.chain.calibration.largest_shift_m`), the candidates are detected again on the
    corrected cloud (a marker on a crater rim, smeared into the rim's ground points, can fail
    the two-box gate on the first pass; so can one whose gate verdict was borderline). The
    default, 1 mm, is half the range resolution: any offset the spheres resolve re-detects.
    """

    enabled: bool = True
    axis_offset_rounds: int = 2
    redetect_shift_m: float = 0.001
    vertical_axis_error_rad: float = 0.0
    lframe_tilt_rad: float = 0.0
    axis_offset_x_m: float = 0.0
    axis_offset_y_m: float = 0.0

    def validate(self) -> CalibrateStage:
        super().validate()
        if int(self.axis_offset_rounds) < 1:
            raise ConfigError(f"calibrate `axis_offset_rounds` must be >= 1, got "
                              f"{self.axis_offset_rounds}")
        if not self.redetect_shift_m >= 0:
            raise ConfigError(f"calibrate `redetect_shift_m` must be >= 0 metres, got "
                              f"{self.redetect_shift_m}")
        return self

    def offsets(self) -> MountingOffsets:
        return MountingOffsets(self.vertical_axis_error_rad, self.lframe_tilt_rad,
                               (self.axis_offset_x_m, self.axis_offset_y_m))

    def calibration(self) -> CalibrationConfig:
        names = {f.name for f in fields(CalibrationConfig)}
        return CalibrationConfig(**{k: getattr(self, k) for k in names})


@dataclass(frozen=True)
class GroundStage:
    """``ground``: grid cell, minimum height above local ground, range band (metres).

    ``min_height_m`` defaults to 0.10 m, not the published 0.2 m: our markers sit on the ground
    (centre = ground + 0.10 m), so nothing of a 0.20 m sphere is 0.2 m above the ground.
    ``max_slope``, ``steepness_tolerance_m``, ``support_radius_m``: the steepness test
    (:func:`pipeline.chain.ground.remove_ground`): terrain up to ``max_slope`` (rise over run) is
    ground, so crater walls and rims do not chain a nearby marker into a rim cluster.
    """

    cell_m: float = 0.5
    min_height_m: float = 0.1
    min_range_m: float = 0.5
    max_range_m: float = 60.0
    max_slope: float = GROUND_MAX_SLOPE
    steepness_tolerance_m: float = STEEPNESS_TOLERANCE_M
    support_radius_m: float = SUPPORT_RADIUS_M

    def validate(self) -> GroundStage:
        if not self.cell_m > 0 or not self.min_height_m >= 0:
            raise ConfigError(f"ground stage needs cell_m > 0 and min_height_m >= 0, got "
                              f"{self.cell_m}, {self.min_height_m}")
        if not (self.max_slope >= 0 and self.steepness_tolerance_m >= 0
                and self.support_radius_m > 0):
            raise ConfigError(f"ground stage needs max_slope >= 0, steepness_tolerance_m >= 0 "
                              f"and support_radius_m > 0, got {self.max_slope}, "
                              f"{self.steepness_tolerance_m}, {self.support_radius_m}")
        if not 0 <= self.min_range_m < self.max_range_m:
            raise ConfigError(f"ground stage needs 0 <= min_range_m < max_range_m, got "
                              f"{self.min_range_m}, {self.max_range_m}")
        return self


@dataclass(frozen=True)
class ClusterStage:
    """``cluster``: link distance (metres) and minimum cluster size."""

    tolerance_m: float = 0.2
    min_points: int = 5

    def validate(self) -> ClusterStage:
        if not self.tolerance_m > 0 or self.min_points < 1:
            raise ConfigError(f"cluster stage needs tolerance_m > 0 and min_points >= 1, got "
                              f"{self.tolerance_m}, {self.min_points}")
        return self


@dataclass(frozen=True)
class GateStage:
    """``gate``: edges of the large and the small cube, metres; widening of the large cube in
    range-noise sigmas (module docstring); the share of a cluster's points that may spill out
    of the large cube (a near sphere's mixed-return tail,
    :func:`pipeline.chain.gate.gate_verdicts`).
    """

    max_box_m: float = 0.30
    min_box_m: float = 0.05
    max_box_sigma: float = 6.0
    spill_fraction: float = GATE_SPILL_FRACTION

    def validate(self) -> GateStage:
        if not 0 < self.min_box_m < self.max_box_m:
            raise ConfigError(f"gate stage needs 0 < min_box_m < max_box_m, got "
                              f"{self.min_box_m}, {self.max_box_m}")
        if not self.max_box_sigma >= 0:
            raise ConfigError(f"gate stage needs max_box_sigma >= 0, got {self.max_box_sigma}")
        if not 0 <= self.spill_fraction < 0.5:
            raise ConfigError(f"gate stage needs 0 <= spill_fraction < 0.5, got "
                              f"{self.spill_fraction}")
        return self


@dataclass(frozen=True)
class ResearchStage:
    """``research``: search radius around each candidate centroid, metres; its widening in
    range-noise sigmas (module docstring)."""

    radius_m: float = 0.3
    radius_sigma: float = 3.0

    def validate(self) -> ResearchStage:
        if not self.radius_m > 0 or not self.radius_sigma >= 0:
            raise ConfigError(f"research stage needs radius_m > 0 and radius_sigma >= 0, got "
                              f"{self.radius_m}, {self.radius_sigma}")
        return self


@dataclass(frozen=True)
class FitStage:
    """``fit``: estimator, known marker radius (metres), ICP correspondence gate (metres)."""

    method: str = "fixed-radius"
    radius_m: float = 0.1
    max_correspondence_m: float = 0.05

    def validate(self) -> FitStage:
        if self.method not in METHODS:
            raise ConfigError(f"fit stage `method` must be one of {', '.join(METHODS)}, got "
                              f"{self.method!r}")
        if not self.radius_m > 0:
            raise ConfigError(f"fit stage `radius_m` must be a positive marker radius in "
                              f"metres, got {self.radius_m}")
        if not self.max_correspondence_m > 0:
            raise ConfigError(f"fit stage `max_correspondence_m` must be > 0, got "
                              f"{self.max_correspondence_m}")
        return self


@dataclass(frozen=True)
class EvaluateStage:
    """``evaluate``: match gate for station-frame references and registration tolerance (m)."""

    match_distance_m: float = 0.5
    registration_tol_m: float = 0.15

    def validate(self) -> EvaluateStage:
        if not self.match_distance_m > 0 or not self.registration_tol_m > 0:
            raise ConfigError("evaluate stage needs match_distance_m > 0 and registration_tol_m "
                              f"> 0, got {self.match_distance_m}, {self.registration_tol_m}")
        return self


STAGES: dict[str, type] = {
    "calibrate": CalibrateStage, "ground": GroundStage, "cluster": ClusterStage,
    "gate": GateStage, "research": ResearchStage, "fit": FitStage, "quality": QualityConfig,
    "evaluate": EvaluateStage,
}


@dataclass(frozen=True)
class ProcessConfig:
    """The validated stage configs of the chain."""

    calibrate: CalibrateStage = field(default_factory=CalibrateStage)
    ground: GroundStage = field(default_factory=GroundStage)
    cluster: ClusterStage = field(default_factory=ClusterStage)
    gate: GateStage = field(default_factory=GateStage)
    research: ResearchStage = field(default_factory=ResearchStage)
    fit: FitStage = field(default_factory=FitStage)
    quality: QualityConfig = field(default_factory=QualityConfig)
    evaluate: EvaluateStage = field(default_factory=EvaluateStage)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {name: dataclasses.asdict(getattr(self, name)) for name in STAGES}


#: (stage, option) -> its value as a multiple of the marker radius (see the module docstring).
RADIUS_SCALED = {("ground", "min_height_m"): 1.0, ("ground", "support_radius_m"): 3.0,
                 ("cluster", "tolerance_m"): 2.0,
                 ("gate", "max_box_m"): 3.0, ("gate", "min_box_m"): 0.5,
                 ("research", "radius_m"): 3.0}


#: (stage, old option) -> what replaced it, for options whose meaning changed (no alias).
REPLACED_OPTIONS = {("calibrate", "redetect_axis_offset_m"):
                    "'redetect_shift_m' (re-detect when the calibration moves any return by "
                    "more than this, metres; default 0.001)"}


def build_config(options: dict[str, dict[str, Any]] | None = None) -> ProcessConfig:
    """Build and validate the stage configs from ``{stage: {option: value}}``.

    Options in :data:`RADIUS_SCALED` that are not given follow ``fit.radius_m``.

    Raises
    ------
    ConfigError
        Unknown stage or option (named), a value of the wrong type, or a value out of range.

    Examples
    --------
    >>> build_config({"fit": {"method": "hemisphere-icp"}}).fit.method
    'hemisphere-icp'
    >>> build_config({"fit": {"radius_m": 0.15}}).gate.max_box_m
    0.45
    >>> try:
    ...     build_config({"gate": {"max_box": 0.3}})
    ... except ConfigError as exc:
    ...     print(exc)
    stage 'gate' has no option 'max_box'; its options are max_box_m, min_box_m, max_box_sigma, \
spill_fraction
    """
    options = options or {}
    radius = options.get("fit", {}).get("radius_m")
    if radius is not None and isinstance(radius, int | float) and radius > 0:
        scaled = {}
        for (stage, key), ratio in RADIUS_SCALED.items():
            if key not in options.get(stage, {}):
                scaled.setdefault(stage, {})[key] = round(ratio * radius, 12)
        options = {**options, **{s: {**options.get(s, {}), **v} for s, v in scaled.items()}}
    built = {}
    for name, values in options.items():
        if name not in STAGES:
            raise ConfigError(f"unknown stage {name!r}; stages are {', '.join(STAGES)}")
        cls = STAGES[name]
        known = {f.name: f for f in fields(cls)}
        kwargs = {}
        for key, value in (values or {}).items():
            if (name, key) in REPLACED_OPTIONS:
                raise ConfigError(f"stage {name!r} option {key!r} was replaced by "
                                  f"{REPLACED_OPTIONS[name, key]}; rename it")
            if key not in known:
                raise ConfigError(f"stage {name!r} has no option {key!r}; its options are "
                                  f"{', '.join(known)}")
            kwargs[key] = _coerce(name, key, known[key].default, value)
        built[name] = cls(**kwargs)
    cfg = ProcessConfig(**built)
    for name in STAGES:
        getattr(cfg, name).validate()
    return cfg


def noise_widened(cfg: ProcessConfig, noise: RangeNoise) -> ProcessConfig:
    """A copy of ``cfg`` whose gate and research radius hold markers under ``noise``.

    Examples
    --------
    >>> cfg = build_config()
    >>> noise_widened(cfg, RangeNoise(0.015)).gate.max_box_m
    0.3
    >>> w = noise_widened(cfg, RangeNoise(0.045, range_resolution_m=0.0))
    >>> round(w.gate.max_box_m, 3), round(w.research.radius_m, 3)
    (0.37, 0.335)
    """
    sigma = float(noise.total_sigma_m(cfg.ground.max_range_m))
    radius = cfg.fit.radius_m
    gate = replace(cfg.gate, max_box_m=max(cfg.gate.max_box_m,
                                           radius + cfg.gate.max_box_sigma * sigma))
    research = replace(cfg.research, radius_m=max(cfg.research.radius_m,
                                                  2 * radius + cfg.research.radius_sigma * sigma))
    return replace(cfg, gate=gate.validate(), research=research.validate())


def _coerce(stage: str, key: str, default: Any, value: Any) -> Any:
    kind = type(default)
    if kind is bool:
        if not isinstance(value, bool | np.bool_):
            raise ConfigError(f"stage {stage!r} option {key!r} must be true/false, got {value!r}")
        return bool(value)
    try:
        if kind is int:
            if isinstance(value, bool) or float(value) != int(value):
                raise ValueError
            return int(value)
        if kind is float:
            if isinstance(value, bool):
                raise ValueError
            return float(value)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"stage {stage!r} option {key!r} must be a {kind.__name__}, got "
                          f"{value!r}") from exc
    return str(value)


def with_offsets(cfg: ProcessConfig, offsets: MountingOffsets, enabled: bool) -> ProcessConfig:
    """A copy of ``cfg`` whose calibrate stage starts from (or, disabled, applies) ``offsets``."""
    cal = replace(cfg.calibrate, enabled=enabled,
                  vertical_axis_error_rad=offsets.vertical_axis_error_rad,
                  lframe_tilt_rad=offsets.lframe_tilt_rad,
                  axis_offset_x_m=offsets.axis_offset_m[0],
                  axis_offset_y_m=offsets.axis_offset_m[1])
    return replace(cfg, calibrate=cal.validate())

