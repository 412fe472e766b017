"""``markerplan plan``: the no-argument default run, its outputs, and one-line errors."""

import json

import numpy as np
import pytest

from planner.cli import main
from tests.cli.invoke import run_cli


@pytest.fixture(scope="module")
def default_plan(tmp_path_factory):
    """``markerplan plan --json`` with no other argument, run in an empty folder."""
    import contextlib
    import io
    import os

    cwd = tmp_path_factory.mktemp("plan-default")
    old = os.getcwd()
    os.chdir(cwd)
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            main(["plan", "--json"])
    finally:
        os.chdir(old)
    return cwd / "markerplan-out", json.loads(buf.getvalue())


def test_default_plan_meets_the_requirement_with_fewer_markers(default_plan):
    out, summary = default_plan
    assert sorted(p.name for p in out.iterdir()) == [
        "map.png", "markers.csv", "markers.csvt", "markers.geojson", "plan.gpkg", "plan.json",
        "provenance.json", "report.md", "station_error.tif", "usable_markers.tif"]
    doc = json.loads((out / "plan.json").read_text())
    assert doc["schema"] == "markerplan-plan" and doc["schema_version"] == 1
    assert summary["status"] == "optimal" and summary["meets_requirement"]
    assert len(doc["stations"]) == 7
    for s in doc["stations"]:
        assert s["predicted_error_m"] <= 0.10 and s["n_sectors"] >= 3 and s["n_markers"] >= 3
    n = doc["n_markers"]
    assert n < doc["baselines"]["as_built"]["n_markers"] == 11
    for b in ("greedy", "regular_grid"):
        assert doc["baselines"][b]["meets_requirement"]
        assert n <= doc["baselines"][b]["n_markers"]
    assert doc["solver"]["dual_bound"] == pytest.approx(n)
    prov = doc["provenance"]
    assert prov["config"]["requirement_m"] == 0.10 and prov["markerplan_version"]
    csv_lines = (out / "markers.csv").read_text().splitlines()
    assert csv_lines[0] == "id,x_m,y_m,z_m,existing,n_stations,stations"
    assert len(csv_lines) == 1 + n and "local metres" in doc["frame"]
    assert (out / "markers.csvt").read_text() == (
        '"String","Real","Real","Real","Integer","Integer","String"\n')
    gj = json.loads((out / "markers.geojson").read_text())
    assert "local metres" in gj["coordinate_frame"]
    assert sum(f["properties"]["kind"] == "marker" for f in gj["features"]) == n
    assert "Compared with" in (out / "report.md").read_text()
    assert (out / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_default_plan_holds_with_its_stated_chance(default_plan, tmp_path, capsys):
    """The default plan is chance-constrained: it records the detection model and every
    planned pair's chance, each station's certified chance of passing and the plan's; the
    naive plan (``--chance-epsilon none``) has fewer markers and a far lower chance."""
    out, summary = default_plan
    doc = json.loads((out / "plan.json").read_text())
    ch = doc["chance"]
    assert ch["epsilon"] == 0.05 and ch["station_target"] == pytest.approx(0.05 / 7)
    assert ch["plan_pass_probability"] >= 0.95
    for s in doc["stations"]:
        assert s["pass_probability"] >= 1 - ch["station_target"]
        assert ch["stations"][s["id"]]["pass_probability"] == s["pass_probability"]
    pairs = doc["detection"]["pairs"]
    assert len(pairs) == sum(s["n_markers"] for s in doc["stations"])
    assert all(0.0 < p["probability"] <= 1.0 for p in pairs)
    assert doc["detection"]["model"]["name"].startswith("default")
    assert doc["provenance"]["detection_model"].startswith("default")
    low, high = ch["sampled"]["wilson_95"]
    assert low <= ch["plan_pass_probability"] <= high or ch["sampled"]["pass_rate"] >= 0.95
    assert "Chance to work" in (out / "report.md").read_text()
    code, stdout, _ = run_cli(capsys, ["plan", "--chance-epsilon", "none", "--json",
                                       "--out", str(tmp_path / "naive")])
    assert code == 0
    naive = json.loads((tmp_path / "naive" / "plan.json").read_text())
    assert naive["chance"]["epsilon"] is None
    assert naive["n_markers"] < doc["n_markers"]
    assert naive["chance"]["plan_pass_probability"] < 0.9 < ch["plan_pass_probability"]


def test_existing_output_is_refused(default_plan, capsys, monkeypatch):
    out, _ = default_plan
    monkeypatch.chdir(out.parent)
    code, _, err = run_cli(capsys, ["plan"])
    assert code == 1 and "already exists" in err and err.count("\n") == 1


def _write(path, text):
    path.write_text(text)
    return path


def _assert_one_line_error(code, err, out_dir, *needles):
    assert code == 1
    assert err.startswith("error: ") and err.count("\n") == 1, err
    for n in needles:
        assert n in err, err
    assert not out_dir.exists()
    assert not list(out_dir.parent.glob(f".{out_dir.name}.partial-*"))


def test_infeasible_requirement_names_each_station(tmp_path, capsys):
    # the default model's 95 % envelope is >= 0.86 mm at the nearest site (1.34 m): 0.5 mm is
    # out of reach everywhere, so every station has no usable site for that reason
    cfg = _write(tmp_path / "c.toml", "requirement_m = 0.0005\n")
    out = tmp_path / "o"
    code, _, err = run_cli(capsys, ["plan", "--config", str(cfg), "--out", str(out)])
    _assert_one_line_error(code, err, out, *(f"S{k}: no usable site" for k in range(1, 8)),
                           "95 % centre error above 0.0005 m")
    cfg.write_text("inclinometer_sigma_deg = 0.5\n")  # 87 mm vertical at 10 m (1 sigma)
    code, _, err = run_cli(capsys, ["plan", "--config", str(cfg), "--out", str(out)])
    _assert_one_line_error(code, err, out, "S1: accuracy unreachable", "S7: accuracy")


def test_too_few_directions_from_a_tight_boundary(tmp_path, capsys):
    # markers only allowed in a strip east of S2 (12, 0): S2 sees them in one or two sectors
    b = _write(tmp_path / "b.geojson", json.dumps(
        {"type": "Polygon", "coordinates": [[[14, -1], [19, -1], [19, 1], [14, 1], [14, -1]]]}))
    out = tmp_path / "o"
    code, _, err = run_cli(capsys, ["plan", "--boundary", str(b), "--out", str(out)])
    _assert_one_line_error(code, err, out, "S2: too few")


@pytest.mark.parametrize("case", ["outside", "empty", "bowtie", "unknown-key", "budget"])
def test_bad_input_gives_one_line_errors_and_no_output(tmp_path, capsys, case):
    out = tmp_path / "o"
    if case == "outside":
        st = _write(tmp_path / "s.csv", "id,x_m,y_m\nA,0,0\nB,100,100\n")
        args, needle = ["--stations", str(st)], "station B at (100.00, 100.00) m lies outside"
    elif case == "empty":
        ex = _write(tmp_path / "x.geojson", json.dumps(
            {"type": "Polygon",
             "coordinates": [[[-40, -40], [40, -40], [40, 40], [-40, 40], [-40, -40]]]}))
        args, needle = ["--exclude", str(ex)], "no candidate marker site"
    elif case == "bowtie":
        ex = _write(tmp_path / "x.geojson", json.dumps(
            {"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]}))
        args, needle = ["--exclude", str(ex)], "invalid polygon"
    elif case == "unknown-key":
        cfg = _write(tmp_path / "c.toml", "sectors = 4\n")
        args, needle = ["--config", str(cfg)], "unknown key(s) sectors"
    else:
        args, needle = ["--budget", "2"], "budget"
    code, _, err = run_cli(capsys, ["plan", *args, "--out", str(out)])
    _assert_one_line_error(code, err, out, needle)


def test_plan_from_a_visibility_table(tmp_path, capsys):
    from visibility.sites import load_site

    site = load_site("default")
    rows = ["station,site,usable,bearing_deg,sigma_m,site_x_m,site_y_m,site_z_m"]
    for sid, (x, y) in zip(site.station_ids, site.station_xy_m, strict=True):
        for k, b in enumerate(range(30, 360, 60)):
            sx, sy = x + 5 * np.cos(np.radians(b)), y + 5 * np.sin(np.radians(b))
            rows.append(f"{sid},{sid}-{k},{int(k != 0)},{b},0.008,{sx:.3f},{sy:.3f},0.1")
    vis = _write(tmp_path / "vis.csv", "\n".join(rows) + "\n")
    out = tmp_path / "o"
    code, stdout, _ = run_cli(capsys, ["plan", "--visibility", str(vis), "--out", str(out),
                                       "--json"])
    assert code == 0
    summary = json.loads(stdout)
    assert summary["n_markers"] == 21 and summary["meets_requirement"]
    assert not any(m.endswith("-0") for m in summary["markers"])  # unusable sites unused


def test_the_error_figure_is_chosen_recorded_and_named(tmp_path, capsys):
    """``--error-figure quantile`` against the default ellipsoid on one visibility table: the
    same layout (the rule decides it), each station's figure 0.70-1.0 x the ellipsoid's,
    recorded in plan.json and named in the report."""
    from visibility.sites import load_site

    site = load_site("default")
    rows = ["station,site,usable,bearing_deg,sigma_m,site_x_m,site_y_m,site_z_m"]
    for sid, (x, y) in zip(site.station_ids, site.station_xy_m, strict=True):
        for k, b in enumerate(range(30, 360, 60)):
            sx, sy = x + 8 * np.cos(np.radians(b)), y + 8 * np.sin(np.radians(b))
            rows.append(f"{sid},{sid}-{k},1,{b},0.01,{sx:.3f},{sy:.3f},0.1")
    vis = _write(tmp_path / "vis.csv", "\n".join(rows) + "\n")
    docs = {}
    for figure in ("quantile", "ellipsoid"):
        out = tmp_path / figure
        code, _, _ = run_cli(capsys, ["plan", "--visibility", str(vis), "--out", str(out),
                                      "--chance-epsilon", "none", "--error-figure", figure])
        assert code == 0
        docs[figure] = json.loads((out / "plan.json").read_text())
        assert docs[figure]["requirement"]["error_figure"] == figure
        assert docs[figure]["provenance"]["config"]["error_figure"] == figure
    assert "95 % figure: 95 % quantile of the worst error" in (
        tmp_path / "quantile" / "report.md").read_text()
    q, e = ({s["id"]: s["predicted_error_m"] for s in docs[f]["stations"]}
            for f in ("quantile", "ellipsoid"))
    assert [m["id"] for m in docs["quantile"]["markers"]] == \
        [m["id"] for m in docs["ellipsoid"]["markers"]]
    ratio = np.array([q[k] / e[k] for k in q])
    assert np.all((ratio >= 0.70) & (ratio < 1.0))


def test_station_ids_select_and_travel_to_reduce(tmp_path, capsys):
    """plan --station-ids plans for those stations only; reduce of that plan keeps them."""
    code, _, err = run_cli(capsys, ["plan", "--station-ids", "S3,S1", "--out",
                                    str(tmp_path / "p")])
    assert code == 0, err
    doc = json.loads((tmp_path / "p" / "plan.json").read_text())
    assert [s["id"] for s in doc["stations"]] == ["S3", "S1"]
    assert doc["provenance"]["inputs"]["station_ids"] == ["S3", "S1"]
    code, _, err = run_cli(capsys, ["reduce", str(tmp_path / "p" / "plan.json"), "--out",
                                    str(tmp_path / "r")])
    assert code == 0, err
    red = json.loads((tmp_path / "r" / "reduce.json").read_text())
    assert all([s["id"] for s in p["stations"]] == ["S3", "S1"] for p in red["curve"])
    code, _, err = run_cli(capsys, ["plan", "--station-ids", "S9", "--out", str(tmp_path / "q")])
    assert code == 1 and "--station-ids: unknown station id(s) S9; valid ids are S1" in err
    assert not (tmp_path / "q").exists()


#: A fast plan of the default site: two stations, a coarse stand map, no cluster.
_SMALL_PLAN = ["plan", "--station-ids", "S1,S2", "--stand-map-cell-m", "4", "--scheduler", "none"]


def test_each_progress_bar_of_a_plan_has_its_own_label(tmp_path, capsys, monkeypatch):
    """The planning visibility and the stand map cast rays under bars of their own names
    (shown on a terminal; bars made with ``disable=True`` never show)."""
    import tqdm

    labels, real = [], tqdm.tqdm

    def recording(*args, **kwargs):
        if kwargs.get("disable") is not True:
            labels.append(kwargs.get("desc"))
        return real(*args, **kwargs)

    monkeypatch.setattr(tqdm, "tqdm", recording)
    code, _, err = run_cli(capsys, [*_SMALL_PLAN, "--out", str(tmp_path / "p")])
    assert code == 0, err
    assert labels == ["visibility", "stand map"]


def test_a_stuck_network_greedy_is_a_warning_and_a_note(tmp_path, capsys, monkeypatch):
    """plan --network with a greedy baseline that gets stuck: its message is one warning line on
    stderr and the greedy's note in plan.json, the --json summary and report.md; the plan
    itself still meets the requirement."""
    import re

    import planner.program.baselines as baselines

    greedy = baselines.greedy_network
    monkeypatch.setattr(baselines, "greedy_network",
                        lambda *a, **k: greedy(*a, **{**k, "max_steps": 0}))
    out = tmp_path / "p"
    code, stdout, err = run_cli(capsys, [*_SMALL_PLAN, "--network", "--json", "--out",
                                         str(out)])
    assert code == 0, err
    doc = json.loads((out / "plan.json").read_text())
    assert doc["meets_requirement"]
    b = doc["baselines"]["greedy"]
    assert not b["meets_requirement"] and b["saved_by_plan"] is None
    found = re.fullmatch(r"greedy \(network\) (got stuck|cannot satisfy) .* after (\d+) "
                         r"markers: stopped after 0 steps", b["note"])
    assert found and int(found[2]) == b["n_markers"]
    assert [line for line in err.splitlines() if line.startswith("warning:")] == \
        [f"warning: greedy baseline falls short: {b['note']}"]
    assert json.loads(stdout)["baselines"]["greedy"]["note"] == b["note"]
    assert f"\n- greedy: {b['note']}\n" in (out / "report.md").read_text()
