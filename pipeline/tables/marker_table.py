"""The marker table: one row per candidate marker per station (the error model's input).

Columns, in this order (station frame = origin at the nominal LiDAR centre, z up):

- ``station_id``: station the scan belongs to.
- ``marker_id``: reference marker matched to this detection; empty when unmatched.
- ``x_m, y_m, z_m``: estimated centre, station frame, metres.
- ``distance_m``: LiDAR centre to marker centre, metres.
- ``elevation_deg``: angle of the marker centre above the horizontal seen from the LiDAR
  centre, degrees (negative below).
- ``azimuth_deg``: ``atan2(y, x)`` of the centre in the station frame, degrees in [0, 360).
- ``n_points``: points used by the centre fit.
- ``point_density_per_m2``: ``n_points / (pi R^2)``, points per m^2 of the projected
  sensor-facing hemisphere.
- ``visible_fraction``: fraction of the projected disc covered by points
  (:mod:`pipeline.chain.quality`).
- ``fit_rms_m``: RMS of the fixed-radius residuals of the points used, metres.
- ``radius_fit_m``: radius of a free-radius fit to the same points, metres.
- ``estimator``: ``fixed-radius`` or ``hemisphere-icp``.
- ``accepted``: ``true`` / ``false`` (quality gate; the readers take either in any case and
  refuse any other cell, :func:`accepted_flags`).
- ``reason``: empty when accepted, else ``too_few_points``, ``high_rms``, ``radius_mismatch``,
  ``partly_buried``, ``incomplete_cloud`` or, in ``range-study`` tables, ``not_detected`` (a
  laid-out marker no detection of the chain matched: its true centre, no points, no error).
- ``error_m``: ``|estimate - reference|``, metres; empty without a reference.
- ``error_x_m, error_y_m, error_z_m``: the components (estimate - reference), station frame.
- ``replicate``: replicate number (range study), 0 otherwise.
- ``seed``: simulation seed when known, else empty.

Every row is one detection: a row that repeats another exactly is one detection read twice,
and the readers refuse it (:func:`refuse_repeated_rows`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from markerplan.errors import InputFileError
from markerplan.reading import read_csv
from markerplan.writing import write_csv

COLUMNS = ("station_id", "marker_id", "x_m", "y_m", "z_m", "distance_m", "elevation_deg",
           "azimuth_deg", "n_points", "point_density_per_m2", "visible_fraction", "fit_rms_m",
           "radius_fit_m", "estimator", "accepted", "reason", "error_m", "error_x_m",
           "error_y_m", "error_z_m", "replicate", "seed")


@dataclass
class MarkerRow:
    """One row of the marker table (fields = :data:`COLUMNS`)."""

    station_id: str
    marker_id: str
    x_m: float
    y_m: float
    z_m: float
    distance_m: float
    elevation_deg: float
    azimuth_deg: float
    n_points: int
    point_density_per_m2: float
    visible_fraction: float
    fit_rms_m: float
    radius_fit_m: float
    estimator: str
    accepted: bool
    reason: str
    error_m: float | None = None
    error_x_m: float | None = None
    error_y_m: float | None = None
    error_z_m: float | None = None
    replicate: int = 0
    seed: int | None = None

    @property
    def centre_m(self) -> np.ndarray:
        return np.array([self.x_m, self.y_m, self.z_m])

    def set_error(self, reference_m: np.ndarray | None) -> None:
        """Fill the error columns from a reference centre (same frame), or clear them."""
        if reference_m is None:
            self.error_m = self.error_x_m = self.error_y_m = self.error_z_m = None
            return
        e = self.centre_m - np.asarray(reference_m, dtype=float)
        self.error_m = float(np.linalg.norm(e))
        self.error_x_m, self.error_y_m, self.error_z_m = (float(v) for v in e)


assert tuple(f.name for f in fields(MarkerRow)) == COLUMNS

#: The cells of the ``accepted`` column and what they mean (case and blanks ignored).
ACCEPTED_CELLS = {"true": True, "false": False}

#: How many repeated rows a message lists.
_SHOWN_REPEATS = 3


def line_of_sight(centre_m: np.ndarray, sensor_m=(0.0, 0.0, 0.0)) -> tuple[float, float, float]:
    """Distance (m), elevation (deg, + up) and azimuth (deg, [0, 360)) of a centre.

    Examples
    --------
    >>> [round(v, 3) for v in line_of_sight([3.0, 3.0, -1.0])]
    [4.359, -13.263, 45.0]
    """
    d = np.asarray(centre_m, dtype=float) - np.asarray(sensor_m, dtype=float)
    dist = float(np.linalg.norm(d))
    elev = math.degrees(math.atan2(d[2], math.hypot(d[0], d[1])))
    az = math.degrees(math.atan2(d[1], d[0])) % 360.0
    return dist, elev, az


def write_marker_table(path: str | Path, rows: list[MarkerRow]) -> Path:
    """Write rows as CSV with the header :data:`COLUMNS` (:func:`markerplan.writing.write_csv`)."""
    return write_csv(path, COLUMNS, [asdict(r) for r in rows])


def read_marker_table(path: str | Path) -> list[dict[str, str]]:
    """Read a marker table back as dicts of strings, checking the header.

    Parameters
    ----------
    path : str or Path
        A ``markers.csv`` written by :func:`write_marker_table`.

    Returns
    -------
    rows : list of dict
        Column name -> cell text, one dict per data row; ``accepted`` as read by
        :func:`accepted_flags`, written ``"true"`` or ``"false"``.

    Raises
    ------
    InputFileError
        Missing, unreadable or non-UTF-8 file, a header other than :data:`COLUMNS`, a row
        with more or fewer cells than the header, an ``accepted`` cell other than true/false
        (:func:`accepted_flags`), or a row that repeats another (:func:`refuse_repeated_rows`).
    """
    path = Path(path)
    what = f"marker table {path}"
    header, rows = read_csv(path, what, COLUMNS, "write it with markerplan process")
    if tuple(header) != COLUMNS:
        raise InputFileError(f"{what} has columns {list(header)}; missing "
                             f"{[c for c in COLUMNS if c not in header]} (expected exactly "
                             f"{list(COLUMNS)})")
    accepted = accepted_flags([row[COLUMNS.index("accepted")] for row in rows], what)
    refuse_repeated_rows(header, rows, what)
    return [{**dict(zip(COLUMNS, row, strict=True)), "accepted": "true" if flag else "false"}
            for row, flag in zip(rows, accepted, strict=True)]


def accepted_flags(cells: Sequence[str], what: str) -> np.ndarray:
    """The ``accepted`` column as (n,) bool: :data:`ACCEPTED_CELLS`, nothing else.

    Parameters
    ----------
    cells : sequence of str
        The column's cells, first data row first (row 2 of the file, as
        :func:`markerplan.reading.read_csv` counts them).
    what : str
        How messages name the table, e.g. ``"marker table t.csv"``.

    Returns
    -------
    accepted : (n,) bool

    Raises
    ------
    InputFileError
        A cell other than ``true`` or ``false`` (``yes``, ``1``, empty...), naming its row.

    Examples
    --------
    >>> accepted_flags(["true", " FALSE"], "t.csv").tolist()
    [True, False]
    >>> accepted_flags(["true", "yes"], "t.csv")
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: t.csv: column 'accepted' row 3 must be true/false, got \
'yes'; write true or false (as markerplan process does)
    """
    flags = np.zeros(len(cells), dtype=bool)
    for row, cell in enumerate(cells, start=2):
        value = ACCEPTED_CELLS.get(str(cell).strip().lower())
        if value is None:
            raise InputFileError(f"{what}: column 'accepted' row {row} must be true/false, got "
                                 f"{str(cell)[:20]!r}; write true or false (as markerplan "
                                 "process does)")
        flags[row - 2] = value
    return flags


def refuse_repeated_rows(header: Sequence[str], rows: Sequence[Sequence[str]],
                         what: str) -> None:
    """Refuse rows that repeat an earlier row cell for cell (one detection read twice).

    Parameters
    ----------
    header : sequence of str
        Column names (for naming the station and marker of a repeat).
    rows : sequence of sequence of str
        Data rows, first one row 2 of the file (:func:`markerplan.reading.read_csv`); cells
        are compared with surrounding blanks stripped.
    what : str
        How messages name the table.

    Raises
    ------
    InputFileError
        Naming the repeated rows and the rows they repeat, and the first one's station and
        marker when the table has those columns.

    Examples
    --------
    >>> refuse_repeated_rows(["station_id", "x_m"], [["S1", "1"], ["S1", "2"]], "t.csv")
    >>> refuse_repeated_rows(["station_id", "x_m"], [["S1", "1"], ["S1", " 1"]], "t.csv")
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: t.csv: 1 row repeats an earlier row exactly: row 3 \
repeats row 2 (station S1); each detection appears once: delete the repeats
    """
    first: dict[tuple[str, ...], int] = {}
    repeats = []
    for row, cells in enumerate(rows, start=2):
        key = tuple(c.strip() for c in cells)
        if key in first:
            repeats.append((row, first[key], key))
        else:
            first[key] = row
    if not repeats:
        return
    shown = ", ".join(f"row {row} repeats row {earlier}"
                      for row, earlier, _ in repeats[:_SHOWN_REPEATS])
    more = f" and {len(repeats) - _SHOWN_REPEATS} more" if len(repeats) > _SHOWN_REPEATS else ""
    names = dict(zip(header, repeats[0][2], strict=True))
    of = ", ".join(f"{label} {names[c]}" for c, label in (("station_id", "station"),
                                                          ("marker_id", "marker"))
                   if names.get(c))
    count = f"{len(repeats)} rows repeat" if len(repeats) > 1 else "1 row repeats"
    raise InputFileError(f"{what}: {count} an earlier row exactly: {shown}"
                         f"{more}{f' ({of})' if of else ''}; each detection appears once: "
                         "delete the repeats")
