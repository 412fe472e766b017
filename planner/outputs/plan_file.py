"""``plan.json``: its one writer (:func:`write_plan`), its one reader (:func:`read_plan`) and
the typed plan that verification works on (:class:`SurveyPlan`, from :func:`load_plan`).

:func:`read_plan` checks every part of a plan that ``verify`` and ``reduce`` read — the schema
and its version, the site, the requirement, the provenance, every marker and every station —
and refuses anything else with one :class:`~markerplan.errors.InputFileError` line that names
the file and the entry, so neither command meets a ``KeyError``, a ``TypeError`` or a NaN later.

``verify`` needs a whole plan (``full=True``). ``reduce`` also takes a hand-written layout
holding only ``schema`` and ``markers`` (``full=False``); the other parts are checked when
present.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from markerplan.errors import InputFileError
from markerplan.reading import (
    MAX_ABS_COORDINATE_M,
    check_schema_version,
    json_kind,
    json_number,
    parse_json,
    read_text,
    require_keys,
    require_type,
    unique_ids,
)
from planner.config import BOUNDS, LOCAL_KINDS, MAX_MARKERS, MAX_STATIONS
from planner.verify.station_rule import StationRule
from visibility.dem import DEM, read_dem
from visibility.sites import MARKER_RADIUS_M, load_site

SCHEMA = "markerplan-plan"
SCHEMA_VERSION = 1

#: Bounds of the requirement, m (those of :data:`planner.config.BOUNDS`).
REQUIREMENT_BOUNDS_M = (0.0, BOUNDS["requirement_m"][2])
WORKING_RADIUS_BOUNDS_M = (0.0, BOUNDS["working_radius_m"][2])
#: Largest marker radius accepted, m.
MAX_MARKER_RADIUS_M = 10.0
#: Largest magnitude of a station heading, rad.
MAX_ABS_HEADING_RAD = 100.0

_FIX = "regenerate it with `markerplan plan`"


@dataclass(frozen=True)
class PlannedStation:
    """One station of a plan."""

    id: str
    position_m: np.ndarray
    """(3,) LiDAR centre, site frame, metres."""
    heading_rad: float
    predicted_error_m: float | None
    marker_ids: tuple[str, ...]
    """The planned markers this station uses."""


@dataclass(frozen=True)
class SurveyPlan:
    """What verifying a plan needs: terrain, stations, markers and the requirement.

    Built from a ``plan.json`` (:func:`load_plan`) or directly from a study
    (:func:`planner.reduction.verify.point_plan`), so nothing is re-parsed.
    """

    dem: DEM
    stations: tuple[PlannedStation, ...]
    marker_ids: tuple[str, ...]
    marker_xyz_m: np.ndarray
    """(m, 3) marker centres, site frame, metres."""
    marker_radius_m: float
    requirement_m: float
    working_radius_m: float
    provenance: dict = field(default_factory=dict)
    """The plan's provenance record (empty for a plan made in memory)."""
    rule: StationRule = field(default_factory=StationRule)
    """How many markers in how many directions every station must detect."""

    @property
    def dem_path(self) -> str | None:
        """The ``--dem`` file the plan was made on, or ``None`` for a preset's terrain."""
        return plan_dem_path(self.provenance)


class PlanLayout(NamedTuple):
    """A checked plan's markers and stations, site frame (:func:`plan_layout`)."""

    marker_ids: tuple[str, ...]
    marker_xyz_m: np.ndarray
    """(m, 3) marker centres, metres."""
    stations: tuple[PlannedStation, ...]


def plan_layout(doc: dict) -> PlanLayout:
    """The markers and stations of a plan document checked by :func:`read_plan` (``full=True``);
    the terrain is not loaded.

    A station without ``heading_rad`` (or with null) faces site x (heading 0); one without
    ``markers`` uses none.
    """
    stations = tuple(PlannedStation(
        s["id"], np.array([s["x_m"], s["y_m"], s["z_m"]], float),
        float(s.get("heading_rad") or 0.0), s.get("predicted_error_m"),
        tuple(s.get("markers", ()))) for s in doc["stations"])
    return PlanLayout(
        tuple(m["id"] for m in doc["markers"]),
        np.array([[m["x_m"], m["y_m"], m["z_m"]] for m in doc["markers"]], float), stations)


def plan_dem_path(provenance: dict) -> str | None:
    """The ``--dem`` file a plan's provenance names (an absolute path since plans record
    their inputs so), or ``None`` for a preset's terrain."""
    return provenance.get("inputs", {}).get("dem")


def plan_dem(provenance: dict) -> DEM | None:
    """The terrain of a plan made on a ``--dem`` file, read as the plan read it (reprojected
    or by window when it was); ``None`` for a preset's terrain.

    Raises
    ------
    InputFileError, DataError
        The DEM the plan names cannot be read (see :func:`visibility.dem.read_dem`).
    """
    path = plan_dem_path(provenance)
    if path is None:
        return None
    inputs = provenance["inputs"]
    window = inputs.get("dem_window")
    return read_dem(path, what=f"DEM {path} (named by the plan)",
                    reproject=bool(inputs.get("reproject")),
                    window=None if window is None else tuple(window))


def write_plan(doc: dict, path: Path) -> None:
    """Write a ``plan.json`` document (:func:`planner.outputs.report.plan_record`) to ``path``."""
    Path(path).write_text(json.dumps(doc, indent=2) + "\n")


def load_plan(path: str | Path) -> SurveyPlan:
    """Read, check (:func:`read_plan`) and type a whole ``plan.json``, with its terrain, on
    which its stations and markers must stand (:func:`_require_on_terrain`).

    Raises
    ------
    InputFileError
        As :func:`read_plan`, or the DEM the plan names cannot be read.
    DataError
        A station or marker off the plan's terrain.
    """
    doc = read_plan(path, "PLAN", full=True)
    site = doc["site"]
    dem = plan_dem(doc["provenance"])
    if dem is None:
        dem = load_site(site["name"], site.get("seed")).dem
    layout = plan_layout(doc)
    plan = SurveyPlan(
        dem=dem, stations=layout.stations, marker_ids=layout.marker_ids,
        marker_xyz_m=layout.marker_xyz_m,
        marker_radius_m=float(site.get("marker_radius_m", MARKER_RADIUS_M)),
        requirement_m=float(doc["requirement"]["requirement_m"]),
        working_radius_m=float(doc["requirement"]["working_radius_m"]),
        provenance=doc["provenance"], rule=StationRule.of(doc["requirement"]))
    _require_on_terrain(plan, f"PLAN {path}")
    return plan


def _require_on_terrain(plan: SurveyPlan, what: str) -> None:
    """Refuse a plan whose stations or markers lie off its terrain (outside the DEM or on
    nodata, :meth:`visibility.dem.DEM.require_inside`): a scan there cannot be simulated.

    Parameters
    ----------
    plan : SurveyPlan
    what : str
        How messages name the plan (``"PLAN plan.json"``).

    Raises
    ------
    DataError
        Names the first such station (else marker), its position and the DEM's extent.
    """
    site = plan.provenance.get("inputs", {}).get("site")
    terrain = (f"DEM {plan.dem_path}" if plan.dem_path else
               f"site preset {site!r}" if site else "its site preset")
    fix = (f"{what} puts it off the terrain it was planned on ({terrain}); correct its "
           "coordinates in the plan or re-plan with `markerplan plan`")
    plan.dem.require_inside(np.array([st.position_m[:2] for st in plan.stations]),
                            [st.id for st in plan.stations], "station", fix)
    plan.dem.require_inside(np.asarray(plan.marker_xyz_m)[:, :2], plan.marker_ids, "marker", fix)


def read_plan(path: str | Path, option: str = "PLAN", full: bool = True) -> dict:
    """Read and check a ``plan.json`` (schema ``markerplan-plan``).

    Parameters
    ----------
    path : str or Path
        The file written by ``markerplan plan``.
    option : str
        How messages name the argument (``"PLAN"``, ``"INPUT"``).
    full : bool
        Require every part ``verify`` reads (``schema_version``, ``site``, ``requirement``,
        ``provenance``, at least one station); else only ``schema`` and ``markers``.

    Returns
    -------
    doc : dict
        The document, unchanged.

    Raises
    ------
    InputFileError
        Missing, unreadable or non-UTF-8 file; not JSON (or NaN/Infinity in it); not a JSON
        object; another schema or a ``schema_version`` newer than :data:`SCHEMA_VERSION`;
        missing keys; a value of the wrong type at any depth read; numbers that are not finite
        or beyond their bounds; zero markers or stations (or more than
        :data:`~planner.config.MAX_MARKERS` / :data:`~planner.config.MAX_STATIONS`);
        repeated ids; a station naming a marker the plan lacks.

    Examples
    --------
    >>> import tempfile, os
    >>> p = os.path.join(tempfile.mkdtemp(), "plan.json")
    >>> _ = open(p, "w").write('{"schema": "markerplan-plan", "markers": []}')
    >>> read_plan(p, "INPUT", full=False)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    markerplan.errors.InputFileError: INPUT ...: 'markers' is empty; a plan needs at least ...
    """
    what = f"{option} {path}"
    text = read_text(path, what)
    try:
        doc = parse_json(text, what, expect=object)
    except InputFileError as exc:
        raise InputFileError(f"{what}: not a JSON file ({exc.__cause__}); give the plan.json "
                             "written by `markerplan plan`") from exc
    if not isinstance(doc, dict):
        raise InputFileError(f"{what}: expected a JSON object at the top level, got "
                             f"{json_kind(doc)}; give the plan.json written by `markerplan plan`")
    return _plan_iv(doc, what, full)


def _plan_iv(doc: dict, what: str, full: bool) -> dict:
    if doc.get("schema") != SCHEMA:
        raise InputFileError(f"{what}: not a markerplan plan (schema {doc.get('schema')!r:.40}, "
                             f"expected {SCHEMA!r}); give the plan.json written by "
                             "`markerplan plan`")
    required = ["schema_version", "site", "requirement", "provenance", "markers", "stations"]
    require_keys(doc, required if full else ["markers"], what, _FIX)
    if "schema_version" in doc:
        check_schema_version(doc["schema_version"], SCHEMA_VERSION, what)
    if "site" in doc:
        _site_iv(doc["site"], f"{what}: site", full)
    if "requirement" in doc:
        _requirement_iv(doc["requirement"], f"{what}: requirement")
    if "provenance" in doc:
        _provenance_iv(doc["provenance"], f"{what}: provenance", full)
    marker_ids = _markers_iv(doc["markers"], what)
    if "stations" in doc:
        _stations_iv(doc["stations"], what, set(marker_ids))
    if "local" in doc:
        _local_iv(doc["local"], f"{what}: local",
                  {s["id"] for s in doc.get("stations", ())})
    return doc


def _local_iv(local: Any, what: str, station_ids: set[str]) -> None:
    """A plan's ``local`` section (:mod:`planner.outputs.local_report`): its kind, and every
    pair's two known stations, separation, allowance and prediction (a number or null)."""
    require_type(local, dict, what)
    require_keys(local, ["requirement_text", "local_kind", "pairs"], what, _FIX)
    require_type(local["requirement_text"], str, f"{what} requirement_text")
    if local["local_kind"] not in LOCAL_KINDS:
        raise InputFileError(f"{what} local_kind: must be one of {', '.join(LOCAL_KINDS)}, got "
                             f"{local['local_kind']!r:.40}; {_FIX}")
    for i, pair in enumerate(require_type(local["pairs"], list, f"{what} pairs")):
        where = f"{what} pairs[{i}]"
        require_type(pair, dict, where)
        require_keys(pair, ["stations", "separation_m", "allowed_error_m",
                            "predicted_error_m"], where, _FIX)
        ids = require_type(pair["stations"], list, f"{where} stations")
        if len(ids) != 2 or not all(isinstance(s, str) and s in station_ids for s in ids):
            raise InputFileError(f"{where} stations: must be two of the plan's station ids, "
                                 f"got {ids!r:.60}; {_FIX}")
        _number(pair, "separation_m", where, 0.0, low_inclusive=True)
        _number(pair, "allowed_error_m", where, 0.0)
        _number(pair, "predicted_error_m", where, 0.0, nullable=True, low_inclusive=True)


def _number(obj: dict, key: str, what: str, low: float | None = None,
            high: float = math.inf, nullable: bool = False, low_inclusive: bool = False,
            max_abs: float = MAX_ABS_COORDINATE_M) -> None:
    """``obj[key]`` must be a finite JSON number of magnitude at most ``max_abs``, above
    ``low`` (or at it if ``low_inclusive``) and at most ``high``; null too if ``nullable``."""
    v = obj[key]
    if v is None and nullable:
        return
    x = json_number(v, f"{what} {key}", max_abs)
    too_low = low is not None and (x < low if low_inclusive else x <= low)
    if too_low or x > high:
        bounds = f"{'[' if low_inclusive else '('}{low:g}, {high:g}]"
        raise InputFileError(f"{what} {key}: must be in {bounds}, got {x:g}; {_FIX}")


def _site_iv(site: Any, what: str, full: bool) -> None:
    require_type(site, dict, what)
    if full:
        require_keys(site, ["name"], what, _FIX)
    if "name" in site:
        require_type(site["name"], str, f"{what} name")
    if site.get("seed") is not None:
        require_type(site["seed"], int, f"{what} seed")
    if "marker_radius_m" in site:
        _number(site, "marker_radius_m", what, 0.0, MAX_MARKER_RADIUS_M)


def _requirement_iv(req: Any, what: str) -> None:
    require_type(req, dict, what)
    require_keys(req, ["requirement_m", "working_radius_m"], what, _FIX)
    _number(req, "requirement_m", what, *REQUIREMENT_BOUNDS_M)
    _number(req, "working_radius_m", what, *WORKING_RADIUS_BOUNDS_M)
    if "datum_requirement" in req:
        require_type(req["datum_requirement"], bool, f"{what} datum_requirement")
    if "requirement_ppm" in req:
        _number(req, "requirement_ppm", what, 0.0, BOUNDS["requirement_ppm"][2],
                low_inclusive=True)
    for key in ("n_sectors", "min_sectors", "min_markers"):
        if key in req:
            low, _, high, _ = BOUNDS[key]
            if not isinstance(req[key], int) or isinstance(req[key], bool) \
                    or not low <= req[key] <= high:
                raise InputFileError(f"{what} {key} must be a whole number in [{low}, {high}], "
                                     f"got {req[key]!r}; {_FIX}")


def _provenance_iv(prov: Any, what: str, full: bool) -> None:
    require_type(prov, dict, what)
    if full:
        require_keys(prov, ["config_sha256"], what, _FIX)
    if "config_sha256" in prov:
        require_type(prov["config_sha256"], str, f"{what} config_sha256")
    if "config" in prov:
        require_type(prov["config"], dict, f"{what} config")
    if "inputs" in prov:
        inputs = require_type(prov["inputs"], dict, f"{what} inputs")
        for key in ("site", "dem", "stations"):
            if inputs.get(key) is not None:
                require_type(inputs[key], str, f"{what} inputs {key}")
        if "reproject" in inputs:
            require_type(inputs["reproject"], bool, f"{what} inputs reproject")
        if inputs.get("dem_window") is not None:
            window = require_type(inputs["dem_window"], list, f"{what} inputs dem_window")
            if len(window) != 4:
                raise InputFileError(f"{what} inputs dem_window: must be [xmin, xmax, ymin, "
                                     f"ymax], got {len(window)} numbers; {_FIX}")
            for v in window:
                json_number(v, f"{what} inputs dem_window", MAX_ABS_COORDINATE_M)
        if "station_ids" in inputs:
            for sid in require_type(inputs["station_ids"], list, f"{what} inputs station_ids"):
                require_type(sid, str, f"{what} inputs station_ids entry")


def _entries(value: Any, what: str, name: str, most: int) -> list[dict]:
    """A non-empty list of at most ``most`` objects."""
    require_type(value, list, f"{what}: {name}")
    if not value:
        raise InputFileError(f"{what}: {name!r} is empty; a plan needs at least one "
                             f"{name[:-1]}")
    if len(value) > most:
        raise InputFileError(f"{what}: {len(value)} {name}, more than the {most} accepted; "
                             f"{_FIX}")
    for k, e in enumerate(value):
        require_type(e, dict, f"{what}: {name}[{k}]")
        require_keys(e, ["id", "x_m", "y_m", "z_m"], f"{what}: {name}[{k}]", _FIX)
        require_type(e["id"], str, f"{what}: {name}[{k}] id")
        for key in ("x_m", "y_m", "z_m"):
            _number(e, key, f"{what}: {name}[{k}]")
    return value


def _markers_iv(markers: Any, what: str) -> list[str]:
    entries = _entries(markers, what, "markers", MAX_MARKERS)
    return unique_ids([m["id"] for m in entries], f"{what}: markers")


def _stations_iv(stations: Any, what: str, marker_ids: set[str]) -> None:
    entries = _entries(stations, what, "stations", MAX_STATIONS)
    unique_ids([s["id"] for s in entries], f"{what}: stations")
    for s in entries:
        where = f"{what}: station {s['id']!r:.40}"
        if "heading_rad" in s:
            _number(s, "heading_rad", where, nullable=True, max_abs=MAX_ABS_HEADING_RAD)
        if "predicted_error_m" in s:
            _number(s, "predicted_error_m", where, 0.0, nullable=True, low_inclusive=True)
        if "markers" in s:
            used = require_type(s["markers"], list, f"{where} markers")
            for m in used:
                require_type(m, str, f"{where} markers entry")
                if m not in marker_ids:
                    raise InputFileError(f"{where} uses marker {m!r:.40}, which is not among the "
                                         f"plan's markers; {_FIX}")
