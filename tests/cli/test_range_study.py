import csv
import json

import numpy as np
import pytest

from pipeline.tables.marker_table import COLUMNS, read_marker_table
from tests.cli.invoke import run_cli

pytest.importorskip("visibility.simulate")



def _laid_out(rows):
    """The rows of laid-out markers (the chain's unmatched detections have no marker id)."""
    return [r for r in rows if r["marker_id"]]


def test_quick_range_study_runs_the_full_chain_by_default(tmp_path, capsys):
    out = tmp_path / "rs"
    code, stdout, _ = run_cli(capsys, ["range-study", "--out", str(out), "--frames", "40",
                                       "--replicates", "1", "--max-distance-m", "4", "--json"])
    assert code == 0
    res = json.loads(stdout)
    assert sorted(p.name for p in out.iterdir()) == ["markers.csv", "provenance.json",
                                                     "range_study.png", "summary.csv",
                                                     "summary.json"]
    record = json.loads((out / "summary.json").read_text())
    assert record["extraction"] == res["extraction"] == "full-chain"
    assert record["provenance"]["config"]["extraction"] == "full-chain"
    assert set(record["unmatched_candidates"]) == {"fixed-radius", "hemisphere-icp"}
    rows = read_marker_table(out / "markers.csv")
    assert list(rows[0]) == list(COLUMNS)
    marked = _laid_out(rows)
    assert sorted((r["marker_id"], r["estimator"]) for r in marked) == sorted(
        (f"R{d:04.1f}", m) for d in (1, 2, 3, 4) for m in ("fixed-radius", "hemisphere-icp"))
    assert len(rows) - len(marked) == sum(u["n_rows"]
                                          for u in record["unmatched_candidates"].values())
    # every marker the chain lost says so; the summary counts rows, detections, acceptances
    lost = [r for r in marked if r["reason"] == "not_detected"]
    assert all(r["accepted"] == "false" and r["error_m"] == "" and r["n_points"] == "0"
               for r in lost)
    summary = list(csv.DictReader((out / "summary.csv").open()))
    assert {s["estimator"] for s in summary} == {"fixed-radius", "hemisphere-icp"}
    assert [int(s["n_rows"]) for s in summary] == [1] * 8
    assert sum(int(s["n_rows"]) - int(s["n_detected"]) for s in summary) == len(lost)
    assert sum(int(s["n_accepted"]) for s in summary) == sum(r["accepted"] == "true"
                                                             for r in marked)


def test_truth_seeded_diagnostic_is_labelled(tmp_path, capsys):
    out = tmp_path / "seeded"
    code, stdout, _ = run_cli(capsys, ["range-study", "--out", str(out), "--frames", "40",
                                       "--replicates", "2", "--max-distance-m", "4",
                                       "--extraction", "truth-seeded"])
    assert code == 0
    assert stdout.splitlines()[0] == "extraction: truth-seeded"
    record = json.loads((out / "summary.json").read_text())
    assert record["extraction"] == record["provenance"]["config"]["extraction"] == "truth-seeded"
    rows = read_marker_table(out / "markers.csv")
    assert len(rows) == 4 * 2 * 2  # distances x estimators x replicates
    assert {r["replicate"] for r in rows} == {"0", "1"} and {r["seed"] for r in rows} == {"0", "1"}
    near = [s for s in record["summary"]
            if s["distance_m"] <= 3 and s["estimator"] == "fixed-radius"]
    assert all(s["median_error_m"] < 0.02 for s in near)
    dens = [s["median_point_density_per_m2"] for s in record["summary"]
            if s["estimator"] == "fixed-radius"]
    assert dens[0] > dens[-1]  # density falls with distance


@pytest.mark.slow  # two studies and their plots, ~10 s of CPU
def test_a_marker_the_detection_loses_is_rejected_only_under_full_chain(monkeypatch, tmp_path):
    """A ground removal that takes the 1 m marker for ground: the default table rejects it as
    not detected, the truth-seeded diagnostic still accepts it (it never asks the detection
    stages); the other markers keep rows either way. ``fit-error-model`` reads both tables."""
    import pipeline.chain.process
    from error_model.table import fit_data, read_marker_tables
    from pipeline.surveys.range_study import marker_layout
    from planner.studies.range_experiment import run_range_study, write_range_study

    lost_centre = marker_layout(np.array([1.0]))[0]
    remove_ground = pipeline.chain.process.remove_ground

    def ground_under_it(pts, *args, **kwargs):
        return remove_ground(pts, *args, **kwargs) & (
            np.linalg.norm(pts - lost_centre, axis=1) > 0.5)

    monkeypatch.setattr(pipeline.chain.process, "remove_ground", ground_under_it)
    chain = run_range_study(2.0, 40, 1)
    seeded = run_range_study(2.0, 40, 1, extraction="truth-seeded")
    assert chain.config["extraction"] == "full-chain"  # the default
    for method in ("fixed-radius", "hemisphere-icp"):
        (c,) = [r for r in chain.rows if r.marker_id == "R01.0" and r.estimator == method]
        (s,) = [r for r in seeded.rows if r.marker_id == "R01.0" and r.estimator == method]
        assert (c.accepted, c.reason) == (False, "not_detected")
        assert s.accepted, s.reason
        assert [r.marker_id for r in chain.rows if r.estimator == method][:2] == ["R01.0",
                                                                                 "R02.0"]
    (s1,) = [s for s in chain.summary if s["distance_m"] == 1.0
             and s["estimator"] == "fixed-radius"]
    assert (s1["n_rows"], s1["n_detected"], s1["n_accepted"]) == (1, 0, 0)
    # fit-error-model's reader takes either table: lost markers are rows it drops as not
    # accepted, unmatched detections rows without an error
    for study in (chain, seeded):
        folder = tmp_path / study.config["extraction"]
        folder.mkdir()
        write_range_study(study, folder)
        table = read_marker_tables(folder / "markers.csv")
        assert table.n_rows == len(study.rows)
        fixed = [r for r in study.rows if r.estimator == "fixed-radius"]
        usable = [r for r in fixed if r.accepted and r.error_m is not None]
        if usable:
            data = fit_data(table, 1, estimator="fixed-radius")
            assert data.counts["rows_used"] == len(usable)
            assert data.counts["dropped_not_accepted"] == sum(not r.accepted for r in fixed)
    assert any(r.accepted for r in seeded.rows)


def test_slope_and_profile_recorded_and_markers_seen(tmp_path, capsys):
    out = tmp_path / "slope"
    code, stdout, _ = run_cli(capsys, [
        "range-study", "--out", str(out), "--frames", "50", "--replicates", "1",
        "--max-distance-m", "10", "--lidar-height-m", "0.8", "--slope-deg", "15",
        "--sensor-profile", "datasheet", "--range-noise-mm", "10", "--json",
        "--extraction", "truth-seeded"])  # every marker's own returns: what the scan sees
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
                            map_tasks=map_tasks, extraction="truth-seeded")
    assert log == ["replicate 0", "progress 1", "replicate 1", "progress 1"]
    assert sorted({r.replicate for r in study.rows}) == [0, 1]
