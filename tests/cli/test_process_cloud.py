"""``markerplan process --cloud``: LAS and PLY files per station and frame, read back."""

import dataclasses
import hashlib
import json
import shutil

import laspy
import numpy as np
import plyfile
import pytest

from pipeline.scans.rig import MountingOffsets, station_to_site_matrix
from pipeline.scans.scan_format import read_scan, read_truth, write_truth
from pipeline.surveys.point_cloud_io import MARKER_CLASS
from pipeline.tables.marker_table import read_marker_table
from tests.cli.bad_input import STATION_MARKERS, write_synthetic_station
from tests.cli.invoke import run_cli

HEADING, POSITION = 0.7, np.array([512345.6, 4201234.5, 1500.0])
UTM_33N = ('PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",'
           '6378137,298.257223563]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],'
           'PROJECTION["Transverse_Mercator"],PARAMETER["central_meridian",15],'
           'PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],'
           'UNIT["metre",1],AUTHORITY["EPSG","32633"]]')
CLOUDS = ["S1.site.las", "S1.site.ply", "S1.station.las", "S1.station.ply"]


@pytest.fixture(scope="module")
def scans(tmp_path_factory):
    """The synthetic station, its truth placed at a UTM-like pose, and a site.json with a CRS."""
    d = tmp_path_factory.mktemp("scans")
    write_synthetic_station(d, n_frames=120, azimuth_step_deg=0.8)
    rot = station_to_site_matrix(HEADING)
    write_truth(d / "station_S1.truth.json", {
        "station_id": "S1", "mounting_offsets": MountingOffsets().to_dict(),
        "station_pose": {"position_m": POSITION.tolist(), "heading_rad": HEADING},
        "marker_radius_m": 0.1,
        "markers": [{"id": f"M{k}", "centre_station_m": c.tolist(),
                     "centre_site_m": (rot @ c + POSITION).tolist()}
                    for k, c in enumerate(STATION_MARKERS)]})
    (d / "site.json").write_text(json.dumps({"site": "t", "dem": {"crs": UTM_33N}}))
    return d


def _digests(folder, names):
    return [hashlib.sha256((folder / n).read_bytes()).hexdigest() for n in names]


def _marker_points_on_true_centres(las, truth, tol_m):
    """Every marker point of the site LAS lies within radius +- tol of a true site centre."""
    xyz = np.c_[las.x, las.y, las.z][las.classification == MARKER_CLASS]
    true = np.array([m["centre_site_m"] for m in truth["markers"]])
    dist = np.linalg.norm(xyz[:, None] - true, axis=2).min(axis=1)
    assert xyz.size and np.all(np.abs(dist - truth["marker_radius_m"]) < tol_m), (
        dist.min(), dist.max())


def test_process_writes_clouds_in_both_frames(scans, tmp_path, capsys):
    digests = []
    for run in ("a", "b"):
        code, stdout, err = run_cli(capsys, ["process", str(scans), "--cloud", "las,ply",
                                             "--out", str(tmp_path / run), "--json"])
        assert code == 0, err
        digests.append(_digests(tmp_path / run, CLOUDS))
    assert digests[0] == digests[1]
    out = tmp_path / "a"
    assert json.loads(stdout)["files"][4:] == CLOUDS
    n_points = read_scan(scans / "station_S1.scan.npz").n_points
    rows = [r for r in read_marker_table(out / "markers.csv") if r["accepted"] == "true"]
    truth = read_truth(scans / "station_S1.truth.json")
    site = laspy.read(out / "S1.site.las")
    station = laspy.read(out / "S1.station.las")
    for las in (site, station):
        assert las.header.point_count == n_points
        # marker points: exactly the points the chain's fits of the accepted markers used
        assert np.sum(las.classification == MARKER_CLASS) == sum(int(r["n_points"]) for r in rows)
    assert [v.string for v in site.header.vlrs.get("WktCoordinateSystemVlr")] == [UTM_33N]
    assert not station.header.vlrs.get("WktCoordinateSystemVlr")
    # station -> site: the truth's pose, to the LAS resolution
    expected = np.c_[station.x, station.y, station.z] @ station_to_site_matrix(HEADING).T + POSITION
    assert np.max(np.abs(np.c_[site.x, site.y, site.z] - expected)) < 2e-4
    _marker_points_on_true_centres(site, truth, 0.04)
    ply = plyfile.PlyData.read(str(out / "S1.site.ply"))
    assert len(ply["vertex"].data) == n_points
    assert np.array_equal(ply["vertex"]["classification"], site.classification)


def test_without_a_pose_only_the_station_frame(scans, tmp_path, capsys):
    ref = tmp_path / "ts.csv"
    ref.write_text("id,x_m,y_m,z_m\n" + "".join(f"T{k},{x},{y},{z}\n"
                                                 for k, (x, y, z) in enumerate(STATION_MARKERS)))
    out = tmp_path / "o"
    code, _, err = run_cli(capsys, ["process", str(scans / "station_S1.scan.npz"), "--reference",
                                    str(ref), "--no-calibrate", "--cloud", "ply", "--out",
                                    str(out)])
    assert code == 0, err
    assert sorted(p.name for p in out.glob("S1.*")) == ["S1.station.ply"]


def test_no_cloud_unless_asked(scans, tmp_path, capsys):
    code, _, err = run_cli(capsys, ["process", str(scans), "--no-calibrate", "--out",
                                    str(tmp_path / "o")])
    assert code == 0, err
    assert not list((tmp_path / "o").glob("S1.*"))


@pytest.mark.parametrize("formats, message", [("las,xyz", "unknown point-cloud format(s) xyz"),
                                              (",", "comma-separated")])
def test_bad_format_refused(scans, tmp_path, capsys, formats, message):
    code, _, err = run_cli(capsys, ["process", str(scans), "--cloud", formats, "--out",
                                    str(tmp_path / "o")])
    assert code != 0 and message in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("site, message", [("{", "not valid JSON"), ('{"dem": 5}', "'dem'")])
def test_bad_site_json_refused(scans, tmp_path, capsys, site, message):
    folder = tmp_path / "scans"
    folder.mkdir()
    shutil.copy(scans / "station_S1.scan.npz", folder)
    (folder / "site.json").write_text(site)
    code, _, err = run_cli(capsys, ["process", str(folder), "--cloud", "las", "--out",
                                    str(tmp_path / "o")])
    assert code == 1 and "site.json" in err and message in err and "Traceback" not in err


@pytest.mark.slow
def test_simulated_station_clouds_sit_on_the_simulators_markers(tmp_path, capsys):
    """The simulator on the default terrain given a UTM CRS; station S2 (heading 90 deg)."""
    from visibility.dem import write_dem
    from visibility.sites import load_site

    dem = tmp_path / "dem.npz"
    write_dem(dem, dataclasses.replace(load_site("default").dem, crs=UTM_33N))
    sim = tmp_path / "sim"
    code, _, err = run_cli(capsys, ["simulate", "--dem", str(dem), "--station-ids", "S2",
                                    "--frames", "50", "--out", str(sim)])
    assert code == 0, err
    code, _, err = run_cli(capsys, ["process", str(sim), "--cloud", "las", "--out",
                                    str(tmp_path / "o")])
    assert code == 0, err
    site = laspy.read(tmp_path / "o" / "S2.site.las")
    wkt = site.header.vlrs.get("WktCoordinateSystemVlr")[0].string
    assert "UTM zone 33N" in wkt
    truth = read_truth(sim / "station_S2.truth.json")
    assert site.header.point_count == read_scan(sim / "station_S2.scan.npz").n_points
    assert np.sum(site.classification == MARKER_CLASS) >= 3 * 20
    _marker_points_on_true_centres(site, truth, 0.04)
