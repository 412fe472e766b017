"""``markerplan calibrate-sensor``: bad input refused in one line; a small real run is seeded
and reproducible, and its profile is accepted by ``simulate``."""

import json

import pytest

from tests.cli.bad_input import Case, check_refused
from tests.cli.invoke import run_cli

#: The fewest frames calibrate-sensor takes: these cases are refused before any simulation.
CAL = ["calibrate-sensor", "--frames", "100", "--out", "out"]
HEADER = "position,distances_m,mean_abs_edge_residual_m\n"


def summary_case(name, rows, needle):
    return Case(name, CAL[:1] + ["s.csv"] + CAL[1:], needle, files={"s.csv": HEADER + rows})


CASES = [
    summary_case("too-few-markers", "1,5 6 7,0.01\n2,5 6 7 8,0.01\n", "at least 4 markers"),
    summary_case("distance-too-short", "1,0.5 6 7 8,0.01\n2,5 6 7 8,0.01\n", "within 1-50 m"),
    summary_case("distance-too-far", "1,5 6 7 80,0.01\n2,5 6 7 8,0.01\n", "within 1-50 m"),
    summary_case("negative-residual", "1,5 6 7 8,-0.01\n2,5 6 7 8,0.01\n", "must be > 0"),
    summary_case("residual-in-mm", "1,5 6 7 8,11\n2,5 6 7 8,0.01\n", "not millimetres"),
    summary_case("nan-distance", "1,5 nan 7 8,0.01\n2,5 6 7 8,0.01\n", "distance"),
    summary_case("no-rows", "", "no positions"),
    summary_case("repeated-position", "1,5 6 7 8,0.01\n1,5 6 7 8,0.01\n", "more than once"),
    Case("missing-column", CAL[:1] + ["s.csv"] + CAL[1:], "missing column",
         files={"s.csv": "position,distances_m\n1,5 6 7 8\n"}),
    summary_case("one-position-one-parameter", "1,5 6 7 8,0.01\n", "at least 2 positions"),
    Case("unknown-fit-parameter", CAL + ["--fit", "sensor.colour=0:1"], "not a sensor-profile"),
    Case("fit-range-reversed", CAL + ["--fit", "sensor.range_noise_m=0.05:0.01"], "LOW < HIGH"),
    Case("fit-not-numbers", CAL + ["--fit", "sensor.range_noise_m=a:b"], "NAME=LOW:HIGH"),
    Case("three-fit-parameters", CAL + ["--fit", "sensor.range_noise_m=0:0.1",
                                        "--fit", "turntable.periodic_error_rad=0:0.1",
                                        "--fit", "sensor.dropout_prob=0:0.1"],
         "one or two free parameters"),
    Case("fix-unknown", CAL + ["--fix", "sensor.colour=1"], "not a sensor-profile"),
    Case("fix-and-fit", CAL + ["--fix", "turntable.periodic_error_rad=0.001"],
         "both fixed"),
    Case("fix-negative", CAL + ["--fix", "reference.aim_sigma_m=-1"], ">= 0"),
    Case("missing-base-profile", CAL + ["--base-profile", "nope.json"],
         "neither a shipped profile"),
    Case("table-without-reference", CAL + ["--marker-table", "{inputs}/markers.csv"],
         "go together"),
    Case("summary-and-table", CAL[:1] + ["s.csv"] + CAL[1:] + [
        "--marker-table", "{inputs}/markers.csv", "--reference", "{inputs}/reference.csv"],
        "either SUMMARY", files={"s.csv": HEADER + "1,5 6 7 8,0.01\n"}),
    Case("table-ids-not-in-reference", CAL + ["--marker-table", "{inputs}/markers.csv",
                                              "--reference", "ref.csv"],
         "matched to the reference", files={"ref.csv": "id,x_m,y_m,z_m\nX1,0,0,0\nX2,1,0,0\n"
                                                       "X3,0,1,0\n"}),
    Case("missing-summary-file", CAL[:1] + ["nope.csv"] + CAL[1:], "nope.csv: file not found"),
]


@pytest.mark.parametrize("case", CASES, ids=str)
def test_bad_input_refused(case, capsys, monkeypatch, tmp_path, valid_inputs):
    check_refused(case, capsys, monkeypatch, tmp_path, valid_inputs)


@pytest.mark.slow
def test_small_calibration_is_seeded_reproducible_and_usable(tmp_path, capsys, monkeypatch):
    """Two positions of four near markers, 200 frames: the same command twice gives the same
    bytes, the profile records the fit, and simulate accepts it."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.csv").write_text(HEADER + "A,6 8 10 12,0.005\nB,7 9 11 13,0.006\n")
    args = ["calibrate-sensor", "s.csv", "--frames", "200", "--replicates", "1",
            "--check-replicates", "1", "--design-points", "3", "--no-holdout",
            "--fit", "sensor.range_noise_m=0.005:0.03"]
    for out in ("a", "b"):
        code, _, err = run_cli(capsys, args + ["--out", out])
        assert code == 0, err
    for name in ("sensor_profile.json", "calibration.json", "runs.csv", "report.md"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    profile = json.loads((tmp_path / "a" / "sensor_profile.json").read_text())
    fitted = profile["calibration"]["values"]["sensor.range_noise_m"]
    assert profile["sensor"]["range_noise_m"] == pytest.approx(fitted)
    assert 0.005 <= fitted <= 0.03
    assert profile["reference"]["aim_sigma_m"] == pytest.approx(0.003)  # a field prior
    code, _, err = run_cli(capsys, ["simulate", "--station-ids", "S1", "--frames", "8",
                                    "--sensor-profile", "a/sensor_profile.json", "--out", "sim"])
    assert code == 0, err


def test_a_fitted_field_prior_is_fitted_not_refused(tmp_path, capsys, monkeypatch):
    """The field priors fix what --fit does not name: fitting one of them (no --fix given) is
    not "fixed (--fix) and fitted"; the calibration starts from the other priors."""
    from planner.studies import sensor_calibration

    started = {}

    class Stop(Exception):
        pass

    def calibrate(positions, start, free, settings, progress=None):
        started.update(start=start, free=[f.name for f in free])
        raise Stop

    monkeypatch.setattr(sensor_calibration, "calibrate", calibrate)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(Stop):
        run_cli(capsys, CAL + ["--fit", "sensor.incidence_noise_m=0:0.01"])
    assert started["free"] == ["sensor.incidence_noise_m"]
    assert started["start"].turntable.encoder_noise_rad == pytest.approx(1e-4)  # a prior
