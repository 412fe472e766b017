"""The integer program: fewest (cheapest) marker sites meeting directions and accuracy.

- :mod:`planner.program.model`: the model as data (:class:`~planner.program.model.Model`, its
  rows and :class:`~planner.program.model.RowKind` tags), built from a plan problem, and the
  records of a solve and of a plan;
- :mod:`planner.program.solving`: one solve with HiGHS -> a
  :class:`~planner.program.model.Solution`;
- :mod:`planner.program.highs`: the HiGHS call itself (options, statuses, solver record);
- :mod:`planner.program.cuts_known`: known-control accuracy cuts for a failing layout;
- :mod:`planner.program.cuts_network`: network-mode preflight and accuracy cuts;
- :mod:`planner.program.cuts_chance`: chance-constrained planning's valid rows, cuts and
  preflight;
- :mod:`planner.program.chance_start`: a layout repaired until it meets every chance target
  (the chance-constrained search's incumbent);
- :mod:`planner.program.loop`: :func:`~planner.program.loop.plan_sites`, the accuracy-cut loop
  (solve, check every station exactly, cut, re-solve until all pass);
- :mod:`planner.program.baselines`: greedy and regular-grid layouts to compare against;
- :mod:`planner.program.local_search`: the network greedy's layout pruned of the sites it does
  not need (the large-problem search's incumbent);
- :mod:`planner.program.joint`: the joint program of stations and markers over an area of
  interest (stations switch their rows on, coverage and clearance rows, its cut loop);
- :mod:`planner.program.joint_tour`: the traverse inside the joint program (the tour's edges,
  degree and flow rows, its graph, reading the tour back);
- :mod:`planner.program.joint_tour_cuts`: the tour's connectivity cuts separated by maximum
  flow at the root, and the two-part bound of stops and drive plus markers;
- :mod:`planner.program.joint_baselines`: stations chosen for coverage first (weighted greedy
  of viewpoints, regular grid), then their markers.
"""

from planner.program.cuts_known import accuracy_cuts
from planner.program.loop import plan_sites
from planner.program.model import (
    Model,
    PlanResult,
    RowKind,
    aggregate_columns,
    build_model,
    info_weights,
    with_tightening_rows,
)
from planner.program.solving import solve

__all__ = ["Model", "PlanResult", "RowKind", "accuracy_cuts", "aggregate_columns", "build_model",
           "info_weights", "plan_sites", "solve", "with_tightening_rows"]
