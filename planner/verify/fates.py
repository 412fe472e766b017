"""The fate of every planned marker in a verification, against the simulator's truth (both
modes): the stage of the chain that lost it (:mod:`pipeline.surveys.fates`: ``not_in_view``,
``ground``, ``cluster``, ``gate``, ``fit``, ``quality``) and why, or ``accepted``.

:func:`station_fates` builds a station's :class:`StationFates` inside its task (small: it
travels back from a worker); :func:`write_fates` writes ``fates.csv``; :func:`losses_text`,
:func:`unmatched_text`, :func:`fates_record`, :func:`stage_counts` and
:func:`losses_markdown` put the losses into station reasons, ``verify.json`` and ``verify.md``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from markerplan.writing import write_csv, write_gis_sidecars
from pipeline.chain.process import StationResult
from pipeline.chain.stages import ProcessConfig
from pipeline.surveys.fates import false_accepts, marker_fates
from pipeline.tables.marker_table import line_of_sight

#: ``fates.csv``: header and ``.csvt`` column types (both modes).
FATES_COLUMNS = ("trial", "station_id", "marker_id", "distance_m", "elevation_deg", "n_points",
                 "stage", "reason", "accepted", "error_m", "candidate")
FATES_TYPES = ("Integer", "String", "String", "Real", "Real", "Integer", "String", "String",
               "String", "Real", "Integer")

#: How a station's reason names the stage that lost a marker
#: (:data:`pipeline.tables.fate_table.FATE_STAGES`).
LOST_AT = {"not_in_view": "out of view", "ground": "at ground removal",
           "cluster": "at clustering", "gate": "at the gate", "fit": "at the fit",
           "quality": "at quality"}


@dataclass(frozen=True)
class FateRow:
    """One planned marker's fate at one station (a row of ``fates.csv``).

    Attributes
    ----------
    station_id, marker_id : str
        ``marker_id`` is the simulator's (true) id, in both modes.
    distance_m, elevation_deg : float
        Line of sight to the marker's true centre from the station's origin, m and degrees.
    n_points : int
        Simulated returns on the marker.
    stage, reason : str
        :func:`pipeline.surveys.fates.marker_fates`' stage and detail (``""`` when accepted).
    accepted : bool
        ``stage == "accepted"``.
    error_m : float or None
        Distance of the matched candidate's centre from the true centre, m (``None``: no
        candidate within a radius).
    candidate : int or None
        Index of the matched candidate among the station's candidates (its row among the
        station's rows of a marker table), ``None`` if none.
    """

    station_id: str
    marker_id: str
    distance_m: float
    elevation_deg: float
    n_points: int
    stage: str
    reason: str
    accepted: bool
    error_m: float | None
    candidate: int | None


@dataclass(frozen=True)
class StationFates:
    """The fates of one station's planned markers and its false accepts (small: a task's
    result)."""

    rows: tuple[FateRow, ...]
    n_false_accepts: int
    """Accepted candidates farther than a radius from every simulated marker (rocks, terrain)."""

    def lost(self) -> tuple[FateRow, ...]:
        """The planned markers the chain did not accept."""
        return tuple(r for r in self.rows if not r.accepted)


def station_fates(result: StationResult, truth: dict, marker_ids, cfg: ProcessConfig
                  ) -> StationFates:
    """The fate of each planned marker of one processed station against the simulator's truth.

    Parameters
    ----------
    result : StationResult
        :func:`pipeline.chain.process.process_station`'s.
    truth : dict
        :func:`visibility.simulate.simulate_markers`' truth: every simulated marker's
        ``centre_station_m`` and ``n_points``.
    marker_ids : sequence of str
        The station's planned markers.
    cfg : ProcessConfig
        The chain's configuration (its marker radius and the cluster stage's ``min_points``).

    Returns
    -------
    StationFates
        ``rows`` in the order of ``marker_ids``.
    """
    true = {m["id"]: m for m in truth["markers"]}
    planned = [true[m] for m in marker_ids]
    centres = np.array([m["centre_station_m"] for m in planned], dtype=float).reshape(-1, 3)
    radius = cfg.fit.radius_m
    fates = marker_fates(result, centres, list(marker_ids), radius, cfg.cluster.min_points,
                         [m["n_points"] for m in planned])
    rows = []
    for m, centre, fate in zip(planned, centres, fates, strict=True):
        dist, elev, _ = line_of_sight(centre)
        hit = fate.row_index >= 0
        error = float(np.linalg.norm(result.rows[fate.row_index].centre_m - centre)) \
            if hit else None
        rows.append(FateRow(result.station_id, m["id"], dist, elev, int(m["n_points"]),
                            fate.stage, fate.reason, fate.stage == "accepted", error,
                            fate.row_index if hit else None))
    every = np.array([m["centre_station_m"] for m in truth["markers"]]).reshape(-1, 3)
    return StationFates(tuple(rows), len(false_accepts(result, every, radius)))


def losses_text(rows) -> str:
    """The losses of some fate rows in words, ``""`` when none was lost.

    >>> rows = [FateRow("S3", "M07", 9.0, -3.0, 400, "gate", "too_large", False, None, None),
    ...         FateRow("S3", "M08", 7.0, -3.0, 900, "accepted", "", True, 0.004, 2),
    ...         FateRow("S3", "M09", 25.0, -1.0, 40, "quality", "high_rms", False, 0.03, 5)]
    >>> losses_text(rows)
    'lost M07 at the gate (too_large), M09 at quality (high_rms)'
    """
    lost = [f"{r.marker_id} {LOST_AT[r.stage]}" + (f" ({r.reason})" if r.reason else "")
            for r in rows if not r.accepted]
    return "lost " + ", ".join(lost) if lost else ""


def write_fates(path: Path, fates_by_trial) -> list[Path]:
    """Write ``fates.csv`` and its ``.csvt``: one row per trial, station and planned marker.

    Parameters
    ----------
    path : Path
        The ``fates.csv`` to write.
    fates_by_trial : sequence of sequence of StationFates
        Per trial (numbered from 0), the stations' fates in the plan's order.

    Returns
    -------
    written : list of Path
        The CSV and its ``.csvt``.
    """
    records = [{"trial": t, **asdict(row)} for t, stations in enumerate(fates_by_trial)
               for f in stations for row in f.rows]
    return [write_csv(path, FATES_COLUMNS, records),
            *write_gis_sidecars(path, FATES_TYPES, None)]



def unmatched_text(fates: StationFates, matched: set[str], how: str = "matched to the plan"
                   ) -> str:
    """The planned markers a station's solution did not get, in words: the stage that lost
    each (:func:`losses_text`), or that its accepted candidate was not ``how`` (matched to the
    plan; in network mode, identified).

    >>> fates = StationFates((FateRow("S1", "A", 8.0, -5.0, 900, "accepted", "", True, 0.01, 0),
    ...                       FateRow("S1", "B", 9.0, -5.0, 0, "not_in_view", "", False, None,
    ...                               None)), 0)
    >>> unmatched_text(fates, set(), "identified")
    'lost B out of view; accepted but not identified: A'
    """
    missed = [r for r in fates.rows if r.marker_id not in matched]
    text = losses_text(missed)
    unmatched = [r.marker_id for r in missed if r.accepted]
    if unmatched:
        text += ("; " if text else "") + f"accepted but not {how}: {', '.join(unmatched)}"
    return text



def fates_record(fates: StationFates | None) -> dict:
    """A station's losses for ``verify.json`` (both modes): ``lost`` (marker, stage, reason of
    each lost planned marker) and ``n_false_accepts``; empty without fates."""
    if fates is None:
        return {}
    return {"lost": [{"marker_id": r.marker_id, "stage": r.stage, "reason": r.reason}
                     for r in fates.lost()],
            "n_false_accepts": fates.n_false_accepts}


def lost_by_stage(rows) -> dict[str, int]:
    """How many of some fate rows were lost at each stage, in chain order (stages with none
    left out).

    >>> lost_by_stage([FateRow("S1", "A", 8.0, -5.0, 0, "quality", "high_rms", False, 0.02, 1),
    ...                FateRow("S1", "A", 8.0, -5.0, 0, "gate", "too_large", False, None, None),
    ...                FateRow("S1", "A", 8.0, -5.0, 900, "accepted", "", True, 0.001, 0)])
    {'gate': 1, 'quality': 1}
    """
    lost = [r.stage for r in rows if not r.accepted]
    return {stage: lost.count(stage) for stage in LOST_AT if stage in lost}


def stage_counts(fates) -> dict[str, int]:
    """Lost planned markers per stage over some stations' fates (``None`` skipped), in chain
    order, and the false accepts."""
    fates = [f for f in fates if f is not None]
    return {**lost_by_stage(r for f in fates for r in f.rows),
            "false_accepts": sum(f.n_false_accepts for f in fates)}


def losses_markdown(losses: dict[str, int]) -> str:
    """The line of a report that counts the losses by stage (:func:`stage_counts`).

    >>> print(losses_markdown({"gate": 2, "quality": 1, "false_accepts": 0}))
    ... # doctest: +NORMALIZE_WHITESPACE
    Planned markers lost: 2 at the gate, 1 at quality; false accepts: 0 (every planned
    marker's fate: `fates.csv`).
    """
    lost = ", ".join(f"{n} {LOST_AT[stage]}" for stage, n in losses.items()
                     if stage != "false_accepts") or "none"
    return (f"Planned markers lost: {lost}; false accepts: {losses.get('false_accepts', 0)} "
            "(every planned marker's fate: `fates.csv`).")
