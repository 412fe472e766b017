"""The published range experiment, simulated: 0.20 m markers from 1 m to 50 m around one station
on level ground, scanned with the turntable rig and fitted with every estimator; and its relief
variants, the same markers resting on a planar slope with the LiDAR 0.8-1.5 m up.

The simulator (:func:`visibility.simulate.simulate_markers`) scans the markers laid out by
:func:`pipeline.surveys.range_study.marker_layout` once per replicate (replicate ``r`` with seed
``seed + r``); the station chain of ``process`` and ``verify`` extracts and fits the markers
(:func:`pipeline.surveys.range_study.chain_markers`; the ``truth-seeded`` diagnostic,
:func:`pipeline.surveys.range_study.measure_markers`, re-searches each at its true position instead)
and :func:`pipeline.surveys.range_study.summarise` aggregates the marker tables.
:func:`write_range_study` writes the files of ``markerplan range-study``.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from markerplan.errors import ConfigError
from markerplan.provenance import provenance
from markerplan.writing import write_csv
from pipeline.chain.stages import RADIUS_SCALED
from pipeline.surveys.range_study import (
    EXTRACTIONS,
    RANGE_STUDY_DISTANCES_M,
    SUMMARY_COLUMNS,
    chain_markers,
    marker_layout,
    measure_markers,
    plot,
    summarise,
    unmatched_counts,
)
from pipeline.tables.marker_table import MarkerRow, write_marker_table
from visibility.dem import DEM
from visibility.sensor_profile import SensorProfile, default_profile
from visibility.simulate import simulate_markers

#: DEM cell of the ground, m (the ground is a plane, so the cell size changes nothing).
GROUND_CELL_M = 0.5
#: Ground beyond the farthest marker, m.
GROUND_MARGIN_M = 5.0


@dataclass(frozen=True)
class RangeStudy:
    """A simulated range study: its marker tables, their summary and its configuration."""

    distance_of: dict[str, float]
    """Marker id -> horizontal LiDAR-to-marker distance, m (in layout order)."""
    rows: list[MarkerRow]
    """Every marker of every replicate, with each estimator."""
    summary: list[dict]
    """:func:`pipeline.surveys.range_study.summarise` of ``rows``."""
    config: dict
    """Everything the result depends on (recorded in ``summary.json``)."""


def run_range_study(max_distance_m: float = 50.0, frames: int = 800, replicates: int = 3,
                    seed: int = 0, profile: SensorProfile | None = None,
                    marker_radius_m: float = 0.1,
                    progress: Callable[[int], object] | None = None, *, rpm: int = 600,
                    range_noise_m: float | None = None, lidar_height_m: float = 1.0,
                    slope_deg: float = 0.0,
                    map_tasks: Callable[[Callable, Iterable], Iterable] | None = None,
                    extraction: str = "full-chain") -> RangeStudy:
    """Simulate and measure the range experiment, on level ground or on a slope.

    Parameters
    ----------
    max_distance_m : float
        Leave out the published distances beyond this, m.
    frames : int
        Frames per turntable revolution.
    replicates : int
        Scans of the same layout; replicate ``r`` uses noise seed ``seed + r`` and sensor unit
        ``seed + r`` (its per-channel offsets, :meth:`SensorConfig.laser_biases`).
    seed : int
        Noise seed of the first replicate.
    profile : SensorProfile, optional
        The sensor's and turntable's errors (default: the ``calibrated`` profile).
    marker_radius_m : float
        Marker radius, m.
    progress : callable, optional
        Called with 1 as each replicate's result arrives (e.g. a tqdm bar's ``update``).
    rpm : int
        VLP-16 spin rate.
    range_noise_m : float, optional
        1-sigma range noise, m, instead of the profile's.
    lidar_height_m : float
        LiDAR centre above the ground at the station, m (the rig stands 0.8-1.5 m).
    slope_deg : float
        Ground slope, degrees, in (-45, 45): the ground is a plane through the station's foot
        rising towards the station frame's +x; markers rest on it (see
        :func:`pipeline.surveys.range_study.marker_layout`). 0 is the published level ground.
    map_tasks : callable, optional
        ``map_tasks(fn, items)`` -> iterable of ``fn(item)`` in the items' order, running the
        replicates (one task each, e.g. a :class:`planner.distributed.Executor`); default the
        built-in ``map`` (one after another in this process).
    extraction : str
        ``full-chain`` (the station chain of ``process`` and ``verify``, once per estimator)
        or ``truth-seeded`` (the diagnostic re-search at each marker's true position), see
        :mod:`pipeline.surveys.range_study`; recorded in ``config``.

    Returns
    -------
    study : RangeStudy

    Raises
    ------
    ConfigError
        An ``extraction`` not in :data:`pipeline.surveys.range_study.EXTRACTIONS`.
    """
    if extraction not in EXTRACTIONS:
        raise ConfigError(f"`extraction` must be one of {EXTRACTIONS}, got {extraction!r}")
    profile = profile or default_profile()
    sensor = profile.sensor_config(rpm, range_noise_m=range_noise_m)
    distances = RANGE_STUDY_DISTANCES_M[RANGE_STUDY_DISTANCES_M <= max_distance_m]
    rig = profile.rig_config(frames_per_turn=frames, lidar_height_m=lidar_height_m)
    slope_rad = float(np.radians(slope_deg))
    centres = marker_layout(distances, marker_radius_m, lidar_height_m, slope_rad)
    ids = [f"R{d:04.1f}" for d in distances]
    dem = ground_dem(float(distances.max()), slope_rad)
    station = [0.0, 0.0, lidar_height_m]
    research_radius_m = RADIUS_SCALED[("research", "radius_m")] * marker_radius_m
    task = functools.partial(replicate_rows, dem, station, centres, ids, sensor, rig, seed,
                             marker_radius_m, research_radius_m, extraction)
    rows = []
    for reps in (map_tasks or map)(task, range(replicates)):
        rows += reps
        if progress is not None:
            progress(1)
    config = {"distances_m": distances.tolist(), "frames": frames, "replicates": replicates,
              "seed": seed, "sensor_profile": profile.name, "sensor": asdict(sensor),
              "turntable": asdict(profile.turntable),
              "terrain": {"lidar_height_m": lidar_height_m, "slope_deg": slope_deg,
                          "ground": "plane through the station's foot rising towards +x"},
              "marker_radius_m": marker_radius_m, "extraction": extraction}
    distance_of = dict(zip(ids, distances.tolist(), strict=True))
    return RangeStudy(distance_of, rows, summarise(rows, distance_of), config)


def replicate_rows(dem: DEM, station: list[float], centres: np.ndarray, ids: list[str], sensor,
                   rig, seed: int, marker_radius_m: float, research_radius_m: float,
                   extraction: str, rep: int) -> list[MarkerRow]:
    """One replicate of the range experiment (a task of :func:`run_range_study`): simulate a
    scan with sensor unit and noise seed ``seed + rep`` and measure every marker in it.

    Parameters
    ----------
    dem : DEM
        The ground (:func:`ground_dem`).
    station : (3,) float
        LiDAR centre, site frame, m.
    centres : (m, 3) float
        Marker centres relative to the station (as :func:`marker_layout` gives them), m.
    ids : list of str
    sensor : SensorConfig
    rig : RigConfig
    seed : int
        Seed of the first replicate.
    marker_radius_m, research_radius_m : float
        Marker radius and the re-search radius of the ``truth-seeded`` extraction, m.
    extraction : str
        ``full-chain`` or ``truth-seeded`` (:func:`run_range_study`).
    rep : int
        Replicate index.

    Returns
    -------
    rows : list of MarkerRow
    """
    unit = replace(sensor, unit_seed=seed + rep)  # each replicate another sensor unit
    scan, truth = simulate_markers(dem, station, 0.0, centres + station, unit, rig,
                                   seed=seed + rep, marker_radius_m=marker_radius_m,
                                   marker_ids=ids, station_id="RANGE")
    if extraction == "full-chain":
        return chain_markers(scan, truth, marker_radius_m, replicate=rep, seed=seed + rep,
                             noise=sensor.expected_scatter())
    return measure_markers(scan, centres, ids, radius_m=marker_radius_m,
                           research_radius_m=research_radius_m, replicate=rep, seed=seed + rep,
                           noise=sensor.expected_scatter())


def ground_dem(max_distance_m: float, slope_rad: float = 0.0) -> DEM:
    """The planar ground ``z = x tan(slope_rad)`` (site frame) around a station at the origin.

    Parameters
    ----------
    max_distance_m : float
        Farthest marker, metres; the ground reaches :data:`GROUND_MARGIN_M` beyond it in x and y.
    slope_rad : float
        Ground slope, radians (0: level ground of height 0).

    Returns
    -------
    dem : DEM
        :data:`GROUND_CELL_M` cells.
    """
    half_m = max_distance_m + GROUND_MARGIN_M
    n = int(2 * half_m / GROUND_CELL_M) + 1
    x = -half_m + GROUND_CELL_M * np.arange(n)
    heights = np.tile(x * np.tan(slope_rad), (n, 1)) + 0.0  # + 0.0: level ground has no -0.0
    return DEM(heights, (-half_m, -half_m), GROUND_CELL_M)


def write_range_study(study: RangeStudy, folder: Path) -> dict:
    """Write ``markers.csv``, ``summary.csv``, ``range_study.png`` and ``summary.json``.

    Returns
    -------
    record : dict
        The content of ``summary.json``.
    """
    folder = Path(folder)
    write_marker_table(folder / "markers.csv", study.rows)
    write_csv(folder / "summary.csv", SUMMARY_COLUMNS, study.summary)
    plot(study.summary, study.rows, study.distance_of, folder / "range_study.png",
         study.config["marker_radius_m"])
    record = {"extraction": study.config["extraction"], "summary": study.summary,
              "unmatched_candidates": unmatched_counts(study.rows, study.distance_of),
              "files": ["markers.csv", "summary.csv", "range_study.png", "summary.json"],
              "provenance": provenance(study.config, command="range-study")}
    (folder / "summary.json").write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    return record
