"""How markerplan's tables and JSON files spell a value: one CSV cell format, one JSON
fallback for numpy values.

- CSV cells (:func:`csv_cell`, :func:`write_csv`): empty for no value (``None``, NaN,
  infinity), ``true`` / ``false`` for booleans, floats with six decimals, anything else as
  ``str``; ``\\n`` line ends.
- GIS sidecars of a coordinate table ``name.csv`` (:func:`write_gis_sidecars`): ``name.csvt``,
  the column types GDAL and QGIS read (:func:`column_types`), and, when the coordinates have a
  CRS, ``name.prj``, its WKT in the ESRI dialect. The header is always a CSV's first line, so
  pandas, QGIS and spreadsheets read it with their default settings.
- JSON (:func:`json_default`, the ``default=`` of :func:`json.dumps`): numpy arrays as lists,
  numpy scalars as Python numbers, a non-finite numpy float as ``null``; :func:`json_float`
  a number as a JSON-safe float (``None`` for NaN and infinity).
"""

from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np


def csv_cell(value: Any) -> str:
    """The CSV text of one cell.

    Examples
    --------
    >>> [csv_cell(v) for v in (None, True, np.bool_(False), 0.1, np.float32("nan"), 7, "a")]
    ['', 'true', 'false', '0.100000', '', '7', 'a']
    """
    if value is None:
        return ""
    if isinstance(value, bool | np.bool_):
        return "true" if value else "false"
    if isinstance(value, float | np.floating):
        return f"{float(value):.6f}" if np.isfinite(value) else ""
    return str(value)


def json_float(value) -> float | None:
    """A number as a Python float, ``None`` (JSON ``null``) for NaN and infinity.

    >>> json_float(np.float32(0.5)), json_float(float("inf"))
    (0.5, None)
    """
    value = float(value)
    return value if np.isfinite(value) else None


def json_default(obj: Any) -> Any:
    """``default=`` of :func:`json.dumps` for numpy values.

    Raises
    ------
    TypeError
        Anything else (as :func:`json.dumps` expects).

    Examples
    --------
    >>> import json
    >>> json.dumps([np.arange(2), np.int64(3), np.float32("nan")], default=json_default)
    '[[0, 1], 3, null]'
    """
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        v = obj.item()
        return None if isinstance(v, float) and not np.isfinite(v) else v
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")


def write_csv(path: str | Path, columns: tuple[str, ...], records: Iterable[Mapping[str, Any]]
              ) -> Path:
    """Write a header row ``columns`` and one row of :func:`csv_cell` cells per record.

    Parameters
    ----------
    path : str or Path
        Destination (overwritten).
    columns : tuple of str
        Header, and the keys read from each record, in order.
    records : iterable of mapping
        One per data row; every key of ``columns`` must be present.

    Returns
    -------
    path : Path
    """
    path = Path(path)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(columns)
        for rec in records:
            w.writerow([csv_cell(rec[c]) for c in columns])
    return path


def column_types(columns: tuple[str, ...], records: Iterable[Mapping[str, Any]]
                 ) -> tuple[str, ...]:
    """The ``.csvt`` type of each column, from the values :func:`write_csv` would write.

    ``Integer`` when every value is an integer, ``Real`` when every value is a number (an empty
    cell, None or NaN, fits both), else ``String`` (booleans too: their cells are ``true`` /
    ``false``); a column without any value is ``String``.

    Examples
    --------
    >>> column_types(("a", "b", "c", "d"), [{"a": 1, "b": 1, "c": True, "d": None},
    ...                                     {"a": 2, "b": 0.5, "c": False, "d": None}])
    ('Integer', 'Real', 'String', 'String')
    """
    records = list(records)
    types = []
    for c in columns:
        values = [r[c] for r in records if r[c] is not None]
        if not values or any(isinstance(v, bool | np.bool_) or not isinstance(v, int | float
                                                                               | np.number)
                             for v in values):
            types.append("String")
        elif all(isinstance(v, int | np.integer) for v in values):
            types.append("Integer")
        else:
            types.append("Real")
    return tuple(types)


def esri_wkt(crs_wkt: str) -> str:
    """``crs_wkt`` in the ESRI dialect of a ``.prj`` file, or unchanged when that dialect cannot
    express it (GDAL and QGIS also read WKT 1 and 2 there).

    >>> from rasterio.crs import CRS
    >>> esri_wkt(CRS.from_epsg(32633).to_wkt())[:30]
    'PROJCS["WGS_1984_UTM_Zone_33N"'
    """
    from rasterio.crs import CRS
    from rasterio.errors import CRSError

    try:
        return CRS.from_wkt(crs_wkt).to_wkt(version="WKT1_ESRI")
    except CRSError:
        return crs_wkt


def write_gis_sidecars(path: str | Path, types: tuple[str, ...], crs_wkt: str | None
                       ) -> list[Path]:
    """Write the sidecars that GDAL and QGIS read beside the coordinate table ``path``.

    Parameters
    ----------
    path : str or Path
        The CSV (``name.csv``).
    types : tuple of str
        One ``.csvt`` type per column, in the header's order: ``Integer``, ``Real`` or
        ``String`` (:func:`column_types`).
    crs_wkt : str or None
        WKT of the coordinates' CRS; None (a local frame) writes no ``.prj``.

    Returns
    -------
    written : list of Path
        ``name.csvt`` (one line, each type quoted), then ``name.prj`` (:func:`esri_wkt`, one
        line) when there is a CRS.
    """
    path = Path(path)
    written = [path.with_suffix(".csvt")]
    written[0].write_text(",".join(f'"{t}"' for t in types) + "\n")
    if crs_wkt is not None:
        written.append(path.with_suffix(".prj"))
        written[1].write_text(esri_wkt(crs_wkt) + "\n")
    return written
