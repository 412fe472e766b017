"""The integer program at scale: identical columns regrouped, HiGHS limits, honest statuses."""

import itertools
from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from planner.config import PlanConfig
from planner.outputs.report import report_markdown
from planner.program import aggregate_columns, build_model, plan_sites, solve, solving
from planner.program.highs import HighsOutcome, run_highs, solver_record
from tests.planner.instances import brute_force_optimum, make_problem

LOOSE = PlanConfig(requirement_m=5.0, working_radius_m=10.0, max_range_m=14.0)


def _clustered(seed: int, n_clusters: int = 7, per_cluster: int = 3):
    """Stations and candidate sites in tight clusters: sites of one cluster see the same
    stations in the same sectors, so their columns are identical in the directions rows."""
    rng = np.random.default_rng(seed)
    stations = rng.uniform(4, 16, (3, 2))
    centres = rng.uniform(0, 20, (n_clusters, 2))
    sites = np.repeat(centres, per_cluster, axis=0) + rng.uniform(-0.05, 0.05,
                                                                  (n_clusters * per_cluster, 2))
    return make_problem(stations, sites, max_range_m=14.0)


def _directions_only(model):
    keep = np.array([k.family != "info" for k in model.row_kind])
    return replace(model, A=model.A[keep], row_lb=model.row_lb[keep], row_ub=model.row_ub[keep],
                   row_kind=tuple(k for k, q in zip(model.row_kind, keep, strict=True) if q))


def test_identical_sites_form_one_group():
    p = make_problem([[0, 0], [10, 0]], [[5, 3], [5, 3], [5, 3], [5, -3], [-4, 0], [14, 0]],
                     max_range_m=12.0)
    group, first = aggregate_columns(build_model(p, LOOSE))
    # the three copies of (5, 3) share every row, cost and bound; the others are alone
    assert group.tolist() == [0, 0, 0, 1, 2, 3]
    assert first.tolist() == [0, 3, 4, 5]


@pytest.mark.parametrize("seed", range(6))
def test_regrouping_keeps_the_optimum(seed):
    p = _clustered(seed)
    model = _directions_only(build_model(p, LOOSE))
    group, _ = aggregate_columns(model)
    assert group.max() + 1 < model.var_site.size  # something was merged
    plain = solve(model)
    # the last member of each group preferred: markers must move
    merged = solve(model, priority=np.arange(model.var_site.size))
    if plain.status == "infeasible":
        assert merged.status == "infeasible"
        return
    assert plain.status == merged.status == "optimal"
    assert merged.objective == pytest.approx(plain.objective)
    assert merged.dual_bound == pytest.approx(plain.objective)
    # the regrouped layout is feasible for the unaggregated model, at that objective
    x = merged.x
    ax = model.A @ x
    assert np.all(ax >= model.row_lb - 1e-9) and np.all(ax <= model.row_ub + 1e-9)
    assert model.c @ x == pytest.approx(plain.objective)
    assert np.array_equal(np.flatnonzero(merged.selected),
                          np.sort(model.var_site[x[:model.var_site.size] > 0.5]))
    # in every group the markers sit on its last (most preferred) members
    sel = x[:model.var_site.size] > 0.5
    for g in range(group.max() + 1):
        members = np.flatnonzero(group == g)
        assert sel[members[members.size - sel[members].sum():]].all()


@pytest.mark.parametrize("seed", range(4))
def test_plan_matches_brute_force_on_clustered_sites(seed):
    # two stations, five pairs of near-identical sites around them
    rng = np.random.default_rng(seed)
    bearings = np.radians(np.sort(rng.uniform(0, 360, 5)))
    centres = np.array([4.0, 0.0]) + 6.0 * np.column_stack([np.cos(bearings),
                                                            np.sin(bearings)])
    sites = np.repeat(centres, 2, axis=0) + rng.uniform(-0.05, 0.05, (10, 2))
    p = make_problem([[2.0, 0.0], [6.0, 0.0]], sites, max_range_m=14.0)
    cfg = LOOSE.replace(min_sectors=2, min_markers=3)
    assert aggregate_columns(_directions_only(build_model(p, cfg)))[1].size < 10
    for requirement in (5.0, 0.02):
        best = brute_force_optimum(p, cfg.replace(requirement_m=requirement))
        assert best is not None
        r = plan_sites(p, cfg.replace(requirement_m=requirement))
        assert r.status == "optimal" and r.check.all_ok
        assert int(r.selected.sum()) == best


def test_regrouped_counts_never_exceed_a_group():
    # a station needing 3 markers where only one cluster of 3 copies is usable: all 3 go
    p = make_problem([[0, 0]], [[5, 5], [5, 5], [5, 5], [-5, 5], [-5, -5], [5, -5]],
                     max_range_m=10.0)
    cfg = LOOSE.replace(min_sectors=1, n_sectors=1, min_markers=5)
    sol = solve(_directions_only(build_model(p, cfg)), priority=np.zeros(6))
    assert sol.status == "optimal" and int(sol.selected.sum()) == 5
    assert sol.selected[:3].all()


def test_time_limited_run_is_not_called_optimal():
    rng = np.random.default_rng(2)
    g = np.arange(0.5, 40, 1.0)
    xx, yy = np.meshgrid(g, g)
    p = make_problem(rng.uniform(5, 35, (12, 2)), np.column_stack([xx.ravel(), yy.ravel()]),
                     max_range_m=15.0)
    sol = solve(build_model(p, LOOSE), time_limit_s=1e-4)
    assert sol.status in ("time_limit", "no_solution")


def test_a_stopped_run_reports_its_bound_and_gap(monkeypatch):
    # HiGHS stopped by its limit with an incumbent of 5 and a bound of 3.2: integral
    # objective, so the bound is 4 and the gap (5 - 4) / 5
    p = make_problem([[0, 0]], [[5, 0], [0, 5], [-5, 0], [0, -5], [4, 4]], max_range_m=10.0)
    model = build_model(p, LOOSE)
    x = np.ones(model.n_vars)

    def stopped(*args, **kwargs):
        return HighsOutcome(status="time_limit", x=x, objective=5.0, dual_bound=3.2, gap=0.36,
                            solve_time_s=1.0, message="Time limit reached")

    monkeypatch.setattr(solving, "run_highs", stopped)
    sol = solve(model)
    assert sol.status == "time_limit"
    assert sol.dual_bound == 4.0 and sol.gap == pytest.approx(0.2)
    doc = {"site": {"name": "t"}, "n_markers": 5, "stations": [],
           "requirement": {"requirement_m": 0.1, "working_radius_m": 10, "min_markers": 3,
                           "min_sectors": 3, "n_sectors": 6, "redundant": False,
                           "error_figure": "ellipsoid", "error_figure_text": "the ellipsoid"},
           "solver": {**solver_record(60.0, 0.0), "status": sol.status,
                      "objective": sol.objective, "dual_bound": sol.dual_bound, "gap": sol.gap,
                      "iterations": 1, "accuracy_cuts": 0, "proven_optimal": False},
           "baselines": {}, "markers": [], "frame": "site frame",
           "visibility": {"n_pairs": 0, "n_usable": 0}, "candidates": {"n_sites": 5},
           "provenance": {"error_model": "m", "markerplan_version": "0",
                          "config_sha256": "0" * 64}}
    text = report_markdown(doc)
    assert "status **time_limit** — not proven optimal" in text
    assert "dual bound 4.0, gap 0.2" in text
    assert "time limit 60 s, target gap 0, 2 thread(s)" in text


def test_run_highs_small_program_against_enumeration():
    # min x0 + 2 x1 + 3 x2  s.t.  x0 + x1 >= 1, x1 + x2 >= 1, x0 + x2 >= 1 (binary)
    a = np.array([[1, 1, 0], [0, 1, 1], [1, 0, 1]], float)
    c = np.array([1.0, 2.0, 3.0])
    out = run_highs(c, a, np.ones(3), np.full(3, np.inf), np.zeros(3), np.ones(3),
                    np.ones(3, np.int64), 10.0, 0.0, integral_objective=True)
    best = min(c @ np.array(v) for v in itertools.product((0, 1), repeat=3)
               if np.all(a @ np.array(v) >= 1))
    assert out.status == "optimal" and out.objective == pytest.approx(best) == 3.0
    assert solver_record(60.0, 0.0)["threads"] == 2


def test_run_highs_sums_repeated_entries_and_leaves_the_matrix_alone():
    # one row x0 + x1 >= 1 with x0's coefficient given as 0.5 twice, after x1's: unsorted,
    # repeated entries mean their sum, so x0 alone (cost 1) is enough, not x1 (cost 3)
    a = sp.csr_array((np.array([1.0, 0.5, 0.5]), np.array([1, 0, 0]), np.array([0, 3])),
                     shape=(1, 2))
    data = a.data.copy()
    out = run_highs(np.array([1.0, 3.0]), a, np.ones(1), np.full(1, np.inf), np.zeros(2),
                    np.ones(2), np.ones(2, np.int64), 10.0, 0.0, integral_objective=True)
    assert out.status == "optimal" and out.objective == 1.0
    np.testing.assert_array_equal(out.x, [1.0, 0.0])
    assert not a.has_canonical_format and np.array_equal(a.data, data)


def test_directions_only_model_is_the_full_model_without_information_rows():
    p = _clustered(1)
    full = build_model(p, LOOSE)
    relaxed = build_model(p, LOOSE, information=False)
    keep = np.array([k.family != "info" for k in full.row_kind])
    assert keep.sum() < keep.size  # the full model has information rows
    assert relaxed.n_vars == full.n_vars
    assert np.array_equal(relaxed.var_site, full.var_site)
    assert relaxed.row_kind == tuple(k for k, q in zip(full.row_kind, keep, strict=True) if q)
    assert (abs(relaxed.A - full.A[keep]) > 0).nnz == 0
    assert np.array_equal(relaxed.row_lb, full.row_lb[keep])


def test_station_error_from_its_markers_matches_the_cached_information():
    from planner.accuracy import known_control
    from planner.accuracy.checks import StationInfo

    p = _clustered(2)
    for s in range(p.n_stations):
        info = StationInfo(p, s, LOOSE)
        if info.sites.size < 2:
            continue
        picked = info.sites[::2]
        j = info.info[::2].sum(axis=0)  # all sites' information, computed on first use
        expected = known_control.errors_from_information(j[None], info.radius, info.incl,
                                                         info.figure)[0]
        assert info.error(picked) == expected  # bit for bit
        assert info.error(np.r_[picked, -1]) == expected  # not a usable site: ignored
        assert np.array_equal(info.rows(np.r_[info.sites[1], 10**6]), [1])
