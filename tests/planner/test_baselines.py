import time

import numpy as np
import pytest

from planner.accuracy.checks import evaluate_layout
from planner.accuracy.network import network_model
from planner.config import PlanConfig
from planner.program import plan_sites
from planner.program.baselines import (
    GreedyStuckError,
    greedy_cover,
    greedy_network,
    network_baseline,
    regular_grid,
)
from tests.planner.instances import make_problem


def test_baselines_meet_the_requirement_and_never_beat_the_optimum():
    rng = np.random.default_rng(7)
    g = np.arange(0.5, 30, 1.0)
    xx, yy = np.meshgrid(g, g)
    p = make_problem(rng.uniform(5, 25, (5, 2)), np.column_stack([xx.ravel(), yy.ravel()]),
                     max_range_m=20)
    cfg = PlanConfig(requirement_m=0.04, working_radius_m=10, max_range_m=20)
    opt = int(plan_sites(p, cfg).selected.sum())
    greedy = greedy_cover(p, cfg)
    grid = regular_grid(p, cfg, (0.0, 0.0, 30.0, 30.0))
    for b in (greedy, grid):
        assert b.meets_requirement
        assert evaluate_layout(p, b.selected, cfg).all_ok
        assert b.n_markers >= opt
    assert grid.spacing_m is not None and grid.spacing_m >= 1.0
    # a wider grid than the one returned fails at every phase tried
    wider = regular_grid(p, cfg, (0.0, 0.0, 30.0, 30.0),
                         spacings_m=np.array([grid.spacing_m + 0.5]))
    assert not wider.meets_requirement or grid.spacing_m + 0.5 > cfg.max_range_m


def test_regular_grid_in_network_mode_judges_the_network():
    # four stations in a row, 9 m apart: registered to known control a 13 m grid is enough,
    # but as a network tied to S1 the far stations drift and the grid must be denser
    g, h = np.arange(0.5, 40, 1.0), np.arange(0.5, 16, 1.0)
    xx, yy = np.meshgrid(g, h)
    p = make_problem(np.column_stack([np.arange(6.0, 40, 9.0), np.full(4, 8.0)]),
                     np.column_stack([xx.ravel(), yy.ravel()]), max_range_m=14)
    cfg = PlanConfig(requirement_m=0.06, working_radius_m=6, max_range_m=14)
    net_cfg = cfg.replace(network=True)
    net = network_model(p, net_cfg)
    bounds, spacings = (0.0, 0.0, 40.0, 16.0), np.arange(14.0, 1.9, -1.0)
    known = regular_grid(p, cfg, bounds, spacings_m=spacings)
    assert known.meets_requirement and known.spacing_m == 13.0
    assert not evaluate_layout(p, known.selected, net_cfg, net=net).all_ok
    grid = regular_grid(p, net_cfg, bounds, spacings_m=spacings, net=net)
    assert grid.meets_requirement and grid.spacing_m < known.spacing_m
    check = evaluate_layout(p, grid.selected, net_cfg, net=net)
    assert check.all_ok and np.nanmax(check.marker_error_m) <= 0.06
    assert grid.n_markers > known.n_markers
    # the next wider spacing fails the network at every phase tried
    assert not regular_grid(p, net_cfg, bounds, spacings_m=np.array([grid.spacing_m + 1.0]),
                            net=net).meets_requirement


@pytest.mark.parametrize(("requirement", "redundant", "batch", "expected"), [
    (0.3, False, 1, [0, 6, 8, 10, 16, 27, 32, 93, 101, 112, 119]),
    (0.3, True, 1, [3, 6, 8, 17, 31, 35, 42, 47, 52, 54, 64, 77, 103, 109, 119]),
    (0.15, False, 1, [0, 6, 8, 10, 16, 17, 20, 27, 28, 32, 41, 43, 44, 47, 58, 59, 63, 68, 86,
                      93, 95, 101, 105, 112, 119]),
    (0.3, False, 3, [0, 6, 8, 16, 27, 32, 86, 93, 101, 112, 119]),
])
def test_network_greedy_picks_what_the_full_recompute_picked(requirement, redundant, batch,
                                                             expected):
    # expected: the selections of the greedy that rebuilt the information and inverted it
    # afresh at every step (before the incremental covariance), with the tie-first rule: six
    # stations in a row, S4-S6 free in heading after the direction cover; sites 0 (seen by
    # S2-S4) and 5 (S3-S5, the old first-order choice) each remove that one free movement, so
    # the lowest index is tied first; the same marker counts as before the rule
    p = _row_of_stations()
    cfg = _ROW_CONFIG.replace(requirement_m=requirement, redundant=redundant)
    g = greedy_network(p, cfg, batch=batch)
    assert np.flatnonzero(g.selected).tolist() == expected
    assert evaluate_layout(p, g.selected, cfg).all_ok


@pytest.mark.parametrize(("redundant", "expected"), [
    (False, [6, 8, 16, 32, 58, 93, 101, 119]),
    (True, [3, 6, 8, 35, 42, 52, 73, 75, 77, 93, 96, 103, 109, 119]),
])
def test_greedy_cover_picks_what_it_picked_checking_every_station_afresh(redundant, expected):
    # expected: the greedy cover before it remembered each station's error per site set
    rng = np.random.default_rng(3)
    stations = np.column_stack([np.arange(6) * 12.0, rng.uniform(-3, 3, 6)])
    sites = np.column_stack([rng.uniform(-10, 70, 120), rng.uniform(-14, 14, 120)])
    p = make_problem(stations, sites, max_range_m=18)
    cfg = PlanConfig(min_markers=3, min_sectors=2, max_range_m=18, working_radius_m=8,
                     requirement_m=0.03, redundant=redundant)
    g = greedy_cover(p, cfg)
    assert np.flatnonzero(g.selected).tolist() == expected
    assert evaluate_layout(p, g.selected, cfg).all_ok


#: Network rules of the row of stations below (requirement 0.3 m).
_ROW_CONFIG = PlanConfig(network=True, min_markers=3, min_sectors=2, max_range_m=18,
                         working_radius_m=8, requirement_m=0.3)


def _row_of_stations(extra_stations=(), extra_sites=()):
    """The six stations in a row of the tests above, plus optional stations and sites."""
    rng = np.random.default_rng(3)
    stations = np.column_stack([np.arange(6) * 12.0, rng.uniform(-3, 3, 6)])
    sites = np.column_stack([rng.uniform(-10, 70, 120), rng.uniform(-14, 14, 120)])
    stations = np.vstack([stations, np.reshape(extra_stations, (-1, 2))])
    sites = np.vstack([sites, np.reshape(extra_sites, (-1, 2))])
    return make_problem(stations, sites, max_range_m=18)


def _row_with_an_untiable_station():
    """The row plus S7, 200 m away with its own ring of sites: nothing it sees is seen by
    another station, so no site ties it to the reference."""
    ring = 200.0 + 6 * np.column_stack([np.cos(np.arange(8) * np.pi / 4),
                                        np.sin(np.arange(8) * np.pi / 4)])
    ring[:, 1] -= 200.0
    return _row_of_stations(np.array([[200.0, 0.0]]), ring)


def test_network_greedy_that_runs_out_of_steps_says_which_stations_are_untied():
    # after the direction cover S4-S6 turn freely in heading; no step is allowed to tie them
    p = _row_of_stations()
    cfg = _ROW_CONFIG
    with pytest.raises(GreedyStuckError, match=r"^greedy \(network\) got stuck with 3 station\(s\)"
                       r" not tied to the reference \(S4, S5, S6\) after 7 markers: stopped "
                       r"after 0 steps$") as err:
        greedy_network(p, cfg, max_steps=0)
    assert err.value.selected.sum() == 7
    # one step ties them (site 0); S5 and S6 then still fail the requirement
    with pytest.raises(GreedyStuckError, match=r"^greedy \(network\) cannot satisfy station\(s\) "
                       r"S5, S6 after 8 markers: stopped after 1 steps$") as err:
        greedy_network(p, cfg, max_steps=1)
    assert err.value.selected[0] and err.value.selected.sum() == 8


def test_network_greedy_starts_no_step_after_its_deadline():
    p = _row_of_stations()
    cfg = _ROW_CONFIG
    with pytest.raises(GreedyStuckError, match=r"^greedy \(network\) got stuck with 3 station\(s\)"
                       r" not tied .* after 7 markers: its share of the time limit ran out$"):
        greedy_network(p, cfg, deadline=time.perf_counter())
    later = greedy_network(p, cfg, deadline=time.perf_counter() + 3600)
    np.testing.assert_array_equal(later.selected, greedy_network(p, cfg).selected)


def test_network_greedy_stops_at_once_when_no_site_can_tie_a_station():
    # the greedy ties S4-S6 and then stops (not after max_steps) naming S7 alone
    p = _row_with_an_untiable_station()
    cfg = _ROW_CONFIG
    with pytest.raises(GreedyStuckError, match=r"got stuck with 1 station\(s\) not tied to the "
                       r"reference \(S7\) after \d+ markers: no remaining site removes a free "
                       r"movement$") as err:
        greedy_network(p, cfg)
    assert err.value.selected[0]  # S4-S6 were tied first, by site 0 as without S7


def test_network_baseline_keeps_why_the_greedy_got_stuck():
    """The stuck greedy's layout is reported with its error's message as the note; a greedy
    that finishes has none."""
    cfg = _ROW_CONFIG
    p = _row_with_an_untiable_station()
    with pytest.raises(GreedyStuckError) as err:
        greedy_network(p, cfg)
    b = network_baseline(p, cfg)
    assert b.name == "greedy" and not b.meets_requirement
    assert b.note == str(err.value) and "(S7)" in b.note
    np.testing.assert_array_equal(b.selected, err.value.selected)
    done = network_baseline(_row_of_stations(), cfg)
    assert done.meets_requirement and done.note is None
