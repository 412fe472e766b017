"""The association step of a network verification: which planned marker each scanned
detection is (:func:`tied_network`, gated by the planned poses as odometry), the stations it
ties to the datum station, the marker table with the association's ids
(:func:`identified_rows`) and the detections it named wrongly against the simulator's truth
(:func:`misidentified`)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from markerplan.errors import InputFileError
from pipeline.network.detections import Identified
from pipeline.tables.marker_table import MarkerRow, read_marker_table
from planner.verify.fates import StationFates

if TYPE_CHECKING:
    from planner.verify.network import NetworkVerification, NetworkVerifySettings


def identified_rows(rows: list[MarkerRow], check: NetworkVerification) -> list[MarkerRow]:
    """The marker-table rows with ``marker_id`` filled: each accepted detection gets the id the
    association gave it (``check.detection_ids``), the rest stay empty.

    Parameters
    ----------
    rows : list of MarkerRow
        :func:`scan_plan`'s rows (every candidate of every station, in table order).
    check : NetworkVerification
        :func:`adjust_and_compare`'s result on those rows.

    Returns
    -------
    rows : list of MarkerRow
        Copies, in the same order.
    """
    seen: dict[str, int] = {}
    out = []
    for row in rows:
        name = ""
        if row.accepted:
            k = seen[row.station_id] = seen.get(row.station_id, -1) + 1
            ids = check.detection_ids.get(row.station_id, ())
            name = (ids[k] if k < len(ids) else None) or ""
        out.append(dataclasses.replace(row, marker_id=name))
    return out


def misidentified(tables: list[Path], identified: Identified,
                  fates: dict[str, StationFates]) -> list[dict]:
    """The accepted planned markers whose detection the association did not give their true id.

    Parameters
    ----------
    tables : list of Path
        The marker tables the association read (a station's accepted rows, in order, are its
        detections).
    identified : Identified
        The association's ids of the adjusted stations.
    fates : dict of str to StationFates
        Per station, the fates of its planned markers (``candidate``: the row among the
        station's rows of the tables).

    Returns
    -------
    wrong : list of dict
        ``station_id``, ``marker_id`` (the true id), ``identified_as`` (the association's id,
        ``None`` when it left the detection unidentified), in the stations' order.
    """
    accepted_rows: dict[str, list[int]] = {}
    for table in tables:
        count: dict[str, int] = {}
        for row in read_marker_table(table):
            sid = row["station_id"]
            count[sid] = count.get(sid, 0) + 1
            if row["accepted"] == "true":
                accepted_rows.setdefault(sid, []).append(count[sid] - 1)
    wrong = []
    for s, ids in zip(identified.stations, identified.ids, strict=True):
        position = {row: j for j, row in enumerate(accepted_rows.get(s.station_id, ()))}
        station = fates.get(s.station_id)
        for fate in station.rows if station else ():
            named = ids[position[fate.candidate]] if fate.accepted else fate.marker_id
            if named != fate.marker_id:
                wrong.append({"station_id": s.station_id, "marker_id": fate.marker_id,
                              "identified_as": named})
    return wrong


def datum_station(reference: str, stations: list) -> str:
    """``reference``, checked to be among the stations with accepted detections (an
    :func:`pipeline.network.run.adjust_tables` ``reference``)."""
    if reference not in [s.station_id for s in stations]:
        raise InputFileError(f"the reference station {reference} (the datum) has no accepted "
                             "detection, so the network has no datum; the plan cannot be "
                             "verified in network mode")
    return reference


def tied_network(stations: list, plan, reference: str, settings: NetworkVerifySettings):
    """Identify every station's detections with the plan's markers and keep the stations tied to
    the reference; a station that is not is a failed station of the verification, not an error.

    Parameters
    ----------
    stations : list of pipeline.network.detections.StationDetections
    plan : pipeline.network.detections.PlanGeometry
    reference : str
        The datum station.
    settings : NetworkVerifySettings
        The odometry sigmas of the gated association.

    Returns
    -------
    identified : pipeline.network.detections.Identified
        The stations kept (tied to the reference through chains of >= 2 shared identified
        markers, as :func:`pipeline.network.adjustment.adjust` requires) and their ids.
    left_out : dict of str to str
        Why each other station was left out.
    detection_ids : dict of str to tuple of (str or None)
        The association's id of each accepted detection of every station it matched, kept or
        not (``None``: left unidentified).

    Raises
    ------
    InputFileError
        The reference station has no identified detection (the network has no datum).
    """
    from pipeline.network import detections as no
    from pipeline.network.adjustment import tie_order

    left_out: dict[str, str] = {}
    detection_ids: dict[str, tuple[str | None, ...]] = {}
    kept, ids, reasons = [], [], []
    for s in stations:
        try:
            one = no.identify_with_plan([s], plan, settings.odometry_sigma_m,
                                        math.radians(settings.odometry_heading_sigma_deg))
        except InputFileError:  # no detection inside the odometry gate of a planned marker
            left_out[s.station_id] = ("none of its detections matches a planned marker within "
                                      "the odometry's sigma")
            continue
        detection_ids[s.station_id] = tuple(one.ids[0])
        if any(i is not None for i in one.ids[0]):
            kept.append(s)
            ids += one.ids
            reasons += one.reasons
        else:
            left_out[s.station_id] = "no detection identified (ambiguous association)"
    identified = no.Identified(kept, ids, "plan", reasons)
    obs = no.network_observations(identified)
    if reference not in obs.station_ids:
        why = left_out.get(reference, "no accepted detection")
        raise InputFileError(f"the reference station {reference} (the datum) has no detection "
                             f"identified with a planned marker ({why}), so the network has no "
                             "datum and cannot be verified")
    _, untied = tie_order(obs, np.ones(obs.n, dtype=bool), obs.station_ids.index(reference))
    if untied:
        names = {obs.station_ids[i] for i in untied}
        for k, sid in enumerate(obs.station_ids):
            if sid in names:
                n = len(set(obs.marker[obs.station == k]))
                left_out[sid] = (f"{n} identified marker(s), fewer than 2 shared with the part "
                                 f"of the network holding the reference {reference}")
        keep = [k for k, s in enumerate(kept) if s.station_id not in names]
        identified = no.Identified([kept[k] for k in keep], [ids[k] for k in keep], "plan",
                                   [reasons[k] for k in keep])
    return identified, left_out, detection_ids
