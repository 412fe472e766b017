"""Network mode with a control datum (a lander's fiducials as control points, no station
fixed): the pieces of :class:`planner.accuracy.network.NetworkModel` that fold a control
point's prior into its site's information, checked against each other and against the
adjustment (:func:`pipeline.network.adjustment.adjust` with the ``"control"`` datum).

The covariances themselves are checked against the adjustment in
:mod:`tests.planner.test_covariance_consistency`."""

from dataclasses import replace

import numpy as np
import pytest

from pipeline.network.adjustment import AdjustmentSettings, adjust
from pipeline.network.aids import HeadingReadings
from pipeline.network.observations import Datum, NominalPoses
from planner.accuracy.network import NetworkModel
from planner.accuracy.reliability import layout_reliability
from planner.problem.usability import OCCLUDED
from tests.planner.test_covariance_consistency import INCL, _network, _with_control


def _control_net(seed=1, control=(0, 3, 5), sigma_c=0.002):
    obs, truth, problem = _network(seed)
    problem, points = _with_control(problem, truth, control, sigma_c)
    return obs, truth, NetworkModel(problem, 10.0, INCL), points


def test_a_control_points_information_is_the_same_in_every_form():
    """``v^T J^(j) v`` (site_coefficients), the low-rank factor ``U U^T`` (site_factor) and
    the explicit block (site_information) agree at control points and markers alike."""
    _, _, net, _ = _control_net()
    n = net.problem.n_sites
    pos = np.full(6 * net.problem.n_stations, -1)
    pos[net.free] = np.arange(net.n_params)
    v = np.random.default_rng(4).normal(size=(3, net.n_params))
    coef = net.site_coefficients(v)
    for j in range(n):
        one = np.zeros(n)
        one[j] = 1.0
        jj = net.site_information(one)
        np.testing.assert_allclose(coef[:, j], np.einsum("ma,ab,mb->m", v, jj, v),
                                   rtol=1e-8, atol=1e-6)
        index, u = net.site_factor(j)
        m = net.n_stations_seeing[j]
        assert u.shape[1] == (3 * m if net.control[j] else 3 * max(m - 1, 0))
        got = np.zeros_like(jj)
        keep = pos[index] >= 0
        got[np.ix_(pos[index][keep], pos[index][keep])] = u[keep] @ u[keep].T
        np.testing.assert_allclose(got, jj, atol=1e-9 * (1 + np.abs(jj).max()))


def test_a_control_point_seen_by_one_station_ties_it():
    """A marker seen by one station adds nothing; a control point seen by one station adds
    ``(w lambda / (w + lambda)) H^T H``: it ties that station to the datum."""
    _, _, net, _ = _control_net()
    problem = net.problem
    j = int(np.flatnonzero(~net.control)[0])
    reason = problem.pair_reason.copy()
    reason[np.flatnonzero(problem.pair_site == j)[1:]] = OCCLUDED  # one station keeps it
    problem = replace(problem, pair_reason=reason)
    assert not NetworkModel(problem, 10.0, INCL).tying[j]
    sigma = problem.site_control_sigma_m.copy()
    sigma[j] = 0.003
    anchored = NetworkModel(replace(problem, site_existing=problem.site_existing | (sigma > 0),
                                    site_control_sigma_m=sigma), 10.0, INCL)
    assert anchored.tying[j]
    one = np.zeros(problem.n_sites)
    one[j] = 1.0
    p = anchored.pair_index[anchored.pair_site == j]
    w = anchored.weight[anchored.pair_site == j][0]
    lam = 1 / 0.003**2
    h = anchored.design[anchored.pair_site == j][0]
    s = int(problem.pair_station[p[0]])
    expected = np.zeros((6 * problem.n_stations,) * 2)
    expected[6 * s:6 * s + 6, 6 * s:6 * s + 6] = w * lam / (w + lam) * h.T @ h
    np.testing.assert_allclose(anchored.site_information(one),
                               expected[np.ix_(anchored.free, anchored.free)], rtol=1e-9,
                               atol=1e-9)


def test_control_points_are_not_judged_and_the_datum_is_their_centroid():
    _, truth, net, _ = _control_net(control=(1, 4))
    assert np.isinf(net.allowed_site_m[[1, 4]]).all()
    assert np.isfinite(np.delete(net.allowed_site_m, [1, 4])).all()
    centroid = truth.marker_xyz_m[[1, 4]].mean(axis=0)
    np.testing.assert_allclose(net.station_distance_m, np.linalg.norm(
        net.problem.station_xyz[:, :2] - centroid[:2], axis=1))
    assert net.datum_text.startswith("the control points ")
    assert net.connected_to_reference(np.ones(net.problem.n_sites, bool)).all()
    # without any site selected but the control points, only the stations that see them
    only = net.control.copy()
    sees = np.unique(net.pair_station[net.control[net.pair_site]])
    assert set(np.flatnonzero(net.connected_to_reference(only))) == set(sees.tolist())


def test_a_reference_station_with_control_points_is_refused():
    from markerplan.errors import ConfigError
    _, _, net, _ = _control_net()
    with pytest.raises(ConfigError, match="control points are the datum"):
        NetworkModel(net.problem, 10.0, INCL, reference=0)


def test_redundancy_with_a_control_datum_is_the_adjustments():
    """Redundancy numbers and MDBs of the observations, and the degrees of freedom, equal the
    adjustment's under the control datum (whose control priors are observations too)."""
    obs, truth, net, points = _control_net(seed=3, control=(0, 2, 6), sigma_c=0.004)
    rel = layout_reliability(net, np.ones(net.problem.n_sites, bool))
    result = adjust(obs, Datum(kind="control", control=points),
                    AdjustmentSettings(inclinometer_sigma_rad=INCL, snooping=False),
                    nominal=NominalPoses(truth.pose[:, :3], truth.pose[:, 3]))
    assert rel.dof == result.dof
    row = {(s, m): i for i, (s, m) in enumerate(zip(obs.station, obs.marker, strict=True))}
    order = [row[(s, j)] for s, j in zip(rel.station, rel.site, strict=True)]
    np.testing.assert_allclose(rel.redundancy, result.redundancy[order], atol=1e-9)
    np.testing.assert_allclose(rel.mdb_m, result.mdb_m[order], rtol=1e-7)


#: Three fiducials on a lander on the default site, 2.1 m apart (site frame, m).
LANDER = ("id,x_m,y_m,z_m,sigma_m\nL1,8.000,-3.800,1.326,0.005\n"
          "L2,6.961,-5.600,1.398,0.005\nL3,9.039,-5.600,1.308,0.005\n")


@pytest.fixture(scope="module")
def lander_plan(tmp_path_factory):
    from error_model import default_model
    from error_model.default import default_detection_model
    from planner.config import PlanConfig
    from planner.problem.inputs import load_inputs
    from planner.run import make_plan

    path = tmp_path_factory.mktemp("lander") / "lander.csv"
    path.write_text(LANDER)
    inputs = load_inputs("default", control=path)
    config = PlanConfig(network=True, heading_aid="star-tracker", chance_epsilon=None,
                        time_limit_s=30.0, pass_rate_samples=40)
    return make_plan(inputs, config, default_model(), progress=False,
                     detection_model=default_detection_model())


def test_a_plan_on_the_landers_fiducials_meets_its_requirement_by_an_independent_check(
        lander_plan):
    """The default site planned on a lander's three fiducials and a star tracker: the control
    points are in the layout at no cost, no station is fixed, and the adjustment of the
    planned layout (noise-free observations of every usable pair, the control datum) gives
    every station a covariance whose 95 % figure is the plan's and within 0.10 m."""
    from pipeline.network.observations import ControlPoint, NetworkObservations
    from planner.accuracy.figure import ErrorFigure
    from planner.accuracy.network import network_model
    from planner.studies.figure_calibration import site_axes

    problem, result, config = lander_plan.problem, lander_plan.result, lander_plan.config
    assert result.status == "optimal"
    control = problem.site_control
    assert control.sum() == 3 and result.selected[control].all()
    net = network_model(problem, config)
    assert net.reference is None
    sel = result.selected
    pairs = np.flatnonzero(problem.pair_usable & sel[problem.pair_site])
    sites = np.unique(problem.pair_site[pairs])
    marker_of = {j: i for i, j in enumerate(sites)}
    station_xyz, site_xyz = problem.station_xyz, problem.site_xyz
    obs = NetworkObservations(
        problem.station_ids, tuple(problem.site_ids[j] for j in sites),
        problem.pair_station[pairs], np.array([marker_of[j] for j in problem.pair_site[pairs]]),
        site_xyz[problem.pair_site[pairs]] - station_xyz[problem.pair_station[pairs]],
        problem.pair_sigma_m[pairs])
    points = tuple(ControlPoint(problem.site_ids[j], site_xyz[j], np.full(3, 0.005))
                   for j in np.flatnonzero(control))
    s = problem.n_stations
    heading = config.heading_prior_sigma_rad
    adjusted = adjust(obs, Datum(kind="control", control=points),
                      AdjustmentSettings(inclinometer_sigma_rad=config.inclinometer_sigma_rad,
                                         heading_prior_sigma_rad=heading,
                                         heading_bias_sigma_rad=config.heading_bias_sigma_rad,
                                         snooping=False),
                      nominal=NominalPoses(station_xyz, np.zeros(s)),
                      heading=HeadingReadings(np.zeros(s)))
    cov = site_axes(adjusted.covariance[:6 * s, :6 * s], np.zeros(s))
    blocks = np.array([cov[6 * k:6 * k + 6, 6 * k:6 * k + 6] for k in range(s)])
    errors = ErrorFigure(config.error_figure).station_errors(blocks, config.working_radius_m)
    np.testing.assert_allclose(errors, result.check.error_m, rtol=1e-6)
    assert errors.max() <= config.requirement_m


def test_the_lander_plans_files_name_the_control_datum(lander_plan, tmp_path):
    import json

    from planner.outputs.report import write_plan_files

    doc = write_plan_files(lander_plan, tmp_path)
    datum = doc["network"]["datum"]
    assert datum["kind"] == "control" and datum["reference_station"] is None
    assert datum["fixed"] == [] and [c["marker_id"] for c in datum["control"]] == ["L1", "L2",
                                                                                    "L3"]
    np.testing.assert_allclose(datum["datum_xyz_m"][:2], [8.0, -5.0], atol=1e-9)
    assert json.loads((tmp_path / "plan.json").read_text())["network"]["datum"] == datum
    assert "the **control points** L1 (+-0.005 m)" in (tmp_path / "report.md").read_text()
    flagged = {m["id"]: m["control"] for m in doc["markers"]}
    assert flagged["L1"] and sum(flagged.values()) == 3
    # the pass rate is sampled as often as the config's pass_rate_samples says
    assert doc["chance"]["sampled"]["n_samples"] == 40 == lander_plan.sampled.n_samples


def test_reduce_keeps_the_landers_fiducials_and_its_datum(lander_plan, tmp_path, capsys):
    """``reduce`` of a plan on a lander: the control points stay in every subset (they are the
    datum), are refused in --drop, and the study is judged relative to them."""
    import json

    from planner.outputs.report import write_plan_files
    from tests.cli.invoke import run_cli

    (tmp_path / "plan").mkdir()
    write_plan_files(lander_plan, tmp_path / "plan")
    code, out, err = run_cli(capsys, ["reduce", str(tmp_path / "plan" / "plan.json"), "--json",
                                      "--out", str(tmp_path / "r")])
    assert code == 0, err
    summary = json.loads(out)
    assert summary["accuracy"] == "network mode, datum the control points L1, L2, L3"
    doc = json.loads((tmp_path / "r" / "reduce.json").read_text())
    assert doc["network"]["datum"]["kind"] == "control"
    for point in doc["curve"]:
        assert {"L1", "L2", "L3"} <= set(point["markers"])
    code, _, err = run_cli(capsys, ["reduce", str(tmp_path / "plan" / "plan.json"), "--drop",
                                    "L2", "--out", str(tmp_path / "r2")])
    assert code == 1 and "control point(s) L2" in err and not (tmp_path / "r2").exists()


def test_verify_knows_the_control_points_only_to_their_sigma(lander_plan, tmp_path):
    """verify --network adjusts on the lander's control points as the survey knows them: the
    simulated centre plus one seeded draw of their stated error (2,000 draws: per-axis spread
    within 5 % of sigma, mean within 4 standard errors of 0), chained from a station the plan
    gives a control point; a --reference-station is refused."""
    import json

    from markerplan.errors import ConfigError
    from planner.network.plan_geometry import plan_geometry
    from planner.outputs.report import write_plan_files
    from planner.verify.network_datum import verify_datum

    write_plan_files(lander_plan, tmp_path)
    doc = json.loads((tmp_path / "plan.json").read_text())
    geometry = plan_geometry(doc, tmp_path / "plan.json")
    ids = [s["id"] for s in doc["stations"]]
    first = verify_datum(doc, geometry, None, ids, 0)
    again = verify_datum(doc, geometry, None, ids, 0)
    assert first.kind == "control" and first.record() == again.record()
    sees = [s["id"] for s in doc["stations"] if {"L1", "L2", "L3"} & set(s["markers"])]
    assert first.reference == sees[0]
    np.testing.assert_allclose(first.datum_xyz[:2], [8.0, -5.0], atol=1e-9)
    truth = np.array([c["xyz_m"] for c in doc["network"]["datum"]["control"]])
    errors = np.array([[c.xyz_m for c in verify_datum(doc, geometry, None, ids, seed).control]
                       for seed in range(2000)]) - truth
    assert np.all(np.abs(errors.std(axis=0) / 0.005 - 1) < 0.05)
    assert np.all(np.abs(errors.mean(axis=0)) < 4 * 0.005 / np.sqrt(2000))
    with pytest.raises(ConfigError, match="datum is its control points"):
        verify_datum(doc, geometry, "S1", ids, 0)
    with pytest.raises(ConfigError, match="none of the stations verified"):
        verify_datum(doc, geometry, None, [i for i in ids if i not in sees], 0)
