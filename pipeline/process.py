"""The processing chain of one station, as a list of declared stages (PDAL-style).

Stages, in order (each a small typed config; :func:`build_config` validates every option
before anything runs and rejects unknown stages/options by name):

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

The synthesis (:mod:`.synthesis`) runs after the angle calibration; once the axis offset has
been estimated from the accepted spheres, only the candidates' neighbourhoods are synthesised
again and re-fitted. Detection (ground, cluster, gate) runs on a range-thinned copy of the
cloud (:func:`detection_subset`); re-search and fitting use every point.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from markerplan.errors import ConfigError, DataError
from pipeline.calibration import (
    CalibrationConfig,
    estimate_axis_offset,
    estimate_rotation_offsets,
)
from pipeline.clustering import euclidean_clusters
from pipeline.evaluation import (
    Reference,
    edge_residuals,
    match_nearest,
    register_reference,
)
from pipeline.gate import RangeIndex, research, two_box_gate
from pipeline.ground import remove_ground
from pipeline.marker_table import MarkerRow, line_of_sight
from pipeline.quality import MarkerMetrics, QualityConfig, marker_metrics, quality_gate
from pipeline.rig import MountingOffsets
from pipeline.scan_format import StationScan
from pipeline.sphere_fit import METHODS, SphereFit, cap_start, fit_sphere
from pipeline.synthesis import StationCloud, frames_to_station, synthesize


@dataclass(frozen=True)
class CalibrateStage(CalibrationConfig):
    """``calibrate``: self-calibration settings plus the start / known offsets.

    With ``enabled = False`` the given offsets are applied as known values.
    ``axis_offset_rounds``: estimate the axis offset, (first round) re-estimate the angles with
    it, re-fit the spheres (new inlier sets); repeat this many times.
    ``redetect_axis_offset_m``: the first detection runs before the axis offset is known, on a
    cloud whose direct and reverse faces are ``2 |d|`` apart; when the first estimate of ``|d|``
    exceeds this, the candidates are detected again on the corrected cloud (a marker on a crater
    rim, smeared into the rim's ground points, can fail the two-box gate on the first pass).
    """

    enabled: bool = True
    axis_offset_rounds: int = 2
    redetect_axis_offset_m: float = 0.005
    vertical_axis_error_rad: float = 0.0
    lframe_tilt_rad: float = 0.0
    axis_offset_x_m: float = 0.0
    axis_offset_y_m: float = 0.0

    def validate(self) -> CalibrateStage:
        super().validate()
        if int(self.axis_offset_rounds) < 1:
            raise ConfigError(f"calibrate `axis_offset_rounds` must be >= 1, got "
                              f"{self.axis_offset_rounds}")
        if not self.redetect_axis_offset_m >= 0:
            raise ConfigError(f"calibrate `redetect_axis_offset_m` must be >= 0 metres, got "
                              f"{self.redetect_axis_offset_m}")
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
    """

    cell_m: float = 0.5
    min_height_m: float = 0.1
    min_range_m: float = 0.5
    max_range_m: float = 60.0

    def validate(self) -> GroundStage:
        if not self.cell_m > 0 or not self.min_height_m >= 0:
            raise ConfigError(f"ground stage needs cell_m > 0 and min_height_m >= 0, got "
                              f"{self.cell_m}, {self.min_height_m}")
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
    """``gate``: edges of the large and the small cube, metres."""

    max_box_m: float = 0.30
    min_box_m: float = 0.05

    def validate(self) -> GateStage:
        if not 0 < self.min_box_m < self.max_box_m:
            raise ConfigError(f"gate stage needs 0 < min_box_m < max_box_m, got "
                              f"{self.min_box_m}, {self.max_box_m}")
        return self


@dataclass(frozen=True)
class ResearchStage:
    """``research``: search radius around each candidate centroid, metres."""

    radius_m: float = 0.3

    def validate(self) -> ResearchStage:
        if not self.radius_m > 0:
            raise ConfigError(f"research stage needs radius_m > 0, got {self.radius_m}")
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


def build_config(options: dict[str, dict[str, Any]] | None = None) -> ProcessConfig:
    """Build and validate the stage configs from ``{stage: {option: value}}``.

    Raises
    ------
    ConfigError
        Unknown stage or option (named), a value of the wrong type, or a value out of range.

    Examples
    --------
    >>> build_config({"fit": {"method": "hemisphere-icp"}}).fit.method
    'hemisphere-icp'
    >>> try:
    ...     build_config({"gate": {"max_box": 0.3}})
    ... except ConfigError as exc:
    ...     print(exc)
    stage 'gate' has no option 'max_box'; its options are max_box_m, min_box_m
    """
    options = options or {}
    built = {}
    for name, values in options.items():
        if name not in STAGES:
            raise ConfigError(f"unknown stage {name!r}; stages are {', '.join(STAGES)}")
        cls = STAGES[name]
        known = {f.name: f for f in fields(cls)}
        kwargs = {}
        for key, value in (values or {}).items():
            if key not in known:
                raise ConfigError(f"stage {name!r} has no option {key!r}; its options are "
                                  f"{', '.join(known)}")
            kwargs[key] = _coerce(name, key, known[key].default, value)
        built[name] = cls(**kwargs)
    cfg = ProcessConfig(**built)
    for name in STAGES:
        getattr(cfg, name).validate()
    return cfg


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


@dataclass
class Candidate:
    """One marker candidate after re-search, fit and quality gate (station frame)."""

    start_m: np.ndarray
    members: np.ndarray
    fit: SphereFit
    metrics: MarkerMetrics
    accepted: bool
    reason: str


@dataclass
class StationResult:
    """Everything the chain produced for one station."""

    station_id: str
    offsets: MountingOffsets
    calibration: dict[str, Any]
    candidates: list[Candidate]
    rows: list[MarkerRow]
    edges: list[dict]
    summary: dict[str, Any]
    timings_s: dict[str, float]


class _Timer:
    def __init__(self) -> None:
        self.times: dict[str, float] = {}
        self._t = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.times[name] = self.times.get(name, 0.0) + now - self._t
        self._t = now


def detection_subset(range_m: np.ndarray, full_density_range_m: float = 4.0,
                     max_stride: int = 64) -> np.ndarray:
    """Indices of a range-thinned subset for the detection stages.

    Point density falls as ``1 / range^2``; about 80 % of a station's returns are ground within
    3 m. Inside ``full_density_range_m`` every ``(full_density_range_m / range)^2``-th point is
    kept (at most every ``max_stride``-th), so near-field density is capped at that of
    ``full_density_range_m``. Detection only needs a candidate's centroid: the re-search and
    the centre fit use the full cloud.

    Parameters
    ----------
    range_m : (N,) float
        Range of each point, metres.

    Returns
    -------
    subset : (n,) int
        Ascending point indices.
    """
    stride = np.clip((full_density_range_m / np.maximum(range_m, 1e-3)) ** 2, 1, max_stride)
    return np.flatnonzero(np.arange(range_m.size) % stride.astype(np.int64) == 0)


def detect_candidates(cloud: StationCloud, cfg: ProcessConfig) -> list[np.ndarray]:
    """Ground removal, clustering and the two-box gate on the range-thinned cloud.

    Returns
    -------
    clusters : list of (n_k,) int arrays
        Cloud indices of each candidate cluster (above-ground points only).
    """
    g = cfg.ground
    sub = detection_subset(cloud.range_m)
    rng = cloud.range_m[sub]
    pts = cloud.xyz_m[sub]
    band = (rng >= g.min_range_m) & (rng <= g.max_range_m)
    keep = np.flatnonzero(remove_ground(pts, g.cell_m, g.min_height_m) & band)
    above = pts[keep]
    labels = euclidean_clusters(above, cfg.cluster.tolerance_m, cfg.cluster.min_points)
    ids, _ = two_box_gate(above, labels, cfg.gate.max_box_m, cfg.gate.min_box_m)
    sel = np.isin(labels, ids)
    order = np.argsort(labels[sel], kind="stable")
    members = sub[keep[sel][order]]
    split = np.flatnonzero(np.diff(labels[sel][order])) + 1
    return np.split(members, split) if members.size else []


def measure_candidates(xyz_m: np.ndarray, index: RangeIndex, starts_m: np.ndarray,
                       cfg: ProcessConfig) -> list[Candidate]:
    """Re-search, centre fit and quality gate of every candidate; duplicates merged.

    Parameters
    ----------
    xyz_m : (N, 3) float
        Station-frame cloud, metres.
    index : RangeIndex
        Of ``xyz_m``.
    starts_m : (K, 3) float
        Initial centre of each candidate (station frame); the re-search is centred on it.
    cfg : ProcessConfig
    """
    out = []
    fit_cfg = cfg.fit
    for start, members in zip(starts_m, research(index, starts_m, cfg.research.radius_m),
                              strict=True):
        if members.size < 4:  # nothing to fit: noise, not listed
            continue
        pts = xyz_m[members]
        try:
            fit = fit_sphere(pts, fit_cfg.radius_m, method=fit_cfg.method,
                             max_correspondence_m=fit_cfg.max_correspondence_m, centre0_m=start)
        except DataError:  # no sphere in these points (degenerate, none used): not listed
            continue
        metrics = marker_metrics(pts, fit)
        ok, reason = quality_gate(fit, metrics, cfg.quality)
        out.append(Candidate(start, members, fit, metrics, ok, reason))
    return _merge_duplicates(out, fit_cfg.radius_m)


def _merge_duplicates(cands: list[Candidate], radius_m: float) -> list[Candidate]:
    """Keep one candidate per sphere: accepted first, then most points used."""
    order = sorted(cands, key=lambda c: (not c.accepted, -c.fit.n_used))
    kept: list[Candidate] = []
    for c in order:
        if all(np.linalg.norm(c.fit.centre_m - k.fit.centre_m) > radius_m for k in kept):
            kept.append(c)
    kept.sort(key=lambda c: tuple(np.round(c.fit.centre_m, 6)))
    return kept


def process_station(scan: StationScan, config: ProcessConfig | None = None,
                    reference: Reference | None = None, *, replicate: int = 0,
                    seed: int | None = None) -> StationResult:
    """Run the chain on one station scan.

    Parameters
    ----------
    scan : StationScan
        A validated scan.
    config : ProcessConfig, optional
        From :func:`build_config` (defaults otherwise).
    reference : Reference, optional
        Reference centres for evaluation (a station-frame truth for this station, or an
        external CSV).
    replicate, seed : int
        Copied into the marker table (``seed`` defaults to the simulation seed recorded in
        the scan's provenance, if any).

    Returns
    -------
    StationResult
    """
    cfg = config or build_config()
    if seed is None:
        seed = scan.metadata.get("provenance", {}).get("config", {}).get("seed")
    timer = _Timer()
    cal = cfg.calibrate
    offsets = cal.offsets()
    calib: dict[str, Any] = {"enabled": cal.enabled, "redetected": False}
    if cal.enabled:
        offsets, cov, n_pairs, icp_rms = estimate_rotation_offsets(scan, offsets,
                                                                   cal.calibration())
        calib.update(sigma_vertical_axis_error_rad=float(np.sqrt(cov[0, 0])),
                     sigma_lframe_tilt_rad=float(np.sqrt(cov[1, 1])), n_plane_pairs=n_pairs,
                     icp_rms_m=icp_rms)
        timer.lap("calibrate_angles")
    cands = _detect_and_measure(scan, offsets, cfg, timer)
    if cal.enabled:
        # The sphere inlier sets depend on the offsets and the angle ICP is biased by an
        # unknown axis offset: estimate d, re-estimate the angles with it (first round only),
        # re-fit the markers; repeat.
        for round_ in range(cal.axis_offset_rounds):
            good = [c for c in cands if c.accepted]
            offsets, cov_d, n_sph, sph_rms = estimate_axis_offset(
                scan, offsets, [c.members[c.fit.used] for c in good], cfg.fit.radius_m,
                np.array([c.fit.centre_m for c in good]).reshape(-1, 3), cal.calibration())
            calib.update(sigma_axis_offset_m=[float(np.sqrt(cov_d[0, 0])),
                                              float(np.sqrt(cov_d[1, 1]))],
                         n_spheres=n_sph, sphere_rms_m=sph_rms)
            timer.lap("calibrate_axis_offset")
            if not (n_sph and cands):
                break
            if round_ == 0:
                offsets, cov, n_pairs, icp_rms = estimate_rotation_offsets(
                    scan, offsets, cal.calibration())
                calib.update(sigma_vertical_axis_error_rad=float(np.sqrt(cov[0, 0])),
                             sigma_lframe_tilt_rad=float(np.sqrt(cov[1, 1])),
                             n_plane_pairs=n_pairs, icp_rms_m=icp_rms)
                timer.lap("calibrate_angles")
                if np.hypot(*offsets.axis_offset_m) > cal.redetect_axis_offset_m:
                    cands = _detect_and_measure(scan, offsets, cfg, timer)
                    calib["redetected"] = True
                    continue
            cands = _remeasure(scan, offsets, cands, cfg)
            timer.lap("research+fit+quality")
    calib["offsets"] = offsets.to_dict()
    rows = [_row(scan.station_id, c, cfg.fit.method, replicate, seed) for c in cands]
    edges, evaluation = evaluate_rows(rows, reference, cfg.evaluate)
    timer.lap("evaluate")
    summary = {"station_id": scan.station_id, "n_points": scan.n_points,
               "n_frames": scan.n_frames, "n_candidates": len(rows),
               "n_accepted": sum(r.accepted for r in rows), **evaluation,
               "calibration": calib}
    return StationResult(scan.station_id, offsets, calib, cands, rows, edges, summary,
                         timer.times)


def _detect_and_measure(scan: StationScan, offsets: MountingOffsets, cfg: ProcessConfig,
                        timer: _Timer) -> list[Candidate]:
    """Synthesise the cloud with ``offsets``, detect candidates, re-search and fit them."""
    cloud = synthesize(scan, offsets)
    timer.lap("synthesis")
    clusters = detect_candidates(cloud, cfg)
    timer.lap("ground+cluster+gate")
    starts = np.array([cap_start(cloud.xyz_m[m], cfg.fit.radius_m) for m in clusters])
    index = RangeIndex(cloud.xyz_m, cloud.range_m)
    timer.lap("index")
    cands = measure_candidates(cloud.xyz_m, index, starts.reshape(-1, 3), cfg)
    timer.lap("research+fit+quality")
    return cands


def _remeasure(scan: StationScan, offsets: MountingOffsets, cands: list[Candidate],
               cfg: ProcessConfig) -> list[Candidate]:
    """Fit the candidates again with new offsets, re-synthesising only their neighbourhoods."""
    sub = np.unique(np.concatenate([c.members for c in cands]))
    xyz = frames_to_station(scan.xyz_sensor_m[sub], scan.frame_index[sub],
                            scan.turntable_angle_rad, offsets)
    starts = np.array([c.fit.centre_m for c in cands]).reshape(-1, 3)
    new = measure_candidates(xyz, RangeIndex(xyz), starts, cfg)
    for c in new:
        c.members = sub[c.members]
    return new


def _row(station_id: str, c: Candidate, method: str, replicate: int, seed: int | None
         ) -> MarkerRow:
    dist, elev, az = line_of_sight(c.fit.centre_m)
    x, y, z = (float(v) for v in c.fit.centre_m)
    return MarkerRow(station_id, "", x, y, z, dist, elev, az, c.fit.n_used,
                     c.metrics.point_density_per_m2, c.metrics.visible_fraction, c.fit.rms_m,
                     c.metrics.radius_fit_m, method, c.accepted, c.reason,
                     replicate=replicate, seed=seed)


def evaluate_rows(rows: list[MarkerRow], reference: Reference | None, cfg: EvaluateStage
                  ) -> tuple[list[dict], dict[str, Any]]:
    """Match rows to the reference (in place: marker_id, errors), edge residuals, summary.

    Returns
    -------
    edges : list of dict
        See :func:`pipeline.evaluation.edge_residuals`, plus ``station_id``.
    summary : dict
        Matched counts, mean/max centre error of accepted markers, edge statistics.
    """
    if reference is None or not rows:
        return [], {"reference": None if reference is None else reference.source}
    centres = np.array([r.centre_m for r in rows])
    ref = reference.centres_m
    accepted = np.array([r.accepted for r in rows])
    registered = reference.station_id is None
    if registered:
        try:
            _, rot, t = register_reference(centres[accepted], ref, cfg.registration_tol_m)
        except DataError as exc:  # too few accepted markers at this station: no evaluation
            return [], {"reference": reference.source, "registered": False,
                        "evaluation_error": str(exc)}
        ref = ref @ rot.T + t
        match = match_nearest(centres, ref, cfg.registration_tol_m)
    else:
        match = match_nearest(centres, ref, cfg.match_distance_m)
    for r, m in zip(rows, match, strict=True):
        r.marker_id = reference.ids[m] if m >= 0 else ""
        r.set_error(ref[m] if m >= 0 else None)
    use = [i for i, r in enumerate(rows) if r.accepted and match[i] >= 0]
    ids = [reference.ids[match[i]] for i in use]
    edges = edge_residuals(ids, centres[use], reference.centres_m[match[use]])
    for e in edges:
        e["station_id"] = rows[0].station_id
    errs = np.array([rows[i].error_m for i in use])
    resid = np.array([e["residual_m"] for e in edges])
    matched_all = {reference.ids[m] for m in match if m >= 0}
    return edges, {
        "reference": reference.source, "registered": registered,
        "n_reference": len(reference.ids), "n_matched_accepted": len(use),
        "unmatched_reference_ids": sorted(set(reference.ids) - matched_all),
        "mean_error_m": float(errs.mean()) if errs.size else None,
        "max_error_m": float(errs.max()) if errs.size else None,
        "n_edges": len(edges),
        "mean_abs_edge_residual_m": float(np.abs(resid).mean()) if resid.size else None,
        "rms_edge_residual_m": float(np.sqrt(np.mean(resid ** 2))) if resid.size else None,
    }


def with_offsets(cfg: ProcessConfig, offsets: MountingOffsets, enabled: bool) -> ProcessConfig:
    """A copy of ``cfg`` whose calibrate stage starts from (or, disabled, applies) ``offsets``."""
    cal = replace(cfg.calibrate, enabled=enabled,
                  vertical_axis_error_rad=offsets.vertical_axis_error_rad,
                  lframe_tilt_rad=offsets.lframe_tilt_rad,
                  axis_offset_x_m=offsets.axis_offset_m[0],
                  axis_offset_y_m=offsets.axis_offset_m[1])
    return replace(cfg, calibrate=cal.validate())


STATION_COLUMNS = ("station_id", "n_points", "n_frames", "n_candidates", "n_accepted",
                   "n_reference", "n_matched_accepted", "mean_error_m", "max_error_m",
                   "n_edges", "mean_abs_edge_residual_m", "rms_edge_residual_m", "calibrated",
                   "vertical_axis_error_deg", "sigma_vertical_axis_error_deg",
                   "lframe_tilt_deg", "sigma_lframe_tilt_deg", "axis_offset_x_m",
                   "axis_offset_y_m", "sigma_axis_offset_x_m", "sigma_axis_offset_y_m",
                   "n_spheres")
EDGE_COLUMNS = ("station_id", "marker_a", "marker_b", "reference_length_m",
                "estimated_length_m", "residual_m")


def station_record(result: StationResult) -> dict[str, Any]:
    """One ``stations.csv`` row (degrees at this edge only)."""
    s, c = result.summary, result.calibration
    sig_ax = c.get("sigma_axis_offset_m", [None, None])
    deg = (lambda v: None if v is None else float(np.degrees(v)))  # noqa: E731
    return {
        **{k: s.get(k) for k in STATION_COLUMNS[:12]},
        "calibrated": c["enabled"],
        "vertical_axis_error_deg": deg(result.offsets.vertical_axis_error_rad),
        "sigma_vertical_axis_error_deg": deg(c.get("sigma_vertical_axis_error_rad")),
        "lframe_tilt_deg": deg(result.offsets.lframe_tilt_rad),
        "sigma_lframe_tilt_deg": deg(c.get("sigma_lframe_tilt_rad")),
        "axis_offset_x_m": result.offsets.axis_offset_m[0],
        "axis_offset_y_m": result.offsets.axis_offset_m[1],
        "sigma_axis_offset_x_m": sig_ax[0], "sigma_axis_offset_y_m": sig_ax[1],
        "n_spheres": c.get("n_spheres"),
    }


def pick_reference(references: list[Reference], station_id: str) -> Reference | None:
    """The reference for a station: its own truth file, else the (single) external CSV."""
    own = [r for r in references if r.station_id == station_id]
    if own:
        return own[0]
    external = [r for r in references if r.station_id is None]
    return external[0] if external else None


def check_references(references: list[Reference]) -> None:
    """At most one external (CSV) reference; at most one truth file per station."""
    external = [r.source for r in references if r.station_id is None]
    if len(external) > 1:
        raise ConfigError(f"give at most one total-station CSV reference, got {external}")
    ids = [r.station_id for r in references if r.station_id is not None]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise ConfigError(f"several truth files for station(s) {', '.join(dup)}; give one each")


def write_results(folder, results: list[StationResult], prov: dict[str, Any]) -> dict[str, Any]:
    """Write ``markers.csv``, ``stations.csv``, ``edges.csv`` and ``summary.json``.

    Parameters
    ----------
    folder : path-like
        Existing output folder.
    results : list of StationResult
    prov : dict
        :func:`markerplan.provenance.provenance` record.

    Returns
    -------
    summary : dict
        The content of ``summary.json``.
    """
    import csv
    import json
    from pathlib import Path

    from pipeline.marker_table import write_marker_table

    folder = Path(folder)
    write_marker_table(folder / "markers.csv", [r for res in results for r in res.rows])
    with (folder / "stations.csv").open("w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(STATION_COLUMNS)
        for res in results:
            rec = station_record(res)
            w.writerow([_cell(rec[c]) for c in STATION_COLUMNS])
    with (folder / "edges.csv").open("w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(EDGE_COLUMNS)
        for res in results:
            for e in res.edges:
                w.writerow([_cell(e[c]) for c in EDGE_COLUMNS])
    summary = {"stations": [res.summary for res in results],
               "files": ["markers.csv", "stations.csv", "edges.csv", "summary.json"],
               "provenance": prov}
    (folder / "summary.json").write_text(json.dumps(summary, indent=1, sort_keys=True,
                                                    default=_json_default) + "\n")
    return summary


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool | np.bool_):
        return "true" if v else "false"
    if isinstance(v, float | np.floating):
        return f"{float(v):.6f}" if np.isfinite(v) else ""
    return str(v)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        v = obj.item()
        return None if isinstance(v, float) and not np.isfinite(v) else v
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")
