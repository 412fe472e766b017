"""Marker tables: reading the CSV written by ``markerplan process`` / ``range-study`` (columns
:data:`pipeline.tables.marker_table.COLUMNS`), checking it, and extracting the rows an error-model
fit uses.

A marker table has one row per (station, marker, replicate) with, among others, the
marker's distance and elevation seen from the LiDAR centre (station frame), its point count
and visible fraction, whether the quality gate accepted it, and its 3D centre error against
the reference (metres). Only accepted rows with a finite ``error_m`` are fitted.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from markerplan.errors import DataError, InputFileError
from markerplan.provenance import fingerprint_arrays
from markerplan.reading import MAX_ABS_COORDINATE_M, finite_number, read_csv
from pipeline.tables.marker_table import COLUMNS, accepted_flags, refuse_repeated_rows

#: Columns a fit cannot do without.
REQUIRED_COLUMNS = ("distance_m", "elevation_deg", "error_m", "accepted")
#: Text columns; every other column of the schema is numeric (empty cell -> NaN).
TEXT_COLUMNS = ("station_id", "marker_id", "estimator", "reason")
#: Optional predictor name -> table column it is read from.
EXTRA_COLUMNS = {"visible_fraction": "visible_fraction", "expected_points": "n_points"}


@dataclass(frozen=True)
class MarkerTable:
    """Columns of one or more marker tables, as arrays of equal length.

    Attributes
    ----------
    columns : dict of str -> (n,) array
        Numeric columns as float, ``accepted`` as bool, text columns as str.
    sources : tuple of str
        Where the rows came from (file names, or ``"<arrays>"``).
    """

    columns: dict[str, np.ndarray]
    sources: tuple[str, ...] = ("<arrays>",)

    @property
    def n_rows(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]


@dataclass(frozen=True)
class FitData:
    """The rows a fit uses, in SI units.

    Attributes
    ----------
    distance_m : (n,) float
        LiDAR-centre-to-marker-centre distance, metres.
    elevation_rad : (n,) float
        Elevation of the marker seen from the LiDAR centre (station frame, z up), radians.
    error_m : (n,) float
        3D centre error against the reference, metres.
    groups : (n,) int
        Scan each row belongs to (station x replicate), for grouped cross-validation; each
        row is its own group when the table does not name stations.
    extras : dict of str -> (n,) float
        Optional predictors that are finite on every used row.
    unavailable : dict of str -> str
        Optional predictors that could not be used, with the reason.
    counts : dict of str -> int
        ``rows_in``, ``rows_used`` and the number dropped per reason.
    sources : tuple of str
        Origin of the rows.
    """

    distance_m: np.ndarray
    elevation_rad: np.ndarray
    error_m: np.ndarray
    groups: np.ndarray
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    unavailable: dict[str, str] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    sources: tuple[str, ...] = ()

    @property
    def n_rows(self) -> int:
        return int(self.distance_m.size)

    def fingerprint(self) -> str:
        """SHA-256 of the fitted arrays (distance, elevation, error, then extras by name)."""
        arrays = [self.distance_m, self.elevation_rad, self.error_m]
        arrays += [self.extras[k] for k in sorted(self.extras)]
        return fingerprint_arrays(*arrays)


def read_marker_tables(paths: Iterable[str | Path] | str | Path) -> MarkerTable:
    """Read and concatenate marker-table CSVs (columns common to all are kept).

    Parameters
    ----------
    paths : iterable of str or Path, or one str or Path
        CSV files with a header row; each must contain at least :data:`REQUIRED_COLUMNS`.
        Columns of :data:`pipeline.tables.marker_table.COLUMNS` other than :data:`TEXT_COLUMNS` are
        read as numbers (empty cell -> NaN), ``accepted`` as bool (``true`` / ``false``), any
        other column as text.

    Returns
    -------
    table : MarkerTable

    Raises
    ------
    InputFileError
        No file given; a missing or unreadable file, missing columns, unparsable cells, a row
        that repeats another exactly (:func:`pipeline.tables.marker_table.refuse_repeated_rows`).
    """
    if isinstance(paths, str | Path):
        paths = [paths]
    tables = [_read_one(p) for p in paths]
    if not tables:
        raise InputFileError("marker tables: no file given; pass at least one CSV")
    common = [c for c in tables[0].columns if all(c in t.columns for t in tables)]
    columns = {c: np.concatenate([t.columns[c] for t in tables]) for c in common}
    return MarkerTable(columns=columns, sources=tuple(s for t in tables for s in t.sources))


def _read_one(path: str | Path) -> MarkerTable:
    """One marker-table CSV (see :func:`read_marker_tables`)."""
    path = Path(path)
    what = f"marker table {path}"
    if not path.exists():
        raise InputFileError(f"{what}: cannot be read (no such file); check the path")
    header, rows = read_csv(path, what, REQUIRED_COLUMNS,
                            fix="write it with `markerplan process` or `range-study`")
    refuse_repeated_rows(header, rows, what)
    cells = list(zip(*rows, strict=True)) if rows else [()] * len(header)
    columns = {name: _parse_column(path, name, col) for name, col in zip(header, cells,
                                                                          strict=True)}
    return MarkerTable(columns=columns, sources=(str(path),))


def as_marker_table(table: MarkerTable | Mapping[str, object]) -> MarkerTable:
    """Accept a :class:`MarkerTable` or a mapping of column name -> 1-D array."""
    if isinstance(table, MarkerTable):
        return table
    if not isinstance(table, Mapping):
        raise DataError(f"table must be a MarkerTable or a mapping of column -> array, got "
                        f"{type(table).__name__}")
    missing = [c for c in REQUIRED_COLUMNS if c not in table]
    if missing:
        raise DataError(f"table: missing column(s) {missing}; got {sorted(table)}")
    columns: dict[str, np.ndarray] = {}
    for name, values in table.items():
        arr = np.asarray(values)
        if arr.ndim != 1:
            raise DataError(f"table column {name!r} must be 1-D, got shape {arr.shape}")
        if name == "accepted":
            arr = arr if arr.dtype == bool else accepted_flags(arr.astype(str), "table")
        elif name not in TEXT_COLUMNS and arr.dtype.kind in "biuf":
            arr = arr.astype(float)
        columns[name] = arr
    lengths = {name: arr.size for name, arr in columns.items()}
    if len(set(lengths.values())) > 1:
        raise DataError(f"table columns must have equal lengths, got {lengths}")
    return MarkerTable(columns=columns)


def fit_data(table: MarkerTable, min_rows: int, extra_names: Iterable[str] = (),
             estimator: str | None = None) -> FitData:
    """Select the rows a fit uses and convert them to SI units.

    Parameters
    ----------
    table : MarkerTable
    min_rows : int
        Fewest usable rows accepted.
    extra_names : iterable of str
        Optional predictors to extract (keys of :data:`EXTRA_COLUMNS`).
    estimator : str, optional
        Keep only rows of this centre estimator; required when the table mixes several
        (their errors differ, one model describes one estimator).

    Returns
    -------
    data : FitData

    Raises
    ------
    DataError
        A required column is entirely NaN, values are out of range, or fewer than
        ``min_rows`` rows are usable.
    """
    where = ", ".join(table.sources)
    for name in ("distance_m", "elevation_deg", "error_m"):
        col = table[name]
        if col.dtype.kind != "f":
            raise DataError(f"{where}: column {name!r} must be numeric, got dtype {col.dtype}")
        if col.size and not np.isfinite(col).any():
            raise DataError(f"{where}: column {name!r} is all NaN; it must hold values for the "
                            "accepted markers (was the table evaluated against a reference?)")
    accepted = table["accepted"].astype(bool)
    chosen = np.ones(table.n_rows, bool)
    if "estimator" in table.columns:
        names = sorted(set(table["estimator"].astype(str).tolist()))
        if estimator is not None and estimator not in names:
            raise DataError(f"{where}: no rows with estimator {estimator!r}; the table has "
                            f"{names}")
        if estimator is None and len(names) > 1:
            raise DataError(f"{where}: rows come from several estimators {names}; choose one "
                            "(`estimator`)")
        if estimator is not None:
            chosen = table["estimator"].astype(str) == estimator
    elif estimator is not None:
        raise DataError(f"{where}: estimator {estimator!r} requested but the table has no "
                        "'estimator' column")
    finite = (np.isfinite(table["error_m"]) & np.isfinite(table["distance_m"])
              & np.isfinite(table["elevation_deg"]))
    keep = chosen & accepted & finite
    counts = {"rows_in": table.n_rows, "dropped_other_estimator": int((~chosen).sum()),
              "dropped_not_accepted": int((chosen & ~accepted).sum()),
              "dropped_non_finite": int((chosen & accepted & ~finite).sum()),
              "rows_used": int(keep.sum())}
    if counts["rows_used"] < min_rows:
        raise DataError(f"{where}: only {counts['rows_used']} usable rows (accepted, finite "
                        f"error_m/distance_m/elevation_deg) of {table.n_rows}; a fit needs at "
                        f"least {min_rows}; process more stations or replicates")
    d = table["distance_m"][keep]
    e = np.deg2rad(table["elevation_deg"][keep])
    err = table["error_m"][keep]
    if (d <= 0).any() or (err < 0).any() or (np.abs(e) > np.pi / 2 + 1e-9).any():
        raise DataError(f"{where}: distance_m must be > 0, error_m >= 0 and |elevation_deg| <= "
                        f"90; got distance min {d.min():.3g}, error min {err.min():.3g}, "
                        f"|elevation| max {np.rad2deg(np.abs(e)).max():.3g} deg")
    if not (err > 0).any():
        raise DataError(f"{where}: error_m is 0 for every usable row; errors must come from an "
                        "independent reference, not from the estimates themselves")
    extras, unavailable = {}, {}
    for name in extra_names:
        col_name = EXTRA_COLUMNS[name]
        if col_name not in table.columns or table[col_name].dtype.kind != "f":
            unavailable[name] = f"column {col_name!r} absent or not numeric"
            continue
        col = table[col_name][keep]
        bad = int((~np.isfinite(col)).sum())
        if bad:
            unavailable[name] = f"{bad} used rows have a non-finite {col_name!r}"
            continue
        extras[name] = col
    return FitData(distance_m=d, elevation_rad=e, error_m=err, groups=_groups(table, keep),
                   extras=extras,
                   unavailable=unavailable, counts=counts, sources=table.sources)


def _groups(table: MarkerTable, keep: np.ndarray) -> np.ndarray:
    keys = [c for c in ("station_id", "replicate", "seed") if c in table.columns]
    if "station_id" not in keys:
        return np.arange(int(keep.sum()))
    labels = np.char.add(table["station_id"].astype(str), "|")
    for c in keys[1:]:
        labels = np.char.add(np.char.add(labels, table[c].astype(str)), "|")
    return np.unique(labels[keep], return_inverse=True)[1]


def _parse_column(path: Path, name: str, cells: tuple[str, ...]) -> np.ndarray:
    """One column as bool (``accepted``), str (text and unknown columns) or float.

    Numeric cells: empty means no value (NaN, as ``markerplan process`` writes it); anything
    else must be a finite number of sane magnitude (``nan``, ``inf``, ``1e300`` refused).
    """
    if name == "accepted":
        return accepted_flags(cells, f"marker table {path}")
    if name in TEXT_COLUMNS or name not in COLUMNS:
        return np.asarray(cells, dtype=str)
    max_abs = _MAX_ABS.get(name, MAX_ABS_COORDINATE_M)
    out = np.empty(len(cells))
    for i, cell in enumerate(cells):
        cell = cell.strip()
        if not cell:
            out[i] = np.nan
            continue
        what = f"marker table {path}: column {name!r} line {i + 2}"
        try:
            value = finite_number(cell, what, math.inf)
        except InputFileError as exc:
            raise InputFileError(f"{exc}; leave the cell empty for no value, or regenerate the "
                                 "file") from None
        out[i] = finite_number(value, what, max_abs)
    return out


#: Magnitude limits of numeric columns other than :data:`MAX_ABS_COORDINATE_M`.
_MAX_ABS = {"seed": 2.0**64, "replicate": 2.0**64}
