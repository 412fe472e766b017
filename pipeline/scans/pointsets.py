"""Reading plain point sets (``.xyz`` / ``.txt`` / ``.csv``): one point per line, x y z first.

Separators may be tabs, spaces or commas. A ``.csv`` may start with a header row; if that row
names ``x``/``y``/``z`` columns (``x``, ``x_m``, case-insensitive) those columns are used,
otherwise the first three. Further columns (intensity, colour) are ignored.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from markerplan.errors import DataError, InputFileError
from markerplan.reading import MAX_ABS_COORDINATE_M, finite_number, read_text

_SPLIT = re.compile(r"[,\s;]+")


def read_points(path: str | Path) -> np.ndarray:
    """Read a point set file.

    Parameters
    ----------
    path : str or Path
        UTF-8 text file, one point per line.

    Returns
    -------
    points_m : (n, 3) float64
        Coordinates as stored (metres by convention), n >= 1, all finite and of magnitude at
        most :data:`markerplan.reading.MAX_ABS_COORDINATE_M`.

    Raises
    ------
    InputFileError
        Missing/unreadable/non-UTF-8 file, a line that is not at least three numbers, a line
        with more or fewer cells than a header row, NaN/infinite or absurd coordinates.
    DataError
        No points in the file.
    """
    path = Path(path)
    what = f"point file {path}"
    if not path.exists():
        raise InputFileError(f"{what} does not exist; check the path")
    text = read_text(path, what)
    lines = [(k, ln.strip()) for k, ln in enumerate(text.splitlines(), start=1)]
    lines = [(k, ln) for k, ln in lines if ln and not ln.startswith("#")]
    cols = (0, 1, 2)
    n_header = None
    if lines and not _is_numeric(_SPLIT.split(lines[0][1])[0]):
        header = _SPLIT.split(lines[0][1])
        cols = _header_columns(header, path)
        n_header = len(header)
        lines = lines[1:]
    if not lines:
        raise DataError(f"{what} holds no points; expected lines of 'x y z'")
    rows = []
    for lineno, ln in lines:
        parts = _SPLIT.split(ln)
        if n_header is not None and len(parts) != n_header:
            raise InputFileError(f"{what}: line {lineno} has {len(parts)} cells, the header has "
                                 f"{n_header}; fix the row")
        try:
            rows.append([float(parts[c]) for c in cols])
        except (ValueError, IndexError, OverflowError) as exc:
            raise InputFileError(f"{what}: line {lineno} {ln[:60]!r} is not three numbers "
                                 "x y z; fix or remove the line") from exc
    pts = np.asarray(rows, dtype=float)
    ok = np.isfinite(pts) & (np.abs(pts) <= MAX_ABS_COORDINATE_M)
    if not ok.all():
        row, col = np.argwhere(~ok)[0]
        lineno, ln = lines[row]
        finite_number(_SPLIT.split(ln)[cols[col]], f"{what}: line {lineno} {'xyz'[col]}")
    return pts


def _is_numeric(token: str) -> bool:
    try:
        float(token)
    except (ValueError, OverflowError):
        return False
    return True


def _header_columns(header: list[str], path: Path) -> tuple[int, int, int]:
    names = [h.strip().lower() for h in header]
    found = []
    for axis in "xyz":
        for i, n in enumerate(names):
            if n in (axis, f"{axis}_m"):
                found.append(i)
                break
    if len(found) == 3:
        return tuple(found)  # type: ignore[return-value]
    if len(names) >= 3:
        return (0, 1, 2)
    raise InputFileError(f"point file {path}: header {', '.join(header)[:80]!r} has fewer than "
                         "three columns; give x, y and z columns")
