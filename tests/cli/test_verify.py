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
