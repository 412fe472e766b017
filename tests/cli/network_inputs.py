"""Inputs of ``markerplan adjust`` written from a simulated network (for the CLI tests).

:func:`write_network_inputs` turns :func:`pipeline.network.simulation.simulated_network`'s
observations into ``markers.csv`` tables (:func:`pipeline.tables.marker_table.write_marker_table`),
as ``markerplan process`` writes them, with noise drawn from the error model's sigma at each
detection's distance and elevation (the sigma ``adjust`` gives it), plus a ``plan.json`` whose
markers sit at their true centres plus placement scatter and whose stations are the odometry's
nominal poses.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.tables.marker_table import MarkerRow, line_of_sight, write_marker_table


@dataclass
class NetworkInputs:
    """What :func:`write_network_inputs` wrote, and the truth behind it."""

    tables: list[Path]
    plan: Path
    station_ids: tuple[str, ...]
    marker_ids: tuple[str, ...]
    truth: object
    """:class:`pipeline.network.simulation.NetworkTruth`."""


def _row(sid: str, mid: str, xyz: np.ndarray, accepted: bool = True) -> MarkerRow:
    dist, elev, az = line_of_sight(xyz)
    return MarkerRow(sid, mid, *(float(v) for v in xyz), dist, elev, az, 300, 9549.3, 0.9,
                     0.003, 0.1, "fixed-radius", accepted, "" if accepted else "high_rms")


def write_network_inputs(folder: Path, n_stations: int = 6, seed: int = 3,
                         n_tables: int = 2, swap: tuple[str, str, str] | None = None
                         ) -> NetworkInputs:
    """Write ``table_<k>.csv`` (stations split over ``n_tables``) and ``plan.json``.

    Parameters
    ----------
    folder : Path
    n_stations, seed : int
        Of the simulated network (15 m traverse, 30 m range, about 3 markers per station).
    n_tables : int
        Number of marker tables the stations are split over (in order).
    swap : (station, marker_a, marker_b), optional
        Swap the ``marker_id`` of two detections of one station in its table (a blunder of
        identification in the field).

    Returns
    -------
    NetworkInputs
    """
    from error_model import default_model
    from pipeline.network.simulation import simulated_network

    obs, truth = simulated_network(n_stations=n_stations, seed=seed, noise_scale=0.0)
    rng = np.random.default_rng(seed + 100)
    model = default_model()
    d = np.linalg.norm(obs.xyz_m, axis=1)
    elev = np.arctan2(obs.xyz_m[:, 2], np.hypot(obs.xyz_m[:, 0], obs.xyz_m[:, 1]))
    sigma = model.predict(d, elev).sigma_m
    xyz = obs.xyz_m + rng.normal(size=obs.xyz_m.shape) * (sigma / math.sqrt(3.0))[:, None]
    rows: dict[str, list[MarkerRow]] = {sid: [] for sid in obs.station_ids}
    for i in range(obs.n):
        sid = obs.station_ids[obs.station[i]]
        rows[sid].append(_row(sid, obs.marker_ids[obs.marker[i]], xyz[i]))
    for sid in obs.station_ids[::2]:  # a detection the quality gate rejected: never read
        rows[sid].append(_row(sid, "", np.array([4.0, 1.0, -1.0]), accepted=False))
    if swap is not None:
        sid, a, b = swap
        for r in rows[sid]:
            r.marker_id = {a: b, b: a}.get(r.marker_id, r.marker_id)
    folder.mkdir(parents=True, exist_ok=True)
    groups = np.array_split(np.array(obs.station_ids), n_tables)
    tables = []
    for k, group in enumerate(groups):
        path = folder / f"table_{k + 1}.csv"
        write_marker_table(path, [r for sid in group for r in rows[str(sid)]])
        tables.append(path)
    plan = folder / "plan.json"
    placed = truth.marker_xyz_m + rng.normal(0.0, 0.05, truth.marker_xyz_m.shape)
    plan.write_text(json.dumps(plan_document(obs.station_ids, truth.nominal.position_m,
                                             truth.nominal.heading_rad, obs.marker_ids, placed),
                               indent=1))
    return NetworkInputs(tables, plan, obs.station_ids, obs.marker_ids, truth)


def plan_document(station_ids, station_xyz, headings, marker_ids, marker_xyz) -> dict:
    """A minimal whole ``plan.json`` (schema ``markerplan-plan``) of these stations and markers."""
    return {
        "schema": "markerplan-plan", "schema_version": 1,
        "site": {"name": "default", "seed": 0, "marker_radius_m": 0.1},
        "requirement": {"requirement_m": 0.1, "working_radius_m": 10.0},
        "provenance": {"config_sha256": "0" * 64, "config": {"inclinometer_sigma_deg": 0.01}},
        "markers": [{"id": m, "x_m": float(x), "y_m": float(y), "z_m": float(z)}
                    for m, (x, y, z) in zip(marker_ids, marker_xyz, strict=True)],
        "stations": [{"id": s, "x_m": float(p[0]), "y_m": float(p[1]), "z_m": float(p[2]),
                      "heading_rad": float(h)}
                     for s, p, h in zip(station_ids, station_xyz, headings, strict=True)]}
