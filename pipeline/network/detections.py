"""From ``markers.csv`` tables to the observations of a network adjustment.

Three steps, each a function, which :func:`pipeline.network.run.adjust_tables` strings
together:

1. :func:`read_detections` — the accepted detections of every station in the marker tables of
   ``markerplan process`` (:func:`pipeline.tables.marker_table.read_marker_table`), each with its
   1-sigma 3D centre error from the error model at its distance and elevation (as ``verify``
   weighs them);
2. marker identity, one of :data:`IDENTITIES`:

   - ``plan``: gated association of each station's detections with the plan's markers from the
     station's nominal pose (the plan's, standing in for rover odometry, with its sigma):
     :func:`identify_with_plan`, given the plan as :class:`PlanGeometry` (plain data, which
     the planner reads from a ``plan.json``);
   - ``geometry``: consistent inter-marker distances across stations, no plan needed; markers are
     named ``M001``... (:func:`identify_by_geometry`);
   - ``table``: the table's ``marker_id`` column, i.e. ids assigned in the field (coded targets, a
     hand-made list). ``process`` fills that column from the reference it was given, which for
     simulated scans is the simulator's truth, so ``plan`` and ``geometry`` are the ones that
     test identification (:func:`identify_from_table`);
3. :func:`network_observations` — the identified detections as
   :class:`pipeline.network.observations.NetworkObservations` (stations in the order the tables
   give them, so the first station is the default datum).

Frames: detections are in each station's levelled station frame (origin at the LiDAR centre, z
up, x along the station's nominal heading); the plan's markers and stations are in the site
frame. Control points for the datum come from a CSV (:func:`read_control`). Every refusal is
one :class:`~markerplan.errors.InputFileError` line naming the table, the station or the plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from markerplan.errors import InputFileError
from markerplan.reading import finite_number, read_csv, unique_ids

#: Ways to establish marker identity across stations (``adjust --marker-ids``).
IDENTITIES = ("plan", "geometry", "table")

#: Smallest 1-sigma centre error given to a detection, m: an error model predicting ~0 (a
#: marker at the sensor) would otherwise give it an infinite weight (``verify`` floors it so).
MIN_SIGMA_M = 1e-4

#: Largest distance of a detection from its LiDAR centre, m: beyond any LiDAR's range, a
#: table holding it is corrupt.
MAX_DISTANCE_M = 1_000.0

CONTROL_COLUMNS = ("id", "x_m", "y_m", "z_m", "sigma_m")


@dataclass(frozen=True)
class StationDetections:
    """The accepted detections of one station.

    Attributes
    ----------
    station_id : str
    table : Path
        The marker table they come from.
    xyz_m : (n, 3) float
        Marker centres, levelled station frame, m.
    sigma_m : (n,) float
        1-sigma 3D centre error from the error model, m.
    table_ids : tuple of str
        The table's ``marker_id`` of each detection (``""`` when unmatched).
    in_domain : (n,) bool
        Whether the error model was fitted at that distance and elevation.
    """

    station_id: str
    table: Path
    xyz_m: np.ndarray
    sigma_m: np.ndarray
    table_ids: tuple[str, ...]
    in_domain: np.ndarray


@dataclass(frozen=True)
class Identified:
    """Detections with their marker ids: the observations, and what could not be identified.

    Attributes
    ----------
    stations : list of StationDetections
        In table order.
    ids : list of list of (str or None)
        Marker id of every detection of every station (``None``: not identified, left out).
    method : str
        One of :data:`IDENTITIES`.
    reasons : list of list of str, optional
        Why each detection got its id or none (e.g. the association's ``outside_gate``,
        ``ambiguous``); empty when the method gives no reasons.
    """

    stations: list[StationDetections]
    ids: list[list[str | None]]
    method: str
    reasons: list[list[str]] = field(default_factory=list)

    @property
    def unidentified(self) -> list[tuple[str, np.ndarray, str]]:
        """``(station_id, xyz_m, reason)`` of every detection left out (levelled station
        frame; ``reason`` empty when the method gives none)."""
        reasons = self.reasons or [[""] * len(ids) for ids in self.ids]
        return [(s.station_id, s.xyz_m[k], why[k])
                for s, ids, why in zip(self.stations, self.ids, reasons, strict=True)
                for k, i in enumerate(ids) if i is None]


def read_detections(tables: list[Path], error_model) -> list[StationDetections]:
    """The accepted detections of every station in ``tables``, weighted by ``error_model``.

    Parameters
    ----------
    tables : list of Path
        ``markers.csv`` files of ``markerplan process`` (one or more stations each).
    error_model : error_model.model.ErrorModel
        Gives each detection's 1-sigma 3D error at its ``distance_m`` and ``elevation_deg``
        (floored at :data:`MIN_SIGMA_M`).

    Returns
    -------
    stations : list of StationDetections
        In the order the stations first appear (tables in the order given); stations whose
        detections were all rejected by the quality gate are left out.

    Raises
    ------
    InputFileError
        Missing or unreadable table, wrong columns, a repeated row or an ``accepted`` other
        than true/false (:func:`read_marker_table`), a table given twice, a table without any
        accepted detection, a station in two tables, accepted detections of more than one
        centre estimator, or a non-finite or absurd number in an accepted row.
    """
    from pipeline.tables.marker_table import read_marker_table

    seen: dict[Path, Path] = {}
    estimator: dict[str, tuple[Path, int]] = {}
    per_station: dict[str, list[tuple[Path, dict[str, str], int]]] = {}
    source: dict[str, Path] = {}
    for table in tables:
        key = Path(table).resolve()
        if key in seen:
            first = seen[key]
            raise InputFileError(f"marker table {table} is given twice (also as {first}); give "
                                 "each table once")
        seen[key] = Path(table)
        rows = read_marker_table(table)
        accepted = [(row, line) for line, row in enumerate(rows, start=2)
                    if row["accepted"] == "true"]
        if not accepted:
            raise InputFileError(f"marker table {table} holds no accepted detection "
                                 f"({len(rows)} row(s), none with accepted=true); give the "
                                 "markers.csv of `markerplan process` for stations that saw "
                                 "markers")
        for row, line in accepted:
            sid = row["station_id"].strip()
            if not sid:
                raise InputFileError(f"marker table {table} row {line}: station_id is empty")
            owner = source.setdefault(sid, table)
            if owner != table:
                raise InputFileError(f"station {sid} is in marker tables {owner} and {table}; "
                                     "give each station's detections once")
            per_station.setdefault(sid, []).append((table, row, line))
            estimator.setdefault(row["estimator"].strip(), (table, line))
    _one_estimator(estimator)
    return [_station(sid, items, error_model) for sid, items in per_station.items()]


def _one_estimator(first_row: dict[str, tuple[Path, int]]) -> None:
    """Refuse detections of a second centre estimator (``first_row``: estimator -> the table
    and row of its first accepted detection, in reading order)."""
    if len(first_row) < 2:
        return
    (name_a, (table_a, line_a)), (name_b, (table_b, line_b)) = list(first_row.items())[:2]
    raise InputFileError(
        f"marker table {table_b} row {line_b}: estimator {name_b!r}, but the detections up to "
        f"there (from {table_a} row {line_a}) are {name_a!r}; adjust the detections of one "
        "centre estimator (the error model describes one, and each estimator sees every marker "
        "again): keep one estimator's rows, or process every station with the same estimator "
        "(markerplan process)")


def _station(sid: str, items: list[tuple[Path, dict[str, str], int]],
             error_model) -> StationDetections:
    table = items[0][0]
    xyz, dist, elev = [], [], []
    for _, row, line in items:
        what = f"marker table {table} row {line}"
        xyz.append([finite_number(row[c], f"{what} {c}") for c in ("x_m", "y_m", "z_m")])
        dist.append(finite_number(row["distance_m"], f"{what} distance_m", MAX_DISTANCE_M))
        elev.append(finite_number(row["elevation_deg"], f"{what} elevation_deg", 90.0))
        if dist[-1] <= 0.0:
            raise InputFileError(f"{what} distance_m: must be > 0, got {dist[-1]:g}")
    pred = error_model.predict(np.array(dist), np.radians(elev))
    return StationDetections(
        sid, Path(table), np.array(xyz, dtype=float),
        np.maximum(np.asarray(pred.sigma_m, dtype=float), MIN_SIGMA_M),
        tuple(row["marker_id"].strip() for _, row, _ in items),
        np.asarray(pred.in_domain, dtype=bool))


@dataclass(frozen=True)
class PlanGeometry:
    """What association and the report take from a ``plan.json`` (site frame, m, rad)."""

    path: Path
    marker_ids: tuple[str, ...]
    marker_xyz_m: np.ndarray
    """(k, 3) planned marker centres."""
    station_ids: tuple[str, ...]
    station_xyz_m: np.ndarray
    """(s, 3) planned LiDAR centres."""
    station_heading_rad: np.ndarray
    """(s,) planned headings."""
    working_radius_m: float
    requirement_m: float
    inclinometer_sigma_deg: float | None
    """The plan's configured inclinometer sigma, or ``None`` when it records none."""
    heading_prior_sigma_deg: float | None
    """The heading prior the plan assumed (network mode), or ``None``."""
    reference_station: str | None
    """The datum station the plan assumed (network mode), or ``None``."""
    dem: str | None
    """The ``--dem`` the plan was made on, or ``None`` for a preset's terrain."""
    crs: str | None = None
    """The CRS (WKT) of the plan's site frame, or ``None`` for local metres."""
    error_figure: str = "ellipsoid"
    """The 95 % figure the plan judged its requirement by (``"quantile"`` or ``"ellipsoid"``;
    a plan that records none used the ellipsoid)."""
    heading_bias_sigma_deg: float | None = None
    """The heading reference's boresight bias the plan assumed, 1-sigma degrees (its
    ``network.datum`` record of the aids: the ``heading_aid`` class's or the plan's setting),
    or ``None`` for none."""


def identify_with_plan(stations: list[StationDetections], plan: PlanGeometry,
                       odometry_sigma_m: float, odometry_heading_sigma_rad: float) -> Identified:
    """Marker ids by gated association with the plan's markers, from each station's nominal
    (planned) pose with the odometry's sigma
    (:func:`pipeline.network.association.associate_with_plan`).

    Raises
    ------
    InputFileError
        A station the plan does not hold, or a station none of whose detections matches a
        planned marker (both: a table from another site).
    """
    foreign = [s.station_id for s in stations if s.station_id not in plan.station_ids]
    if foreign:
        raise InputFileError(
            f"station(s) {', '.join(foreign)} of the marker tables are not in `plan_path` "
            f"{plan.path} (it holds {_id_range(plan.station_ids)}); are the tables from "
            "another site? Give that site's plan, or leave out `plan_path` to associate by "
            "geometry")
    from pipeline.network.association import associate_with_plan

    ids, reasons = [], []
    for s in stations:
        k = plan.station_ids.index(s.station_id)
        found = associate_with_plan(
            s.xyz_m, plan.station_xyz_m[k], float(plan.station_heading_rad[k]),
            plan.marker_xyz_m, list(plan.marker_ids), s.sigma_m, odometry_sigma_m,
            odometry_heading_sigma_rad)
        if not any(i is not None for i in found.ids):
            raise InputFileError(
                f"none of the {len(found.ids)} detection(s) of station {s.station_id} "
                f"({s.table}) matches a marker of `plan_path` {plan.path} within the odometry's "
                f"sigma ({odometry_sigma_m:g} m, {math.degrees(odometry_heading_sigma_rad):g} "
                "deg); is the table from another site, or is `odometry_sigma_m` too small?")
        ids.append(list(found.ids))
        reasons.append(list(found.status))
    return Identified(stations, ids, "plan", reasons)


def identify_by_geometry(stations: list[StationDetections],
                         inclinometer_sigma_rad: float) -> Identified:
    """Marker ids from consistent inter-marker distances across stations
    (:func:`pipeline.network.association.associate_by_geometry`, with each detection's sigma and
    the inclinometer's residual tilt); a marker seen by one station gets an id of its own.

    Raises
    ------
    InputFileError
        Stations matched with no other station (so they share no marker with the network),
        naming why: the residual tilt blurring the detections beyond their centre error, or
        too little overlap or a repeating layout.
    """
    from pipeline.network.association import associate_by_geometry

    found = associate_by_geometry([(s.station_id, s.xyz_m) for s in stations],
                                  [s.sigma_m for s in stations],
                                  inclinometer_sigma_rad=inclinometer_sigma_rad)
    _refuse_unmatched(stations, found.pairs, inclinometer_sigma_rad)
    return Identified(stations, [list(i) for i in found.ids], "geometry")


def _refuse_unmatched(stations: list[StationDetections], pairs, inclinometer_sigma_rad: float
                      ) -> None:
    """Refuse the stations no pair of :func:`identify_by_geometry` matched (``pairs``:
    :class:`~pipeline.network.association.StationPairMatch`), naming the likely cause."""
    matched = {sid for p in pairs if p.status == "matched" for sid in (p.station_a, p.station_b)}
    lone = [s for s in stations if s.station_id not in matched]
    if len(stations) < 2 or not lone:
        return
    ids = {s.station_id for s in lone}
    statuses = [p.status for p in pairs if {p.station_a, p.station_b} & ids]
    counts = ", ".join(f"{statuses.count(k)} {k.replace('_', ' ')}"
                       for k in ("ambiguous", "no_overlap") if k in statuses)
    distance_m = float(np.median(np.concatenate([np.linalg.norm(s.xyz_m, axis=1) for s in lone])))
    centre_m = float(np.median(np.concatenate([s.sigma_m for s in lone]))) / math.sqrt(3.0)
    tilt_m = inclinometer_sigma_rad * distance_m
    if tilt_m > centre_m:
        cause = (f"at their median distance {distance_m:.3g} m the residual tilt "
                 f"(`inclinometer_sigma_deg` {math.degrees(inclinometer_sigma_rad):g} deg) "
                 f"blurs each detection by {tilt_m:.2g} m (1-sigma per axis, against "
                 f"{centre_m:.2g} m of centre error), so inter-marker distances cannot tell the "
                 "markers apart; give a smaller `inclinometer_sigma_deg`, `plan_path` or "
                 "`identity` table")
    else:
        cause = ("they share too few markers with the others, or the layout repeats itself (a "
                 "grid, a circle); give `plan_path` or `identity` table, or leave them out")
    raise InputFileError(f"`identity` geometry: station(s) {_id_range(tuple(sorted(ids)))} "
                         f"match no other station ({counts} station pairs): {cause}")


def identify_from_table(stations: list[StationDetections]) -> Identified:
    """Marker ids from the tables' ``marker_id`` column (empty: not identified).

    Raises
    ------
    InputFileError
        No detection of any station carries a marker id.
    """
    ids = [[i or None for i in s.table_ids] for s in stations]
    if not any(i is not None for row in ids for i in row):
        raise InputFileError("`identity` table: no accepted detection in the tables has a "
                             "marker_id; give `plan_path`, or use `identity` geometry")
    return Identified(stations, ids, "table")


def network_observations(identified: Identified):
    """The identified detections as :class:`pipeline.network.observations.NetworkObservations`.

    Stations keep the order of ``identified.stations`` (those with no identified detection are
    left out); markers are numbered in order of first sight. Unidentified detections are left
    out.

    Parameters
    ----------
    identified : Identified

    Returns
    -------
    obs : pipeline.network.observations.NetworkObservations
        Levelled station frames, m; ``sigma_m`` the error model's.
    """
    from pipeline.network.observations import NetworkObservations

    station_ids, marker_ids = [], {}
    st, mk, xyz, sig = [], [], [], []
    for s, ids in zip(identified.stations, identified.ids, strict=True):
        keep = [k for k, i in enumerate(ids) if i is not None]
        if not keep:
            continue
        station_ids.append(s.station_id)
        for k in keep:
            st.append(len(station_ids) - 1)
            mk.append(marker_ids.setdefault(ids[k], len(marker_ids)))
            xyz.append(s.xyz_m[k])
            sig.append(s.sigma_m[k])
    return NetworkObservations(tuple(station_ids), tuple(marker_ids), np.array(st, dtype=int),
                               np.array(mk, dtype=int), np.array(xyz, dtype=float).reshape(-1, 3),
                               np.array(sig, dtype=float))


def read_control(path: Path):
    """Control points from a CSV ``id,x_m,y_m,z_m,sigma_m`` (site frame, m; ``sigma_m`` the
    1-sigma error of each coordinate).

    Returns
    -------
    control : tuple of pipeline.network.observations.ControlPoint

    Raises
    ------
    InputFileError
        Missing file, missing columns, no rows, repeated or empty ids, non-finite numbers or a
        sigma below :data:`pipeline.network.observations.MIN_SIGMA`.
    """
    from pipeline.network.observations import SIGMA_RULE, ControlPoint, usable_sigma

    what = f"`control_path` {path}"
    header, rows = read_csv(path, what, CONTROL_COLUMNS,
                            "give one row per control point: id,x_m,y_m,z_m,sigma_m")
    if not rows:
        raise InputFileError(f"{what}: no control points; give one row per point "
                             "(id,x_m,y_m,z_m,sigma_m)")
    col = {c: header.index(c) for c in CONTROL_COLUMNS}
    ids = unique_ids([r[col["id"]].strip() for r in rows], what)
    points = []
    for line, (cid, r) in enumerate(zip(ids, rows, strict=True), start=2):
        xyz = [finite_number(r[col[c]], f"{what} row {line} {c}") for c in ("x_m", "y_m", "z_m")]
        sigma = finite_number(r[col["sigma_m"]], f"{what} row {line} sigma_m")
        if not usable_sigma(sigma):
            raise InputFileError(f"{what} row {line} sigma_m: must be {SIGMA_RULE}, got "
                                 f"{sigma:g}")
        points.append(ControlPoint(cid, np.array(xyz), np.full(3, sigma)))
    return tuple(points)


def _id_range(ids: tuple[str, ...]) -> str:
    """A short list of ids for messages.

    >>> _id_range(("S1", "S2")), _id_range(tuple(f"S{i}" for i in range(1, 9)))
    ('S1, S2', 'S1, S2, S3, ..., S8 (8 stations)')
    """
    if len(ids) <= 4:
        return ", ".join(ids)
    return f"{', '.join(ids[:3])}, ..., {ids[-1]} ({len(ids)} stations)"


def nominal_poses(plan, obs):
    """Planned poses of the network's stations, the adjustment's odometry.

    Parameters
    ----------
    plan : PlanGeometry or None
    obs : pipeline.network.observations.NetworkObservations

    Returns
    -------
    nominal : pipeline.network.observations.NominalPoses or None
        Positions (s, 3), site frame, m, and headings (s,), rad, in ``obs.station_ids``'
        order (the plan's order is not the tables'); ``None`` without a plan.
    """
    if plan is None:
        return None
    from pipeline.network.observations import NominalPoses

    k = [plan.station_ids.index(s) for s in obs.station_ids]
    return NominalPoses(plan.station_xyz_m[k], plan.station_heading_rad[k])
