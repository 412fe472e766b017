"""What a field experiment measured, per LiDAR position: the statistic a sensor profile is
calibrated against (:mod:`planner.studies.sensor_calibration`).

A position is its LiDAR-to-marker distances and the mean absolute edge-length residual over all
marker pairs (LiDAR cloud against the reference), the figure the published experiment reports.
Two sources:

- a **summary CSV** with columns ``position`` (a name), ``distances_m`` (the distances,
  separated by spaces, metres) and ``mean_abs_edge_residual_m`` (metres); the published
  experiment's is shipped as ``planner/studies/data/field_experiment_residuals.csv``;
- a **marker table** written by ``markerplan process`` of real scans, with the reference CSV
  (``id,x_m,y_m,z_m``) it was evaluated against: accepted markers matched to a reference id
  give the distances, and their edges the residual (:func:`positions_from_marker_table`).

Limits (refused with one line): at least :data:`MIN_MARKERS` markers per position (the
statistic needs several edges and the chain's registration three markers); distances within
[:data:`MIN_DISTANCE_M`, :data:`MAX_DISTANCE_M`] (the simulated field must be able to hold
them and the chain's ground stage keeps returns to 60 m); a residual > 0 and below
:data:`MAX_RESIDUAL_M`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplan.errors import DataError, InputFileError
from markerplan.reading import finite_number, read_csv, unique_ids
from pipeline.chain.evaluation import edge_residuals, read_reference
from pipeline.tables.marker_table import read_marker_table

SUMMARY_COLUMNS = ("position", "distances_m", "mean_abs_edge_residual_m")
#: Shipped summary of the published field experiment (three positions, 11 markers each).
FIELD_EXPERIMENT_CSV = Path(__file__).resolve().parent / "data" / \
    "field_experiment_residuals.csv"
MIN_MARKERS = 4
MIN_DISTANCE_M = 1.0
MAX_DISTANCE_M = 50.0
MAX_RESIDUAL_M = 1.0


@dataclass(frozen=True)
class FieldPosition:
    """One LiDAR position of a field experiment.

    Attributes
    ----------
    name : str
    distances_m : (n,) float
        LiDAR-to-marker distances, metres.
    mean_abs_edge_residual_m : float
        Measured mean |edge-length residual| over the position's marker pairs, metres.
    """

    name: str
    distances_m: np.ndarray
    mean_abs_edge_residual_m: float


def read_field_summary(path: str | Path) -> list[FieldPosition]:
    """Read a summary CSV (see the module docstring).

    Raises
    ------
    InputFileError
        Missing/unreadable file or columns, a cell that is not a number, repeated positions.
    DataError
        Too few markers, distances out of range, a residual <= 0 or absurd, no rows.
    """
    path = Path(path)
    what = f"field summary {path}"
    header, rows = read_csv(path, what, SUMMARY_COLUMNS,
                            "expected position,distances_m,mean_abs_edge_residual_m")
    if not rows:
        raise DataError(f"{what} has no positions; add one row per LiDAR position")
    col = {c: header.index(c) for c in SUMMARY_COLUMNS}
    names = unique_ids([r[col["position"]].strip() for r in rows], f"{what}: positions")
    out = []
    for name, row in zip(names, rows, strict=True):
        cells = row[col["distances_m"]].replace(";", " ").split()
        distances = np.array([finite_number(c, f"{what}: a distance of position {name!r}")
                              for c in cells])
        residual = finite_number(row[col["mean_abs_edge_residual_m"]].strip(),
                                 f"{what}: mean_abs_edge_residual_m of position {name!r}")
        out.append(checked_position(FieldPosition(name, distances, residual), what))
    return out


def checked_position(position: FieldPosition, what: str) -> FieldPosition:
    """Refuse a position the calibration cannot use (see the module docstring's limits)."""
    d = position.distances_m
    label = f"{what}: position {position.name!r}"
    if d.size < MIN_MARKERS:
        raise DataError(f"{label} has {d.size} marker distance(s); calibration needs at least "
                        f"{MIN_MARKERS} markers per position")
    bad = d[(d < MIN_DISTANCE_M) | (d > MAX_DISTANCE_M)]
    if bad.size:
        raise DataError(f"{label} has a distance of {bad[0]:g} m; distances must be within "
                        f"{MIN_DISTANCE_M:g}-{MAX_DISTANCE_M:g} m of the LiDAR")
    r = position.mean_abs_edge_residual_m
    if not 0 < r < MAX_RESIDUAL_M:
        raise DataError(f"{label} has a mean |edge residual| of {r:g} m; it must be > 0 and "
                        f"< {MAX_RESIDUAL_M:g} m (metres, not millimetres)")
    return position


def positions_from_marker_table(table_path: str | Path, reference_path: str | Path
                                ) -> list[FieldPosition]:
    """Positions from a real marker table and the reference it was evaluated against.

    Each station of the table is one position: its accepted markers whose ``marker_id`` is in
    the reference give the distances (``distance_m``) and the edges (estimated station-frame
    centres against the reference; edge lengths do not depend on the frame).

    Raises
    ------
    InputFileError
        Unreadable table or reference (as their readers), a cell that is not a number.
    DataError
        A station with too few matched accepted markers (process the scans with
        ``--reference`` so that markers carry reference ids), or no station at all.
    """
    table = read_marker_table(table_path)
    reference = read_reference(reference_path)
    ref_of = dict(zip(reference.ids, reference.centres_m, strict=True))
    what = f"marker table {table_path}"
    stations: dict[str, list[dict]] = {}
    for row in table:
        if row["accepted"] == "true" and row["marker_id"] in ref_of:
            stations.setdefault(row["station_id"], []).append(row)
    seen = {row["station_id"] for row in table}
    if not seen:
        raise DataError(f"{what} has no rows; process the real scans with markerplan process")
    out = []
    for station in sorted(seen):
        rows = stations.get(station, [])
        if len(rows) < MIN_MARKERS:
            raise DataError(f"{what}: station {station!r} has {len(rows)} accepted marker(s) "
                            f"matched to the reference; calibration needs {MIN_MARKERS} (process "
                            "against the reference coordinates so markers carry reference "
                            "ids)")
        ids = [r["marker_id"] for r in rows]
        est = np.array([[_cell(r, c, what) for c in ("x_m", "y_m", "z_m")] for r in rows])
        edges = edge_residuals(ids, est, np.array([ref_of[i] for i in ids]))
        residual = float(np.mean([abs(e["residual_m"]) for e in edges]))
        distances = np.array([_cell(r, "distance_m", what) for r in rows])
        out.append(checked_position(FieldPosition(station, distances, residual), what))
    return out


def _cell(row: dict, column: str, what: str) -> float:
    try:
        return finite_number(row[column], f"{what}: {column} of station {row['station_id']!r}")
    except InputFileError:
        raise InputFileError(f"{what}: {column} of station {row['station_id']!r} is "
                             f"{row[column]!r:.40}; expected a number") from None
