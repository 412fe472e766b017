"""The processing chain of one station: synthesis, self-calibration, detection, measurement,
evaluation.

The chain runs the stages of :mod:`pipeline.chain.stages` in order (calibrate, ground, cluster,
gate, research, fit, quality, evaluate). The synthesis (:mod:`.synthesis`) runs after the angle
calibration; once the axis offset has been estimated from the accepted spheres (and applied
only if they resolve it, :func:`pipeline.chain.calibration.resolved_axis_offset`), the candidates
are detected again when the new offsets move any return by more than the calibrate stage's
``redetect_shift_m`` (:func:`pipeline.chain.calibration.largest_shift_m`), else only their
neighbourhoods are synthesised again and re-fitted. Detection (ground, cluster,
gate) runs on a range-thinned copy of the cloud (:func:`detection_subset`); re-search and
fitting use every point (indexed only within the candidates' range bands,
:func:`pipeline.chain.gate.within_range_bands`); :func:`pipeline.chain.evaluation.evaluate_rows`
evaluates the rows.

When the range noise is known (recorded in the scan, or given), the gate and re-search are
widened for it (:func:`pipeline.chain.stages.noise_widened`) and the fit and quality gate take their
scales from it (:mod:`pipeline.sphere_centres.sphere_fit`, :mod:`pipeline.chain.quality`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from markerplan.errors import DataError
from pipeline.chain.calibration import (
    estimate_axis_offset,
    estimate_rotation_offsets,
    largest_shift_m,
    resolved_axis_offset,
)
from pipeline.chain.clustering import euclidean_clusters
from pipeline.chain.evaluation import Reference, evaluate_rows
from pipeline.chain.gate import RangeIndex, gate_verdicts, research, within_range_bands
from pipeline.chain.ground import remove_ground
from pipeline.chain.quality import MarkerMetrics, marker_metrics, quality_gate
from pipeline.chain.stages import ProcessConfig, build_config, noise_widened
from pipeline.chain.synthesis import StationCloud, synthesize
from pipeline.kernels import range_thinned
from pipeline.scans.rig import MountingOffsets, sensor_to_station
from pipeline.scans.scan_format import StationScan
from pipeline.scans.sensor_noise import RangeNoise
from pipeline.sphere_centres.geometric_sphere_fit import cap_start
from pipeline.sphere_centres.sphere_fit import SphereFit, fit_sphere
from pipeline.tables.marker_table import MarkerRow, line_of_sight


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
class Detection:
    """What the detection stages (ground, cluster, gate) made of one synthesised cloud.

    Attributes
    ----------
    above : (n,) int
        Cloud indices of the detection subset's points in the ground stage's range band that
        stand above the ground (:func:`pipeline.chain.ground.remove_ground`: both its tests).
    above_xyz_m : (n, 3) float
        Their station-frame coordinates, metres.
    labels : (n,) int
        Their cluster labels ``0..L-1`` (-1: in no cluster of ``min_points``).
    verdicts : (L,) str
        The gate's verdict per cluster (:data:`pipeline.chain.gate.GATE_VERDICTS`).
    clusters : list of (n_k,) int arrays
        Cloud indices of each passing cluster, by ascending label.
    """

    above: np.ndarray
    above_xyz_m: np.ndarray
    labels: np.ndarray
    verdicts: np.ndarray
    clusters: list[np.ndarray]


@dataclass
class StationResult:
    """Everything the chain produced for one station.

    ``detection`` is the last detection the chain ran (after a re-detection, the second), on
    the cloud synthesised with the offsets it then had; :mod:`pipeline.surveys.fates` reads it.
    """

    station_id: str
    offsets: MountingOffsets
    calibration: dict[str, Any]
    candidates: list[Candidate]
    rows: list[MarkerRow]
    edges: list[dict]
    summary: dict[str, Any]
    timings_s: dict[str, float]
    detection: Detection


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
    the centre fit use the full cloud. One compiled pass (:func:`pipeline.kernels.range_thinned`),
    the arithmetic in the ranges' float type.

    Parameters
    ----------
    range_m : (N,) float
        Range of each point, metres.

    Returns
    -------
    subset : (n,) int
        Ascending point indices.
    """
    range_m = np.asarray(range_m)
    if range_m.dtype not in (np.float32, np.float64):
        range_m = range_m.astype(np.float64)
    limits = np.array([full_density_range_m, max_stride, 1e-3, 1.0], dtype=range_m.dtype)
    return range_thinned(np.ascontiguousarray(range_m), limits)


def detect_candidates(cloud: StationCloud, cfg: ProcessConfig) -> Detection:
    """Ground removal, clustering and the two-box gate on the range-thinned cloud.

    Returns
    -------
    Detection
        Its ``clusters`` are the candidates (above-ground points only).
    """
    g = cfg.ground
    sub = detection_subset(cloud.range_m)
    rng = cloud.range_m[sub]
    pts = np.take(cloud.xyz_m, sub, axis=0)  # same rows as xyz_m[sub], in half the time
    band = (rng >= g.min_range_m) & (rng <= g.max_range_m)
    keep = np.flatnonzero(remove_ground(pts, g.cell_m, g.min_height_m, g.max_slope,
                                        g.steepness_tolerance_m, g.support_radius_m) & band)
    above = pts[keep]
    labels = euclidean_clusters(above, cfg.cluster.tolerance_m, cfg.cluster.min_points)
    verdicts = gate_verdicts(above, labels, cfg.gate.max_box_m, cfg.gate.min_box_m,
                             cfg.gate.spill_fraction)
    sel = np.isin(labels, np.flatnonzero(verdicts == "passed"))
    order = np.argsort(labels[sel], kind="stable")
    members = sub[keep[sel][order]]
    split = np.flatnonzero(np.diff(labels[sel][order])) + 1
    clusters = np.split(members, split) if members.size else []
    return Detection(sub[keep], above, labels, verdicts, clusters)


def measure_candidates(xyz_m: np.ndarray, index: RangeIndex, starts_m: np.ndarray,
                       cfg: ProcessConfig, noise: RangeNoise | None = None) -> list[Candidate]:
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
    noise : RangeNoise, optional
        The sensor's range noise, for the fit and the quality gate (``None``: unknown).
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
                             max_correspondence_m=fit_cfg.max_correspondence_m, centre0_m=start,
                             noise=noise)
        except DataError:  # no sphere in these points (degenerate, none used): not listed
            continue
        metrics = marker_metrics(pts, fit, noise=noise)
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
                    reference: Reference | None = None, *, noise: RangeNoise | None = None,
                    replicate: int = 0, seed: int | None = None) -> StationResult:
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
    noise : RangeNoise, optional
        The sensor's range noise; default: the one the scan records
        (:meth:`RangeNoise.recorded`), else unknown (absolute gates, geometric fits).
    replicate, seed : int
        Copied into the marker table (``seed`` defaults to the simulation seed recorded in
        the scan's provenance, if any).

    Returns
    -------
    StationResult
    """
    cfg = config or build_config()
    noise = noise or RangeNoise.recorded(scan.metadata.get("sensor", {}))
    if noise is not None:
        cfg = noise_widened(cfg, noise)
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
    cands, detection = _detect_and_measure(scan, offsets, cfg, noise, timer)
    detected_with = offsets
    if cal.enabled:
        # The sphere inlier sets depend on the offsets and the angle ICP is biased by an
        # unknown axis offset: estimate d (kept at its start value unless the spheres resolve
        # it), re-estimate the angles with it (first round only), re-fit the markers; repeat.
        for round_ in range(cal.axis_offset_rounds):
            good = [c for c in cands if c.accepted]
            estimate, cov_d, n_sph, sph_rms = estimate_axis_offset(
                scan, offsets, [c.members[c.fit.used] for c in good], cfg.fit.radius_m,
                np.array([c.fit.centre_m for c in good]).reshape(-1, 3), cal.calibration())
            previous = offsets
            offsets, chi2 = resolved_axis_offset(cal.offsets(), estimate, cov_d,
                                                 cal.axis_offset_chi2)
            calib.update(axis_offset_estimate_m=[float(v) for v in estimate.axis_offset_m],
                         sigma_axis_offset_m=[float(np.sqrt(cov_d[0, 0])),
                                              float(np.sqrt(cov_d[1, 1]))],
                         axis_offset_chi2=chi2, axis_offset_resolved=offsets is estimate,
                         n_spheres=n_sph, sphere_rms_m=sph_rms)
            timer.lap("calibrate_axis_offset")
            if not (n_sph and cands) or offsets == previous:
                break  # nothing moved: the candidates already stand on these offsets
            if round_ == 0:
                offsets, cov, n_pairs, icp_rms = estimate_rotation_offsets(
                    scan, offsets, cal.calibration())
                calib.update(sigma_vertical_axis_error_rad=float(np.sqrt(cov[0, 0])),
                             sigma_lframe_tilt_rad=float(np.sqrt(cov[1, 1])),
                             n_plane_pairs=n_pairs, icp_rms_m=icp_rms)
                timer.lap("calibrate_angles")
                if (largest_shift_m(detected_with, offsets, cfg.ground.max_range_m)
                        > cal.redetect_shift_m):
                    cands, detection = _detect_and_measure(scan, offsets, cfg, noise, timer)
                    detected_with = offsets
                    calib["redetected"] = True
                    continue
            cands = _remeasure(scan, offsets, cands, cfg, noise)
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
                         timer.times, detection)


def _detect_and_measure(scan: StationScan, offsets: MountingOffsets, cfg: ProcessConfig,
                        noise: RangeNoise | None, timer: _Timer
                        ) -> tuple[list[Candidate], Detection]:
    """Synthesise the cloud with ``offsets``, detect candidates, re-search and fit them."""
    cloud = synthesize(scan, offsets)
    timer.lap("synthesis")
    detection = detect_candidates(cloud, cfg)
    timer.lap("ground+cluster+gate")
    starts = np.array([cap_start(cloud.xyz_m[m], cfg.fit.radius_m)
                       for m in detection.clusters])
    starts = starts.reshape(-1, 3)
    near = within_range_bands(cloud.range_m, starts, cfg.research.radius_m)
    xyz = cloud.xyz_m[near]
    index = RangeIndex(xyz, cloud.range_m[near])
    timer.lap("index")
    cands = measure_candidates(xyz, index, starts, cfg, noise)
    for c in cands:
        c.members = near[c.members]
    timer.lap("research+fit+quality")
    return cands, detection


def _remeasure(scan: StationScan, offsets: MountingOffsets, cands: list[Candidate],
               cfg: ProcessConfig, noise: RangeNoise | None) -> list[Candidate]:
    """Fit the candidates again with new offsets, re-synthesising only their neighbourhoods."""
    sub = np.unique(np.concatenate([c.members for c in cands]))
    xyz = sensor_to_station(scan.xyz_sensor_m[sub], scan.frame_index[sub],
                            scan.turntable_angle_rad, offsets)
    starts = np.array([c.fit.centre_m for c in cands]).reshape(-1, 3)
    new = measure_candidates(xyz, RangeIndex(xyz), starts, cfg, noise)
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
