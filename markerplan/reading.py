"""Strict reading of the small text inputs every package shares: UTF-8 text, JSON objects,
CSV tables and the numbers in them.

Every helper raises :class:`~markerplan.errors.InputFileError` with one line that names the
input (``what``), the rule and what was received, so a reader built on them never lets a
``UnicodeDecodeError``, ``KeyError`` or ``ValueError`` reach the user.
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from markerplan.errors import InputFileError

#: Largest magnitude accepted for a coordinate or length read from a file, metres. Projected
#: Earth and lunar coordinates stay below 1e7 m; 1e300 is a corrupt file, not a position.
MAX_ABS_COORDINATE_M = 1e8


def read_text(path: str | Path, what: str) -> str:
    """The whole text of ``path``, decoded as UTF-8 (a BOM is accepted).

    Parameters
    ----------
    path : str or Path
        File to read.
    what : str
        How the message names the input, e.g. ``"--config settings.toml"``.

    Raises
    ------
    InputFileError
        Missing file, a folder, unreadable, or not UTF-8.
    """
    path = Path(path)
    if not path.exists():
        raise InputFileError(f"{what}: file not found; check the path")
    if path.is_dir():
        raise InputFileError(f"{what}: is a folder; give a file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputFileError(f"{what}: cannot be read ({exc.strerror}); check its "
                             "permissions") from exc
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{what}: not UTF-8 text (byte {exc.start} is "
                             f"0x{data[exc.start]:02x}); save it as UTF-8") from exc


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def parse_json(text: str, what: str, expect: type = dict) -> Any:
    """Parse JSON text whose top level must be ``expect`` (``NaN``/``Infinity`` refused).

    >>> parse_json('{"a": 1}', "x")
    {'a': 1}
    >>> parse_json('[1]', "plan.json")
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: plan.json: expected a JSON object at the top level, got a list
    """
    try:
        doc = json.loads(text, parse_constant=_refuse_constant)
    except (json.JSONDecodeError, ValueError, RecursionError) as exc:
        raise InputFileError(f"{what}: not valid JSON ({exc})") from exc
    if not isinstance(doc, expect):
        kinds = {dict: "a JSON object", list: "a JSON list"}
        raise InputFileError(f"{what}: expected {kinds.get(expect, expect.__name__)} at the top "
                             f"level, got {json_kind(doc)}")
    return doc


def load_json(path: str | Path, what: str, expect: type = dict) -> Any:
    """:func:`read_text` then :func:`parse_json`."""
    return parse_json(read_text(path, what), what, expect)


def json_kind(value: Any) -> str:
    """A word for a JSON value's type, for messages.

    >>> json_kind([]), json_kind(None), json_kind(1.5)
    ('a list', 'null', 'a number')
    """
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


def require_keys(doc: Mapping[str, Any], keys: Iterable[str], what: str, fix: str) -> None:
    """Refuse a mapping that lacks any of ``keys``; ``fix`` says how to get a good file."""
    missing = [k for k in keys if k not in doc]
    if missing:
        raise InputFileError(f"{what}: missing {', '.join(map(repr, missing))}; {fix}")


def require_type(value: Any, kind: type | tuple[type, ...], what: str) -> Any:
    """Return ``value`` if it is of ``kind`` (a bool is never a number), else refuse it.

    >>> require_type(3, int, "n")
    3
    >>> require_type(True, (int, float), "sigma_m")
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: sigma_m: expected int or float, got a boolean (True)
    """
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if isinstance(value, bool) and bool not in kinds or not isinstance(value, kinds):
        names = " or ".join(k.__name__ for k in kinds)
        raise InputFileError(f"{what}: expected {names}, got {json_kind(value)} ({value!r:.40})")
    return value


def check_schema_version(found: Any, supported: int, what: str) -> int:
    """Accept a ``schema_version`` this markerplan can read; refuse a newer or malformed one.

    >>> check_schema_version(1, 1, "plan.json")
    1
    >>> check_schema_version(2, 1, "plan.json")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: plan.json: schema_version 2 is newer than ... (1); upgrade...
    """
    if isinstance(found, bool) or not isinstance(found, int) or found < 1:
        raise InputFileError(f"{what}: schema_version must be a positive integer, got {found!r}")
    if found > supported:
        raise InputFileError(f"{what}: schema_version {found} is newer than this markerplan "
                             f"reads ({supported}); upgrade markerplan")
    return found


def finite_number(value: Any, what: str, max_abs: float = MAX_ABS_COORDINATE_M) -> float:
    """A finite float of magnitude at most ``max_abs`` from a JSON number or a text cell.

    >>> finite_number("2.5", "x_m")
    2.5
    >>> finite_number("nan", "x_m of S1")
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: x_m of S1: must be a finite number, got 'nan'
    """
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise InputFileError(f"{what}: must be a number, got {json_kind(value)}")
    try:
        number = float(value)
    except (ValueError, OverflowError) as exc:
        raise InputFileError(f"{what}: must be a number, got {value!r:.40}") from exc
    if not math.isfinite(number):
        raise InputFileError(f"{what}: must be a finite number, got {value!r:.40}")
    if abs(number) > max_abs:
        raise InputFileError(f"{what}: {number:g} is beyond the accepted magnitude {max_abs:g}; "
                             "check the file's units and content")
    return number


def json_number(value: Any, what: str, max_abs: float = MAX_ABS_COORDINATE_M) -> float:
    """A finite JSON number (not a string, not a boolean) of magnitude at most ``max_abs``."""
    return finite_number(require_type(value, (int, float), what), what, max_abs)


def json_numbers(values: Any, what: str, max_abs: float = MAX_ABS_COORDINATE_M,
                 length: int | None = None) -> list[float]:
    """A JSON list of finite numbers (strings and booleans refused), as floats.

    Parameters
    ----------
    values : Any
        The parsed JSON value.
    what : str
        How messages name it; items are named ``what[i]``.
    max_abs : float
        Largest magnitude accepted.
    length : int, optional
        The exact number of items required (e.g. 3 for a point).

    >>> json_numbers([1, 2.5], "knots")
    [1.0, 2.5]
    >>> json_numbers([1, "2"], "knots")
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: knots[1]: expected int or float, got a string ('2')
    >>> json_numbers([1, 2], "centre_m", length=3)
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: centre_m: must be a list of 3 numbers, got 2 items
    """
    if length is None:
        require_type(values, list, what)
    elif not isinstance(values, list) or len(values) != length:
        shown = f"{len(values)} items" if isinstance(values, list) else json_kind(values)
        raise InputFileError(f"{what}: must be a list of {length} numbers, got {shown}")
    return [json_number(v, f"{what}[{i}]", max_abs) for i, v in enumerate(values)]


def read_csv(path: str | Path, what: str, required: Iterable[str] = (),
             fix: str = "") -> tuple[list[str], list[list[str]]]:
    """Header and rows of a UTF-8 CSV; ragged rows and missing columns refused.

    The header is the first row. Leading one-cell rows starting with ``#`` are skipped: the
    ``markers.csv`` and ``stations.csv`` of older plans put a quoted ``# markerplan plan ...``
    comment line before their header.

    Parameters
    ----------
    path : str or Path
        CSV file with a header row.
    what : str
        How messages name the input.
    required : iterable of str
        Columns that must be present.
    fix : str
        Appended to messages about missing columns, e.g. ``"write it with markerplan process"``.

    Returns
    -------
    header : list of str
        Column names, stripped.
    rows : list of list of str
        Data rows (blank lines skipped), each as long as the header.
    """
    text = read_text(path, what)
    try:
        records = [r for r in csv.reader(io.StringIO(text, newline="")) if r]
    except csv.Error as exc:
        raise InputFileError(f"{what}: not a readable CSV ({exc})") from exc
    while records and len(records[0]) == 1 and records[0][0].lstrip().startswith("#"):
        del records[0]
    if not records:
        raise InputFileError(f"{what}: file is empty; expected a header row")
    header = [h.strip() for h in records[0]]
    missing = [c for c in required if c not in header]
    if missing:
        raise InputFileError(f"{what}: missing column(s) {', '.join(missing)}; got "
                             f"{', '.join(header)[:120]}" + (f"; {fix}" if fix else ""))
    duplicated = sorted({h for h in header if header.count(h) > 1})
    if duplicated:
        raise InputFileError(f"{what}: column(s) {', '.join(duplicated)} appear twice in the "
                             "header; keep one of each")
    rows = records[1:]
    for line, row in enumerate(rows, start=2):
        if len(row) != len(header):
            raise InputFileError(f"{what}: row {line} has {len(row)} cells, the header has "
                                 f"{len(header)}; fix the row")
    return header, rows


def unique_ids(ids: Iterable[str], what: str) -> list[str]:
    """Refuse empty or repeated ids.

    >>> unique_ids(["M1", "M1"], "reference ref.csv")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: reference ref.csv: id 'M1' appears more than once; ids...
    """
    seen: set[str] = set()
    out = []
    for i in ids:
        if not i:
            raise InputFileError(f"{what}: an id is empty; give every row an id")
        if i in seen:
            raise InputFileError(f"{what}: id {i!r} appears more than once; ids must be unique")
        seen.add(i)
        out.append(i)
    return out
