"""The survey design over an area of interest (planner.design): the chosen stations cover
the AOI by an independent count of the coverage matrix, meet the marker rules by the
as-built check of the ordinary plan, the route is closed at the start, and the joint
program's cost is no higher than either baseline's."""

import numpy as np
import pytest
from shapely.geometry import box

from error_model.default import default_model
from markerplan.errors import ConfigError, InfeasiblePlanError
from planner.accuracy.checks import evaluate_layout
from planner.config import PlanConfig
from planner.design.plan import design_plan
from planner.design.run import design_survey, flat_reach_m
from planner.outputs.design_report import design_record
from planner.problem.inputs import load_inputs

CONFIG = PlanConfig(chance_epsilon=None, time_limit_s=30.0)


@pytest.fixture(scope="module")
def inputs():
    return load_inputs("default")


@pytest.fixture(scope="module")
def design(inputs):
    # 24 m x 12 m of the crater field: more than one station's reach (11.4 m on flat ground)
    return design_survey(inputs, CONFIG, default_model(), box(-12.0, -6.0, 12.0, 6.0),
                         route_start_xy=(0.0, -3.0), progress=False)


def test_chosen_stations_cover_every_coverable_cell(design):
    chosen = np.zeros(len(design.candidate_ids), bool)
    chosen[design.order] = True
    counts = np.bincount(design.coverage.cell[chosen[design.coverage.station]],
                         minlength=len(design.grid))
    short = np.flatnonzero(counts < CONFIG.cover_min_stations)
    np.testing.assert_array_equal(short, np.sort(design.uncoverable.cell))
    assert design.order.size >= 2  # the AOI is wider than one station's reach


def test_chosen_stations_meet_the_marker_rules(design):
    sub = design.problem.restrict_stations(np.flatnonzero(design.joint.stations))
    assert evaluate_layout(sub, design.joint.selected, CONFIG).ok.all()


def test_joint_cost_is_no_higher_than_the_baselines(design):
    """Stops, markers and drive: the program's optimum against each baseline's mission time
    (its PyVRP route), up to the program's rounding of each leg to the second."""
    plan = design.joint.solution.objective
    for option in design.options[1:3]:
        assert option.covered_fraction > 0.99 and option.meets_requirement, option.note
        legs = option.n_stations + 1
        assert plan <= option.time_s["total"] + 0.5 * legs + 1e-6, option.name
    assert design.options[3].name == "hand"
    # the plan's own mission time is its objective up to the rounding of its legs
    total = design.options[0].time_s["total"]
    assert abs(total - plan) <= 0.5 * (design.order.size + 1) + 1e-6


def test_drive_is_the_program_tour_or_shorter(design):
    tour = design.joint.tour
    assert sorted(tour.tolist()) == sorted(design.order.tolist())
    xy = np.vstack([design.route_start_xy, design.candidate_position_m[tour, :2],
                    design.route_start_xy])
    straight = np.linalg.norm(np.diff(xy, axis=0), axis=1).sum()
    assert straight - 1e-6 <= design.route.length_m
    assert design.route.solver["proven_optimal"] == (design.joint.status == "optimal"
                                                     and design.joint.tour_complete)


def test_route_is_closed_at_the_start_and_visits_every_station(design):
    route = design.route
    np.testing.assert_allclose(route.polyline[0], design.route_start_xy, atol=0.5)
    np.testing.assert_allclose(route.polyline[-1], design.route_start_xy, atol=0.5)
    assert sorted(route.order.tolist()) == list(range(design.order.size))
    assert route.length_m == pytest.approx(route.leg_m.sum())
    # every leg is at least the straight line between its stops
    stops = np.vstack([design.route_start_xy, design.station_position_m[:, :2],
                       design.route_start_xy])
    assert np.all(route.leg_m >= np.linalg.norm(np.diff(stops, axis=0), axis=1) - 1e-6)


def test_design_plan_keeps_the_route_order_and_its_marker_count(inputs, design):
    outcome = design_plan(inputs, CONFIG, default_model(), box(-12.0, -6.0, 12.0, 6.0),
                          route_start_xy=(0.0, -3.0), progress=False)
    assert outcome.problem.station_ids == tuple(f"S{k + 1}" for k in range(design.order.size))
    np.testing.assert_allclose(outcome.problem.station_xyz, design.station_position_m)
    # the stations' own plan needs no more markers than the joint layout, and no fewer when
    # the joint program proved its layout optimal
    assert outcome.result.selected.sum() <= design.joint.selected.sum()
    if design.joint.status == "optimal":
        assert outcome.result.selected.sum() == design.joint.selected.sum()
    assert outcome.result.check.ok.all()


def test_flat_reach_is_the_incidence_limit():
    assert flat_reach_m(PlanConfig(), 1.0) == pytest.approx(np.tan(np.radians(85.0)))
    assert flat_reach_m(PlanConfig(cover_max_range_m=5.0), 1.0) == 5.0


def test_route_start_on_untrafficable_ground_is_refused(inputs):
    # the 8 m crater at (13.75, 10): its centre is crater interior
    with pytest.raises(ConfigError, match="`route_start` .* not on trafficable ground .*"
                                          "crater interior.*nearest trafficable point"):
        design_survey(inputs, CONFIG, default_model(), box(-6.0, -6.0, 6.0, 6.0),
                      route_start_xy=(13.75, 10.0), progress=False)


def test_an_aoi_no_station_can_cover_names_where_and_why(inputs):
    # the rover may not drive east of x = -4 m: the AOI's east end is beyond every reach
    keepout = [box(-4.0, -30.0, 30.0, 30.0)]
    with pytest.raises(InfeasiblePlanError, match=r"covers part of the AOI: \d+ AOI cells .* "
                                                  r"in \[.*\] x \[.*\] m .*incidence"):
        design_survey(inputs, CONFIG, default_model(), box(-12.0, -6.0, 12.0, 6.0),
                      keepouts=keepout, route_start_xy=(-10.0, -3.0), progress=False)


def test_an_uncoverable_part_within_the_allowance_is_left_out_and_reported(inputs):
    keepout = [box(-4.0, -30.0, 30.0, 30.0)]
    d = design_survey(inputs, CONFIG.replace(cover_min_fraction=0.6), default_model(),
                      box(-12.0, -6.0, 12.0, 6.0), keepouts=keepout,
                      route_start_xy=(-10.0, -3.0), progress=False)
    left_out = d.grid.centre_xy_m[d.uncoverable.cell]
    assert 0 < len(d.uncoverable) <= 0.4 * len(d.grid)
    # far from every candidate (all west of the keep-out): near the incidence limit's reach
    gap = np.linalg.norm(left_out[:, None] - d.candidate_position_m[None, :, :2], axis=2)
    assert gap.min(axis=1).min() > 0.8 * flat_reach_m(CONFIG, 1.0)
    assert np.all(d.candidate_position_m[:, 0] < -4.0)
    assert np.all(d.station_position_m[:, 0] < -4.0)
    assert d.options[0].covered_fraction == pytest.approx(1 - len(left_out) / len(d.grid))
    # plan.json lists its patches: together every left-out cell, each box round its cells
    cov = design_record(d, 0)["coverage"]
    assert cov["uncoverable"] == d.uncoverable.text
    patches = cov["uncoverable_patches"]
    assert sum(p["n_cells"] for p in patches) == cov["uncoverable_cells"] == len(left_out)
    assert sum(p["area_m2"] for p in patches) == pytest.approx(cov["uncoverable_area_m2"])
    assert sum(sum(p["reasons"].values()) for p in patches) == len(left_out)
    for k, p in enumerate(patches):
        xy = left_out[d.uncoverable.patch == k]
        half = 0.5 * d.grid.cell_m
        assert p["n_cells"] == len(xy)
        assert p["bounds_m"] == pytest.approx([*(xy.min(axis=0) - half),
                                               *(xy.max(axis=0) + half)], abs=1e-3)
