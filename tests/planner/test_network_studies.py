import json

import numpy as np

from planner.accuracy.network import network_model
from planner.config import PlanConfig
from planner.studies import network as ns
from tests.planner.instances import make_problem


def _row_problem():
    # four stations in a row, 9 m apart: the network's error grows away from S1
    g, h = np.arange(1.0, 40, 2.0), np.arange(1.0, 16, 2.0)
    xx, yy = np.meshgrid(g, h)
    return make_problem(np.column_stack([np.arange(6.0, 40, 9.0), np.full(4, 8.0)]),
                        np.column_stack([xx.ravel(), yy.ravel()]), max_range_m=14)


def test_studies_of_a_row_of_stations(tmp_path):
    p = _row_problem()
    cfg = PlanConfig(requirement_m=0.15, working_radius_m=6, max_range_m=14,
                     grid_spacing_m=2.0, time_limit_s=20)
    doc, layouts = ns.run_studies(p, cfg, (0.0, 0.0, 40.0, 16.0), requirements_m=(0.15, 0.2),
                                  sigmas_deg=(None, 0.1), grid_step_m=2.0,
                                  info={"site": "row", "n_candidates": p.n_sites})
    json.dumps(doc, allow_nan=False)  # JSON-safe: no nan or inf
    a = doc["modes"]
    assert a["network"]["status"] == "optimal" and set(layouts) == {"known_control", "network"}
    # the known-control optimum is no larger; judged as a network it fails or just passes
    assert a["known_control"]["markers"] <= a["network"]["markers"]
    asn = a["known_control_as_network"]
    assert (asn["stations_failing"] + asn["markers_failing"] > 0) == \
        (asn["worst_station_error_m"] > 0.15 or (asn["worst_marker_error_m"] or 0) > 0.15)
    b = doc["distance"]["layouts"]["network"]
    assert b["slope_cm_per_100m"] > 0  # errors grow away from the reference
    assert doc["distance"]["distance_m"][0] == 0.0
    # a looser requirement never needs more markers
    c = [q["markers"] for q in doc["tradeoff"]]
    assert c[1] <= c[0]
    # the no-prior plan judged with a heading prior is never worse
    d = doc["heading_prior"]
    assert d[1]["same_layout_worst_station_error_m"] <= \
        d[0]["same_layout_worst_station_error_m"] + 1e-12
    e = doc["baselines"]
    for k in ("greedy", "regular_grid"):
        assert not e[k]["meets_requirement"] or e[k]["markers"] >= a["network"]["markers"]
    text = "\n".join(ns.report_lines(doc))
    assert "(a) known control" in text and "(e) baselines" in text
    assert ns.plot_error_vs_distance(doc, tmp_path / "d.png").stat().st_size > 0
    assert ns.plot_tradeoff_and_prior(doc, tmp_path / "t.png").stat().st_size > 0


def test_plan_text_never_calls_a_time_limited_plan_optimal():
    assert ns.plan_text({"markers": 3, "status": "optimal"}) == "3 (optimal)"
    assert ns.plan_text({"markers": 763, "status": "time_limit", "dual_bound": 80.2,
                         "gap": 0.89}) == "<= 763 (time limit, bound 81, gap 89 %)"
    assert ns.plan_text({"status": "no_solution"}) == "no layout in the time limit"
    assert ns.plan_text({"status": "infeasible"}) == "infeasible"


def test_an_untied_station_is_reported_as_undetermined():
    # S3 shares no marker with S1 and S2: as a network it is not tied to the reference
    p = make_problem([[0.0, 0.0], [6.0, 0.0], [60.0, 0.0]],
                     [[3.0, 4.0], [3.0, -4.0], [-3.0, 0.0], [60.0, 5.0]], max_range_m=10)
    cfg = PlanConfig(network=True, min_markers=1, min_sectors=1, max_range_m=10)
    j = ns.judge_as_network(p, np.ones(4, bool), cfg, network_model(p, cfg))
    assert j["stations_undetermined"] == 1 and j["worst_station_error_m"] is None
    assert j["worst_determined_station_error_m"] is not None
    assert j["stations_failing"] >= 1
    assert ns._worst(j, "station").startswith("inf (else ")
