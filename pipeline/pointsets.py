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

_SPLIT = re.compile(r"[,\s;]+")


def read_points(path: str | Path) -> np.ndarray:
    """Read a point set file.

    Parameters
    ----------
    path : str or Path
        Text file, one point per line.

    Returns
    -------
    points_m : (n, 3) float64
        Coordinates as stored (metres by convention), n >= 1.

    Raises
    ------
    InputFileError
        Missing/unreadable file, or a line that is not at least three numbers.
    DataError
        No points in the file.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"point file {path} does not exist; check the path")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f"point file {path} is not readable text ({exc}); expected lines "
                             "of 'x y z'") from exc
    lines = [ln.strip() for ln in text.splitlines()]
    lines = [ln for ln in lines if ln and not ln.startswith("#")]
    cols = (0, 1, 2)
    if lines and not _is_numeric(_SPLIT.split(lines[0])[0]):
        cols = _header_columns(_SPLIT.split(lines[0]), path)
        lines = lines[1:]
    if not lines:
        raise DataError(f"point file {path} holds no points; expected lines of 'x y z'")
    rows = []
    for lineno, ln in enumerate(lines, start=1):
        parts = _SPLIT.split(ln)
        try:
            rows.append([float(parts[c]) for c in cols])
        except (ValueError, IndexError) as exc:
            raise InputFileError(f"point file {path}: data line {lineno} {ln[:60]!r} is not "
                                 "three numbers x y z; fix or remove the line") from exc
    pts = np.asarray(rows, dtype=float)
    if not np.all(np.isfinite(pts)):
        raise InputFileError(f"point file {path} contains NaN or infinite coordinates")
    return pts


def _is_numeric(token: str) -> bool:
    try:
        float(token)
    except ValueError:
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
    raise InputFileError(f"point file {path}: header {header} has fewer than three columns")
