import csv
import json

import pytest

from pipeline.marker_table import COLUMNS, read_marker_table
from tests.cli.invoke import run_cli

pytest.importorskip("visibility.simulate")



def test_quick_range_study(tmp_path, capsys):
    out = tmp_path / "rs"
    code, stdout, _ = run_cli(capsys, ["range-study", "--out", str(out), "--frames", "40",
                                       "--replicates", "2", "--max-distance-m", "4", "--json"])
    assert code == 0
    res = json.loads(stdout)
    assert sorted(p.name for p in out.iterdir()) == ["markers.csv", "provenance.json",
                                                     "range_study.png", "summary.csv",
                                                     "summary.json"]
    rows = read_marker_table(out / "markers.csv")
    assert list(rows[0]) == list(COLUMNS)
    assert len(rows) == 4 * 2 * 2  # distances x estimators x replicates
    assert {r["replicate"] for r in rows} == {"0", "1"} and {r["seed"] for r in rows} == {"0", "1"}
    summary = list(csv.DictReader((out / "summary.csv").open()))
    assert {s["estimator"] for s in summary} == {"fixed-radius", "hemisphere-icp"}
    near = [s for s in res["summary"] if s["distance_m"] <= 3 and s["estimator"] == "fixed-radius"]
    assert all(s["median_error_m"] < 0.02 for s in near)
    dens = [s["median_point_density_per_m2"] for s in res["summary"]
            if s["estimator"] == "fixed-radius"]
    assert dens[0] > dens[-1]  # density falls with distance


def test_slope_and_profile_recorded_and_markers_seen(tmp_path, capsys):
    out = tmp_path / "slope"
    code, stdout, _ = run_cli(capsys, [
        "range-study", "--out", str(out), "--frames", "50", "--replicates", "1",
        "--max-distance-m", "10", "--lidar-height-m", "0.8", "--slope-deg", "15",
        "--sensor-profile", "datasheet", "--range-noise-mm", "10", "--json"])
    assert code == 0
    config = json.loads((out / "summary.json").read_text())["provenance"]["config"]
    assert json.loads(stdout)["provenance"]["config"] == config
    assert config["terrain"]["lidar_height_m"] == 0.8 and config["terrain"]["slope_deg"] == 15
    assert config["sensor_profile"] == "datasheet"
    assert config["sensor"]["range_noise_m"] == 0.01 and config["sensor"]["beam_divergence"]
    assert set(config["turntable"]) == {"encoder_noise_rad", "backlash_rad", "sync_jitter_s",
                                        "wobble_rad", "periodic_error_rad"}
    rows = [r for r in read_marker_table(out / "markers.csv") if r["estimator"] == "fixed-radius"]
    assert len(rows) == 10 and all(int(r["n_points"]) > 0 for r in rows)  # no marker hidden
    # the 9 m marker lies almost straight uphill (azimuth 20 deg): seen above the horizon
    assert float(next(r for r in rows if r["marker_id"] == "R09.0")["elevation_deg"]) > 9


def test_bad_options(tmp_path, capsys):
    code, _, err = run_cli(capsys, ["range-study", "--out", str(tmp_path / "o"), "--replicates",
                                    "0"])
    assert code == 2 and "--replicates" in err and not (tmp_path / "o").exists()


def test_progress_advances_as_each_replicate_arrives():
    """The caller's progress moves with the results of ``map_tasks`` (an Executor's lazy,
    in-order iterator has no bar of its own), not once they are all back."""
    from planner.studies.range_experiment import run_range_study

    log = []

    def map_tasks(fn, items):
        for item in items:
            log.append(f"replicate {item}")
            yield fn(item)

    study = run_range_study(2.0, 4, 2, progress=lambda n: log.append(f"progress {n}"),
                            map_tasks=map_tasks)
    assert log == ["replicate 0", "progress 1", "replicate 1", "progress 1"]
    assert sorted({r.replicate for r in study.rows}) == [0, 1]
