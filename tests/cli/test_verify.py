"""``markerplan verify``: bad plan files fail in one line; a simulated check passes and fails."""

import json

import pytest

from tests.cli.invoke import run_cli


@pytest.mark.parametrize("content,needle", [(None, "file not found"),
                                            ("{not json", "not a JSON file"),
                                            ('{"schema": "other"}', "not a markerplan plan")])
def test_bad_plan_files(tmp_path, capsys, content, needle):
    plan = tmp_path / "plan.json"
    if content is not None:
        plan.write_text(content)
    out = tmp_path / "v"
    code, _, err = run_cli(capsys, ["verify", str(plan), "--out", str(out)])
    assert code == 1 and needle in err and err.count("\n") == 1
    assert not out.exists()


@pytest.mark.slow
def test_verify_passes_and_fails_with_the_reason(tmp_path, capsys, valid_inputs):
    doc = json.loads((valid_inputs / "plan" / "plan.json").read_text())  # the default plan
    doc["stations"] = doc["stations"][:1]  # one station keeps the test short
    # a mis-mounted rig: the pipeline self-calibrates, the plan still passes, the truth is kept
    one = tmp_path / "one.json"
    one.write_text(json.dumps(doc))
    code, stdout, _ = run_cli(capsys, ["verify", str(one), "--vertical-axis-error-deg", "0.3",
                                       "--lframe-tilt-deg", "0.3", "--axis-offset-mm", "15,0",
                                       "--out", str(tmp_path / "v3"), "--json"])
    assert code == 0 and json.loads(stdout)["stations"]["S1"]["passed"]
    rec = json.loads((tmp_path / "v3" / "verify.json").read_text())
    truth = rec["provenance"]["config"]["mounting_offsets"]
    assert truth["axis_offset_m"] == [0.015, 0.0]
    assert truth["lframe_tilt_rad"] == pytest.approx(0.005236, abs=1e-6)
    # a well-mounted rig against a requirement no real registration meets: it fails with the
    # reason, and (the requirement changes only the verdict) it achieves the plan's 0.10 m
    requirement_m = doc["requirement"]["requirement_m"]
    assert requirement_m == 0.10
    doc["requirement"]["requirement_m"] = 1e-5
    strict = tmp_path / "strict.json"
    strict.write_text(json.dumps(doc))
    code, _, err = run_cli(capsys, ["verify", str(strict), "--out", str(tmp_path / "v2")])
    assert code == 1 and "verification failed at S1: achieved" in err
    # a failed verification is its own error, not an infeasible plan
    from markerplan.errors import InfeasiblePlanError, VerificationFailedError
    from planner.cli.verify import command as verify_command

    with pytest.raises(VerificationFailedError, match="^verification failed at S1") as caught:
        verify_command.main([str(strict), "--out", str(tmp_path / "v-failed")],
                            standalone_mode=False)
    assert isinstance(caught.value, RuntimeError)
    assert not isinstance(caught.value, InfeasiblePlanError)
    rec = json.loads((tmp_path / "v2" / "verify.json").read_text())
    assert rec["passed"] is False
    [s] = rec["stations"]
    assert s["id"] == "S1" and s["achieved_error_m"] is not None
    assert s["achieved_error_m"] <= requirement_m
    # every planned marker's fate, its losses in the record and the reason
    fates = (tmp_path / "v2" / "fates.csv").read_text().splitlines()
    assert fates[0].startswith("trial,station_id,marker_id,distance_m,elevation_deg,")
    assert [line.split(",")[2] for line in fates[1:]] == doc["stations"][0]["markers"]
    assert s["n_false_accepts"] == 0 and "losses" in rec
    for lost in s["lost"]:
        assert f"{lost['marker_id']} " in s["reason"]


def _files(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.mark.slow
def test_trials_repeat_with_their_seeds_and_one_trial_is_the_plain_verify(tmp_path, capsys,
                                                                         valid_inputs):
    doc = json.loads((valid_inputs / "plan" / "plan.json").read_text())
    doc["stations"] = doc["stations"][:1]
    one = tmp_path / "one.json"
    one.write_text(json.dumps(doc))
    base = ["verify", str(one), "--scheduler", "none", "--seed", "4"]
    runs = {}
    for name, extra in (("plain", []), ("t1", ["--trials", "1"]), ("t3", ["--trials", "3"]),
                        ("t3-again", ["--trials", "3"])):
        code, _, err = run_cli(capsys, base + extra + ["--out", str(tmp_path / name)])
        assert code in (0, 1), err
        runs[name] = _files(tmp_path / name)
    assert runs["t1"] == runs["plain"]  # --trials 1 is verify as it was
    assert set(runs["plain"]) == {"fates.csv", "fates.csvt", "provenance.json", "verify.json",
                                  "verify.md"}
    assert runs["t3"] == runs["t3-again"]  # the same seed, the same files
    assert {"trials.csv", "trials.csvt"} <= set(runs["t3"])
    rows = [line.split(",") for line in runs["t3"]["trials.csv"].decode().splitlines()[1:]]
    assert [r[0] for r in rows] == ["0", "1", "2"] and rows[0][1] == "4"
    # trial 0 is the plain verification (seed 4); the others draw other noise
    plain = json.loads(runs["plain"]["verify.json"])["stations"][0]
    assert float(rows[0][5]) == pytest.approx(plain["achieved_error_m"], abs=1e-6)
    assert len({r[5] for r in rows}) == 3
    rec = json.loads(runs["t3"]["verify.json"])
    n = rec["pass_rate"]["n_passed"]
    assert rec["mode"] == "trials" and n == sum(r[3] == "true" for r in rows)
    assert rec["provenance"]["config"]["trial_seeds"][0] == 4
    fates = runs["t3"]["fates.csv"].decode().splitlines()
    assert len(fates) == 1 + 3 * len(doc["stations"][0]["markers"])


@pytest.mark.slow
def test_marker_radius_travels_from_plan_to_simulation_and_fit(tmp_path, capsys):
    """Plan with 0.15 m markers; verify must simulate and fit 0.15 m spheres (a 0.10 m fit of a
    0.15 m sphere puts its centre about 5 cm too far along the line of sight)."""
    plan_dir = tmp_path / "plan"
    code, _, err = run_cli(capsys, ["plan", "--marker-radius-m", "0.15", "--out", str(plan_dir)])
    assert code == 0, err
    doc = json.loads((plan_dir / "plan.json").read_text())
    assert doc["site"]["marker_radius_m"] == 0.15
    code, stdout, err = run_cli(capsys, ["verify", str(plan_dir / "plan.json"), "--station-ids",
                                         "S1", "--out", str(tmp_path / "v"), "--json"])
    assert code == 0, err
    assert list(json.loads(stdout)["stations"]) == ["S1"]
    rec = json.loads((tmp_path / "v" / "verify.json").read_text())
    errors = rec["stations"][0]["marker_centre_errors_m"]
    assert len(errors) >= 3 and max(errors.values()) < 0.02, errors
