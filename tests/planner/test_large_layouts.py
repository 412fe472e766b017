"""The layouts of the requirement table on ``large`` (``benchmarks/network_requirements.py
--save-layouts``), each re-checked by an independent covariance: the full normal matrix of the
layout's geometry with the markers (and a heading reference's bias) as unknowns, written out
and inverted here (:func:`full_normal_covariance`), instead of the planner's Schur complement
on the poses with the bias eliminated. Every station's 95 % figure (and, for a local
requirement, every pair's) from that covariance must meet the requirement the layout was
planned for, and the covariance must equal the planner's.

The layouts are stored by :func:`planner.studies.layout_geometry.save_layout` in
``tests/planner/data/large_layouts/``; the round trip of that file is tested here on a small
network."""

from pathlib import Path

import numpy as np
import pytest

from planner.accuracy.local import local_accuracy
from planner.accuracy.network import network_model
from planner.accuracy.network_covariance import NetworkCovariance
from planner.studies.layout_geometry import load_layout, save_layout

LAYOUTS = sorted((Path(__file__).parent / "data" / "large_layouts").glob("*.npz"))
#: The two covariances agree to ~1e-12 (a 0.1 % error in any design column or weight is far
#: above this).
RTOL = 1e-9
#: The computed 95 % quantile's own precision: its fixed directions pass through a square root
#: of the covariance, which a 1e-12 change of an ill-conditioned covariance can turn, moving a
#: pair's 12-dimensional figure by up to 0.9 % on these layouts (a station's by 3e-4;
#: :data:`planner.accuracy.figure.N_DIRECTIONS`).
QUANTILE_PRECISION = 0.01


def full_normal_covariance(problem, config) -> NetworkCovariance:
    """The pose covariance (site axes) of every station from the full normal matrix of the
    layout: every pose (6 parameters a station), every marker (3) and, with a heading
    reference, its boresight bias (1) as unknowns; the design written out here at the nominal
    geometry (headings and tilts 0: a marker ``p`` from the station moves by ``dt + dpsi
    (-p_y, p_x, 0) + droll (0, -p_z, p_y) + dpitch (p_z, 0, -p_x)``); the inclinometer's
    roll and pitch rows, each station's heading reading ``psi_s + b``, the bias prior and the
    control points' coordinate priors as observations; the datum station's x, y, z and heading
    (or, with control points, nothing) fixed. Inverted whole, not by eliminating the markers."""
    s, m = problem.n_stations, problem.n_sites
    heading = config.heading_prior_sigma_rad
    bias = config.heading_bias_sigma_rad if heading is not None else 0.0
    n = 6 * s + 3 * m + (1 if bias > 0 else 0)
    rows, cols, vals, weights = [], [], [], []
    r = 0

    def row(entries, weight):
        nonlocal r
        for c, v in entries:
            rows.append(r)
            cols.append(c)
            vals.append(v)
        weights.append(weight)
        r += 1

    for st, si, sigma in zip(problem.pair_station, problem.pair_site, problem.pair_sigma_m,
                             strict=True):
        px, py, pz = problem.site_xyz[si] - problem.station_xyz[st]
        pose = 6 * st
        lever = ((-py, 0.0, pz), (px, -pz, 0.0), (0.0, py, -px))  # heading, roll, pitch
        for axis in range(3):
            row([(pose + axis, 1.0), (pose + 3, lever[axis][0]), (pose + 4, lever[axis][1]),
                 (pose + 5, lever[axis][2]), (6 * s + 3 * si + axis, -1.0)], 3.0 / sigma**2)
    for st in range(s):
        for k in (4, 5):
            row([(6 * st + k, 1.0)], 1.0 / config.inclinometer_sigma_rad**2)
        if heading is not None:
            row([(6 * st + 3, 1.0)] + ([(n - 1, 1.0)] if bias > 0 else []), 1.0 / heading**2)
    if bias > 0:
        row([(n - 1, 1.0)], 1.0 / bias**2)
    for j in np.flatnonzero(problem.site_control):
        for axis in range(3):
            row([(6 * s + 3 * j + axis, 1.0)], 1.0 / problem.site_control_sigma_m[j] ** 2)
    a = np.zeros((r, n))
    np.add.at(a, (rows, cols), vals)
    normal = a.T @ (np.asarray(weights)[:, None] * a)
    free = np.ones(n, bool)
    if not problem.site_control.any():
        ref = problem.station_ids.index(config.reference_station)
        free[6 * ref:6 * ref + 4] = False
    cov = np.zeros((n, n))
    cov[np.ix_(free, free)] = np.linalg.inv(normal[np.ix_(free, free)])
    return NetworkCovariance(full=cov[:6 * s, :6 * s], determined=np.ones(s, bool))


def recheck(problem, config) -> tuple[float, float]:
    """The worst ratio of an error to its allowance from the full normal matrix's covariance,
    and the largest difference of that covariance from the planner's (relative to the square
    root of the diagonals: ``|c_ij - c'_ij| / sqrt(c_ii c_jj)``)."""
    net = network_model(problem, config)
    mine = net.covariance(net.information(np.ones(problem.n_sites, bool)))
    theirs = full_normal_covariance(problem, config)
    scale = np.sqrt(np.outer(np.diag(theirs.full), np.diag(theirs.full)))
    scale[scale == 0] = 1.0
    differs = float(np.max(np.abs(mine.full - theirs.full) / scale))
    ratios = [net.station_errors_from(theirs) / net.allowed_station_m] \
        if config.datum_requirement else []
    local = local_accuracy(net, config)
    if local is not None:
        ratios.append(local.errors(theirs) / local.pairs.allowed_m)
    return float(np.max(np.concatenate(ratios))), differs


def test_a_saved_layout_reads_back_as_planned(tmp_path):
    from planner.config import PlanConfig
    from tests.planner.test_covariance_consistency import _network

    _, _, problem = _network(3)
    config = PlanConfig(network=True, reference_station=problem.station_ids[1],
                        heading_aid="sun-sensor")
    selected = np.ones(problem.n_sites, bool)
    selected[::3] = False
    path = save_layout(tmp_path / "a.npz", problem, config, selected, {"label": "x"})
    again, config_again, meta = load_layout(path)
    assert meta == {"label": "x"} and config_again == config
    assert again.site_ids == tuple(problem.site_ids[j] for j in np.flatnonzero(selected))
    net = network_model(problem, config)
    net_again = network_model(again, config_again)
    np.testing.assert_allclose(net_again.station_errors(np.ones(again.n_sites, bool)),
                               net.station_errors(selected), rtol=1e-12)
    worst, differs = recheck(again, config_again)
    assert differs < RTOL
    assert not list(tmp_path.glob("*.partial"))


@pytest.mark.slow
@pytest.mark.parametrize("path", LAYOUTS, ids=[p.stem for p in LAYOUTS])
def test_each_large_layout_meets_its_requirement_by_the_full_normal_matrix(path):
    problem, config, meta = load_layout(path)
    assert problem.n_sites == meta["markers"]
    worst, differs = recheck(problem, config)
    assert differs < RTOL, f"{meta['label']}: the covariances differ by {differs:.2g}"
    # a layout found for the requirement meets it, to the quantile figure's precision
    assert worst <= 1.0 + QUANTILE_PRECISION, \
        f"{meta['label']}: worst error {worst:.4f} of its allowance"
