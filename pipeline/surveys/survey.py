"""A survey's stations processed alike: the processing config of a survey's settings, and the
station loop over its scan files.

:func:`processing_config` is the one place where the settings of a survey (marker radius,
estimator, mounting offsets, quality gate, stage options) become the validated
:class:`~pipeline.chain.stages.ProcessConfig` of :func:`pipeline.chain.process.process_station`;
``markerplan process``, ``verify`` (known control and network mode) and ``calibrate-sensor``
all take their config from it. :func:`process_scans` runs the chain on every scan file of a
survey, one after another, with each station's reference and range noise.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pipeline.chain.evaluation import Reference, pick_reference
from pipeline.chain.process import StationResult, process_station
from pipeline.chain.stages import ProcessConfig, build_config, with_offsets
from pipeline.scans.rig import MountingOffsets
from pipeline.scans.scan_format import StationScan, read_scan
from pipeline.scans.sensor_noise import RangeNoise


@dataclass(frozen=True)
class ProcessingSettings:
    """How every station of a survey is processed.

    Attributes
    ----------
    marker_radius_m : float or None
        Known marker radius, m (the fit's ``radius_m``; the radius-scaled lengths follow it).
        ``None``: the one ``stage_options`` gives, else the fit stage's default.
    estimator : str or None
        Sphere-centre estimator (:data:`pipeline.sphere_centres.sphere_fit.METHODS`); ``None``: the
        one ``stage_options`` gives, else the fit stage's default.
    offsets : MountingOffsets
        The rig's mounting offsets (rad, m): where self-calibration starts, or, with
        ``calibrate = False``, the known values applied.
    calibrate : bool
        Self-calibrate the mounting offsets from each scan.
    min_points : int or None
        Quality gate: minimum points per marker (``None``: the gate's).
    max_rms_m : float or None
        Quality gate: maximum fit RMS, m; given, it replaces the noise-scaled limit.
    min_visible_fraction : float or None
        Quality gate: minimum visible fraction of the sphere (``None``: the gate's).
    stage_options : mapping of str to mapping of str to object
        Any other ``{stage: {option: value}}`` (:func:`pipeline.chain.stages.build_config`); the
        fields above take precedence over them.
    """

    marker_radius_m: float | None = None
    estimator: str | None = None
    offsets: MountingOffsets = MountingOffsets()
    calibrate: bool = True
    min_points: int | None = None
    max_rms_m: float | None = None
    min_visible_fraction: float | None = None
    stage_options: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)


def processing_config(settings: ProcessingSettings) -> ProcessConfig:
    """The validated stage configuration of ``settings``.

    Parameters
    ----------
    settings : ProcessingSettings

    Returns
    -------
    config : ProcessConfig

    Raises
    ------
    ConfigError
        An unknown stage or option, or a value out of range (:func:`build_config`).

    Examples
    --------
    >>> cfg = processing_config(ProcessingSettings(marker_radius_m=0.15, min_points=30))
    >>> cfg.gate.max_box_m, cfg.quality.min_points, cfg.calibrate.enabled
    (0.45, 30, True)
    """
    options = {stage: dict(values) for stage, values in settings.stage_options.items()}
    fit = options.setdefault("fit", {})
    if settings.estimator is not None:
        fit["method"] = settings.estimator
    if settings.marker_radius_m is not None:
        fit["radius_m"] = settings.marker_radius_m
    quality = {"min_points": settings.min_points, "max_rms_m": settings.max_rms_m,
               "max_rms_sigma": None if settings.max_rms_m is None else 0.0,
               "min_visible_fraction": settings.min_visible_fraction}
    options.setdefault("quality", {}).update({k: v for k, v in quality.items() if v is not None})
    return with_offsets(build_config(options), settings.offsets, enabled=settings.calibrate)


@dataclass
class SurveyResult:
    """What :func:`process_scans` produced.

    Attributes
    ----------
    results : list of StationResult
        One per scan, in the order of the scans.
    inputs : list of dict
        Per scan, for the provenance: ``scan`` (path), ``station_id``, ``sha256`` (fingerprint
        of its points, frame indices and turntable angles) and ``range_noise`` (the noise the
        chain followed, m, and its ``source``).
    """

    results: list[StationResult]
    inputs: list[dict[str, Any]]


def process_scans(scans: Sequence[Path], config: ProcessConfig, references: list[Reference],
                  fallback_noise: RangeNoise, fallback_source: str, *,
                  each: Callable[[StationScan, StationResult], None] | None = None
                  ) -> SurveyResult:
    """Read every scan file and run the chain (:func:`~pipeline.chain.process.process_station`).

    Only one scan is in memory at a time; a progress bar over the stations goes to stderr.

    Parameters
    ----------
    scans : sequence of Path
        ``.scan.npz`` files, one station each.
    config : ProcessConfig
        The stations' configuration (:func:`processing_config`).
    references : list of Reference
        Reference centres (:func:`pipeline.chain.evaluation.pick_reference` picks each station's).
    fallback_noise : RangeNoise
        The range noise of a scan that records none (real scans: the user's sensor profile).
    fallback_source : str
        Where ``fallback_noise`` comes from, for the provenance (e.g. ``sensor profile NAME``).
    each : callable, optional
        ``each(scan, result)`` after each station, while its scan is in memory (e.g. to
        write its classified cloud).

    Returns
    -------
    SurveyResult

    Raises
    ------
    InputFileError
        An unreadable or invalid scan file (:func:`pipeline.scans.scan_format.read_scan`).
    """
    from tqdm import tqdm

    from markerplan.provenance import fingerprint_arrays

    results, inputs = [], []
    for path in tqdm(scans, desc="stations", file=sys.stderr, disable=None):
        scan = read_scan(path)
        noise = RangeNoise.recorded(scan.metadata.get("sensor", {}))
        source = "scan" if noise else fallback_source
        noise = noise or fallback_noise
        inputs.append({"scan": str(path), "station_id": scan.station_id,
                       "sha256": fingerprint_arrays(scan.xyz_sensor_m, scan.frame_index,
                                                    scan.turntable_angle_rad),
                       "range_noise": {**dataclasses.asdict(noise), "source": source}})
        results.append(process_station(scan, config, pick_reference(references, scan.station_id),
                                       noise=noise))
        if each is not None:
            each(scan, results[-1])
        del scan
    return SurveyResult(results, inputs)
