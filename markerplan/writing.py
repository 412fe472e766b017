"""How markerplan's tables and JSON files spell a value: one CSV cell format, one JSON
fallback for numpy values.

- CSV cells (:func:`csv_cell`, :func:`write_csv`): empty for no value (``None``, NaN,
  infinity), ``true`` / ``false`` for booleans, floats with six decimals, anything else as
  ``str``; ``\\n`` line ends.
- JSON (:func:`json_default`, the ``default=`` of :func:`json.dumps`): numpy arrays as lists,
  numpy scalars as Python numbers, a non-finite numpy float as ``null``.
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
