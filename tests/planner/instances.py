"""Small hand-built planning instances (no terrain, analytic error model) for the planner tests."""

from __future__ import annotations

import itertools

import numpy as np

from planner.problem.usability import OCCLUDED, USABLE, PlanProblem


def analytic_sigma(distance_m):
    """Stand-in error model for tests only: sigma grows linearly with distance, m."""
    return 0.004 + 0.0015 * np.asarray(distance_m, float)


def make_problem(station_xy, site_xy, max_range_m=30.0, occluded=(), sigma=analytic_sigma,
                 existing=None):
    """PlanProblem from plain coordinates: every pair within ``max_range_m`` is usable unless
    listed in ``occluded`` as (station index, site index)."""
    st = np.column_stack([np.asarray(station_xy, float), np.full(len(station_xy), 1.0)])
    si = np.column_stack([np.asarray(site_xy, float), np.full(len(site_xy), 0.1)])
    d = np.linalg.norm(st[:, None, :] - si[None, :, :], axis=2)
    ps, pj = np.nonzero(d <= max_range_m)
    diff = si[pj] - st[ps]
    reason = np.full(ps.size, USABLE, dtype=np.int8)
    occ = set(occluded)
    for k in range(ps.size):
        if (int(ps[k]), int(pj[k])) in occ:
            reason[k] = OCCLUDED
    n = len(site_xy)
    ex = np.zeros(n, bool) if existing is None else np.asarray(existing, bool)
    return PlanProblem(
        station_ids=tuple(f"S{i + 1}" for i in range(len(station_xy))), station_xyz=st,
        site_ids=tuple(f"C{j:03d}" for j in range(n)), site_xyz=si, site_existing=ex,
        site_cost=np.where(ex, 0.0, 1.0), pair_station=ps, pair_site=pj,
        pair_distance_m=d[ps, pj], pair_bearing_rad=np.arctan2(diff[:, 1], diff[:, 0]),
        pair_sigma_m=sigma(d[ps, pj]), pair_reason=reason)


def ring(centre, radius, bearings_deg):
    """Points on a circle around ``centre`` at the given bearings (degrees)."""
    b = np.radians(np.asarray(bearings_deg, float))
    return np.asarray(centre, float) + radius * np.column_stack([np.cos(b), np.sin(b)])


def station_line(n_stations=4, seed=5, n_sites=12, spacing=15.0):
    """Stations ``spacing`` m apart on the x axis with ``n_sites`` random sites around them
    (x from 10 m before the first to 10 m past the last, y within 12 m), 20 m range."""
    rng = np.random.default_rng(seed)
    st_xy = np.column_stack([np.arange(n_stations) * spacing, np.zeros(n_stations)])
    x0, x1 = -10.0, (n_stations - 1) * spacing + 10.0
    sites = np.column_stack([rng.uniform(x0, x1, n_sites), rng.uniform(-12, 12, n_sites)])
    return make_problem(st_xy, sites, max_range_m=20.0)


class AnalyticModel:
    """Tiny stand-in error model for tests only (sigma linear in distance, fixed domain)."""

    predictors = ("distance_m", "elevation_rad")

    def __init__(self, max_distance_m: float = 40.0):
        self.max_distance_m = max_distance_m

    def predict(self, distance_m, elevation_rad, **extra):
        from types import SimpleNamespace

        d = np.asarray(distance_m, float)
        sigma = analytic_sigma(d)
        return SimpleNamespace(sigma_m=sigma, q95_m=2.0 * sigma,
                               in_domain=d <= self.max_distance_m)


def brute_force_optimum(problem: PlanProblem, config) -> int | None:
    """Fewest sites of any layout that passes :func:`planner.accuracy.checks.evaluate_layout`
    (known-control or network mode, as ``config`` says), by enumerating every subset; None
    when none passes."""
    from planner.accuracy.checks import evaluate_layout, station_infos
    from planner.accuracy.network import network_model

    infos = None if config.network else station_infos(problem, config)
    net = network_model(problem, config) if config.network else None
    for k in range(1, problem.n_sites + 1):
        for combo in itertools.combinations(range(problem.n_sites), k):
            sel = np.zeros(problem.n_sites, bool)
            sel[list(combo)] = True
            if evaluate_layout(problem, sel, config, infos, net=net).all_ok:
                return k
    return None
