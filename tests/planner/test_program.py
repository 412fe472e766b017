
import itertools
from dataclasses import replace

import numpy as np
import pytest

from markerplan.errors import ConfigError, InfeasiblePlanError
from planner.accuracy.checks import diagnose, evaluate_layout
from planner.config import PlanConfig
from planner.problem.usability import sector_index
from planner.program import (
    RowKind,
    build_model,
    info_weights,
    plan_sites,
    solve,
    with_tightening_rows,
)
from tests.planner.instances import brute_force_optimum, make_problem, ring

LOOSE = PlanConfig(requirement_m=0.10, working_radius_m=10.0, max_range_m=30.0)


def test_one_station_six_sectors_needs_exactly_three():
    p = make_problem([[0, 0]], ring([0, 0], 8.0, [30, 90, 150, 210, 270, 330]))
    r = plan_sites(p, LOOSE)
    assert r.selected.sum() == 3 and r.status == "optimal"
    assert r.solution.dual_bound == pytest.approx(3.0)
    assert r.check.sectors[0] == 3


def test_success_means_a_proven_optimum():
    p = make_problem([[0, 0]], ring([0, 0], 8.0, [30, 90, 150, 210, 270, 330]))
    r = plan_sites(p, LOOSE)
    assert r.success is True and r.solution.success is True
    for status in ("gap_reached", "time_limit", "infeasible", "no_solution", "error"):
        late = replace(r, solution=replace(r.solution, status=status))
        assert late.success is False and late.solution.success is False, status


def test_two_stations_sharing_a_lens_need_four():
    # sites within 12 m of both stations lie within +-40 deg of the baseline: at most two
    # sectors, so each station needs one private site -> optimum 4
    sites = [[10, 6], [10, -6], [10, 0], [-5, 0], [0, -8], [0, 8], [25, 0], [20, 8], [20, -8]]
    p = make_problem([[0, 0], [20, 0]], sites, max_range_m=12.0)
    cfg = LOOSE.replace(max_range_m=12.0)
    r = plan_sites(p, cfg)
    assert r.selected.sum() == 4 and r.status == "optimal"
    assert r.selected[0] and r.selected[1]
    assert brute_force_optimum(p, cfg) == 4


@pytest.mark.parametrize("seed,figure", [(0, "ellipsoid"), (1, "ellipsoid"), (3, "ellipsoid"),
                                         (4, "ellipsoid"), (0, "quantile"), (3, "quantile")])
def test_accuracy_binding_instances_match_brute_force(seed, figure):
    rng = np.random.default_rng(seed)
    p = make_problem(rng.uniform(5, 25, (3, 2)), rng.uniform(0, 30, (11, 2)), max_range_m=25)
    req = 0.04 if figure == "ellipsoid" else 0.033  # about the same share of layouts binding
    cfg = PlanConfig(requirement_m=req, working_radius_m=10, max_range_m=25, error_figure=figure)
    r = plan_sites(p, cfg)
    loose = plan_sites(p, cfg.replace(requirement_m=5.0))
    # accuracy binds: some layout as small as the directions-only optimum meets counts and
    # directions but fails it (which one the solver picks among ties is its own choice)
    k = int(loose.selected.sum())
    layouts = [np.isin(np.arange(p.n_sites), c)
               for c in itertools.combinations(range(p.n_sites), k)]
    directions_ok = [s for s in layouts
                     if evaluate_layout(p, s, cfg.replace(requirement_m=5.0)).all_ok]
    assert any(not evaluate_layout(p, s, cfg).all_ok for s in directions_ok)
    assert r.selected.sum() == brute_force_optimum(p, cfg)
    assert r.check.all_ok and np.all(r.check.error_m <= req)


def _grid_instance(seed=4, spacing=3.0):
    rng = np.random.default_rng(seed)
    g = np.arange(1.5, 30, spacing)
    xx, yy = np.meshgrid(g, g)
    return make_problem(rng.uniform(5, 25, (4, 2)), np.column_stack([xx.ravel(), yy.ravel()]),
                        max_range_m=20)


def test_accuracy_cuts_are_needed_and_the_plan_is_minimal():
    p = _grid_instance()
    cfg = PlanConfig(requirement_m=0.03, working_radius_m=10, max_range_m=20)
    # the full model from the start (no directions-only first solve): the cut loop itself
    full = with_tightening_rows(p, build_model(p, cfg), cfg)
    r = plan_sites(p, cfg, model=full)
    assert r.check.all_ok
    assert r.n_cuts > 0  # directions and information cuts alone were not enough
    assert plan_sites(p, cfg).selected.sum() == r.selected.sum()
    for j in np.flatnonzero(r.selected):
        fewer = r.selected.copy()
        fewer[j] = False
        assert not evaluate_layout(p, fewer, cfg).all_ok, f"marker {p.site_ids[j]} is spare"


def test_redundant_plan_survives_every_single_loss():
    p = _grid_instance(seed=5, spacing=4.0)
    cfg = PlanConfig(requirement_m=0.05, working_radius_m=10, max_range_m=20, redundant=True,
                     time_limit_s=60)
    r = plan_sites(p, cfg)
    normal = cfg.replace(redundant=False)
    assert r.check.all_ok
    for j in np.flatnonzero(r.selected):
        fewer = r.selected.copy()
        fewer[j] = False
        assert evaluate_layout(p, fewer, normal).all_ok, f"losing {p.site_ids[j]} breaks it"
    assert r.selected.sum() > plan_sites(p, normal).selected.sum()


def test_infeasible_requirement_names_each_station_and_why():
    sites = ring([0, 0], 8.0, [30, 90, 150, 210, 270, 330])
    sites = np.vstack([sites, [[40, 0], [44, 2]]])  # only two sectors for S3
    stations = [[0, 0], [200, 0], [40, 5], [0, 1]]
    occluded = [(3, j) for j in range(8)]
    p = make_problem(stations, sites, max_range_m=30, occluded=occluded)
    with pytest.raises(InfeasiblePlanError) as exc:
        plan_sites(p, LOOSE)
    msg = str(exc.value)
    assert "\n" not in msg
    assert "S2: no candidate site within" in msg
    assert "S3: too few" in msg
    assert "S4: all" in msg and "occluded" in msg
    assert "S1:" not in msg  # S1 is satisfiable
    with pytest.raises(InfeasiblePlanError, match="accuracy unreachable"):
        plan_sites(make_problem([[0, 0]], sites[:6]), LOOSE.replace(requirement_m=0.001))


@pytest.mark.parametrize("z_m, reason", [
    (None, "no candidate site within 30 m: the nearest, C000, is 93.2 m away"),
    (500.0, "lies at least 499.9 m above the 6 candidate sites within 30 m across, so it stands "
            "on a spike"),
    (-500.0, "lies at least 500.1 m below the 6 candidate sites within 30 m across, so it "
             "stands in a pit"),
    (1.0, "no pair with any of the 6 candidate sites within 30 m: the visibility lists none"),
])
def test_a_station_with_no_site_in_range_is_told_why(z_m, reason):
    """S2 has no pair: far from every site, or (moved onto S1, its pairs left out) far above
    or below them, or paired by a table that lists none for it."""
    p = make_problem([[0, 0], [100, 0]], ring([0, 0], 8.0, [30, 90, 150, 210, 270, 330]))
    if z_m is not None:
        p = replace(p, station_xyz=np.array([[0, 0, 1.0], [0, 0, z_m]]))
    assert reason in diagnose(p, LOOSE)["S2"]


def test_budget_existing_and_forbidden():
    p = make_problem([[0, 0]], ring([0, 0], 8.0, [30, 90, 150, 210, 270, 330]))
    with pytest.raises(InfeasiblePlanError, match="budget"):
        plan_sites(p, LOOSE.replace(budget=2))
    r = plan_sites(p, LOOSE.replace(existing=("C000", "C001"), forbidden=("C002", "C003")))
    assert r.selected[0] and r.selected[1] and not r.selected[2] and not r.selected[3]
    assert r.selected.sum() == 3
    with pytest.raises(ConfigError, match="unknown site"):
        plan_sites(p, LOOSE.replace(forbidden=("nope",)))


def test_models_and_inputs_are_never_mutated():
    p = _grid_instance()
    before = {k: np.copy(getattr(p, k)) for k in ("pair_reason", "pair_sigma_m", "site_xyz")}
    model = build_model(p, LOOSE)
    rows = model.site_row([0, 1])
    bigger = model.with_rows(rows, [1.0], [np.inf], [RowKind("budget")])
    assert model.A.shape[0] + 1 == bigger.A.shape[0]
    assert len(bigger.row_kind) == bigger.A.shape[0] and bigger.row_kind[-1].station == -1
    plan_sites(p, LOOSE)
    for k, v in before.items():
        assert np.array_equal(getattr(p, k), v)
    sol = solve(model, 10.0)
    assert sol.status == "optimal" and sol.gap == pytest.approx(0.0)


@pytest.mark.parametrize("redundant", [False, True])
def test_model_rows_spell_the_formulation(redundant):
    # two stations sharing sites, one seeing none; read every row back against the
    # formulation written out station by station
    rng = np.random.default_rng(2)
    p = make_problem([[0, 0], [6, 2], [300, 0]], rng.uniform(-8, 12, (14, 2)), max_range_m=12)
    cfg = LOOSE.replace(redundant=redundant, budget=9, n_sectors=4, min_sectors=2)
    m = build_model(p, cfg)
    a = m.A.toarray()
    nx, kinds = m.var_site.size, [(k.family, k.station) for k in m.row_kind]
    expected, r, var = [], 0, nx
    for s in range(p.n_stations):
        idx = p.usable_pairs(s)
        cols = m.site_var[p.pair_site[idx]]
        sec = sector_index(p.pair_bearing_rad[idx], cfg.n_sectors)
        expected += [("count", s, {c: 1.0 for c in cols}, 3 + redundant, np.inf),
                     ("info", s, dict(zip(cols, info_weights(p, idx, cfg)[0], strict=True)),
                      1.0, np.inf)]
        ys = {}
        for k in np.unique(sec):
            ys[k] = var
            expected.append(("sector", s, {var: 1.0} | {c: -1.0 for c in cols[sec == k]},
                             -np.inf, 0.0))
            if redundant:
                expected += [("sector2", s, {var + 1: 2.0} | {c: -1.0 for c in cols[sec == k]},
                              -np.inf, 0.0),
                             ("sector21", s, {var + 1: 1.0, var: -1.0}, -np.inf, 0.0)]
            var += 1 + redundant
        expected.append(("directions", s, {y: 1.0 for y in ys.values()}, 2, np.inf))
        if redundant:
            expected += [("directions-loss", s, {y: 1.0 for kk, y in ys.items() if kk != k}
                          | {ys[k] + 1: 1.0}, 2, np.inf) for k in ys]
    expected.append(("budget", -1, dict.fromkeys(range(nx), 1.0), -np.inf, 9.0))
    assert m.n_vars == var and len(kinds) == len(expected) == a.shape[0]
    for r, (family, s, entries, lo, hi) in enumerate(expected):
        assert kinds[r] == (family, s)
        assert (m.row_lb[r], m.row_ub[r]) == (lo, hi)
        row = np.zeros(m.n_vars)
        row[list(entries)] = list(entries.values())
        np.testing.assert_array_equal(a[r], row, err_msg=f"row {r} ({family}, station {s})")


def test_a_linear_relaxation_keeps_its_fractional_solution():
    # the root relaxation linearises at the LP's own point: its x must not come back rounded
    import scipy.sparse as sp

    from planner.program.model import Model

    model = Model(c=np.ones(2), A=sp.csr_array(np.array([[2.0, 2.0]])), row_lb=np.ones(1),
                  row_ub=np.full(1, np.inf), lb=np.zeros(2), ub=np.ones(2),
                  integrality=np.zeros(2, np.int32), var_site=np.arange(2),
                  site_var=np.arange(2), row_kind=(RowKind("cover"),))
    sol = solve(model, 10.0)
    assert sol.status == "optimal" and sol.objective == pytest.approx(0.5)
    assert sol.x.sum() == pytest.approx(0.5)
    integer = solve(replace(model, integrality=np.ones(2, np.int32)), 10.0)
    assert integer.objective == 1.0 and set(integer.x) <= {0.0, 1.0}


def test_a_warm_lp_with_rows_added_solves_as_the_whole_lp_would():
    import scipy.sparse as sp

    from planner.program.highs import WarmLP, run_highs

    rng = np.random.default_rng(0)
    a = sp.csr_array(rng.uniform(0, 1, (6, 8)) * (rng.uniform(size=(6, 8)) < 0.6)
                     + np.eye(6, 8))  # every row can reach 1 with x <= 1
    c, lb, ub = rng.uniform(1, 2, 8), np.zeros(8), np.ones(8)
    lp = WarmLP(c, a[:2], np.ones(2), np.full(2, np.inf), lb, ub)
    assert lp.solve(10.0).status == "optimal"
    lp.add_rows(a[2:], np.ones(4), np.full(4, np.inf))
    warm = lp.solve(10.0)
    whole = run_highs(c, a, np.ones(6), np.full(6, np.inf), lb, ub, np.zeros(8, np.int32),
                      10.0, 0.0)
    assert warm.status == whole.status == "optimal"
    assert warm.objective == pytest.approx(whole.objective, rel=1e-9, abs=1e-9)
