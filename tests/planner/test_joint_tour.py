"""The tour inside the joint program (planner.program.joint_tour) against brute force: every
covering subset of candidate stations, each with its fewest markers and its shortest closed
tour from the route start over every permutation."""

import itertools

import numpy as np
import pytest

from planner.program import joint_tour, plan_sites
from planner.program.joint import JointCosts, plan_stations_and_sites, tour_units
from planner.program.joint_tour import tour_block, tour_graph, tour_order, tour_start
from tests.planner.test_joint_program import LOOSE, _brute_force, _instance


def _drive(problem, start_xy):
    xy = np.vstack([start_xy, problem.station_xyz[:, :2]])
    return np.linalg.norm(xy[:, None] - xy[None], axis=2)


def _best_tour_units(drive_m, combo, costs):
    best = np.inf
    for perm in itertools.permutations(combo):
        best = min(best, tour_units(drive_m, np.array(perm), costs))
    return best


@pytest.mark.parametrize("seed,costs,start", [
    (3, JointCosts(10.0, 1.0, drive_per_m=0.5), (-20.0, 5.0)),
    (4, JointCosts(2.0, 1.0, drive_per_m=1.0), (40.0, -10.0)),
    (7, JointCosts(6.0, 2.0, drive_per_m=0.25), (16.0, 0.0)),
])
def test_joint_optimum_with_drive_equals_brute_force(seed, costs, start):
    problem, cover = _instance(seed)
    drive = _drive(problem, start)
    expected = _brute_force(problem, cover, costs, LOOSE,
                            lambda combo: _best_tour_units(drive, combo, costs))
    r = plan_stations_and_sites(problem, LOOSE, cover, costs, drive_m=drive)
    assert r.status == "optimal" and r.tour_complete
    assert r.solution.objective == pytest.approx(expected)
    # the tour visits exactly the chosen stations, once each, and costs what the program says
    assert sorted(r.tour.tolist()) == np.flatnonzero(r.stations).tolist()
    n_markers = int(problem.site_cost[r.selected].sum())
    assert costs.of(int(r.stations.sum()), n_markers, tour_units(drive, r.tour, costs)) == \
        pytest.approx(r.solution.objective)


def test_drive_moves_the_choice_towards_the_start():
    """Two stations each cover all cells; with the drive priced the one nearer the start
    wins, whichever the marker cost prefers."""
    problem, cover = _instance(3, n_stations=5)
    all_cells = np.arange(cover.n_cells)
    from planner.program.joint import StationCover

    both = StationCover(np.r_[np.zeros_like(all_cells), np.full_like(all_cells, 4)],
                        np.r_[all_cells, all_cells], cover.n_cells)
    for start, near in (((-30.0, 0.0), 0), ((62.0, 0.0), 4)):
        drive = _drive(problem, start)
        r = plan_stations_and_sites(problem, LOOSE, both,
                                    JointCosts(10.0, 1.0, drive_per_m=1.0), drive_m=drive)
        assert np.flatnonzero(r.stations).tolist() == [near]
        assert r.tour.tolist() == [near]


def test_incumbent_tour_is_a_feasible_start_and_never_beaten_by_it():
    problem, cover = _instance(4)
    drive = _drive(problem, (40.0, -10.0))
    costs = JointCosts(2.0, 1.0, drive_per_m=1.0)
    free = plan_stations_and_sites(problem, LOOSE, cover, costs, drive_m=drive)
    every = np.ones(problem.n_stations, bool)
    sites = plan_sites(problem, LOOSE).selected
    started = plan_stations_and_sites(problem, LOOSE, cover, costs, incumbent=(every, sites),
                                      drive_m=drive)
    assert started.solution.objective == pytest.approx(free.solution.objective)


def test_tour_block_rows_hold_exactly_for_closed_tours():
    """Every closed tour through a subset satisfies the degree, flow and capacity rows at its
    own values (tour_start); two disjoint cycles satisfy the degrees but no flow can feed the
    one away from the start."""
    d = np.random.default_rng(0).uniform(1, 9, (6, 6))
    d = d + d.T
    graph = tour_graph(d, np.ones(5, bool))
    station_var = np.arange(5)
    block = tour_block(graph, station_var, 5, 1.0, 1.0, max_stations=5)
    for order in ([2], [0, 3], [4, 1, 2], [3, 0, 4, 1, 2]):
        w = np.zeros(5)
        w[order] = 1
        x = np.r_[w, tour_start(block, np.array(order))]
        ax = block.A @ x
        assert np.all(ax >= block.row_lb - 1e-9) and np.all(ax <= block.row_ub + 1e-9)
        assert np.all(x >= np.r_[np.zeros(5), block.lb]) and np.all(
            x <= np.r_[np.ones(5), block.ub])
        got = tour_order(block, x)
        assert got.tolist() in (order, order[::-1])
    # degrees of start-0-1-start plus the cycle 2-3-4: the flow rows cannot hold
    index = {tuple(e): k for k, e in enumerate(graph.edge.tolist())}
    z = np.zeros(len(graph.edge))
    for a, b in ((0, 1), (1, 2), (0, 2), (3, 4), (4, 5), (3, 5)):
        z[index[(a, b)]] = 1
    deg = block.A[:6] @ np.r_[np.ones(5), z, np.zeros(2 * len(z))]
    assert np.allclose(deg, np.r_[2.0, np.zeros(5)])
    from scipy.optimize import linprog

    free_flow = np.r_[block.flow_var.ravel()]
    A = block.A.toarray()
    fixed = np.r_[np.ones(5), z, np.zeros(2 * len(z))]
    rhs_lb = block.row_lb - A[:, np.r_[np.arange(5), block.edge_var]] @ fixed[:5 + len(z)]
    rhs_ub = block.row_ub - A[:, np.r_[np.arange(5), block.edge_var]] @ fixed[:5 + len(z)]
    F = A[:, free_flow]
    eq = np.isclose(rhs_lb, rhs_ub)
    lp = linprog(np.zeros(F.shape[1]), A_ub=F[~eq & np.isfinite(rhs_ub)],
                 b_ub=rhs_ub[~eq & np.isfinite(rhs_ub)], A_eq=F[eq], b_eq=rhs_lb[eq],
                 bounds=list(zip(block.lb[len(z):], block.ub[len(z):], strict=True)))
    assert lp.status == 2  # infeasible


def test_sparse_graph_keeps_neighbours_start_edges_and_extra_edges(monkeypatch):
    monkeypatch.setattr(joint_tour, "COMPLETE_MAX_NODES", 4)
    monkeypatch.setattr(joint_tour, "NEIGHBOURS", 2)
    xy = np.c_[np.arange(8.0), np.zeros(8)]  # node 0 the start at x = 0, stations at 1..7
    d = np.abs(xy[:, None, 0] - xy[None, :, 0])
    g = tour_graph(d, np.ones(7, bool), extra_edges=[(2, 7)])
    edges = {tuple(e) for e in g.edge.tolist()}
    assert not g.complete
    assert {(0, k) for k in range(1, 8)} <= edges  # every station to the start
    # the two nearest of each: its neighbours on the line, and two on one side at the ends
    assert {(k, k + 1) for k in range(1, 7)} | {(1, 3), (5, 7)} <= edges
    assert (2, 4) not in edges and (1, 7) not in edges
    assert (2, 7) in edges  # the extra edge
    assert np.allclose(g.length_m, d[g.edge[:, 0], g.edge[:, 1]])


def test_fewest_markers_bound_is_the_count_rule_and_never_above_brute_force():
    """Every site costs one marker, so the bound is the count rule's ``min_markers``; no
    single station, hence no layout, needs fewer (brute force over each station alone)."""
    from planner.program.joint import fewest_markers_bound, joint_model

    problem, cover = _instance(5, n_sites=20)
    costs = JointCosts(3.0, 1.0)
    jm = joint_model(problem, LOOSE, cover, costs)
    bound = fewest_markers_bound(jm.model, jm.station_var)
    assert bound == pytest.approx(LOOSE.min_markers)
    alone = [plan_sites(problem.restrict_stations(np.array([s])), LOOSE).selected.sum()
             for s in range(problem.n_stations)]
    assert bound <= min(alone) + 1e-9
