"""Coverage achieved, checked independently of the prediction: the chosen stations scanned by
the simulator, processed by the chain, and their ground points counted per AOI cell.

Per station ``k`` (the same three steps as ``markerplan simulate`` then ``markerplan process
--cloud las``, without the files):

1. **simulate**: :func:`visibility.simulate.simulate_markers` casts the full turntable scan of
   the station on its DEM tile (the station +- the sensor's maximum range,
   :func:`planner.verify.known_control.station_tile`) with the site's marker spheres, with the
   sensor and turntable errors of a sensor profile (default the shipped ``calibrated``), seed
   ``seed + k`` (as ``verify`` seeds the plan's station ``k``);
2. **process**: :func:`pipeline.chain.process.process_station` self-calibrates the mounting
   offsets and detects the markers; :func:`pipeline.surveys.point_cloud_io.classify_cloud`
   synthesises the calibrated cloud and classifies it as ``process --cloud`` writes it. Only
   its **ground** points (class :data:`pipeline.surveys.point_cloud_io.GROUND_CLASS`, the chain's
   ground stage, :func:`pipeline.chain.ground.remove_ground`) are counted: marker inliers
   (0.20 m spheres), rocks and anything else standing above the local ground are left out;
3. **rasterise**: the ground points go into the site frame with the station's **true** pose
   (the simulator's truth, :meth:`pipeline.surveys.point_cloud_io.StationPose.from_truth`; the
   chain registers no station to the site, and the registration error, centimetres, is far
   below a cell; ``verify`` checks registration on its own) and are counted per cell
   (horizontal squares of side ``cell_m`` centred on ``cell_xy``).

A station **covers** a cell when it puts at least ``min_density_per_m2 * cell_m**2`` ground
points into it: the density is per m² of horizontal cell area (on ground sloping by ``s`` the
surface density is lower by ``cos s``: 1 % at 8 deg, 21 % on a 38 deg crater wall). With
``max_range_m`` and ``max_incidence_rad`` (the prediction's range and incidence limits,
:class:`planner.coverage.sight.CoverageSettings`) the station must also see the cell within
them, judged from its own points in the cell, not from the DEM: the range is the LiDAR centre's
distance to their centroid, the incidence the angle between that ray and the normal of the plane
fitted to them (least squares: the smallest principal axis of their scatter).
A marker's lowest returns (within the ground stage's 0.1 m of the local ground) count as
ground unless the chain accepted the marker (its fit inliers are marker points), as in the
chain's own classified cloud.

Densities are stated for a full turn of ``full_turn_frames`` frames (800, the rig's turn and
:class:`visibility.visibility_matrix.AngularSampling`'s). A scan of fewer ``frames_per_turn``
(tests) lays proportionally fewer lines over the same azimuths (the returns per steradian are
proportional to the frames, :meth:`~visibility.visibility_matrix.AngularSampling.density_per_sr`),
so its counts are scaled by ``full_turn_frames / frames_per_turn`` before the comparison: the
same as comparing the reduced scan against the reduced density. This holds while the lines of
the reduced scan stay finer than a cell (the turntable step of 100 frames, 3.6 deg, is 0.6 m at
10 m but 1.4 m at 22 m), and the counts' Poisson scatter grows by the same factor's square root.
On flat ground with 0.5 m cells the radius covered at 1000 points per m² is 10.54 m at 100
frames and 10.56 m at 800 (analytic 10.51 m); at 100 points per m², 22.4 m and 23.1 m
(analytic 22.7 m).

Cost (``default`` site, one 800-frame turn: 11.3 M returns; 2 cores shared with other work):
per station 3-8 s to simulate, 2-6 s to process and classify, 2-6 s to rasterise, 10-15 s in
all; 2.5-3 GB peak for its 7 stations (``benchmarks/coverage_check.py``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from markerplan.errors import ConfigError
from pipeline.chain.process import process_station
from pipeline.surveys.point_cloud_io import GROUND_CLASS, StationPose, classify_cloud
from pipeline.surveys.survey import ProcessingSettings, processing_config
from planner.verify.known_control import station_tile
from visibility.dem import DEM
from visibility.sensor import RigConfig
from visibility.sensor_profile import SensorProfile, default_profile
from visibility.simulate import simulate_markers
from visibility.sites import MARKER_RADIUS_M

#: Frames of the full turn densities are stated for (the rig's default turn).
FULL_TURN_FRAMES = RigConfig().frames_per_turn


@dataclass(frozen=True)
class AchievedCoverage:
    """What the scanned clouds of the stations put into the AOI cells.

    Attributes
    ----------
    stations_covering : (c,) int
        Number of stations whose ground points in the cell reach the minimum density.
    best_density_per_m2 : (c,) float
        The largest single-station ground-point density in the cell, points per m² of
        horizontal area, for a full turn (module docstring).
    station_density_per_m2 : scipy.sparse.csr_matrix, (s, c) float
        Each station's ground-point density in each cell (full turn; 0, not stored, where it puts
        no point or misses the range or incidence limit), for judging other minimum densities
        (:meth:`stations_covering_at`).
    station_ids : tuple of str
    n_points : (s,) int
        Returns in each station's scan.
    n_ground : (s,) int
        Of them, the ground points.
    n_in_cells : (s,) int
        Of those, the ones that fall into an AOI cell.
    timings_s : list of dict
        Per station: ``simulate``, ``process`` (chain and classification) and ``rasterise``,
        seconds.
    config : dict
        What produced it: sensor profile, frames, full-turn frames, seed, minimum density,
        cell size, range and incidence limits, markers, ground class and pose source.
    """

    stations_covering: np.ndarray
    best_density_per_m2: np.ndarray
    station_density_per_m2: sparse.csr_matrix
    station_ids: tuple[str, ...]
    n_points: np.ndarray
    n_ground: np.ndarray
    n_in_cells: np.ndarray
    timings_s: list[dict[str, float]] = field(default_factory=list)
    config: dict[str, Any] = field(default_factory=dict)

    def stations_covering_at(self, min_density_per_m2: float) -> np.ndarray:
        """(c,) int: stations reaching ``min_density_per_m2`` (points per m², full turn) in
        each cell, from the same scans."""
        _positive_density_iv(min_density_per_m2)
        reached = self.station_density_per_m2 >= min_density_per_m2
        return np.asarray(reached.sum(axis=0), dtype=np.int64).reshape(-1)

    def covered(self, min_stations: int = 1) -> np.ndarray:
        """(c,) bool: the cells covered by at least ``min_stations`` stations."""
        return self.stations_covering >= min_stations

    def summary(self) -> dict[str, Any]:
        """Covered fractions, per-station counts and mean times, and the configuration (a dict
        for a report; the timings are the only part that changes between identical runs)."""
        n = len(self.stations_covering)
        time_per_station = {step: float(np.mean([t[step] for t in self.timings_s]))
                            for step in ("simulate", "process", "rasterise")} if n else {}
        return {"n_cells": n,
                "covered_fraction": float(self.covered(1).mean()) if n else 0.0,
                "covered_by_two_fraction": float(self.covered(2).mean()) if n else 0.0,
                "n_covered": int(self.covered(1).sum()), "n_covered_by_two":
                int(self.covered(2).sum()),
                "stations": [{"id": sid, "n_points": int(p), "n_ground": int(g),
                              "n_in_cells": int(c)}
                             for sid, p, g, c in zip(self.station_ids, self.n_points,
                                                     self.n_ground, self.n_in_cells,
                                                     strict=True)],
                "mean_time_per_station_s": time_per_station, "config": self.config}


def achieved_coverage(dem: DEM, station_position_m: np.ndarray, station_heading_rad: np.ndarray,
                      cell_xy: np.ndarray, cell_m: float, min_density_per_m2: float,
                      seed: int = 0, *, marker_xyz_m: np.ndarray | None = None,
                      marker_radius_m: float = MARKER_RADIUS_M,
                      frames_per_turn: int | None = None,
                      full_turn_frames: int = FULL_TURN_FRAMES,
                      max_range_m: float | None = None, max_incidence_rad: float | None = None,
                      profile: SensorProfile | None = None,
                      station_ids: Sequence[str] | None = None, threads: int | None = None,
                      progress: Callable[[int], None] | None = None) -> AchievedCoverage:
    """Scan, process and rasterise every station over the AOI cells (module docstring).

    Parameters
    ----------
    dem : DEM
        The terrain scanned (the truth terrain), site frame.
    station_position_m : (s, 3) float
        LiDAR centres, site frame, metres.
    station_heading_rad : (s,) float
        Station headings, radians.
    cell_xy : (c, 2) float
        AOI cell centres on a regular grid of step ``cell_m``, site frame, metres.
    cell_m : float
        Cell side, metres.
    min_density_per_m2 : float
        Ground points per m² (horizontal, full turn) a station must reach to cover a cell.
    seed : int
        Station ``k`` is simulated with seed ``seed + k``.
    marker_xyz_m : (m, 3) float, optional
        Marker centres in the scene (default none), site frame, metres.
    marker_radius_m : float
        Their radius (and the chain's), metres.
    frames_per_turn : int, optional
        Frames simulated per station (default ``full_turn_frames``); fewer for tests.
    full_turn_frames : int
        Frames of the full turn the densities are stated for.
    max_range_m : float, optional
        A station covers only cells whose points' centroid lies within this range of its LiDAR
        centre, metres (default: no limit but the sensor's).
    max_incidence_rad : float, optional
        ... and whose fitted plane it sees at an incidence of at most this, radians (default:
        no limit).
    profile : SensorProfile, optional
        Sensor and turntable errors (default the shipped ``calibrated`` profile), 600 rpm.
    station_ids : sequence of str, optional
        Default ``S1``, ``S2``, ...
    threads : int, optional
        Ray-casting threads (default all cores).
    progress : callable, optional
        Called with the number of frames just simulated.

    Returns
    -------
    AchievedCoverage

    Raises
    ------
    ConfigError
        Arrays of the wrong shape, cells off a regular grid of ``cell_m``, a non-positive
        density, cell, range or incidence limit, or too many frames.
    """
    position, heading, cells, ids, frames = _achieved_iv(
        station_position_m, station_heading_rad, cell_xy, cell_m, min_density_per_m2,
        frames_per_turn, full_turn_frames, max_range_m, max_incidence_rad, station_ids)
    profile = profile or default_profile()
    sensor = profile.sensor_config()
    rig = profile.rig_config(frames_per_turn=frames)
    markers = (np.zeros((0, 3)) if marker_xyz_m is None
               else np.asarray(marker_xyz_m, dtype=float).reshape(-1, 3))
    cfg = processing_config(ProcessingSettings(marker_radius_m=marker_radius_m))
    grid = _CellGrid(cells, float(cell_m))
    scale = full_turn_frames / frames
    n_points, n_ground, n_in, timings, density = [], [], [], [], []
    for k, sid in enumerate(ids):
        t0 = time.perf_counter()
        tile = station_tile(dem, position[k], sensor.max_range_m)
        scan, truth = simulate_markers(tile, position[k], float(heading[k]), markers, sensor,
                                       rig, seed=seed + k, marker_radius_m=marker_radius_m,
                                       station_id=sid, progress=progress, threads=threads,
                                       sensor_profile=profile.name)
        t1 = time.perf_counter()
        cloud = classify_cloud(scan, process_station(scan, cfg, seed=seed + k), cfg.ground)
        t2 = time.perf_counter()
        ground = np.flatnonzero(cloud.classification == GROUND_CLASS)
        xyz = StationPose.from_truth(truth).to_site(np.take(cloud.xyz_m, ground, axis=0))
        counts, seen = grid.counts(xyz, position[k], max_range_m, max_incidence_rad)
        density.append(sparse.csr_matrix(np.where(seen, counts * (scale / cell_m ** 2), 0.0)))
        n_points.append(scan.n_points)
        n_ground.append(len(ground))
        n_in.append(int(counts.sum()))
        timings.append({"simulate": t1 - t0, "process": t2 - t1,
                        "rasterise": time.perf_counter() - t2})
    config = {"sensor_profile": profile.name, "rpm": sensor.rpm, "frames_per_turn": frames,
              "full_turn_frames": int(full_turn_frames), "seed": int(seed),
              "station_seeds": "seed + k", "min_density_per_m2": float(min_density_per_m2),
              "cell_m": float(cell_m), "max_range_m": max_range_m,
              "max_incidence_rad": max_incidence_rad,
              "n_markers": len(markers), "marker_radius_m": float(marker_radius_m),
              "points": "ground class of pipeline.surveys.point_cloud_io.classify_cloud",
              "pose": "simulator truth", "density_area": "horizontal cell area"}
    per_station = sparse.vstack(density, format="csr")
    best = np.asarray(per_station.max(axis=0).todense()).reshape(-1)
    covering = np.asarray((per_station >= min_density_per_m2).sum(axis=0),
                          dtype=np.int64).reshape(-1)
    return AchievedCoverage(covering, best, per_station, tuple(ids),
                            np.array(n_points, dtype=np.int64),
                            np.array(n_ground, dtype=np.int64), np.array(n_in, dtype=np.int64),
                            timings, config)


class _CellGrid:
    """Cells on a regular grid: the cell (index into ``cell_xy``) each point falls into."""

    def __init__(self, cell_xy: np.ndarray, cell_m: float) -> None:
        self.origin = cell_xy.min(axis=0) - cell_m / 2
        self.cell_m = cell_m
        ij = np.rint((cell_xy - self.origin) / cell_m - 0.5).astype(np.int64)
        self.lookup = np.full(ij.max(axis=0) + 1, -1, dtype=np.int64)
        self.lookup[ij[:, 0], ij[:, 1]] = np.arange(len(cell_xy))
        self.n = len(cell_xy)

    def counts(self, xyz: np.ndarray, lidar_m: np.ndarray, max_range_m: float | None,
               max_incidence_rad: float | None) -> tuple[np.ndarray, np.ndarray]:
        """Points per cell, and the cells the LiDAR sees within the limits.

        Parameters
        ----------
        xyz : (N, 3) float
            One station's ground points, site frame, metres.
        lidar_m : (3,) float
            Its LiDAR centre, site frame, metres.
        max_range_m, max_incidence_rad : float or None
            As :func:`achieved_coverage` (None: no limit).

        Returns
        -------
        counts : (c,) float
        seen : (c,) bool
            Cells holding points whose centroid (and fitted plane) meet the limits.
        """
        nx, ny = self.lookup.shape
        i = np.floor((xyz[:, 0] - self.origin[0]) / self.cell_m).astype(np.int64)
        j = np.floor((xyz[:, 1] - self.origin[1]) / self.cell_m).astype(np.int64)
        inside = np.flatnonzero((i >= 0) & (i < nx) & (j >= 0) & (j < ny))
        cell = self.lookup.ravel()[i[inside] * ny + j[inside]]
        mine = cell >= 0
        cell, rows = cell[mine], inside[mine]
        counts = np.bincount(cell, minlength=self.n).astype(float)
        seen = counts > 0
        if max_range_m is None and max_incidence_rad is None:
            return counts, seen
        p = np.take(xyz, rows, axis=0) - lidar_m
        centroid = np.column_stack([np.bincount(cell, p[:, a], self.n) for a in range(3)])
        centroid /= np.maximum(counts, 1.0)[:, None]
        distance = np.linalg.norm(centroid, axis=1)
        if max_range_m is not None:
            seen &= distance <= max_range_m
        if max_incidence_rad is not None:
            d = p - centroid[cell]  # two passes: the scatter about the centroid
            scatter = np.empty((self.n, 3, 3))
            for a in range(3):
                for b in range(a, 3):
                    scatter[:, a, b] = scatter[:, b, a] = np.bincount(cell, d[:, a] * d[:, b],
                                                                      self.n)
            normal = np.linalg.eigh(scatter)[1][:, :, 0]  # the smallest principal axis
            cos_i = np.abs(np.einsum("ij,ij->i", normal, centroid)) / np.maximum(distance,
                                                                               1e-12)
            seen &= (counts >= 3) & (cos_i >= np.cos(max_incidence_rad))
        return counts, seen


def _achieved_iv(station_position_m, station_heading_rad, cell_xy, cell_m, min_density_per_m2,
                 frames_per_turn, full_turn_frames, max_range_m, max_incidence_rad,
                 station_ids):
    position = np.asarray(station_position_m, dtype=float)
    if (position.ndim != 2 or position.shape[1] != 3 or len(position) == 0
            or not np.all(np.isfinite(position))):
        raise ConfigError(f"`station_position_m` must be finite with shape (s, 3), s >= 1, got "
                          f"shape {position.shape}")
    heading = np.asarray(station_heading_rad, dtype=float).reshape(-1)
    if heading.shape != (len(position),):
        raise ConfigError(f"`station_heading_rad` must have one heading per station "
                          f"({len(position)}), got {heading.shape[0]}")
    cells = np.asarray(cell_xy, dtype=float)
    if cells.ndim != 2 or cells.shape[1] != 2 or len(cells) == 0:
        raise ConfigError(f"`cell_xy` must have shape (c, 2) with c >= 1, got {cells.shape}")
    if not (np.isfinite(cell_m) and cell_m > 0):
        raise ConfigError(f"`cell_m` must be > 0 metres, got {cell_m}")
    steps = (cells - cells.min(axis=0)) / cell_m
    if np.abs(steps - np.rint(steps)).max() > 1e-6:
        raise ConfigError(f"`cell_xy` must lie on a regular grid of step `cell_m` ({cell_m} "
                          "m); give the AOI's cell centres")
    if len(np.unique(np.rint(steps), axis=0)) != len(cells):
        raise ConfigError("`cell_xy` lists a cell twice; give each AOI cell once")
    _positive_density_iv(min_density_per_m2)
    frames = int(full_turn_frames if frames_per_turn is None else frames_per_turn)
    if not 1 <= frames <= full_turn_frames:
        raise ConfigError(f"`frames_per_turn` must be in [1, `full_turn_frames` = "
                          f"{full_turn_frames}], got {frames}")
    if max_range_m is not None and not max_range_m > 0:
        raise ConfigError(f"`max_range_m` must be > 0 metres, got {max_range_m}")
    if max_incidence_rad is not None and not 0 < max_incidence_rad <= np.pi / 2:
        raise ConfigError(f"`max_incidence_rad` must be in (0, pi/2] radians, got "
                          f"{max_incidence_rad}")
    ids = ([f"S{k + 1}" for k in range(len(position))] if station_ids is None
           else [str(s) for s in station_ids])
    if len(ids) != len(position):
        raise ConfigError(f"`station_ids` has {len(ids)} ids for {len(position)} stations")
    return position, heading, cells, ids, frames


def _positive_density_iv(min_density_per_m2: float) -> None:
    if not (np.isfinite(min_density_per_m2) and min_density_per_m2 > 0):
        raise ConfigError(f"`min_density_per_m2` must be > 0, got {min_density_per_m2}")


@dataclass(frozen=True)
class CoverageAgreement:
    """Predicted against achieved coverage, cell by cell.

    Attributes
    ----------
    min_stations : int
        A cell is covered when at least this many stations cover it.
    both, predicted_only, achieved_only, neither : int
        Confusion counts (covered by prediction and achieved, by the prediction only, ...).
    predicted_only_cells, achieved_only_cells : (k,) int
        Indices of the disagreeing cells.
    predicted_only_distance_m, achieved_only_distance_m : float or None
        Mean horizontal distance of those cells to the nearest station, metres (None without
        positions or without such cells).
    """

    min_stations: int
    both: int
    predicted_only: int
    achieved_only: int
    neither: int
    predicted_only_cells: np.ndarray
    achieved_only_cells: np.ndarray
    predicted_only_distance_m: float | None = None
    achieved_only_distance_m: float | None = None

    @property
    def n_cells(self) -> int:
        return self.both + self.predicted_only + self.achieved_only + self.neither

    @property
    def agreement_fraction(self) -> float:
        """Share of the cells on which prediction and achievement agree."""
        return (self.both + self.neither) / self.n_cells

    def to_dict(self) -> dict[str, Any]:
        """The figures for a report (cell indices left out)."""
        n = self.n_cells
        return {"min_stations": self.min_stations, "n_cells": n, "both": self.both,
                "predicted_only": self.predicted_only, "achieved_only": self.achieved_only,
                "neither": self.neither, "agreement_fraction": self.agreement_fraction,
                "predicted_covered_fraction": (self.both + self.predicted_only) / n,
                "achieved_covered_fraction": (self.both + self.achieved_only) / n,
                "n_disagree": self.predicted_only + self.achieved_only,
                "predicted_only_mean_distance_m": self.predicted_only_distance_m,
                "achieved_only_mean_distance_m": self.achieved_only_distance_m}


def compare_coverage(predicted_count: np.ndarray, achieved_count: np.ndarray,
                     min_stations: int = 1, cell_xy: np.ndarray | None = None,
                     station_xy_m: np.ndarray | None = None) -> CoverageAgreement:
    """Compare the predicted and the achieved number of stations covering each cell.

    Parameters
    ----------
    predicted_count, achieved_count : (c,) int
        Stations covering each cell, predicted and achieved
        (:attr:`AchievedCoverage.stations_covering`).
    min_stations : int
        Covered means at least this many stations (1, or 2 for a two-station requirement).
    cell_xy : (c, 2) float, optional
        Cell centres, site frame, metres.
    station_xy_m : (s, 2) float, optional
        Station positions (x, y; further columns ignored), site frame, metres; with
        ``cell_xy``, the disagreeing cells' mean distance to their nearest station is given.

    Returns
    -------
    CoverageAgreement

    Examples
    --------
    >>> a = compare_coverage([2, 1, 0, 0], [2, 0, 1, 0], cell_xy=[[0, 0], [1, 0], [3, 0],
    ...                      [4, 0]], station_xy_m=[[0, 0]])
    >>> a.both, a.predicted_only, a.achieved_only, a.neither, a.agreement_fraction
    (1, 1, 1, 1, 0.5)
    >>> a.predicted_only_distance_m, a.achieved_only_distance_m
    (1.0, 3.0)
    """
    predicted = np.asarray(predicted_count).reshape(-1)
    achieved = np.asarray(achieved_count).reshape(-1)
    if predicted.shape != achieved.shape or predicted.size == 0:
        raise ConfigError(f"`predicted_count` and `achieved_count` must have one count per "
                          f"cell each, got {predicted.size} and {achieved.size}")
    if int(min_stations) < 1:
        raise ConfigError(f"`min_stations` must be >= 1, got {min_stations}")
    p, a = predicted >= min_stations, achieved >= min_stations
    p_only, a_only = np.flatnonzero(p & ~a), np.flatnonzero(a & ~p)
    distance = [None, None]
    if cell_xy is not None and station_xy_m is not None:
        cells = np.asarray(cell_xy, dtype=float).reshape(-1, 2)
        if len(cells) != predicted.size:
            raise ConfigError(f"`cell_xy` must have one row per cell ({predicted.size}), got "
                              f"{len(cells)}")
        stations = np.asarray(station_xy_m, dtype=float)
        nearest = cKDTree(stations.reshape(len(stations), -1)[:, :2]).query(cells)[0]
        distance = [float(nearest[idx].mean()) if idx.size else None for idx in (p_only, a_only)]
    return CoverageAgreement(int(min_stations), int((p & a).sum()), len(p_only), len(a_only),
                             int((~p & ~a).sum()), p_only, a_only, *distance)
