"""A free network in the planner (``datum = "free"``): the estimable quantities are the
adjustment's free datum's, whichever station is fixed internally; the per-station figures are its
inner-constraint covariance; refused combinations say what to change.

The geometry is :mod:`tests.planner.test_covariance_consistency`'s noise-free network, both a
plan and the adjustment's input.
"""

import math

import numpy as np
import pytest

from markerplan.errors import ConfigError
from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.observations import Datum, NominalPoses
from pipeline.network.relative import marker_pair_covariances, pair_covariances
from planner.accuracy.local import LocalAccuracy, LocalRequirement, point_pairs
from planner.accuracy.local_markers import LocalMarkerAccuracy
from planner.accuracy.network import NetworkModel
from planner.accuracy.requirement import datum_clause, datum_text
from planner.config import PlanConfig
from planner.problem.usability import PlanProblem
from planner.studies.figure_calibration import site_axes
from planner.verify.network_datum import free_alignment
from tests.cli.bad_input import Case, check_refused
from tests.planner.test_covariance_consistency import INCL, _network

HEADING = math.radians(0.5)
#: Relative agreement of the planner's and the adjustment's covariances (they agree to ~1e-12).
RTOL = 1e-9


def _adjusted(obs, truth, heading):
    return adjust(obs, Datum("free"),
                  AdjustmentSettings(inclinometer_sigma_rad=INCL, heading_prior_sigma_rad=heading,
                                     snooping=False),
                  nominal=NominalPoses(truth.pose[:, :3], truth.pose[:, 3]))


def _local(problem, heading, reference=None, free=True):
    net = NetworkModel(problem, 10.0, INCL, heading_prior_sigma_rad=heading,
                       reference=reference, free_datum=free)
    return net, net.covariance(net.information(np.ones(problem.n_sites, bool)))


def _estimable(cov3, direction, heading):
    """What of pair covariances ((p, 3, 3)) a free network estimates: all of it with a heading
    reference, else the variance along the line (``u^T Sigma u``)."""
    if heading is not None:
        return cov3.reshape(len(cov3), -1)
    return np.einsum("pa,pab,pb->p", direction, cov3, direction)[:, None]


def _close(a, b):
    return np.allclose(a, b, rtol=RTOL, atol=RTOL * np.abs(b).max())


def _pair_figures(problem, net, cov, heading):
    """Station-pair and marker-pair estimable covariances of the planner's internal covariance."""
    pairs = point_pairs(problem.station_xyz, LocalRequirement(1.0, within_m=1e4))
    stations = _estimable(pair_covariances(cov.full, pairs.first, pairs.second),
                          pairs.direction, heading)
    local = LocalMarkerAccuracy(net, LocalRequirement(1.0, within_m=1e4))
    mp = local.pairs(np.ones(problem.n_sites, bool))
    markers = _estimable(local.difference_covariances(cov, mp), mp.direction, heading)
    return pairs, mp, stations, markers


@pytest.mark.parametrize("heading", [None, HEADING], ids=["no-heading", "heading-aid"])
def test_pair_and_station_covariances_are_the_free_adjustments(heading):
    obs, truth, problem = _network(3)
    net, cov = _local(problem, heading)
    result = _adjusted(obs, truth, heading)
    pairs, mp, stations, markers = _pair_figures(problem, net, cov, heading)
    assert pairs.size == 10 and mp.size > 20
    want = _estimable(pair_covariances(result.covariance, pairs.first, pairs.second),
                      pairs.direction, heading)
    assert _close(stations, want)
    n6 = 6 * problem.n_stations
    want_m = _estimable(marker_pair_covariances(result.covariance, n6, mp.first, mp.second),
                        mp.direction, heading)
    assert _close(markers, want_m)
    # per-station and per-marker figures: the adjustment's inner constraints (S-transformed)
    free = net.datum_free(cov)
    assert _close(free.full, site_axes(result.covariance[:n6, :n6], truth.pose[:, 3]))
    predicted = net.marker_covariances(free, np.arange(problem.n_sites))
    for j in range(problem.n_sites):
        assert _close(predicted[j], result.marker_covariance(j))


def _rolled(problem: PlanProblem, k: int) -> PlanProblem:
    """``problem`` with its stations renumbered so that station ``k`` comes first."""
    from dataclasses import replace

    s = problem.n_stations
    order = np.roll(np.arange(s), -k)
    new_index = np.argsort(order)
    return replace(problem, station_ids=tuple(problem.station_ids[i] for i in order),
                   station_xyz=problem.station_xyz[order],
                   pair_station=new_index[problem.pair_station])


@pytest.mark.parametrize("heading, kind", [(None, "distance"), (HEADING, "position"),
                                           (HEADING, "distance")])
def test_figures_do_not_depend_on_the_station_fixed_internally(heading, kind):
    _, _, problem = _network(5)
    req = LocalRequirement(1.0, within_m=1e4, kind=kind)
    base = None
    for k in range(problem.n_stations):
        p = _rolled(problem, k)
        net, cov = _local(p, heading)
        back = np.argsort(np.roll(np.arange(problem.n_stations), -k))  # old index -> new
        local = LocalAccuracy(net, req)
        err = dict(zip(zip(np.asarray(p.station_ids)[local.pairs.first],
                           np.asarray(p.station_ids)[local.pairs.second], strict=True),
                       local.errors(cov), strict=True))
        got = (np.array([err.get((a, b), err.get((b, a))) for a, b in
                         zip(*np.triu_indices(problem.n_stations, 1), strict=True)
                         for a, b in [(problem.station_ids[a], problem.station_ids[b])]]),
               net.station_errors_from(cov)[back], net.marker_errors(cov, np.arange(p.n_sites)))
        if base is None:
            base = got
            continue
        for a, b in zip(got, base, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-8)


def test_fixing_one_parameter_too_many_is_caught():
    """With a heading aid the heading is observed: fixing it too (the station datum) changes
    the relative covariances, and the comparison with the free adjustment fails."""
    obs, truth, problem = _network(3)
    result = _adjusted(obs, truth, HEADING)
    net, cov = _local(problem, HEADING, reference=0, free=False)
    pairs, _, stations, _ = _pair_figures(problem, net, cov, HEADING)
    want = _estimable(pair_covariances(result.covariance, pairs.first, pairs.second),
                      pairs.direction, HEADING)
    assert not _close(stations, want)
    assert np.abs(stations - want).max() > 1e-3 * np.abs(want).max()


def test_datum_record_says_nothing_is_fixed():
    _, _, problem = _network(3)
    net, _ = _local(problem, None)
    rec = net.datum_record()
    assert rec["kind"] == "free" and rec["fixed"] == [] and rec["reference_station"] is None
    assert "nothing fixed" in rec["description"] and "relative" in rec["description"]
    assert "mean heading" in rec["description"]
    assert "mean heading" not in _local(problem, HEADING)[0].datum_record()["description"]
    np.testing.assert_allclose(rec["datum_xyz_m"], problem.station_xyz.mean(axis=0))
    assert datum_text(rec) == "free network (datum-free)"
    assert datum_clause(rec).startswith("a **free network (datum-free)**: nothing fixed")
    assert net.datum_text == "free network (datum-free)"
    from planner.outputs.report import _relative_to

    words = _relative_to(rec)
    assert words.startswith("a **free network (datum-free)**") and "not judged" in words


def test_free_alignment_removes_a_rigid_motion():
    """A translated (and, without a heading reference, slightly rotated) copy of the truth is
    aligned back onto it; with a heading reference the rotation is an error and stays."""
    _, truth, _ = _network(3)
    obs, _, _ = _network(3)
    result = _adjusted(obs, truth, None)
    pose = truth.pose.copy()
    centre = pose[:, :2].mean(axis=0)
    phi, shift = 1e-6, np.array([0.3, -0.2, 0.05])

    def moved(xyz):
        out = xyz + shift
        out[:, 0] -= phi * (xyz[:, 1] - centre[1])
        out[:, 1] += phi * (xyz[:, 0] - centre[0])
        return out

    pose[:, :3] = moved(pose[:, :3])
    pose[:, 3] += phi
    from dataclasses import replace
    copy = replace(result, pose=pose, marker_xyz_m=moved(truth.marker_xyz_m))
    back = free_alignment(copy, truth.pose, heading_observed=False)
    assert np.abs(back.pose - truth.pose).max() < 1e-10
    assert np.abs(back.marker_xyz_m - truth.marker_xyz_m).max() < 1e-10
    kept = free_alignment(copy, truth.pose, heading_observed=True)
    assert np.abs(kept.pose[:, 3] - truth.pose[:, 3]).max() == pytest.approx(phi, rel=1e-6)


@pytest.mark.parametrize("settings, needle", [
    (dict(datum="free"), "`datum` = 'free' is a network-mode datum"),
    (dict(network=True, datum="free", local_requirement_m=0.1, local_kind="distance"),
     "`datum_requirement`"),
    (dict(network=True, datum="free", datum_requirement=False, local_requirement_m=0.1,
          local_kind="distance", requirement_ppm=100.0), "`requirement_ppm`"),
    (dict(network=True, datum="free", datum_requirement=False, local_requirement_m=0.1,
          local_kind="distance", reference_station="S2"), "`reference_station`"),
    (dict(network=True, datum="free", datum_requirement=False, local_requirement_m=0.1),
     "`local_kind` = 'position') are not estimable"),
    (dict(network=True, datum="origin"), "`datum` must be one of"),
])
def test_config_refuses(settings, needle):
    with pytest.raises(ConfigError, match=None) as exc:
        PlanConfig(**settings)
    assert needle in str(exc.value) and "\n" not in str(exc.value)


def test_config_accepts_a_free_network_with_estimable_requirements():
    base = dict(network=True, datum="free", datum_requirement=False, local_requirement_m=0.1)
    assert PlanConfig(**base, local_kind="distance").datum == "free"
    assert PlanConfig(**base, heading_aid="star-tracker").datum == "free"
    assert PlanConfig(**base, local_kind="distance", odometry_percent=2.0).datum == "free"
    with pytest.raises(ConfigError, match="heading aid"):  # odometry turns no absolute heading
        PlanConfig(**base, odometry_percent=2.0, odometry_heading_deg_per_m=0.1)


def test_control_points_with_a_free_network_are_refused():
    _, _, problem = _network(3)
    from dataclasses import replace
    sigma = np.zeros(problem.n_sites)
    sigma[:2] = 0.01
    with_control = replace(problem, site_existing=sigma > 0, site_control_sigma_m=sigma)
    with pytest.raises(ConfigError, match="a free network fixes nothing"):
        NetworkModel(with_control, 10.0, INCL, free_datum=True)


FREE = ["plan", "--network", "--datum", "free", "--out", "out"]


@pytest.mark.parametrize("case", [
    Case("free-datum-requirement", FREE + ["--local-requirement-m", "0.1", "--local-kind",
                                           "distance"], "set datum_requirement = false"),
    Case("free-reference", FREE + ["--no-datum-requirement", "--local-requirement-m", "0.1",
                                   "--local-kind", "distance", "--reference-station", "S2"],
         "--reference-station S2 names the datum station"),
    Case("free-control", FREE + ["--no-datum-requirement", "--local-requirement-m", "0.1",
                                 "--control", "c.csv"], "give one datum",
         files={"c.csv": "id,x_m,y_m,z_m,sigma_m\nL1,0,0,0,0.01\n"}),
    Case("free-position", FREE + ["--no-datum-requirement", "--local-requirement-m", "0.1"],
         "add a heading aid"),
    Case("free-known-control", ["plan", "--datum", "free", "--no-datum-requirement",
                                "--local-requirement-m", "0.1", "--out", "out"],
         "network-mode"),
    Case("free-bad-kind", FREE[:3] + ["origin", "--out", "out"], "give station or free",
         code=2),
], ids=str)
def test_plan_refuses(case, capsys, monkeypatch, tmp_path):
    (tmp_path / "cwd").mkdir()
    (tmp_path / "inputs").mkdir()
    check_refused(case, capsys, monkeypatch, tmp_path / "cwd", tmp_path / "inputs")
