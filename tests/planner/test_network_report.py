"""The writers of ``markerplan adjust`` on a hand-built adjustment result: the numbers in the
tables (ellipsoids, station error, observation status), the files, and their determinism."""

from __future__ import annotations

import csv
import hashlib
import json
import math

import numpy as np
import pytest
from scipy.stats import chi2

from pipeline.network.adjustment import AdjustmentSettings, NetworkAdjustment
from pipeline.network.observations import Datum, NetworkObservations
from pipeline.network.reliability import PointTests, Rejection, normalised_statistic
from planner.network import record as nr
from planner.network.files import FILES, write_network_files

CHI2_3 = chi2.ppf(0.95, 3)


def _given() -> NetworkObservations:
    """Two stations, three markers; S2's view of M3 is the blunder snooping removed."""
    return NetworkObservations(
        ("S1", "S2"), ("M1", "M2", "M3"), np.array([0, 0, 0, 1, 1, 1]),
        np.array([0, 1, 2, 0, 1, 2]),
        np.array([[5.0, 0, -1], [0, 6, -1], [-4, -4, -1], [-5, 1, -1], [-10, 7, -1],
                  [-14, -3, -1]]), np.full(6, 0.01))


def hand_built(snooping: bool = True) -> nr.AdjustmentRun:
    """An adjustment result made by hand (not by :func:`adjust`): known covariances, one
    observation removed, one flagged, one uncontrolled."""
    given = _given()
    keep = np.array([True, True, True, True, True, False])
    kept = given.subset(keep)
    u = 6 * 2 + 3 * 3
    var = np.zeros(u)
    var[6:9] = 1e-4                     # S2 position: 1 cm per axis
    var[9] = math.radians(0.1) ** 2     # S2 heading: 0.1 deg
    var[[4, 5, 10, 11]] = math.radians(0.01) ** 2
    var[12:] = np.tile([4e-4, 1e-4, 1e-4], 3)
    pose = np.array([[0, 0, 0, 0, 0, 0], [10.0, 0, 0.2, 0.5, 0, 0]])
    w = np.array([[0.5, -0.2, 0.1], [4.2, 0.3, 0.0], [-1.0, 0.2, 0.3], [0.1, 0.1, 0.1],
                  [0.0, 0.0, 0.0]])
    mdb = np.full((5, 3), 0.05)
    mdb[4] = np.inf
    t = np.array([0.3, 21.0, 1.2, 0.03, 0.0])  # the second: w 3.88 > 3.29
    dof = np.array([3, 3, 3, 3, 0])
    result = NetworkAdjustment(
        observations=kept, pose=pose,
        marker_xyz_m=np.array([[5.0, 0, -1], [0, 6, -1], [-4, -4, -1]]),
        covariance=np.diag(var), residuals_m=np.full((5, 3), 0.001),
        redundancy=np.vstack([np.full((4, 3), 0.5), np.zeros((1, 3))]), w_test=w, mdb_m=mdb,
        mdb_effect_m=np.array([0.02, 0.03, 0.01, 0.04, np.inf]), sigma0_squared=1.2, dof=4,
        iterations=3, point=PointTests(t, dof, normalised_statistic(t, dof), np.full(5, 0.5)),
        mdb_point_m=np.array([0.06, 0.07, 0.05, 0.08, np.inf]), robust_weight=np.ones(5),
        rejected=[Rejection("S2", "M3", 9.5, 1, 95.0, 3)], datum=Datum(),
        settings=AdjustmentSettings(snooping=snooping))
    return nr.AdjustmentRun(
        result=result, observations=given, config={"datum": "station"}, working_radius_m=10.0,
        requirement_m=0.1, error_figure="ellipsoid", identity="table",
        frame=nr.frame_note("station", "S1", False),
        inputs=[{"kind": "marker table", "path": "t.csv", "sha256": "0" * 64}],
        error_model="test", unidentified=[("S2", np.array([1.0, 2.0, 3.0]), "outside_gate")],
        plan_markers={"M1": np.array([5.0, 0.0, -0.9])})


def test_station_rows_ellipsoid_and_error():
    run = hand_built()
    s1, s2 = nr.station_rows(run)
    assert s1["reference"] and not s2["reference"]
    assert s1["sigma_x_m"] == 0.0 and s1["ellipsoid_major_m"] == 0.0
    assert s2["ellipsoid_major_m"] == pytest.approx(math.sqrt(CHI2_3 * 1e-4))
    assert s2["sigma_heading_deg"] == pytest.approx(0.1)
    assert s2["n_observations"] == 2 and s2["n_removed"] == 1
    # position (1e-4 per axis) and heading over 10 m add up horizontally; roll/pitch vertically
    horizontal = 1e-4 + (10.0 * math.radians(0.1)) ** 2
    assert s2["station_error_95_m"] == pytest.approx(math.sqrt(CHI2_3 * horizontal), rel=1e-3)
    assert s2["meets_requirement"] == (s2["station_error_95_m"] <= 0.1)


def test_station_error_of_a_tilt_is_vertical_at_the_rim():
    cov = np.zeros((1, 6, 6))
    cov[0, 4, 4] = 1e-6  # roll only, 1 mrad
    err = nr.station_errors(cov, np.array([1.0]), 20.0, "ellipsoid")
    assert err[0] == pytest.approx(math.sqrt(CHI2_3) * 20.0 * 1e-3, rel=1e-3)


def test_station_error_matches_the_design_block_at_any_heading():
    """Brute force with the spec's 3 x 6 block G(q) (q in the levelled station frame, the
    heading column rotated into the site frame) at a heading of 2 rad, correlated covariance."""
    rng = np.random.default_rng(5)
    a = rng.normal(size=(6, 6)) * np.array([0.01, 0.01, 0.01, 1e-3, 2e-4, 1e-4])
    cov = a @ a.T
    heading, radius = 2.0, 12.0
    c, s = math.cos(heading), math.sin(heading)
    worst = 0.0
    for phi in np.radians(np.arange(0, 360, 5)).tolist() + [None]:
        qx, qy = (0.0, 0.0) if phi is None else (radius * math.cos(phi), radius * math.sin(phi))
        g = np.zeros((3, 6))
        g[:, :3] = np.eye(3)
        g[:, 3] = [-(s * qx + c * qy), c * qx - s * qy, 0.0]
        g[2, 4], g[2, 5] = qy, -qx
        worst = max(worst, np.linalg.eigvalsh(g @ cov @ g.T)[-1])
    err = nr.station_errors(cov[None], np.array([heading]), radius, "ellipsoid")
    assert err[0] == pytest.approx(math.sqrt(CHI2_3 * worst), rel=1e-9)


def test_marker_rows():
    rows = nr.marker_rows(hand_built())
    assert [r["marker_id"] for r in rows] == ["M1", "M2", "M3"]
    assert rows[0]["ellipsoid_major_m"] == pytest.approx(math.sqrt(CHI2_3 * 4e-4))
    assert rows[0]["offset_from_plan_m"] == pytest.approx(0.1)
    assert rows[1]["offset_from_plan_m"] is None
    assert rows[2]["stations"] == "S1" and rows[0]["stations"] == "S1 S2"


def test_observation_status():
    rows = nr.observation_rows(hand_built(), critical_value=3.29)
    assert [r["status"] for r in rows] == ["kept", "flagged", "kept", "kept", "kept", "removed"]
    removed = rows[-1]
    assert (removed["station_id"], removed["marker_id"]) == ("S2", "M3")
    assert removed["test_w"] == 9.5 and removed["removed_in_round"] == 1
    assert removed["test_statistic"] == 95.0 and removed["test_dof"] == 3
    assert removed["test_p_value"] == pytest.approx(chi2.sf(95.0, 3), rel=1e-9)
    assert removed["residual_x_m"] is None and removed["max_abs_w"] is None
    # flagged by the point test (T 21 with 3 dof: p 1e-4 < 0.001), not by a component
    assert rows[1]["max_abs_w"] == pytest.approx(4.2)
    assert rows[1]["test_p_value"] == pytest.approx(chi2.sf(21.0, 3), rel=1e-9)
    assert rows[1]["test_w"] > 3.29 > rows[0]["test_w"]
    assert rows[4]["test_dof"] == 0 and rows[4]["test_w"] == 0.0
    assert rows[4]["mdb_x_m"] == np.inf  # uncontrolled: written as an empty cell


def test_global_test_against_chi2():
    t = nr.global_test(1.0, 50)
    assert t["passed"] and t["upper"] == pytest.approx(chi2.isf(0.025, 50) / 50)
    assert nr.global_test(float("nan"), 0)["passed"] is None
    assert nr.global_test(3.0, 50)["verdict"] == "noisier than the error model"
    assert nr.global_test(0.3, 50)["verdict"] == "error model pessimistic"
    assert nr.global_test(0.3, 50)["passed"]  # conservative errors: reported, not failed


def _digests(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def test_files_are_complete_and_deterministic(tmp_path):
    run = hand_built()
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        doc = write_network_files(tmp_path / name, run)
    assert _digests(tmp_path / "a") == _digests(tmp_path / "b")
    folder = tmp_path / "a"
    assert sorted(p.name for p in folder.iterdir()) == sorted(FILES)
    assert doc["files"] == list(FILES)
    cov = np.load(folder / "covariance.npy")
    params = list(csv.DictReader((folder / "parameters.csv").open()))
    assert cov.shape == (len(params),) * 2 == (21, 21)
    assert params[6]["parameter"] == "S2.x_m" and params[12]["parameter"] == "M1.x_m"
    for name, columns in (("stations.csv", nr.STATION_COLUMNS),
                          ("markers.csv", nr.MARKER_COLUMNS),
                          ("observations.csv", nr.OBSERVATION_COLUMNS)):
        header = next(csv.reader((folder / name).open()))
        assert tuple(header) == columns
    obs = list(csv.DictReader((folder / "observations.csv").open()))
    assert obs[4]["mdb_x_m"] == "" and obs[-1]["status"] == "removed"
    saved = json.loads((folder / "adjustment.json").read_text())
    assert saved["schema"] == nr.SCHEMA and saved["statistics"]["dof"] == 4
    assert saved["data_snooping"]["rejected"] == [
        {"station_id": "S2", "marker_id": "M3", "w": 9.5, "T": 95.0, "dof": 3, "round": 1}]
    assert saved["data_snooping"]["flagged"][0]["marker_id"] == "M2"
    assert saved["provenance"]["solver"]["status"] == "converged"
    assert saved["provenance"]["markerplan_version"]
    assert saved["reliability"]["n_uncontrolled"] == 1
    assert saved["identity"]["n_detections"] == 7
    gj = json.loads((folder / "network.geojson").read_text())
    kinds = [f["properties"]["kind"] for f in gj["features"]]
    assert kinds.count("station") == 2 and kinds.count("marker") == 3 and kinds.count("tie") == 6
    assert "not WGS84" in gj["coordinate_frame"] or "not geographic" in gj["coordinate_frame"]
    report = (folder / "report.md").read_text()
    assert "| 1 | S2 | M3 | 9.50 | 95 |" in report
    assert "Flagged but kept (w above the critical value): S1→M2 (w 3.88)" in report
    assert "reference station S1" in report and "Global test: passed" in report
    assert "Seen by one station only (1): M3" in report


def test_no_redundancy_is_reported_not_crashed(tmp_path):
    run = hand_built()
    res = run.result
    res.dof, res.sigma0_squared = 0, float("nan")
    doc = write_network_files(tmp_path, run, draw_map=False)
    assert doc["global_test"]["passed"] is None
    assert doc["statistics"]["sigma0_squared"] is None
    assert "no redundancy" in (tmp_path / "report.md").read_text()
    assert not (tmp_path / "network.png").exists()
