"""Baselines of the joint program: stations chosen for coverage first, then their markers.

- :func:`greedy_viewpoints`: a weighted greedy of viewpoints in the manner of Jia & Lichti
  (2019): one station at a time, the one whose covered cells weigh most, a cell weighing its
  remaining need over the number of candidate stations that could cover it (rare cells
  first); then stations whose cells the others cover are dropped, last chosen first;
- :func:`grid_viewpoints`: stations on a regular square grid, each grid point moved to the
  nearest candidate station, at the widest spacing that covers the area;
- :func:`joint_baseline`: either set of stations with its markers from the marker program's
  greedy (:func:`planner.program.baselines.greedy_cover`; network mode
  :func:`planner.program.baselines.network_baseline`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from markerplan.errors import InfeasiblePlanError
from planner.problem.usability import PlanProblem
from planner.program.baselines import greedy_cover, network_baseline
from planner.program.joint import JointCosts, StationCover


@dataclass(frozen=True)
class JointBaseline:
    """A baseline choice of stations and markers.

    Attributes
    ----------
    name : str
        "greedy" or "grid".
    stations : (s,) bool
        Candidate stations chosen.
    selected : (n,) bool
        Candidate sites holding a marker.
    covered : bool
        Whether the stations cover every cell as required.
    meets_requirement : bool
        Whether the markers meet every chosen station's requirement.
    cost : float
        Stations and markers at the stated costs (without the drive).
    spacing_m : float or None
        Grid spacing (grid only), m.
    note : str or None
        Why it falls short, when it does.
    """

    name: str
    stations: np.ndarray
    selected: np.ndarray
    covered: bool
    meets_requirement: bool
    cost: float
    spacing_m: float | None = None
    note: str | None = None


def greedy_viewpoints(cover: StationCover, eligible: np.ndarray) -> np.ndarray:
    """Weighted greedy of viewpoints until every cell is covered ``min_stations`` times.

    Parameters
    ----------
    cover : StationCover
    eligible : (s,) bool
        Candidate stations that may be chosen.

    Returns
    -------
    stations : (s,) bool
        Chosen stations; the greedy stops early, leaving cells short, when no eligible station
        covers any cell still in need.

    Examples
    --------
    >>> cover = StationCover(np.array([0, 0, 1, 2, 2]), np.array([0, 1, 1, 1, 2]), 3)
    >>> greedy_viewpoints(cover, np.ones(3, bool)).tolist()
    [True, False, True]
    """
    eligible = np.asarray(eligible, bool)
    ns = eligible.size
    keep = eligible[cover.pair_station]
    st, cell = cover.pair_station[keep], cover.pair_cell[keep]
    rarity = 1.0 / np.maximum(np.bincount(cell, minlength=cover.n_cells), 1)
    chosen = np.zeros(ns, bool)
    order = []
    while True:
        need = np.maximum(cover.min_stations - cover.counts(chosen), 0)
        open_pair = (need[cell] > 0) & ~chosen[st]
        if not open_pair.any():
            break
        score = np.bincount(st[open_pair], (need * rarity)[cell[open_pair]], minlength=ns)
        best = int(np.argmax(score))
        chosen[best] = True
        order.append(best)
    for s in reversed(order):  # drop stations the others make redundant
        chosen[s] = False
        if np.any(cover.counts(chosen) < np.minimum(cover.min_stations,
                                                    cover.counts(eligible))):
            chosen[s] = True
    return chosen


def grid_viewpoints(cover: StationCover, station_xy: np.ndarray, eligible: np.ndarray,
                    bounds_xy: tuple[float, float, float, float], spacings_m
                    ) -> tuple[np.ndarray, float]:
    """Stations on a square grid at the widest of ``spacings_m`` that covers the area.

    Parameters
    ----------
    cover : StationCover
    station_xy : (s, 2) float
        Candidate stations, site frame, m.
    eligible : (s,) bool
    bounds_xy : (xmin, xmax, ymin, ymax)
        The area the grid spans, m (grid points at half a spacing in from the edges).
    spacings_m : sequence of float
        Spacings tried, widest first, m.

    Returns
    -------
    stations : (s,) bool
        The grid's stations (each grid point moved to the nearest eligible candidate within
        half a spacing); the narrowest spacing's when none covers.
    spacing_m : float
    """
    idx = np.flatnonzero(eligible)
    tree = cKDTree(station_xy[idx])
    xmin, xmax, ymin, ymax = bounds_xy
    chosen, spacing = np.zeros(len(station_xy), bool), float("nan")
    for spacing in sorted((float(s) for s in spacings_m), reverse=True):
        gx = np.arange(xmin + spacing / 2, xmax, spacing)
        gy = np.arange(ymin + spacing / 2, ymax, spacing)
        points = np.stack(np.meshgrid(gx if gx.size else [(xmin + xmax) / 2],
                                      gy if gy.size else [(ymin + ymax) / 2]), -1).reshape(-1, 2)
        dist, near = tree.query(points)
        chosen = np.zeros(len(station_xy), bool)
        chosen[idx[near[dist <= spacing / 2]]] = True
        if cover.covered(chosen):
            break
    return chosen, spacing


def joint_baseline(name: str, problem: PlanProblem, config, cover: StationCover,
                   costs: JointCosts, stations: np.ndarray, spacing_m: float | None = None
                   ) -> JointBaseline:
    """The stations' markers from the marker program's greedy, and the layout's cost.

    Parameters
    ----------
    name : str
    problem : PlanProblem
        Every candidate station and site.
    config : PlanConfig
    cover : StationCover
    costs : JointCosts
    stations : (s,) bool
    spacing_m : float, optional
    """
    stations = np.asarray(stations, bool)
    sub = problem.restrict_stations(np.flatnonzero(stations))
    note = None
    try:
        base = network_baseline(sub, config) if config.network else greedy_cover(sub, config)
        selected, meets, note = base.selected, base.meets_requirement, base.note
    except InfeasiblePlanError as exc:
        selected, meets, note = np.zeros(problem.n_sites, bool), False, str(exc)
    covered = cover.covered(stations)
    if not covered:
        short = int(np.sum(cover.counts(stations) < cover.min_stations))
        note = f"{short} cell(s) not covered" + (f"; {note}" if note else "")
    cost = costs.of(int(stations.sum()), int(problem.site_cost[selected].sum()))
    return JointBaseline(name=name, stations=stations, selected=selected, covered=covered,
                         meets_requirement=meets, cost=cost, spacing_m=spacing_m, note=note)
