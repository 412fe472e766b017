"""The layouts of the requirement table on ``large`` (``benchmarks/network_requirements.py
--save-layouts``), each re-checked by an independent covariance: the network adjustment
(:func:`pipeline.network.adjustment.adjust`, the full normal matrix with the markers as
unknowns, Gauss-Newton on noise-free observations) of the layout's geometry, instead of the
planner's Schur complement on the poses. Every station's 95 % figure (and, for a local
requirement, every pair's) from the adjustment's covariance must meet the requirement the
layout was planned for and equal the planner's.

The layouts are stored by :func:`planner.studies.layout_geometry.save_layout` in
``tests/planner/data/large_layouts/``; the round trip of that file is tested here on a small
network."""

from pathlib import Path

import numpy as np
import pytest

from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.aids import HeadingReadings
from pipeline.network.observations import (
    ControlPoint,
    Datum,
    NetworkObservations,
    NominalPoses,
)
from planner.accuracy.local import local_accuracy
from planner.accuracy.network import network_model
from planner.accuracy.network_covariance import NetworkCovariance
from planner.studies.figure_calibration import site_axes
from planner.studies.layout_geometry import load_layout, save_layout

LAYOUTS = sorted((Path(__file__).parent / "data" / "large_layouts").glob("*.npz"))
#: The planner and the adjustment agree to ~1e-12 on exact geometry; the quantile figure is
#: computed from each covariance by the same integration, so they agree as closely.
RTOL = 1e-6


def adjusted_covariance(problem, config) -> NetworkCovariance:
    """The pose covariance (site axes) of every station from the adjustment of noise-free
    observations of every pair of ``problem`` (every site selected), with the configuration's
    datum and heading reference."""
    obs = NetworkObservations(
        problem.station_ids, problem.site_ids, problem.pair_station, problem.pair_site,
        problem.site_xyz[problem.pair_site] - problem.station_xyz[problem.pair_station],
        problem.pair_sigma_m)
    control = problem.site_control
    if control.any():
        datum = Datum(kind="control", control=tuple(
            ControlPoint(problem.site_ids[j], problem.site_xyz[j],
                         np.full(3, problem.site_control_sigma_m[j]))
            for j in np.flatnonzero(control)))
    else:
        datum = Datum(reference_station=config.reference_station)
    s = problem.n_stations
    heading = config.heading_prior_sigma_rad
    result = adjust(obs, datum,
                    AdjustmentSettings(inclinometer_sigma_rad=config.inclinometer_sigma_rad,
                                       heading_prior_sigma_rad=heading,
                                       heading_bias_sigma_rad=config.heading_bias_sigma_rad
                                       if heading is not None else None,
                                       snooping=False),
                    nominal=NominalPoses(problem.station_xyz, np.zeros(s)),
                    heading=HeadingReadings(np.zeros(s)) if heading is not None else None)
    assert np.abs(result.marker_xyz_m - problem.site_xyz).max() < 1e-8
    full = site_axes(result.covariance[:6 * s, :6 * s], np.zeros(s))
    return NetworkCovariance(full=full, determined=np.ones(s, bool))


def recheck(problem, config) -> tuple[float, float]:
    """The worst ratio of an error to its allowance, from the adjustment's covariance, and the
    largest relative difference from the planner's own errors."""
    net = network_model(problem, config)
    mine = net.covariance(net.information(np.ones(problem.n_sites, bool)))
    theirs = adjusted_covariance(problem, config)
    local = local_accuracy(net, config)
    if local is not None:
        got, want, allowed = local.errors(theirs), local.errors(mine), local.pairs.allowed_m
    else:
        got, want = net.station_errors_from(theirs), net.station_errors_from(mine)
        allowed = net.allowed_station_m
    if config.datum_requirement and local is not None:
        got = np.r_[got, net.station_errors_from(theirs)]
        want = np.r_[want, net.station_errors_from(mine)]
        allowed = np.r_[allowed, net.allowed_station_m]
    return float(np.max(got / allowed)), float(np.max(np.abs(got - want) / want))


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


@pytest.mark.parametrize("path", LAYOUTS, ids=[p.stem for p in LAYOUTS])
def test_each_large_layout_meets_its_requirement_by_the_adjustment(path):
    problem, config, meta = load_layout(path)
    assert problem.n_sites == meta["markers"]
    worst, differs = recheck(problem, config)
    assert differs < RTOL, f"{meta['label']}: the planner and the adjustment differ by {differs}"
    # a layout found for the requirement meets it (the quantile figure to its integration's
    # precision)
    assert worst <= 1.0 + 1e-6, f"{meta['label']}: worst error {worst:.4f} of its allowance"
