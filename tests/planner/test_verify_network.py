"""Network-mode verification's comparison step on a simulated network (no scans): marker tables
with the error model's noise, a plan whose stations are the odometry's poses, and the truth."""

import json

import numpy as np
import pytest

from error_model import default_model
from markerplan.errors import ConfigError, InputFileError
from planner.accuracy.known_control import pose_difference_m
from planner.verify.network import NetworkVerifySettings, TrueStation, adjust_and_compare
from planner.verify.network_report import network_markdown, network_record
from tests.cli.network_inputs import write_network_inputs


@pytest.fixture(scope="module")
def network(tmp_path_factory):
    inputs = write_network_inputs(tmp_path_factory.mktemp("net"), n_stations=6, seed=3,
                                  n_tables=1)
    t = inputs.truth
    markers = dict(zip(inputs.marker_ids, t.marker_xyz_m, strict=True))
    truth = {sid: TrueStation(sid, t.pose[i], markers)
             for i, sid in enumerate(inputs.station_ids)}
    return inputs, truth


def _compare(inputs, truth, planned=None, **kw):
    predicted = {sid: 0.05 for sid in truth}
    return adjust_and_compare(inputs.tables, inputs.plan, default_model(), truth, predicted,
                              {inputs.marker_ids[0]: 0.02}, NetworkVerifySettings(**kw),
                              "default", planned)


class _Plan:
    provenance = {"config_sha256": "0" * 64}


def _record(check):
    from visibility.sensor_profile import default_profile

    return network_record(_Plan(), check, 0, "default", None, default_profile())


def test_achieved_errors_agree_with_the_adjustments_own_figures(network):
    inputs, truth = network
    check = _compare(inputs, truth)
    assert check.passed and check.reference_station == inputs.station_ids[0]
    assert [s.station_id for s in check.stations] == list(inputs.station_ids)
    assert all(s.n_identified == s.n_accepted == s.n_used for s in check.stations)
    achieved = np.array([s.achieved_error_m for s in check.stations])
    stated = np.array([s.stated_error_m for s in check.stations])
    # the datum station is fixed at its (exact) nominal pose: only its tilt is estimated
    assert achieved[0] < 0.005
    # truth against the adjustment's 95 % bound: noisy, but not wildly off either way
    assert np.all(achieved < 2.0 * stated) and np.all(achieved[1:] > 0.0)
    marker_err = np.array([m.achieved_error_m for m in check.markers])
    assert len(check.markers) == len(inputs.marker_ids) and np.all(marker_err < 0.1)
    assert check.markers[0].predicted_error_m in (0.02, None)
    assert sum(m.predicted_error_m is not None for m in check.markers) == 1
    rec = _record(check)
    assert rec["mode"] == "network" and rec["passed"]
    assert rec["worst"]["achieved_error_m"] == pytest.approx(achieved.max())
    assert rec["worst"]["predicted_error_m"] == 0.05
    assert rec["provenance"]["config"]["network"]["odometry_sigma_m"] == 0.5
    text = network_markdown(rec)
    assert "Worst station: predicted 50.0 mm" in text and "| marker |" in text
    # the same inputs give the same bytes
    assert json.dumps(_record(_compare(inputs, truth))) == json.dumps(rec)


def test_a_station_off_its_true_pose_fails_with_the_reason(network):
    inputs, truth = network
    sid = inputs.station_ids[2]
    moved = dict(truth)
    pose = truth[sid].pose.copy()
    pose[3] += 0.02  # 2 cm per metre: 20 cm at the 10 m rim
    moved[sid] = TrueStation(sid, pose, truth[sid].marker_xyz_m)
    check = _compare(inputs, moved, planned={sid: ("M_never_placed",)})
    failed = [s for s in check.stations if not s.passed]
    assert not check.passed and [s.station_id for s in failed] == [sid]
    assert failed[0].achieved_error_m == pytest.approx(0.2, abs=0.02)
    assert failed[0].reason.startswith("achieved 0.") and failed[0].reason.endswith(
        "> requirement 0.1 m (planned markers not identified: M_never_placed)")
    assert _record(check)["worst"]["achieved_station"] == sid


def test_the_reference_station_must_be_verified(network):
    inputs, truth = network
    without = {sid: t for sid, t in truth.items() if sid != inputs.station_ids[0]}
    with pytest.raises(ConfigError, match="reference station .* include it in `station_ids`"):
        _compare(inputs, without)


def test_settings_are_checked():
    with pytest.raises(ConfigError, match="odometry_sigma_m"):
        NetworkVerifySettings(odometry_sigma_m=0.0)
    with pytest.raises(ConfigError, match="alpha0"):
        NetworkVerifySettings(alpha0=1.0)


def test_pose_difference_counts_the_tilt():
    tilt = np.array([0, 0, 0, 0, 1e-3, 0])  # 1 mrad roll: 1 cm vertical at the 10 m rim
    assert pose_difference_m(tilt, np.zeros(6), 10.0) == pytest.approx(0.01, rel=1e-3)
    assert pose_difference_m(np.zeros(6), np.zeros(6), 10.0) == 0.0


def test_stations_not_tied_to_the_reference_fail_without_stopping_the_rest(network, tmp_path):
    """One station keeps a single detection (not tied: fewer than 2 shared markers), another
    sees its markers 50 m from where the plan puts them (nothing inside the gate)."""
    from markerplan.reading import read_csv

    inputs, truth = network
    header, rows = read_csv(inputs.tables[0], "table", ())
    col = header.index("station_id")
    last, far = inputs.station_ids[-1], inputs.station_ids[-2]
    lines = [",".join(header)]
    n_last = 0
    for r in rows:
        if r[col] == last:
            n_last += 1
            if n_last > 1:
                continue
        if r[col] == far:
            r[header.index("x_m")] = str(float(r[header.index("x_m")]) + 50.0)
        lines.append(",".join(r))
    table = tmp_path / "markers.csv"
    table.write_text("\n".join(lines) + "\n")
    check = adjust_and_compare([table], inputs.plan, default_model(), truth, {})
    out = {s.station_id: s for s in check.stations}
    assert not check.passed
    assert out[last].reason == (f"not in the adjustment: 1 identified marker(s), fewer than 2 "
                                f"shared with the part of the network holding the reference "
                                f"{inputs.station_ids[0]}")
    assert out[far].reason.startswith("not in the adjustment: none of its detections matches")
    assert out[far].achieved_error_m is None and out[far].n_accepted > 0
    assert all(out[sid].passed for sid in inputs.station_ids[:-2])
    assert out[last].n_identified == 1 and out[last].n_used == 0
    rec = _record(check)
    assert rec["worst"]["not_adjusted"] == [far, last] and rec["worst"]["achieved_station"] \
        in inputs.station_ids[:-2]
    assert f"not in the adjustment: {far}, {last}." in network_markdown(rec)


def test_a_station_left_with_two_identified_markers_breaks_the_plans_rule(network, tmp_path):
    """Two detections tie the station into the adjustment and it registers, but the plan asked
    for three markers in three directions: it fails, saying so."""
    from markerplan.reading import read_csv

    inputs, truth = network
    header, rows = read_csv(inputs.tables[0], "table", ())
    col = header.index("station_id")
    last = inputs.station_ids[-1]
    kept = [r for r in rows if r[col] != last] + [r for r in rows if r[col] == last][:2]
    table = tmp_path / "markers.csv"
    table.write_text("\n".join([",".join(header)] + [",".join(r) for r in kept]) + "\n")
    out = {s.station_id: s for s in adjust_and_compare([table], inputs.plan, default_model(),
                                                        truth, {}).stations}
    assert out[last].n_identified == 2 and out[last].achieved_error_m is not None
    assert not out[last].passed
    assert out[last].reason.startswith("2 marker(s) in ") and "the plan's rule asks >= 3" \
        in out[last].reason
    assert all(out[sid].passed for sid in inputs.station_ids[:-1])


def _plan_with_aids(inputs, tmp_path, **aids):
    doc = json.loads(inputs.plan.read_text())
    doc["provenance"]["config"].update(network=True, **aids)
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(doc))
    return path


def _compare_with(inputs, truth, plan, seed):
    return adjust_and_compare(inputs.tables, plan, default_model(), truth,
                              {sid: 0.05 for sid in truth}, None, NetworkVerifySettings(),
                              "default", seed=seed)


def test_a_plan_with_odometry_and_a_biased_heading_reference_is_verified_with_them(network,
                                                                                   tmp_path):
    """The plan's aids are simulated from the truth with its sigmas and used by the
    adjustment: its stated errors shrink, the achieved errors stay within reach of them, the
    same seed repeats the outputs exactly and another seed draws other readings."""
    inputs, truth = network
    aided = _plan_with_aids(inputs, tmp_path, odometry_percent=1.0,
                            odometry_heading_deg_per_m=0.05, heading_aid="sun-sensor")
    plain = _compare_with(inputs, truth, inputs.plan, 0)
    first = _compare_with(inputs, truth, aided, 7)
    assert first.config["odometry_percent"] == 1.0 and first.config["aids_seed"] == 7
    assert first.config["heading_prior_sigma_deg"] == 0.1
    assert first.config["heading_bias_sigma_deg"] == 0.05
    stated = np.array([[s.stated_error_m for s in c.stations] for c in (plain, first)])
    assert np.all(stated[1, 1:] < stated[0, 1:])
    achieved = np.array([s.achieved_error_m for s in first.stations])
    assert np.all(achieved < 2.0 * stated[1]) and first.passed
    again = _compare_with(inputs, truth, aided, 7)
    other = _compare_with(inputs, truth, aided, 8)
    assert [s.achieved_error_m for s in again.stations] == achieved.tolist()
    assert again.sigma0_squared == first.sigma0_squared
    assert [s.achieved_error_m for s in other.stations] != achieved.tolist()


def test_a_plan_with_bad_aids_is_refused_in_one_line(network, tmp_path):
    inputs, truth = network
    bad = _plan_with_aids(inputs, tmp_path, odometry_percent=-1.0)
    with pytest.raises(InputFileError, match="odometry_percent") as err:
        _compare_with(inputs, truth, bad, 0)
    assert "\n" not in str(err.value)


def test_a_closed_traverse_is_verified_with_its_closing_reading(network, tmp_path):
    """A plan whose odometry closes the traverse (``odometry_loop_m``): verify records the
    loop, reads the closing reading too, and the adjustment's stated error of the last station,
    far from the datum along the open chain, shrinks while the achieved errors stay within
    reach of the stated."""
    inputs, truth = network
    first, last = (truth[inputs.station_ids[i]].pose[:3] for i in (0, -1))
    loop = 1.2 * float(np.linalg.norm(last - first))
    aids = dict(odometry_percent=0.1, odometry_heading_deg_per_m=0.002)  # strong enough to matter
    opened = _compare_with(inputs, truth, _plan_with_aids(inputs, tmp_path, **aids), 7)
    closed = _compare_with(inputs, truth, _plan_with_aids(inputs, tmp_path, **aids,
                                                          odometry_loop_m=loop), 7)
    assert opened.config["odometry_loop_m"] is None
    assert closed.config["odometry_loop_m"] == loop
    stated = np.array([[s.stated_error_m for s in c.stations] for c in (opened, closed)])
    assert stated[1, -1] < 0.98 * stated[0, -1]
    assert np.all(stated[1, 1:] <= stated[0, 1:] * (1 + 1e-9))
    achieved = np.array([s.achieved_error_m for s in closed.stations])
    assert np.all(achieved < 2.0 * stated[1]) and closed.passed
