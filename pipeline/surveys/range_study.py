"""The range study (processing and aggregation side): centre error and point density against
distance, for both estimators.

The published experiment places 0.20 m markers from 1 m to 50 m from the LiDAR (every 1 m from
1 to 15 m, every 2 m from 15 to 25 m, every 5 m from 25 to 50 m) and scans them with 800
frames. The scans themselves come from the simulator (``visibility``); this module lays the
markers out, extracts and fits each one, and aggregates the marker tables of the replicates.

Two extractions (:data:`EXTRACTIONS`):

- ``full-chain`` (the default, :func:`chain_markers`): the station chain of ``markerplan
  process`` and ``verify`` (:func:`pipeline.chain.process.process_station` configured by
  :func:`pipeline.surveys.survey.processing_config`: self-calibration, ground removal, clustering,
  two-box gate, re-search, fit, quality gate), once per estimator; its detections are matched
  to the laid-out markers by their station-frame centres (:func:`pipeline.chain.evaluation.
  evaluate_rows`). A marker no detection matched is still a row, rejected as
  :data:`NOT_DETECTED`, so the table's acceptance rate is the chain's.
- ``truth-seeded`` (a diagnostic, :func:`measure_markers`): each marker's points are
  re-searched within ``research_radius_m`` of its true position (as a total station would guide
  it), skipping ground removal, clustering and the gate; the fit starts from the points above
  the marker's equator (:func:`pipeline.sphere_centres.geometric_sphere_fit.cap_start`). It shows
  what the fit and quality gate alone make of a marker, not what the chain delivers.

Given the sensor's range noise, the fit and the quality gate take their scales from it, as in
:mod:`pipeline.chain.process`.
"""

from __future__ import annotations

import numpy as np

from markerplan.constants import GOLDEN_ANGLE_RAD
from markerplan.errors import ConfigError, DataError
from pipeline.chain.evaluation import reference_from_truth
from pipeline.chain.gate import RangeIndex
from pipeline.chain.process import process_station
from pipeline.chain.quality import QualityConfig, marker_metrics, quality_gate
from pipeline.chain.synthesis import synthesize
from pipeline.scans.rig import MountingOffsets
from pipeline.scans.scan_format import StationScan
from pipeline.scans.sensor_noise import RangeNoise
from pipeline.sphere_centres.geometric_sphere_fit import cap_start
from pipeline.sphere_centres.sphere_fit import METHODS, fit_sphere
from pipeline.surveys.survey import ProcessingSettings, processing_config
from pipeline.tables.marker_table import MarkerRow, line_of_sight

#: Horizontal LiDAR-to-marker distances of the published range experiment, metres.
RANGE_STUDY_DISTANCES_M = np.r_[np.arange(1.0, 16.0, 1.0), np.arange(17.0, 26.0, 2.0),
                                np.arange(30.0, 51.0, 5.0)]

#: How the markers are extracted: the station chain (default) or the truth-seeded diagnostic.
EXTRACTIONS = ("full-chain", "truth-seeded")
#: ``reason`` of a laid-out marker that no detection of the chain matched.
NOT_DETECTED = "not_detected"

SUMMARY_COLUMNS = ("estimator", "distance_m", "n_rows", "n_detected", "n_fitted", "n_accepted",
                   "median_n_points", "median_point_density_per_m2", "median_error_m",
                   "p95_error_m", "median_error_accepted_m")


def marker_layout(distances_m: np.ndarray = RANGE_STUDY_DISTANCES_M, radius_m: float = 0.1,
                  lidar_height_m: float = 1.0, slope_rad: float = 0.0) -> np.ndarray:
    """Marker centres in the station frame, one per distance, resting on a planar ground.

    The ground is the plane ``z = x tan(slope_rad) - lidar_height_m`` (station frame, LiDAR
    centre at the origin, z up): it passes ``lidar_height_m`` below the LiDAR centre and rises
    towards +x by ``slope_rad`` (level for 0). Marker ``k`` sits at horizontal distance
    ``distances_m[k]`` and azimuth ``k`` times the golden angle (137.5 deg), so no marker
    hides another; it rests on the plane, so its centre lies ``radius_m`` from the plane along
    the plane's upward normal (``radius_m / cos(slope_rad)`` above the plane vertically). With
    a slope, markers towards +x are uphill (seen higher than on level ground) and markers
    towards -x downhill; from a LiDAR above the plane no marker is hidden by the ground.

    Parameters
    ----------
    distances_m : (n,) float
        Horizontal LiDAR-to-marker-centre distances, metres, each > ``2 * radius_m``.
    radius_m : float
        Marker radius, metres.
    lidar_height_m : float
        LiDAR centre above the ground at the station, metres (> 0).
    slope_rad : float
        Ground slope, radians, in (-pi/4, pi/4); positive rises towards +x.

    Returns
    -------
    centres_m : (n, 3) float
        Station frame, metres.

    Examples
    --------
    >>> c = marker_layout(np.array([1.0, 2.0]))
    >>> np.round(np.hypot(c[:, 0], c[:, 1]), 6).tolist(), c[:, 2].tolist()
    ([1.0, 2.0], [-0.9, -0.9])
    >>> c = marker_layout(np.array([4.0]), lidar_height_m=0.8, slope_rad=np.radians(15))
    >>> c.round(4).tolist(), round(float(np.degrees(np.arctan2(c[0, 2], c[0, 0]))), 2)
    ([[4.0, 0.0, 0.3753]], 5.36)
    """
    d = _layout_iv(distances_m, radius_m, lidar_height_m, slope_rad)
    az = GOLDEN_ANGLE_RAD * np.arange(d.size)
    x = d * np.cos(az)
    return np.column_stack([x, d * np.sin(az), x * np.tan(slope_rad)
                            + radius_m / np.cos(slope_rad) - lidar_height_m])


def _layout_iv(distances_m, radius_m: float, lidar_height_m: float, slope_rad: float
               ) -> np.ndarray:
    """Validate :func:`marker_layout`'s arguments; return the distances as a float array."""
    d = np.asarray(distances_m, dtype=float)
    if d.ndim != 1 or d.size == 0 or np.any(d <= 2 * radius_m):
        raise ConfigError(f"`distances_m` must be a non-empty list of distances > 2 * radius, "
                          f"got {d}")
    if not (np.isfinite(lidar_height_m) and lidar_height_m > 0):
        raise ConfigError(f"`lidar_height_m` must be > 0, got {lidar_height_m}")
    if not (np.isfinite(slope_rad) and abs(slope_rad) < np.pi / 4):
        raise ConfigError(f"`slope_rad` must be in (-pi/4, pi/4) (steeper than 45 deg no marker "
                          f"rests on the ground), got {slope_rad}")
    return d


def measure_markers(scan: StationScan, centres_m: np.ndarray, ids: list[str],
                    radius_m: float = 0.1, methods: tuple[str, ...] = METHODS,
                    offsets: MountingOffsets | None = None, research_radius_m: float = 0.3,
                    quality: QualityConfig | None = None, replicate: int = 0,
                    seed: int | None = None, noise: RangeNoise | None = None
                    ) -> list[MarkerRow]:
    """The ``truth-seeded`` diagnostic: fit every known marker at its true position with each
    estimator, skipping ground removal, clustering and the gate (see the module docstring).

    Parameters
    ----------
    scan : StationScan
    centres_m : (n, 3) float
        True marker centres, station frame, metres.
    ids : list of str
        Marker ids.
    radius_m : float
    methods : tuple of str
        Estimators to run.
    offsets : MountingOffsets, optional
        Known mounting offsets (default none).
    research_radius_m : float
    quality : QualityConfig, optional
    replicate, seed : int
        Written into the rows.
    noise : RangeNoise, optional
        The sensor's range noise, for the fit and the quality gate (``None``: unknown).

    Returns
    -------
    rows : list of MarkerRow
        One per marker and estimator; a marker with fewer than 4 points gets a row with
        ``n_points = 0``, ``accepted = false``, ``reason = too_few_points`` and no error.
    """
    quality = (quality or QualityConfig()).validate()
    _check_methods(methods)
    cloud = synthesize(scan, offsets)
    index = RangeIndex(cloud.xyz_m, cloud.range_m)
    rows = []
    for mid, truth in zip(ids, np.asarray(centres_m, dtype=float), strict=True):
        members = index.within(truth, research_radius_m)
        pts = cloud.xyz_m[members]
        cap = pts[pts[:, 2] >= truth[2]]
        for method in methods:
            fit = None
            if cap.shape[0] >= 4:
                try:
                    fit = fit_sphere(pts, radius_m, method=method,
                                     centre0_m=cap_start(cap, radius_m), noise=noise)
                except DataError:  # degenerate points or none used: no fit
                    fit = None
            if fit is None:
                rows.append(lost_marker_row(scan.station_id, mid, truth, method,
                                            "too_few_points", replicate, seed))
                continue
            metrics = marker_metrics(pts, fit, noise=noise)
            ok, reason = quality_gate(fit, metrics, quality)
            dist, elev, az = line_of_sight(fit.centre_m)
            row = MarkerRow(scan.station_id, mid, *(float(v) for v in fit.centre_m), dist, elev,
                            az, fit.n_used, metrics.point_density_per_m2,
                            metrics.visible_fraction, fit.rms_m, metrics.radius_fit_m, method, ok,
                            reason, replicate=replicate, seed=seed)
            row.set_error(truth)
            rows.append(row)
    return rows


def chain_markers(scan: StationScan, truth: dict, radius_m: float = 0.1,
                  methods: tuple[str, ...] = METHODS, replicate: int = 0,
                  seed: int | None = None, noise: RangeNoise | None = None
                  ) -> list[MarkerRow]:
    """The ``full-chain`` extraction: run the station chain of ``process`` / ``verify`` on the
    scan once per estimator and give every laid-out marker its row.

    Parameters
    ----------
    scan : StationScan
        A simulated scan of the layout.
    truth : dict
        Its simulator truth (marker ids and station-frame centres,
        :func:`visibility.simulate.simulate_markers`).
    radius_m : float
        Marker radius, metres (the fit's radius; the radius-scaled stage lengths follow it).
    methods : tuple of str
        Estimators; the chain runs once with each as its ``fit.method``.
    replicate, seed : int
        Written into the rows.
    noise : RangeNoise, optional
        The sensor's range noise (default: the one the scan records).

    Returns
    -------
    rows : list of MarkerRow
        Per estimator: one row per laid-out marker in truth order — the chain's detection
        matched to it (accepted or rejected with the quality gate's reason, its error against
        the truth), or, if none matched, a rejected :data:`NOT_DETECTED` row at the true centre
        with no points and no error — then the detections that matched no marker (empty
        ``marker_id``, no error).
    """
    _check_methods(methods)
    reference = reference_from_truth(truth, "range-study layout")
    rows = []
    for method in methods:
        cfg = processing_config(ProcessingSettings(marker_radius_m=radius_m, estimator=method))
        result = process_station(scan, cfg, reference, noise=noise, replicate=replicate,
                                 seed=seed)
        matched = {r.marker_id: r for r in result.rows if r.marker_id}
        rows += [matched.get(mid) or lost_marker_row(scan.station_id, mid, centre, method,
                                                     NOT_DETECTED, replicate, seed)
                 for mid, centre in zip(reference.ids, reference.centres_m, strict=True)]
        rows += [r for r in result.rows if not r.marker_id]
    return rows


def lost_marker_row(station_id: str, marker_id: str, centre_m: np.ndarray, estimator: str,
                    reason: str, replicate: int, seed: int | None) -> MarkerRow:
    """The rejected row of a marker that was not fitted: placed at its true centre
    ``centre_m`` ((3,) float, station frame, m), no points, no fit, no error."""
    dist, elev, az = line_of_sight(centre_m)
    return MarkerRow(station_id, marker_id, *(float(v) for v in centre_m), dist, elev, az, 0,
                     0.0, 0.0, float("nan"), float("nan"), estimator, False, reason,
                     replicate=replicate, seed=seed)


def _check_methods(methods: tuple[str, ...]) -> None:
    """Refuse an empty or unknown set of estimators."""
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise ConfigError(f"`methods` must be a non-empty subset of {METHODS}, got {methods}")


def summarise(rows: list[MarkerRow], distances_m: dict[str, float]) -> list[dict]:
    """Per estimator and distance: counts, median density, median / 95th-percentile error.

    Parameters
    ----------
    rows : list of MarkerRow
        All replicates; rows of no laid-out marker (detections the chain matched to none) are
        left out (:func:`unmatched_counts` counts them).
    distances_m : dict
        Nominal horizontal distance of each marker id.

    Returns
    -------
    summary : list of dict
        Keys :data:`SUMMARY_COLUMNS`, sorted by estimator then distance; ``n_detected``
        counts the rows that are not :data:`NOT_DETECTED`; errors are NaN where no marker
        could be fitted.
    """
    out = []
    for method in sorted({r.estimator for r in rows}):
        for d in sorted(set(distances_m.values())):
            sel = [r for r in rows
                   if r.estimator == method and distances_m.get(r.marker_id) == d]
            fitted = [r for r in sel if r.error_m is not None]
            err = np.array([r.error_m for r in fitted])
            acc = np.array([r.error_m for r in fitted if r.accepted])
            out.append({
                "estimator": method, "distance_m": d, "n_rows": len(sel),
                "n_detected": sum(r.reason != NOT_DETECTED for r in sel),
                "n_fitted": len(fitted), "n_accepted": int(sum(r.accepted for r in sel)),
                "median_n_points": float(np.median([r.n_points for r in sel])) if sel else 0.0,
                "median_point_density_per_m2": float(np.median(
                    [r.point_density_per_m2 for r in sel])) if sel else 0.0,
                "median_error_m": float(np.median(err)) if err.size else float("nan"),
                "p95_error_m": float(np.percentile(err, 95)) if err.size else float("nan"),
                "median_error_accepted_m": float(np.median(acc)) if acc.size else float("nan"),
            })
    return out


def unmatched_counts(rows: list[MarkerRow], distances_m: dict[str, float]) -> dict[str, dict]:
    """Per estimator, the detections that matched no laid-out marker (clutter the chain
    kept; none on the planar ground unless something is wrong) and how many it accepted.

    Returns
    -------
    counts : dict
        ``{estimator: {"n_rows": int, "n_accepted": int}}``, every estimator of ``rows``.
    """
    out = {}
    for method in sorted({r.estimator for r in rows}):
        sel = [r for r in rows if r.estimator == method and r.marker_id not in distances_m]
        out[method] = {"n_rows": len(sel), "n_accepted": sum(r.accepted for r in sel)}
    return out


def plot(summary: list[dict], rows: list[MarkerRow], distances_m: dict[str, float], path,
         radius_m: float = 0.1) -> None:
    """Two panels against distance: point density (log) and centre error per estimator, for
    markers of radius ``radius_m`` (m)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 7), sharex=True)
    colours = {"fixed-radius": "tab:blue", "hemisphere-icp": "tab:orange"}
    for method in sorted({s["estimator"] for s in summary}):
        s = [x for x in summary if x["estimator"] == method]
        d = np.array([x["distance_m"] for x in s])
        c = colours.get(method, None)
        pts = [r for r in rows if r.estimator == method and r.error_m is not None
               and r.marker_id in distances_m]
        ax2.scatter([distances_m[r.marker_id] for r in pts], [r.error_m * 1e3 for r in pts],
                    s=6, alpha=0.3, color=c)
        ax2.plot(d, [x["median_error_m"] * 1e3 for x in s], "-o", ms=3, color=c,
                 label=f"{method} median")
        if method == "fixed-radius":
            dens = np.array([x["median_point_density_per_m2"] for x in s])
            ax1.plot(d, np.where(dens > 0, dens, np.nan), "-o", ms=3, color="k")
    ax1.set_yscale("log")
    ax1.set_ylabel("points per m$^2$ (projected disc)")
    ax1.set_title(f"Range study: {2 * radius_m:.2f} m markers, VLP-16 turntable rig")
    ax2.set_yscale("log")
    ax2.set_ylabel("centre error (mm)")
    ax2.set_xlabel("horizontal distance LiDAR - marker (m)")
    ax2.legend()
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120, metadata={"Software": None})
    plt.close(fig)
