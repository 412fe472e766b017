"""The published range experiment, simulated: 0.20 m markers from 1 m to 50 m around one station
on level ground, scanned with the turntable rig and fitted with every estimator.

The simulator (:func:`visibility.simulate.simulate_markers`) scans the markers laid out by
:func:`pipeline.range_study.marker_layout` once per replicate (replicate ``r`` with seed
``seed + r``); :func:`pipeline.range_study.measure_markers` fits each marker and
:func:`pipeline.range_study.summarise` aggregates the marker tables. :func:`write_range_study`
writes the files of ``markerplan range-study``.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplan.provenance import provenance
from markerplan.writing import write_csv
from pipeline.marker_table import MarkerRow, write_marker_table
from pipeline.range_study import (
    RANGE_STUDY_DISTANCES_M,
    SUMMARY_COLUMNS,
    marker_layout,
    measure_markers,
    plot,
    summarise,
)
from pipeline.stages import RADIUS_SCALED
from visibility.dem import DEM
from visibility.sensor import RigConfig, SensorConfig
from visibility.simulate import simulate_markers

#: DEM cell of the level ground, m.
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
    """:func:`pipeline.range_study.summarise` of ``rows``."""
    config: dict
    """Everything the result depends on (recorded in ``summary.json``)."""


def run_range_study(max_distance_m: float = 50.0, frames: int = 800, replicates: int = 3,
                    seed: int = 0, sensor: SensorConfig | None = None,
                    marker_radius_m: float = 0.1,
                    progress: Callable[[int], object] | None = None) -> RangeStudy:
    """Simulate and measure the range experiment.

    Parameters
    ----------
    max_distance_m : float
        Leave out the published distances beyond this, m.
    frames : int
        Frames per turntable revolution.
    replicates : int
        Scans of the same layout; replicate ``r`` uses noise seed ``seed + r``.
    seed : int
        Noise seed of the first replicate.
    sensor : SensorConfig, optional
        Default: :class:`~visibility.sensor.SensorConfig` ().
    marker_radius_m : float
        Marker radius, m.
    progress : callable, optional
        Called with 1 after each replicate.

    Returns
    -------
    study : RangeStudy
    """
    sensor = sensor or SensorConfig()
    distances = RANGE_STUDY_DISTANCES_M[RANGE_STUDY_DISTANCES_M <= max_distance_m]
    rig = RigConfig(frames_per_turn=frames)
    centres = marker_layout(distances, marker_radius_m, rig.lidar_height_m)
    ids = [f"R{d:04.1f}" for d in distances]
    half = float(distances.max()) + GROUND_MARGIN_M
    dem = DEM(np.zeros((int(2 * half / GROUND_CELL_M) + 1,) * 2), (-half, -half), GROUND_CELL_M)
    station = [0.0, 0.0, rig.lidar_height_m]
    research_radius_m = RADIUS_SCALED[("research", "radius_m")] * marker_radius_m
    rows = []
    for rep in range(replicates):
        scan, _ = simulate_markers(dem, station, 0.0, centres + station, sensor, rig,
                                   seed=seed + rep, marker_radius_m=marker_radius_m,
                                   marker_ids=ids, station_id="RANGE")
        rows += measure_markers(scan, centres, ids, radius_m=marker_radius_m,
                                research_radius_m=research_radius_m, replicate=rep,
                                seed=seed + rep, noise=sensor.range_noise())
        del scan
        if progress is not None:
            progress(1)
    config = {"distances_m": distances.tolist(), "frames": frames, "replicates": replicates,
              "seed": seed, "sensor": {"rpm": sensor.rpm, "range_noise_m": sensor.range_noise_m},
              "terrain": "level ground", "marker_radius_m": marker_radius_m}
    distance_of = dict(zip(ids, distances.tolist(), strict=True))
    return RangeStudy(distance_of, rows, summarise(rows, distance_of), config)


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
    record = {"summary": study.summary,
              "files": ["markers.csv", "summary.csv", "range_study.png", "summary.json"],
              "provenance": provenance(study.config, command="range-study")}
    (folder / "summary.json").write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    return record
