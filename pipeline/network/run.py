"""Marker tables in, adjusted network out: read the detections, identify the markers, adjust.

:func:`adjust_tables` is the one sequence that ``markerplan adjust`` and ``verify --network``
both run (:mod:`pipeline.network.detections`, then :func:`pipeline.network.adjustment.adjust`).
What differs between them is passed in: how the datum station is chosen among the stations
the tables hold, and how the markers are identified. A plan, when there is one, comes as
:class:`~pipeline.network.detections.PlanGeometry` data (its poses are the adjustment's
odometry); nothing here reads a ``plan.json``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from pipeline.network.adjustment import AdjustmentSettings, NetworkAdjustment, adjust
from pipeline.network.detections import (
    Identified,
    PlanGeometry,
    StationDetections,
    network_observations,
    nominal_poses,
    read_detections,
)
from pipeline.network.observations import ControlPoint, Datum, NetworkObservations


@dataclass(frozen=True)
class TablesAdjustment:
    """What :func:`adjust_tables` produced.

    Attributes
    ----------
    stations : list of StationDetections
        The accepted detections of every station the tables hold, in table order.
    identified : Identified
        Their marker ids (the stations ``identify`` kept).
    observations : NetworkObservations
        The identified detections, before data snooping (``result.observations`` holds the
        ones the adjustment kept).
    result : NetworkAdjustment
    reference_station : str or None
        The datum station chosen (``None``: the first station of ``observations``).
    timings_s : dict of str to float
        Seconds spent to ``read``, ``identify`` and ``adjust``.
    """

    stations: list[StationDetections]
    identified: Identified
    observations: NetworkObservations
    result: NetworkAdjustment
    reference_station: str | None
    timings_s: dict[str, float]


def adjust_tables(tables: Sequence[Path], error_model,
                  reference: Callable[[list[StationDetections]], str | None],
                  identify: Callable[[list[StationDetections]], Identified],
                  settings: AdjustmentSettings, datum_kind: str = "station",
                  control: tuple[ControlPoint, ...] = (),
                  plan: PlanGeometry | None = None,
                  aids: Callable[[NetworkObservations], tuple] | None = None
                  ) -> TablesAdjustment:
    """Read the marker tables, identify their markers and adjust the network.

    Parameters
    ----------
    tables : sequence of Path
        ``markers.csv`` files of ``markerplan process``.
    error_model : error_model.model.ErrorModel
        Weights of the detections (:func:`pipeline.network.detections.read_detections`).
    reference : callable
        ``reference(stations)`` -> the datum station among the stations read (``None``: the
        first); it raises when the one wanted is missing.
    identify : callable
        ``identify(stations)`` -> their marker ids
        (e.g. :func:`pipeline.network.detections.identify_with_plan` with its options bound).
    settings : AdjustmentSettings
        Priors (rad), test levels and iteration limits of the adjustment.
    datum_kind : {"station", "control", "free"}
        What fixes the datum (:class:`pipeline.network.observations.Datum`).
    control : tuple of ControlPoint
        The control points of ``"control"``, site frame, m.
    plan : PlanGeometry, optional
        The plan whose planned poses (site frame, m, rad) are the stations' odometry.
    aids : callable, optional
        ``aids(observations)`` -> ``(odometry, heading)``: the pose aids' readings of the
        identified network (:class:`~pipeline.network.aids.OdometryReadings`,
        :class:`~pipeline.network.aids.HeadingReadings`, either None), passed to
        :func:`~pipeline.network.adjustment.adjust`.

    Returns
    -------
    TablesAdjustment

    Raises
    ------
    InputFileError
        As :func:`~pipeline.network.detections.read_detections`, ``reference``, ``identify``
        and :func:`~pipeline.network.adjustment.adjust` raise it.
    ConfigError
        As ``reference`` raises it.
    """
    t0 = time.perf_counter()
    stations = read_detections(list(tables), error_model)
    station = reference(stations)
    t1 = time.perf_counter()
    identified = identify(stations)
    obs = network_observations(identified)
    t2 = time.perf_counter()
    odometry, heading = aids(obs) if aids is not None else (None, None)
    result = adjust(obs, Datum(datum_kind, station, control), settings, nominal_poses(plan, obs),
                    odometry=odometry, heading=heading)
    t3 = time.perf_counter()
    return TablesAdjustment(stations, identified, obs, result, station,
                            {"read": t1 - t0, "identify": t2 - t1, "adjust": t3 - t2})
