"""``reduce`` judges every requirement kind ``plan`` has (issue 29): on a nine-site network
small enough to enumerate, the fewest markers the trade-off curve finds passing equals the
fewest any subset passes with (brute force, :func:`~planner.accuracy.checks.evaluate_layout`'s
``all_ok``), and each kind changes that count, so a study ignoring it would fail."""

from __future__ import annotations

import functools
import itertools
from dataclasses import replace

import numpy as np
import pytest

from planner.accuracy.checks import evaluate_layout
from planner.accuracy.network import network_model
from planner.reduction.curve import tradeoff_curve
from planner.reduction.losses import drop_order, local_ok
from tests.planner.test_reduction import NETWORK, _network_instance

#: Datum requirement 0.13 m: five of the nine sites meet it (worst 0.124 m; six give 0.116 m).
BASE = NETWORK.replace(requirement_m=0.13)
#: Sites C007 and C008 as control points (2 mm), the datum instead of station S1.
CONTROL_SIGMA_M = np.array([0, 0, 0, 0, 0, 0, 0, 0.002, 0.002])


@functools.cache
def _problem(control: bool = False):
    problem = _network_instance()
    return replace(problem, site_control_sigma_m=CONTROL_SIGMA_M) if control else problem


def _fewest_passing(problem, config) -> int | None:
    """Fewest markers of any subset meeting every kind (``all_ok``), by enumeration; control
    points are in every subset (as ``reduce`` keeps them: ``existing``)."""
    net = network_model(problem, config)
    must = set(np.flatnonzero(problem.site_control))
    for k in range(1, problem.n_sites + 1):
        for sub in itertools.combinations(range(problem.n_sites), k):
            if must <= set(sub):
                sel = np.zeros(problem.n_sites, bool)
                sel[list(sub)] = True
                if evaluate_layout(problem, sel, config, net=net).all_ok:
                    return k
    return None


#: name -> (config with the kind, the same without it, control datum, fewest with, without).
KINDS = {
    "requirement_ppm": (BASE.replace(requirement_m=0.118, requirement_ppm=300.0),
                        BASE.replace(requirement_m=0.118), False, 5, 6),
    "local_requirement_m": (BASE.replace(local_requirement_m=0.14, local_within_m=20.0),
                            BASE, False, 6, 5),
    # 13 m judges no station pair (14 m apart): only the marker pairs
    "local_markers": (BASE.replace(local_requirement_m=0.06, local_within_m=13.0,
                                   local_markers=True),
                      BASE.replace(local_requirement_m=0.06, local_within_m=13.0), False, 6, 5),
    "datum_requirement": (BASE.replace(requirement_m=0.01, datum_requirement=False,
                                       local_requirement_m=0.14, local_within_m=20.0),
                          BASE.replace(requirement_m=0.01, local_requirement_m=0.14,
                                       local_within_m=20.0), False, 6, None),
    "heading_aid": (BASE.replace(requirement_m=0.10, heading_aid="sun-sensor"),
                    BASE.replace(requirement_m=0.10), False, 5, None),
    "odometry_percent": (BASE.replace(requirement_m=0.11, odometry_percent=0.1),
                         BASE.replace(requirement_m=0.11), False, 6, None),
    "control": (BASE.replace(requirement_m=0.08, existing=("C007", "C008")),
                BASE.replace(requirement_m=0.08), True, 5, None),
}


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_the_curve_judges_each_kind_as_plan_does(kind):
    with_kind, without, control, fewest, fewest_without = KINDS[kind]
    problem = _problem(control)
    # the kind matters here: judging without it gives another answer
    assert _fewest_passing(problem, with_kind) == fewest
    assert _fewest_passing(_problem(False), without) == fewest_without
    curve = tradeoff_curve(problem, with_kind)
    assert curve.k_feasible == fewest
    assert curve.k_feasible_minimal and curve.proven  # (ppm: no descent to the time limit)
    for p in curve.points:  # the curve's verdict is evaluate_layout's, kind included
        assert p.meets_requirement == evaluate_layout(problem, p.selected, with_kind).all_ok


def test_a_marker_pair_can_fail_where_every_station_and_marker_passes_the_datum():
    """At five markers the datum-best subset passes the datum requirement but not the
    marker pairs: the curve keeps six; the drop order prefers drops keeping the pairs."""
    with_kind, without, *_ = KINDS["local_markers"]
    problem = _problem()
    five = next(p for p in tradeoff_curve(problem, without).points if p.k == 5)
    check = evaluate_layout(problem, five.selected, with_kind)
    assert check.ok.all() and check.markers_ok and not check.marker_pairs_ok
    curve = tradeoff_curve(problem, with_kind)
    assert [p.k for p in curve.points] == [9, 8, 7, 6]
    assert all(p.marker_pairs_ok for p in curve.points)
    steps = drop_order(problem, with_kind, np.ones(problem.n_sites, bool))
    passing = [s.k for s in steps if local_ok(s.check)]
    assert passing == list(range(8, 8 - len(passing), -1)) and 6 in passing
