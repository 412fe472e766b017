"""The fate table: one row per known marker in range of a scan, with the stage of the chain
that lost it (or ``accepted``) and what a planner knew of the pair before the scan (the
detection model's input; :mod:`planner.studies.loss_study` writes it).

Columns, in this order:

- ``layout``, ``seed``, ``station_id``: the scan (one scan = one layout, seed and station);
- ``marker_id``;
- ``distance_m``: LiDAR centre to marker centre, metres;
- ``elevation_deg``: of the marker centre seen from the LiDAR centre, degrees (negative below);
- ``incidence_deg``: between the line of sight and the terrain normal at the marker, degrees;
- ``slope_deg``: terrain slope at the marker, degrees;
- ``rim_distance_m``: to the nearest crater rim crest, metres; empty (or ``inf``) when no
  crater is known;
- ``visible_fraction``: unoccluded fraction of the sensor-facing hemisphere, 0..1;
- ``expected_points``: returns expected on the marker from one full scan;
- ``n_points``: returns the scan put on the marker (the simulator's truth); empty if unknown;
- ``stage``: one of :data:`FATE_STAGES`; ``reason``: its detail (empty when accepted).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from markerplan.errors import InputFileError
from markerplan.reading import finite_number, read_csv
from markerplan.writing import write_csv

#: The stages a marker can be lost at, in chain order, then ``accepted``.
FATE_STAGES = ("not_in_view", "ground", "cluster", "gate", "fit", "quality", "accepted")

#: Columns of the fate table, in order.
FATE_COLUMNS = ("layout", "seed", "station_id", "marker_id", "distance_m", "elevation_deg",
                "incidence_deg", "slope_deg", "rim_distance_m", "visible_fraction",
                "expected_points", "n_points", "stage", "reason")

#: The covariate columns (what a planner knows of a pair), with their accepted ranges.
COVARIATE_RANGES = {"distance_m": (0.0, 1e4), "elevation_deg": (-90.0, 90.0),
                    "incidence_deg": (0.0, 90.0), "slope_deg": (0.0, 90.0),
                    "rim_distance_m": (0.0, np.inf), "visible_fraction": (0.0, 1.0),
                    "expected_points": (0.0, 1e9)}

_FIX = "write it with pipeline.tables.fate_table.write_fate_table (as the loss study does)"


@dataclass(frozen=True)
class FateTable:
    """Fate tables read back.

    Attributes
    ----------
    covariates : dict of str to (n,) float
        The :data:`COVARIATE_RANGES` columns (``rim_distance_m`` ``inf`` where empty).
    stage : (n,) str
    scan : (n,) str
        ``layout/seed/station_id`` of each row (held-out folds keep a scan together).
    sources : list of str
        The files read.
    """

    covariates: dict[str, np.ndarray]
    stage: np.ndarray
    scan: np.ndarray
    sources: list[str]

    @property
    def accepted(self) -> np.ndarray:
        """(n,) bool: the marker was detected and accepted."""
        return self.stage == "accepted"

    def __len__(self) -> int:
        return len(self.stage)


def write_fate_table(path: str | Path, rows: Iterable[Mapping[str, Any]]) -> Path:
    """Write rows (dicts keyed by :data:`FATE_COLUMNS`) as CSV, header first."""
    return write_csv(path, FATE_COLUMNS, rows)


def read_fate_tables(paths: Sequence[str | Path]) -> FateTable:
    """Read and check fate tables written by :func:`write_fate_table`.

    Raises
    ------
    InputFileError
        A missing or unreadable file, a header other than :data:`FATE_COLUMNS`, a covariate
        that is not a finite number in its range (:data:`COVARIATE_RANGES`), an unknown stage,
        or a (scan, marker) pair that appears twice. One line, naming the file and row.
    """
    cov: dict[str, list[float]] = {c: [] for c in COVARIATE_RANGES}
    stages, scans, seen = [], [], {}
    for path in paths:
        what = f"fate table {path}"
        header, rows = read_csv(path, what, FATE_COLUMNS, _FIX)
        if tuple(header) != FATE_COLUMNS:
            raise InputFileError(f"{what}: columns {header} are not {list(FATE_COLUMNS)}; "
                                 f"{_FIX}")
        for line, cells in enumerate(rows, start=2):
            row = dict(zip(header, (c.strip() for c in cells), strict=True))
            for name, (lo, hi) in COVARIATE_RANGES.items():
                cov[name].append(_covariate(row[name], name, lo, hi, f"{what} row {line}"))
            if row["stage"] not in FATE_STAGES:
                raise InputFileError(f"{what} row {line}: stage {row['stage'][:20]!r} is not "
                                     f"one of {', '.join(FATE_STAGES)}; {_FIX}")
            scan = f"{row['layout']}/{row['seed']}/{row['station_id']}"
            key = (scan, row["marker_id"])
            if key in seen:
                raise InputFileError(f"{what} row {line}: marker {row['marker_id']} of scan "
                                     f"{scan} already appears ({seen[key]}); each marker has "
                                     "one fate per scan: delete the repeat")
            seen[key] = f"{what} row {line}"
            stages.append(row["stage"])
            scans.append(scan)
    return FateTable({k: np.array(v) for k, v in cov.items()}, np.array(stages, dtype=str),
                     np.array(scans, dtype=str), [str(p) for p in paths])


def _covariate(cell: str, name: str, lo: float, hi: float, where: str) -> float:
    if name == "rim_distance_m" and cell.lower() in ("", "inf"):
        return np.inf
    value = finite_number(cell, f"{where} {name}", max_abs=1e12)
    if not lo <= value <= hi:
        raise InputFileError(f"{where}: {name} {value:g} is outside [{lo:g}, {hi:g}]; {_FIX}")
    return value
