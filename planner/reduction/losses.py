"""Drop order and per-marker losses of a layout, and the layout checks every reduction study
shares.

- :func:`drop_order`: remove one marker at a time, each time the one whose loss hurts least;
- :func:`marker_losses`: for every marker, the layout without it (robustness);
- :func:`layout_checker`, :func:`check_worst`, :func:`local_ok`, :func:`failure_reason`: a
  layout's per-station check, its worst error, its local verdict and why a station fails;
  :func:`reduction_iv`: the input checks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from markerplan.errors import ConfigError
from planner.accuracy.checks import LayoutCheck, evaluate_layout, station_infos
from planner.accuracy.network import network_model
from planner.problem.usability import PlanProblem


def worst_marker(marker_error_m) -> float | None:
    """Largest error among the selected markers (nan: not selected); ``None`` if none."""
    if marker_error_m is None or np.isnan(marker_error_m).all():
        return None
    return float(np.nanmax(marker_error_m))


def check_worst(check: LayoutCheck) -> float:
    """Worst error of a :class:`~planner.accuracy.checks.LayoutCheck`, m: the worst station,
    and in network mode also the worst selected marker (both relative to the datum)."""
    markers = worst_marker(check.marker_error_m)
    worst = float(check.error_m.max())
    return worst if markers is None else max(worst, markers)


def local_ok(check: LayoutCheck) -> bool:
    """Whether a :class:`~planner.accuracy.checks.LayoutCheck` meets the local requirement on
    its station pairs and (``local_markers``) its marker pairs (True without one)."""
    return bool(check.pairs_ok and check.marker_pairs_ok)


@dataclass(frozen=True)
class DropStep:
    """One step of the drop order.

    Attributes
    ----------
    k : int
        Markers left after the step.
    removed : int
        Candidate-site index of the marker removed.
    check : LayoutCheck
        Per-station count, sectors, predicted error and verdict of the remaining layout.
    selected : (n,) bool
        The remaining layout.
    """

    k: int
    removed: int
    check: LayoutCheck
    selected: np.ndarray = field(repr=False)

    @property
    def worst_error_m(self) -> float:
        """As :attr:`~planner.reduction.curve.CurvePoint.worst_error_m`."""
        return check_worst(self.check)

    @property
    def mean_error_m(self) -> float:
        return float(self.check.error_m.mean())


@dataclass(frozen=True)
class MarkerLoss:
    """The full layout without one marker.

    Attributes
    ----------
    marker : int
        Candidate-site index of the marker lost.
    check : LayoutCheck
        The layout without it.
    failing : tuple of int
        Stations that then fail (count, directions or accuracy).
    """

    marker: int
    check: LayoutCheck
    failing: tuple[int, ...]

    @property
    def worst_error_m(self) -> float:
        """As :attr:`~planner.reduction.curve.CurvePoint.worst_error_m`."""
        return check_worst(self.check)


def reduction_iv(problem: PlanProblem, config, layout: np.ndarray) -> np.ndarray:
    layout = np.asarray(layout, dtype=bool)
    if layout.shape != (problem.n_sites,):
        raise ConfigError(f"`layout` must have shape ({problem.n_sites},), got {layout.shape}")
    if not layout.any():
        raise ConfigError("`layout` must hold at least one marker, got none")
    if config.redundant:
        raise ConfigError("reduction studies do not support `redundant = true`; set it to false "
                          "(robustness to losing one marker is reported per marker instead)")
    if config.budget is not None:
        raise ConfigError(f"reduction studies set the marker count themselves; leave `budget` "
                          f"unset, got {config.budget}")
    if np.any(problem.site_existing):
        raise ConfigError("reduction studies may drop any marker; the problem must mark no site "
                          "as existing (fixed)")
    return layout


def drop_order(problem: PlanProblem, config, layout: np.ndarray) -> list[DropStep]:
    """Remove markers one at a time, each time the one whose loss hurts least.

    Markers in ``config.existing`` are kept; markers in ``config.forbidden`` are removed before
    the first step. At every step each remaining marker is tried (exact, by enumeration); the
    removal chosen keeps every station's count and directions if possible, then (network mode)
    the local requirement on station and marker pairs, then gives the lowest worst-station
    error, then the lowest mean error, then the lowest index. Stops when every removal would
    break a station's count or directions. A nested sequence: compare it with
    :func:`~planner.reduction.curve.tradeoff_curve`, whose subsets need not be nested.

    Parameters
    ----------
    problem : PlanProblem
    config : PlanConfig
    layout : (n,) bool
        The markers in the field.

    Returns
    -------
    steps : list of DropStep
    """
    current = reduction_iv(problem, config, layout) \
        & ~problem.site_mask(config.forbidden, "forbidden")
    kept = problem.site_mask(config.existing, "existing")
    check = layout_checker(problem, config)
    steps = []
    while (current & ~kept).any():
        best = None
        for m in np.flatnonzero(current & ~kept):
            trial = current.copy()
            trial[m] = False
            chk = check(trial)
            directions = bool(np.all((chk.count >= config.min_markers)
                                     & (chk.sectors >= config.min_sectors)))
            key = (not directions, not local_ok(chk), check_worst(chk),
                   float(chk.error_m.mean()), int(m))
            if best is None or key < best[0]:
                best = (key, m, trial, chk)
        if best[0][0]:  # every removal breaks directions somewhere
            break
        _, m, current, chk = best
        steps.append(DropStep(k=int(current.sum()), removed=int(m), check=chk,
                              selected=current.copy()))
    return steps


def marker_losses(problem: PlanProblem, config, layout: np.ndarray) -> list[MarkerLoss]:
    """For every marker of ``layout``: the layout without it and the stations that then fail.

    Parameters
    ----------
    problem : PlanProblem
    config : PlanConfig
    layout : (n,) bool

    Returns
    -------
    losses : list of MarkerLoss
        In site order.
    """
    layout = reduction_iv(problem, config, layout)
    check = layout_checker(problem, config)
    out = []
    for m in np.flatnonzero(layout):
        trial = layout.copy()
        trial[m] = False
        chk = check(trial)
        out.append(MarkerLoss(marker=int(m), check=chk,
                              failing=tuple(int(s) for s in np.flatnonzero(~chk.ok))))
    return out


def layout_checker(problem: PlanProblem, config):
    """``selected -> LayoutCheck`` for one problem
    (:func:`~planner.accuracy.checks.evaluate_layout` with its caches; in network mode the
    network's accuracy relative to the datum)."""
    infos = station_infos(problem, config)
    net = network_model(problem, config) if config.network else None
    return lambda selected: evaluate_layout(problem, selected, config, infos, net=net)


def failure_reason(check, s: int, config) -> str:
    """Why station ``s`` fails in a :class:`~planner.accuracy.checks.LayoutCheck` ("" when it
    passes)."""
    why = []
    if check.count[s] < config.min_markers:
        why.append(f"{int(check.count[s])} usable markers < {config.min_markers}")
    if check.sectors[s] < config.min_sectors:
        why.append(f"{int(check.sectors[s])} directions < {config.min_sectors}")
    if check.error_m[s] > config.requirement_m:
        why.append(f"error {check.error_m[s]:.4f} m > {config.requirement_m:g} m")
    return "; ".join(why)
