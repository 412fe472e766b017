"""The loss study: where the station chain loses markers, against what a planner knows.

Markers are laid out on a terrain (a level field for the range sweep, or a site's relief),
each station is scanned with them by the simulator (:func:`visibility.simulate.simulate_markers`,
the sensor and turntable errors of a sensor profile, as ``verify`` scans a plan), the scan runs
through the full chain (:func:`pipeline.chain.process.process_station`, configured as ``verify``
configures it), and every marker within the sensor's range gets its fate
(:func:`planner.verify.fates.station_fates`: the stage that lost it, or ``accepted``) beside the
covariates a planner has for the pair before any scan (a row of the fate table,
:mod:`pipeline.tables.fate_table`):

=====================  ===================================================================
column                 meaning
=====================  ===================================================================
``distance_m``         LiDAR centre to marker centre, m
``elevation_deg``      of the marker centre seen from the LiDAR centre, degrees
``incidence_deg``      between the line of sight and the terrain normal at the marker, deg
``slope_deg``          terrain slope at the marker, degrees
``rim_distance_m``     to the nearest crater rim crest, m (``inf`` without craters)
``visible_fraction``   unoccluded fraction of the sensor-facing hemisphere (terrain only)
``expected_points``    returns the planner expects from one full scan
``n_points``           returns the simulator put on the marker
``stage``, ``reason``  the fate (:data:`pipeline.tables.fate_table.FATE_STAGES`)
=====================  ===================================================================

:func:`loss_table` aggregates the rows into detection and acceptance rates per bin of one
covariate, with the losses counted per stage. ``benchmarks/loss_study.py`` prints it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from pipeline.chain.process import process_station
from pipeline.surveys.range_study import RANGE_STUDY_DISTANCES_M, marker_layout
from pipeline.surveys.survey import ProcessingSettings, processing_config
from pipeline.tables.fate_table import FATE_COLUMNS, FATE_STAGES
from planner.problem.detection_odds import rim_distance, terrain_normal
from planner.verify.fates import station_fates
from visibility.dem import DEM
from visibility.sensor_profile import SensorProfile, default_profile
from visibility.terrain import Crater

#: Stages after which a marker counts as detected (a candidate was fitted on it).
DETECTED_STAGES = ("quality", "accepted")


@dataclass(frozen=True)
class LossLayout:
    """Stations and markers on one terrain, site frame.

    Attributes
    ----------
    name : str
    dem : DEM
    station_ids : list of str
    station_position_m : (s, 3) float
        LiDAR centres, metres.
    station_heading_rad : (s,) float
    marker_ids : list of str
    marker_centres_m : (m, 3) float
        Centres resting on the terrain, metres.
    marker_radius_m : float
    craters : list of Crater
        For ``rim_distance_m``.
    """

    name: str
    dem: DEM
    station_ids: list[str]
    station_position_m: np.ndarray
    station_heading_rad: np.ndarray
    marker_ids: list[str]
    marker_centres_m: np.ndarray
    marker_radius_m: float = 0.1
    craters: list[Crater] = field(default_factory=list)


def level_layout(distances_m: np.ndarray = RANGE_STUDY_DISTANCES_M, radius_m: float = 0.1,
                 lidar_height_m: float = 1.0, cell_m: float = 0.1) -> LossLayout:
    """The range sweep: one station over a level field, one marker per distance.

    The markers are those of the range study (:func:`pipeline.surveys.range_study.marker_layout`:
    golden-angle azimuths, so none hides another), on a flat DEM reaching 2 m beyond the
    farthest.

    Parameters
    ----------
    distances_m : (n,) float
        Horizontal distances, metres.
    radius_m, lidar_height_m, cell_m : float
        Marker radius, LiDAR height above the ground and DEM cell, metres.

    Returns
    -------
    LossLayout
    """
    centres = marker_layout(np.asarray(distances_m, float), radius_m, lidar_height_m)
    centres[:, 2] += lidar_height_m  # station frame (LiDAR at 0) -> site frame (ground at 0)
    half = float(np.ceil(np.abs(centres[:, :2]).max() + 2.0))
    n = int(round(2 * half / cell_m)) + 1
    dem = DEM(np.zeros((n, n)), (-half, -half), cell_m)
    ids = [f"D{d:05.1f}" for d in distances_m]
    return LossLayout("level", dem, ["S1"], np.array([[0.0, 0.0, lidar_height_m]]),
                      np.zeros(1), ids, centres, radius_m)


def relief_layout(site, spacing_m: float = 4.0, seed: int = 0,
                  keep_from_station_m: float = 1.5) -> LossLayout:
    """A site's stations with markers on a jittered grid over its working area.

    Parameters
    ----------
    site : visibility.sites.Site
    spacing_m : float
        Grid step, metres; each marker is jittered by up to a quarter step.
    seed : int
        Jitter seed.
    keep_from_station_m : float
        No marker nearer a station than this (horizontal), metres; none on a rock either.

    Returns
    -------
    LossLayout
    """
    rng = np.random.default_rng(seed)
    bx, by = site.boundary_xy_m[:, 0], site.boundary_xy_m[:, 1]
    gx, gy = np.meshgrid(np.arange(bx.min() + spacing_m / 2, bx.max(), spacing_m),
                         np.arange(by.min() + spacing_m / 2, by.max(), spacing_m))
    xy = np.column_stack([gx.ravel(), gy.ravel()])
    xy += rng.uniform(-spacing_m / 4, spacing_m / 4, xy.shape)
    far = np.linalg.norm(xy[:, None] - site.station_xy_m[None], axis=2).min(axis=1)
    keep = far >= keep_from_station_m
    radius = site.marker_radius_m
    if len(site.rock_radii_m):
        gap = np.linalg.norm(xy[:, None] - site.rock_centres_m[None, :, :2], axis=2)
        keep &= (gap > site.rock_radii_m[None] + radius + 0.05).all(axis=1)
    xy = xy[keep]
    centres = np.column_stack([xy, site.dem.height_at(xy) + radius])
    ids = [f"G{k:03d}" for k in range(len(xy))]
    return LossLayout(f"{site.name}-relief", site.dem, list(site.station_ids),
                      site.station_position_m, np.asarray(site.station_heading_rad, float),
                      ids, centres, radius, list(site.craters))


def pair_covariates(layout: LossLayout, station: int, max_range_m: float,
                    frames_per_turn: int = 800) -> dict[str, np.ndarray]:
    """The planner's covariates of every marker within ``max_range_m`` of one station.

    Returns
    -------
    covariates : dict of (p,) arrays
        ``marker`` (index into the layout's markers) and the covariate columns of
        :data:`pipeline.tables.fate_table.FATE_COLUMNS` (``distance_m`` ... ``expected_points``).
    """
    from visibility.scene import RayScene
    from visibility.visibility_matrix import AngularSampling, visibility_matrix

    origin = layout.station_position_m[station]
    centres = layout.marker_centres_m
    vis = visibility_matrix(RayScene(layout.dem), origin[None], centres,
                            layout.marker_radius_m, max_range_m,
                            sampling=AngularSampling(frames_per_turn=frames_per_turn),
                            progress=False)
    j = vis.site
    los = centres[j] - origin
    los /= np.linalg.norm(los, axis=1)[:, None]
    normal = terrain_normal(layout.dem, centres[j, :2])
    incidence = np.degrees(np.arccos(np.clip(np.abs((los * normal).sum(axis=1)), 0.0, 1.0)))
    slope = np.degrees(np.arccos(np.clip(normal[:, 2], 0.0, 1.0)))
    return {"marker": j, "distance_m": vis.distance_m,
            "elevation_deg": np.degrees(vis.elevation_rad), "incidence_deg": incidence,
            "slope_deg": slope, "rim_distance_m": rim_distance(layout.craters, centres[j, :2]),
            "visible_fraction": vis.visible_fraction, "expected_points": vis.expected_points}


@dataclass(frozen=True)
class LossJob:
    """One scan of the study: a station, a seed, the markers (indices into the layout's)."""

    station: int
    seed: int
    markers: np.ndarray
    profile: SensorProfile
    frames: tuple[int, ...] | None = None


@dataclass(frozen=True)
class ScanLosses:
    """What one scan of the study gave: a row per placed marker in range, and the accepted
    candidates that are no marker (rocks, terrain, fits that walked off)."""

    rows: list[dict]
    false_accepts: int


def station_losses(layout: LossLayout, job: LossJob) -> ScanLosses:
    """Scan one station of a layout, run the chain, and give each marker in range its fate.

    Parameters
    ----------
    layout : LossLayout
    job : LossJob
        The station, the simulation's seed (noise, sensor unit, turntable), the markers
        placed for this scan, the sensor profile, the frames (default all 800).

    Returns
    -------
    ScanLosses
        Its rows are keyed by :data:`pipeline.tables.fate_table.FATE_COLUMNS`.
    """
    from visibility.simulate import simulate_markers

    sensor = job.profile.sensor_config()
    placed = replace(layout, marker_ids=[layout.marker_ids[j] for j in job.markers],
                     marker_centres_m=layout.marker_centres_m[job.markers])
    cov = pair_covariates(placed, job.station, sensor.max_range_m)
    picked = cov["marker"]
    ids = [placed.marker_ids[j] for j in picked]
    sid = layout.station_ids[job.station]
    scan, truth = simulate_markers(layout.dem, layout.station_position_m[job.station],
                                   float(layout.station_heading_rad[job.station]),
                                   placed.marker_centres_m[picked], sensor,
                                   job.profile.rig_config(), seed=job.seed,
                                   marker_radius_m=layout.marker_radius_m, marker_ids=ids,
                                   station_id=sid, frames=job.frames, threads=1,
                                   sensor_profile=job.profile.name)
    cfg = processing_config(ProcessingSettings(marker_radius_m=layout.marker_radius_m))
    result = process_station(scan, cfg, seed=job.seed)
    fates = station_fates(result, truth, ids, cfg)
    rows = []
    for k, fate in enumerate(fates.rows):
        row = {"layout": layout.name, "seed": job.seed, "station_id": sid,
               "marker_id": fate.marker_id}
        row.update({c: float(cov[c][k]) for c in FATE_COLUMNS[4:11]})
        row.update(n_points=fate.n_points, stage=fate.stage, reason=fate.reason)
        rows.append(row)
    return ScanLosses(rows, fates.n_false_accepts)


def loss_jobs(layout: LossLayout, seeds: Sequence[int], groups: int = 1,
              profile: SensorProfile | None = None,
              frames: Sequence[int] | None = None) -> list[LossJob]:
    """Every station of ``layout`` for every seed; the markers split into ``groups``
    interleaved sets (marker ``j`` in set ``j % groups``), seed ``i`` scanning set
    ``i % groups``, so markers of one scan stand ``sqrt(groups)`` grid steps apart and hide
    one another less."""
    profile = profile or default_profile()
    frames = None if frames is None else tuple(int(f) for f in frames)
    index = np.arange(len(layout.marker_ids))
    return [LossJob(s, int(seed), index[index % groups == i % groups], profile, frames)
            for i, seed in enumerate(seeds) for s in range(len(layout.station_ids))]


def run_loss_study(layout: LossLayout, jobs: Sequence[LossJob], executor=None
                   ) -> list[ScanLosses]:
    """:func:`station_losses` for every job, on ``executor`` (a
    :class:`planner.distributed.Executor`; default: in this process, no progress bar), in job
    order wherever the jobs ran."""
    from planner.distributed import Executor

    executor = executor or Executor(progress=False)
    labels = [f"{layout.station_ids[j.station]} seed {j.seed}" for j in jobs]
    return executor.map(station_losses, jobs, shared=layout, labels=labels, desc="loss study")


def loss_table(rows: Sequence[dict], column: str, edges: Sequence[float]) -> list[dict]:
    """Detection and acceptance rates per bin of one covariate, losses per stage.

    Parameters
    ----------
    rows : sequence of dict
        Loss-study rows (:data:`pipeline.tables.fate_table.FATE_COLUMNS`).
    column : str
        The covariate binned.
    edges : sequence of float
        Bin edges, ascending; a row falls in ``[edges[i], edges[i + 1])``.

    Returns
    -------
    table : list of dict
        Per non-empty bin: ``lo``, ``hi``, ``n``, ``detected`` and ``accepted`` rates, and the
        count lost at each stage of :data:`pipeline.tables.fate_table.FATE_STAGES` but ``accepted``.

    Examples
    --------
    >>> rows = [{"d": 1.0, "stage": "gate"}, {"d": 1.5, "stage": "accepted"},
    ...         {"d": 3.0, "stage": "quality"}]
    >>> t = loss_table(rows, "d", [0, 2, 4])
    >>> [(r["n"], r["detected"], r["accepted"], r["gate"]) for r in t]
    [(2, 0.5, 0.5, 1), (1, 1.0, 0.0, 0)]
    """
    values = np.array([r[column] for r in rows], dtype=float)
    stages = np.array([r["stage"] for r in rows])
    table = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        inside = (values >= lo) & (values < hi)
        n = int(inside.sum())
        if not n:
            continue
        s = stages[inside]
        entry = {"lo": float(lo), "hi": float(hi), "n": n,
                 "detected": float(np.isin(s, DETECTED_STAGES).mean()),
                 "accepted": float((s == "accepted").mean())}
        entry.update({stage: int((s == stage).sum()) for stage in FATE_STAGES[:-1]})
        table.append(entry)
    return table
