"""``markerplan adjust`` end to end on marker tables written from a simulated network
(:mod:`tests.cli.network_inputs`): the adjusted stations and markers lie within their 95 %
ellipsoids, a swapped marker id is removed by data snooping and named in the report, and a
second run writes the same bytes."""

from __future__ import annotations

import csv
import hashlib
import json
import math

import numpy as np
import pytest
from scipy.stats import chi2

from tests.cli.invoke import run_cli
from tests.cli.network_inputs import write_network_inputs

CHI2_3_95 = chi2.ppf(0.95, 3)


@pytest.fixture(scope="module")
def network(tmp_path_factory):
    return write_network_inputs(tmp_path_factory.mktemp("network"), n_stations=6, seed=3)


def _tables(net) -> list[str]:
    return [str(t) for t in net.tables]


def _digests(folder):
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _mahalanobis(folder, truth_station_xyz, truth_marker_xyz, station_ids, marker_ids):
    """Squared Mahalanobis distances of the adjusted station positions and marker centres from
    the truth, with the covariance adjust wrote."""
    cov = np.load(folder / "covariance.npy")
    params = {p["parameter"]: (int(p["index"]), float(p["value"]))
              for p in csv.DictReader((folder / "parameters.csv").open())}
    d2 = []
    for ids, truth in ((station_ids, truth_station_xyz), (marker_ids, truth_marker_xyz)):
        for pid, true in zip(ids, truth, strict=True):
            idx = [params[f"{pid}.{a}_m"][0] for a in "xyz"]
            est = np.array([params[f"{pid}.{a}_m"][1] for a in "xyz"])
            c = cov[np.ix_(idx, idx)]
            if np.allclose(c, 0.0):  # the datum station: fixed
                assert np.allclose(est, true, atol=1e-6)
                continue
            e = est - true
            d2.append(float(e @ np.linalg.solve(c, e)))
    return np.array(d2)


def test_plan_association_within_ellipsoids_and_reproducible(network, tmp_path, capsys,
                                                             monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = ["adjust", *_tables(network), "--plan", str(network.plan), "--json"]
    code, out, err = run_cli(capsys, args + ["--out", "first"])
    assert code == 0, err
    summary = json.loads(out)
    assert summary["n_stations"] == 6 and summary["n_markers"] == len(network.marker_ids)
    assert summary["marker_ids"] == "plan" and summary["rejected"] == []
    assert summary["global_test_passed"] is True
    folder = tmp_path / "first"
    d2 = _mahalanobis(folder, network.truth.pose[:, :3], network.truth.marker_xyz_m,
                      network.station_ids, network.marker_ids)
    assert len(d2) == 5 + len(network.marker_ids)
    # one network: its points' errors are correlated, so coverage of the 95 % ellipsoids is
    # checked loosely here (the library's Monte-Carlo test checks 93-97 %); none is far out
    assert np.mean(d2 <= CHI2_3_95) >= 0.7, d2
    assert d2.max() <= chi2.ppf(0.999, 3), d2
    doc = json.loads((folder / "adjustment.json").read_text())
    assert doc["identity"]["n_identified"] == doc["statistics"]["n_observations"]
    assert doc["datum"]["reference_station"] == "S01"
    assert doc["provenance"]["config"]["marker_ids"] == "plan"
    assert doc["provenance"]["config"]["body"] == {
        "name": "plane", "radius_m": None,
        "tangent_point": "station S01's initial position (the reference)"}
    code, _, err = run_cli(capsys, args + ["--out", "second"])
    assert code == 0, err
    assert _digests(folder) == _digests(tmp_path / "second")


def test_body_moon_centres_the_tilt_priors_on_the_local_vertical(network, tmp_path, capsys,
                                                                monkeypatch):
    """``--body moon`` moves each station's roll and pitch by (up to) the local vertical's
    deflection from S01's, and adjustment.json records the body."""
    from pipeline.network.body import Body

    monkeypatch.chdir(tmp_path)
    args = ["adjust", *_tables(network), "--plan", str(network.plan), "--json"]
    tilt = {}
    for body in ("plane", "moon"):
        code, _, err = run_cli(capsys, args + ["--body", body, "--out", body])
        assert code == 0, err
        rows = list(csv.DictReader((tmp_path / body / "stations.csv").open()))
        tilt[body] = np.radians([[float(r["roll_deg"]), float(r["pitch_deg"])] for r in rows])
    config = json.loads((tmp_path / "moon" / "adjustment.json").read_text())["provenance"][
        "config"]
    assert config["body"]["name"] == "moon" and config["body"]["radius_m"] == 1_737_400.0
    pose = network.truth.pose
    deflection = Body.named("moon").vertical_tilt(pose[:, :3], pose[:, 3], pose[0, :2])
    shift = tilt["moon"] - tilt["plane"]
    # the prior pulls the tilts towards the deflection; the markers hold them back in part
    far = int(np.argmax(np.abs(deflection).max(axis=1)))
    assert np.abs(deflection[far]).max() > 1e-6
    assert np.all(np.abs(shift[far] - deflection[far]) < np.abs(deflection[far]) + 1e-9)
    assert np.dot(shift[far], deflection[far]) > 0.3 * np.dot(deflection[far], deflection[far])


def test_swapped_marker_id_is_removed_and_named(tmp_path, capsys, monkeypatch):
    net = write_network_inputs(tmp_path / "net", n_stations=6, seed=3,
                               swap=("S03", "M005", "M006"))  # 21 m apart
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, ["adjust", *_tables(net), "--marker-ids", "table",
                                      "--json", "--out", "out"])
    assert code == 0, err
    rejected = json.loads(out)["rejected"]
    assert rejected and {(r["station_id"], r["marker_id"]) for r in rejected} <= {
        ("S03", "M005"), ("S03", "M006")}
    report = (tmp_path / "out" / "report.md").read_text()
    first = rejected[0]
    assert f"| 1 | S03 | {first['marker_id']} |" in report
    rows = list(csv.DictReader((tmp_path / "out" / "observations.csv").open()))
    removed = [(r["station_id"], r["marker_id"]) for r in rows if r["status"] == "removed"]
    assert removed == [(r["station_id"], r["marker_id"]) for r in rejected] or \
        sorted(removed) == sorted((r["station_id"], r["marker_id"]) for r in rejected)
    assert json.loads((tmp_path / "out" / "adjustment.json").read_text())[
        "global_test"]["passed"] is True


def test_geometry_without_plan(network, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, ["adjust", *_tables(network), "--json", "--out", "o"])
    assert code == 0, err
    summary = json.loads(out)
    assert summary["marker_ids"] == "geometry" and summary["rejected"] == []
    stations = list(csv.DictReader((tmp_path / "o" / "stations.csv").open()))
    # the frame is S01's levelled frame: station distances from S01 are the truth's
    true = np.linalg.norm(network.truth.pose[:, :2] - network.truth.pose[0, :2], axis=1)
    got = np.array([np.hypot(float(s["x_m"]), float(s["y_m"])) for s in stations])
    assert np.abs(got - true).max() < 0.1
    assert "reference station S01's levelled frame" in (tmp_path / "o" / "report.md").read_text()


def test_control_and_free_datum(network, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    truth = dict(zip(network.marker_ids, network.truth.marker_xyz_m, strict=True))
    (tmp_path / "lander.csv").write_text("id,x_m,y_m,z_m,sigma_m\n" + "".join(
        f"{m},{x},{y},{z},0.005\n" for m, (x, y, z) in truth.items()
        if m in ("M002", "M005", "M011")))
    code, out, err = run_cli(capsys, ["adjust", *_tables(network), "--plan", str(network.plan),
                                      "--control", "lander.csv", "--json", "--out", "c"])
    assert code == 0, err
    assert json.loads(out)["datum"].startswith("control points M002")
    d2 = _mahalanobis(tmp_path / "c", network.truth.pose[:, :3], network.truth.marker_xyz_m,
                      network.station_ids, network.marker_ids)
    assert np.mean(d2 <= CHI2_3_95) >= 0.7 and d2.max() <= chi2.ppf(0.999, 3), d2
    code, out, err = run_cli(capsys, ["adjust", *_tables(network), "--plan", str(network.plan),
                                      "--datum", "free", "--heading-prior-sigma-deg", "2", "--json",
                                      "--out", "f"])
    assert code == 0, err
    doc = json.loads((tmp_path / "f" / "adjustment.json").read_text())
    assert doc["datum"]["kind"] == "free"
    assert doc["provenance"]["config"]["heading_prior_sigma_deg"] == 2.0


def test_smallest_documented_bounds_adjust(network, tmp_path, capsys, monkeypatch):
    """``--alpha0 1e-300`` (critical value 37.07, no longer inf) and the smallest
    ``--inclinometer-sigma-deg`` and ``--heading-prior-sigma-deg`` the bounds allow give a
    network and a report, not a traceback."""
    from pipeline.network.observations import MIN_SIGMA

    monkeypatch.chdir(tmp_path)
    smallest = repr(math.degrees(MIN_SIGMA))
    code, out, err = run_cli(capsys, [
        "adjust", *_tables(network), "--plan", str(network.plan), "--alpha0", "1e-300",
        "--inclinometer-sigma-deg", smallest, "--heading-prior-sigma-deg", smallest, "--out", "o"])
    assert code == 0, err
    doc = json.loads((tmp_path / "o" / "adjustment.json").read_text())
    assert doc["data_snooping"]["critical_value"] == pytest.approx(37.066, abs=1e-3)
    assert "alpha0 = 1e-300" in (tmp_path / "o" / "report.md").read_text()


def test_help_has_an_example(capsys):
    code, out, _ = run_cli(capsys, ["adjust", "--help"])
    assert code == 0 and "Example:" in out and "markerplan adjust" in out


def test_robust_igg3_downweights_the_swapped_ids_and_variance_components(tmp_path, capsys,
                                                                        monkeypatch):
    """``--robust igg3`` keeps every observation, gives the two swapped ones weight 0 and
    lists them in the report; ``--variance-components station`` writes one row per station
    and the network's; the same command writes the same bytes twice."""
    net = write_network_inputs(tmp_path / "net", n_stations=6, seed=3,
                               swap=("S03", "M005", "M006"))
    monkeypatch.chdir(tmp_path)
    args = ["adjust", *_tables(net), "--marker-ids", "table", "--robust", "igg3",
            "--variance-components", "station", "--json"]
    code, out, err = run_cli(capsys, args + ["--out", "r"])
    assert code == 0, err
    summary = json.loads(out)
    assert summary["rejected"] == [] and summary["robust"] == "igg3"
    zero = {(d["station_id"], d["marker_id"]) for d in summary["downweighted"]
            if d["weight"] == 0.0}
    assert zero == {("S03", "M005"), ("S03", "M006")}
    assert set(summary["variance_components"]) == {*net.station_ids, "all"}
    rows = list(csv.DictReader((tmp_path / "r" / "observations.csv").open()))
    assert all(r["status"] != "removed" for r in rows)
    weights = {(r["station_id"], r["marker_id"]): float(r["robust_weight"]) for r in rows}
    assert weights[("S03", "M005")] == weights[("S03", "M006")] == 0.0
    doc = json.loads((tmp_path / "r" / "adjustment.json").read_text())
    assert doc["provenance"]["config"]["robust"] == "igg3"
    assert doc["provenance"]["config"]["snooping"] is False
    assert doc["robust"]["constants"] == {"k0": 1.5, "k1": 3.0}
    report = (tmp_path / "r" / "report.md").read_text()
    assert "## Robust estimation" in report and "| S03 | M005 | 0.000 |" in report
    assert "## Variance components" in report
    variance = list(csv.DictReader((tmp_path / "r" / "variance_components.csv").open()))
    assert [v["group"] for v in variance] == [*net.station_ids, "all"]
    assert "variance_components.csv" in doc["files"]
    code, _, err = run_cli(capsys, args + ["--out", "again"])
    assert code == 0, err
    assert _digests(tmp_path / "r") == _digests(tmp_path / "again")


def _write_odometry(path, ids, pose, rng, ratio, rate):
    """Dead-reckoned poses in drive order: the truth's relative poses with noise of the
    stated sigmas, composed from the first station's true pose."""
    from pipeline.network.aids import OdometryReadings

    exact = OdometryReadings.from_poses(np.arange(len(ids)), pose[:, :3], pose[:, 3])
    d = np.linalg.norm(exact.delta_xyz_m, axis=1)
    dp = exact.delta_xyz_m + rng.normal(size=(d.size, 3)) * (ratio * d)[:, None]
    dpsi = exact.delta_heading_rad + rng.normal(size=d.size) * rate * d
    xyz, h = [pose[0, :3]], [pose[0, 3]]
    for k in range(d.size):
        c, s = math.cos(h[-1]), math.sin(h[-1])
        xyz.append(xyz[-1] + np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ dp[k])
        h.append(h[-1] + dpsi[k])
    path.write_text("id,x_m,y_m,z_m,heading_deg\n" + "".join(
        f"{i},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f},{math.degrees(a):.6f}\n"
        for i, p, a in zip(ids, xyz, h, strict=True)))


def test_odometry_and_a_heading_bias_are_used_and_recorded(network, tmp_path, capsys,
                                                           monkeypatch):
    monkeypatch.chdir(tmp_path)
    _write_odometry(tmp_path / "odo.csv", network.station_ids, network.truth.pose,
                    np.random.default_rng(5), 0.01, math.radians(0.05))
    base = ["adjust", *_tables(network), "--plan", str(network.plan), "--json"]
    aids = ["--odometry", "odo.csv", "--odometry-percent", "1",
            "--odometry-heading-deg-per-m", "0.05"]
    bias = ["--heading-prior-sigma-deg", "0.1", "--heading-bias-sigma-deg", "0.05"]
    for out, extra in (("plain", []), ("aided", aids), ("biased", bias)):
        code, _, err = run_cli(capsys, base + extra + ["--out", out])
        assert code == 0, err
    doc = json.loads((tmp_path / "aided" / "adjustment.json").read_text())
    config = doc["provenance"]["config"]
    assert config["odometry"] == "odo.csv" and config["odometry_percent"] == 1.0
    assert config["odometry_heading_deg_per_m"] == 0.05
    assert config["heading_bias_sigma_deg"] is None
    assert "odometry" in [f["kind"] for f in doc["provenance"]["inputs"]]
    config = json.loads((tmp_path / "biased" / "adjustment.json").read_text()
                        )["provenance"]["config"]
    assert config["heading_bias_sigma_deg"] == 0.05 and config["odometry"] is None
    plain_cov = np.load(tmp_path / "plain" / "covariance.npy")
    aided_cov = np.load(tmp_path / "aided" / "covariance.npy")
    n6 = 6 * len(network.station_ids)
    # the odometry ties consecutive stations: every variance at most that without it
    assert np.all(np.diag(aided_cov)[:n6] <= np.diag(plain_cov)[:n6] * (1 + 1e-9))
    assert np.trace(aided_cov[:n6, :n6]) < np.trace(plain_cov[:n6, :n6])
    d2 = _mahalanobis(tmp_path / "aided", network.truth.pose[:, :3], network.truth.marker_xyz_m,
                      network.station_ids, network.marker_ids)
    assert d2.max() <= chi2.ppf(0.999, 3), d2


def test_relative_pairs_within_d_and_sparse_equals_dense(network, tmp_path, capsys,
                                                         monkeypatch):
    """relative.csv holds exactly the station pairs at most --relative-within-m apart
    horizontally (recomputed from stations.csv); the sparse covariance writes the same
    relative.csv and report, and no covariance.npy; --json names the worst pair."""
    from pipeline.network.settings import COVARIANCE_KINDS
    from planner.cli.adjust import COVARIANCE_KINDS as CLI_KINDS

    assert CLI_KINDS == COVARIANCE_KINDS
    monkeypatch.chdir(tmp_path)
    args = ["adjust", *_tables(network), "--plan", str(network.plan), "--json",
            "--relative-within-m", "30", "--relative-requirement-m", "0.02",
            "--relative-requirement-ppm", "500"]
    summaries = {}
    for kind in ("dense", "sparse"):
        code, out, err = run_cli(capsys, args + ["--covariance", kind, "--out", kind])
        assert code == 0, err
        summaries[kind] = json.loads(out)["relative"]
    stations = list(csv.DictReader((tmp_path / "dense" / "stations.csv").open()))
    xy = {s["station_id"]: (float(s["x_m"]), float(s["y_m"])) for s in stations}
    ids = [s["station_id"] for s in stations]
    expected = [(a, b) for i, a in enumerate(ids) for b in ids[i + 1:]
                if math.dist(xy[a], xy[b]) <= 30.0]
    every = list(csv.DictReader((tmp_path / "dense" / "relative.csv").open()))
    rows = [r for r in every if r["kind"] == "station"]
    assert [(r["first"], r["second"]) for r in rows] == expected
    # then every pair of adjusted markers as close, from markers.csv
    markers = list(csv.DictReader((tmp_path / "dense" / "markers.csv").open()))
    mxy = {m["marker_id"]: (float(m["x_m"]), float(m["y_m"])) for m in markers}
    mids = [m["marker_id"] for m in markers]
    expected_m = [(a, b) for i, a in enumerate(mids) for b in mids[i + 1:]
                  if math.dist(mxy[a], mxy[b]) <= 30.0]
    assert [(r["first"], r["second"]) for r in every if r["kind"] == "marker"] == expected_m
    assert expected_m and [r["kind"] for r in every] == ["station"] * len(rows) + [
        "marker"] * len(expected_m)
    assert 0 < len(expected) < len(ids) * (len(ids) - 1) // 2
    for r in rows:
        assert float(r["allowed_95_m"]) == pytest.approx(
            0.02 + 500e-6 * float(r["separation_m"]), abs=1e-6)
        assert (r["passed"] == "true") == (float(r["horizontal_major_95_m"])
                                           <= float(r["allowed_95_m"]))
        assert float(r["horizontal_minor_95_m"]) <= float(r["horizontal_major_95_m"])
    worst = max(rows, key=lambda r: float(r["horizontal_major_95_m"]) / float(r["allowed_95_m"]))
    assert summaries["dense"]["worst_pair"]["first"] == worst["first"]
    assert summaries["dense"]["worst_pair"]["second"] == worst["second"]
    assert summaries["dense"]["n_marker_pairs"] == len(expected_m)
    assert summaries["dense"] == summaries["sparse"]
    for name in ("relative.csv", "stations.csv", "markers.csv", "observations.csv"):
        assert (tmp_path / "dense" / name).read_bytes() == (tmp_path / "sparse" / name
                                                            ).read_bytes(), name
    reports = [[line for line in (tmp_path / kind / "report.md").read_text().splitlines()
                if "configuration sha256" not in line] for kind in ("dense", "sparse")]
    assert reports[0] == reports[1]  # all but the configuration's digest (--covariance)
    assert (tmp_path / "dense" / "covariance.npy").exists()
    assert not (tmp_path / "sparse" / "covariance.npy").exists()
    doc = json.loads((tmp_path / "sparse" / "adjustment.json").read_text())
    assert doc["relative"]["n_pairs"] == len(expected)
    assert "## Relative accuracy between neighbouring stations" in (
        tmp_path / "sparse" / "report.md").read_text()


def test_heading_readings_and_the_plans_heading_aid_bias(network, tmp_path, capsys,
                                                         monkeypatch):
    """``--headings`` centres the heading prior on the readings: with their common bias
    eliminated (``--heading-bias-sigma-deg``) the headings stay on the truth, without it they
    follow the biased readings; a plan's ``network.datum`` bias is taken unless the option
    overrides it."""
    monkeypatch.chdir(tmp_path)
    truth = np.degrees(network.truth.pose[:, 3])
    readings = truth + 0.5 + np.random.default_rng(7).normal(0.0, 0.01, truth.size)
    (tmp_path / "headings.csv").write_text("id,heading_deg\n" + "".join(
        f"{i},{h:.6f}\n" for i, h in zip(network.station_ids, readings, strict=True)))
    base = ["adjust", *_tables(network), "--plan", str(network.plan), "--json",
            "--headings", "headings.csv", "--heading-prior-sigma-deg", "0.01"]
    error = {}
    for out, extra in (("eliminated", ["--heading-bias-sigma-deg", "2"]), ("followed", [])):
        code, _, err = run_cli(capsys, base + extra + ["--out", out])
        assert code == 0, err
        doc = json.loads((tmp_path / out / "adjustment.json").read_text())
        with (tmp_path / out / "stations.csv").open() as fh:
            adjusted = {r["station_id"]: float(r["heading_deg"]) for r in csv.DictReader(fh)}
        error[out] = np.array([(adjusted[sid] - t + 180.0) % 360.0 - 180.0
                               for sid, t in zip(network.station_ids, truth, strict=True)])
        assert doc["provenance"]["config"]["headings"] == "headings.csv"
        assert "headings" in [f["kind"] for f in doc["provenance"]["inputs"]]
    assert np.abs(error["eliminated"]).max() < 0.1
    assert np.abs(error["followed"][1:]).min() > 0.25  # the datum's heading is fixed

    plan = json.loads(network.plan.read_text())
    plan["provenance"]["config"]["heading_aid"] = "sun-sensor"
    plan["network"] = {"datum": {"heading_aid": "sun-sensor", "heading_prior_sigma_deg": 0.1,
                                 "heading_bias_sigma_deg": 0.05}}
    (tmp_path / "aided.json").write_text(json.dumps(plan))
    for out, extra, bias in (("plan-bias", [], 0.05),
                             ("given-bias", ["--heading-bias-sigma-deg", "0.2"], 0.2)):
        code, _, err = run_cli(capsys, ["adjust", *_tables(network), "--plan", "aided.json",
                                        *extra, "--out", out])
        assert code == 0, err
        config = json.loads((tmp_path / out / "adjustment.json").read_text()
                            )["provenance"]["config"]
        assert config["heading_prior_sigma_deg"] == 0.1
        assert config["heading_bias_sigma_deg"] == bias
