"""The joint program of stations and markers (planner.program.joint) against brute force:
every subset of candidate stations that covers the cells, each with its fewest markers from
the marker program (planner.program.plan_sites, tested on its own), cheapest total cost."""

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

from markerplan.errors import InfeasiblePlanError
from planner.accuracy.checks import evaluate_layout
from planner.config import PlanConfig
from planner.program import plan_sites
from planner.program.joint import (
    JointCosts,
    StationCover,
    joint_model,
    plan_stations_and_sites,
    switched_rows,
)
from planner.program.joint_baselines import greedy_viewpoints, grid_viewpoints, joint_baseline
from tests.planner.instances import make_problem

LOOSE = PlanConfig(requirement_m=0.10, working_radius_m=10.0, max_range_m=20.0,
                   chance_epsilon=None)


def _instance(seed=3, n_stations=5, n_sites=16, n_cells=8):
    """Candidate stations on a line, random sites, random cells covered by the stations
    within 9 m."""
    rng = np.random.default_rng(seed)
    st = np.column_stack([np.arange(n_stations) * 8.0, rng.uniform(-2, 2, n_stations)])
    sites = np.column_stack([rng.uniform(-10, 8 * n_stations + 2, n_sites),
                             rng.uniform(-10, 10, n_sites)])
    cells = np.column_stack([rng.uniform(0, 8 * (n_stations - 1), n_cells),
                             rng.uniform(-3, 3, n_cells)])
    d = np.linalg.norm(st[:, None] - cells[None], axis=2)
    ps, pc = np.nonzero(d <= 9.0)
    return make_problem(st, sites), StationCover(ps, pc, n_cells)


def _brute_force(problem, cover, costs, config, drive_units=lambda combo: 0.0):
    """Cheapest covering subset with its fewest markers and, with ``drive_units``, its
    drive."""
    best = np.inf
    for k in range(1, problem.n_stations + 1):
        for combo in itertools.combinations(range(problem.n_stations), k):
            on = np.zeros(problem.n_stations, bool)
            on[list(combo)] = True
            if not cover.covered(on):
                continue
            try:
                r = plan_sites(problem.restrict_stations(np.array(combo)), config)
            except InfeasiblePlanError:
                continue
            best = min(best, costs.of(k, int(r.selected.sum()), drive_units(combo)))
    return best


@pytest.mark.parametrize("seed,station_cost", [(3, 10.0), (4, 1.0), (7, 2.5)])
def test_joint_optimum_equals_brute_force(seed, station_cost):
    problem, cover = _instance(seed)
    costs = JointCosts(station=station_cost, marker=1.0)
    expected = _brute_force(problem, cover, costs, LOOSE)
    r = plan_stations_and_sites(problem, LOOSE, cover, costs)
    assert r.status == "optimal"
    assert r.solution.objective == pytest.approx(expected)
    assert cover.covered(r.stations)
    chosen = problem.restrict_stations(np.flatnonzero(r.stations))
    check = evaluate_layout(chosen, r.selected, LOOSE)
    assert check.ok.all()


def test_tight_requirement_needs_accuracy_cuts_and_still_matches():
    problem, cover = _instance(5, n_sites=20)
    cfg = PlanConfig(requirement_m=0.03, working_radius_m=10.0, max_range_m=20.0,
                     chance_epsilon=None)
    costs = JointCosts(station=3.0, marker=1.0)
    r = plan_stations_and_sites(problem, cfg, cover, costs)
    assert r.n_cuts > 0 and r.iterations > 1
    assert r.solution.objective == pytest.approx(_brute_force(problem, cover, costs, cfg))
    chosen = problem.restrict_stations(np.flatnonzero(r.stations))
    assert evaluate_layout(chosen, r.selected, cfg).ok.all()


def test_a_station_off_constrains_nothing():
    """With every station switched off and no coverage asked, the program places nothing."""
    problem, _ = _instance(3)
    cover = StationCover(np.zeros(0, int), np.zeros(0, int), 0)
    r = plan_stations_and_sites(problem, LOOSE, cover, JointCosts(1.0, 1.0))
    assert r.stations.sum() == 0 and r.selected.sum() == 0


def test_switched_rows_hold_only_when_on():
    rng = np.random.default_rng(0)
    A = rng.integers(-2, 3, (6, 4)).astype(float)
    lb = rng.integers(-1, 3, 6).astype(float)
    B, lb2, ub2 = switched_rows(sp.csr_array(A), lb, np.full(6, np.inf), np.zeros(6, int),
                                np.array([4]), 5)
    for bits in itertools.product([0, 1], repeat=4):
        x = np.array(bits, float)
        off = B.toarray() @ np.r_[x, 0.0]
        on = B.toarray() @ np.r_[x, 1.0]
        assert np.all(off >= lb2 - 1e-12)  # off: every binary x passes
        np.testing.assert_array_equal(on >= lb2 - 1e-12, A @ x >= lb - 1e-12)


def test_cells_nobody_can_cover_are_refused():
    problem, cover = _instance(3)
    far = StationCover(cover.pair_station, cover.pair_cell, cover.n_cells + 1)
    with pytest.raises(InfeasiblePlanError, match="1 of 9 cells"):
        joint_model(problem, LOOSE, far, JointCosts(1.0, 1.0))


def test_network_mode_chooses_by_coverage_and_directions():
    problem, cover = _instance(3)
    cfg = PlanConfig(requirement_m=0.10, working_radius_m=10.0, max_range_m=20.0,
                     chance_epsilon=None, network=True)
    r = plan_stations_and_sites(problem, cfg, cover, JointCosts(10.0, 1.0))
    assert cover.covered(r.stations) and r.status == "optimal"
    chosen = problem.restrict_stations(np.flatnonzero(r.stations))
    assert evaluate_layout(chosen, r.selected, LOOSE).sectors.min() >= 3


@pytest.mark.parametrize("seed", [3, 4, 7, 11])
def test_baselines_cover_and_never_beat_the_proven_optimum(seed):
    problem, cover = _instance(seed, n_stations=6)
    costs = JointCosts(station=4.0, marker=1.0)
    best = plan_stations_and_sites(problem, LOOSE, cover, costs)
    eligible = np.ones(problem.n_stations, bool)
    greedy = greedy_viewpoints(cover, eligible)
    grid, spacing = grid_viewpoints(cover, problem.station_xyz[:, :2], eligible,
                                    (-2.0, 42.0, -4.0, 4.0), [40.0, 20.0, 10.0, 5.0])
    assert cover.covered(greedy) and cover.covered(grid)
    for name, stations in (("greedy", greedy), ("grid", grid)):
        b = joint_baseline(name, problem, LOOSE, cover, costs, stations)
        assert b.covered and b.meets_requirement, b.note
        assert b.cost >= best.solution.objective - 1e-9
        chosen = problem.restrict_stations(np.flatnonzero(b.stations))
        assert evaluate_layout(chosen, b.selected, LOOSE).ok.all()


def test_greedy_viewpoints_drops_a_station_the_others_make_redundant():
    # S0 covers cells 0-3 and is taken first; S1 (cells 0, 1, 4) and S2 (2, 3, 5) follow for
    # cells 4 and 5, and then cover all S0 covered: S0 is dropped
    st = np.array([0, 0, 0, 0, 1, 1, 1, 2, 2, 2])
    cells = np.array([0, 1, 2, 3, 0, 1, 4, 2, 3, 5])
    cover = StationCover(st, cells, 6)
    chosen = greedy_viewpoints(cover, np.ones(3, bool))
    assert chosen.tolist() == [False, True, True]


def test_a_site_too_near_a_chosen_station_holds_no_marker():
    problem, cover = _instance(3)
    costs = JointCosts(station=10.0, marker=1.0)
    free = plan_stations_and_sites(problem, LOOSE, cover, costs)
    # forbid, for every chosen station, the markers it was given: the optimum must move
    st, site = [], []
    for s in np.flatnonzero(free.stations):
        for j in np.flatnonzero(free.selected):
            st.append(s)
            site.append(j)
    r = plan_stations_and_sites(problem, LOOSE, cover, costs,
                                clashes=(np.array(st), np.array(site)))
    clash = np.zeros((problem.n_stations, problem.n_sites), bool)
    clash[st, site] = True
    assert not np.any(clash[np.ix_(r.stations, r.selected)])
    assert r.solution.objective >= free.solution.objective - 1e-9
    assert cover.covered(r.stations)
