"""Point clouds out (:mod:`pipeline.surveys.point_cloud_io`): LAS 1.4 and PLY read back with laspy
and plyfile, classes checked against the chain and the scene's truth."""

import hashlib
import json

import laspy
import numpy as np
import plyfile
import pytest

from markerplan.errors import ConfigError, DataError
from pipeline.chain.ground import remove_ground
from pipeline.chain.process import process_station
from pipeline.chain.stages import build_config
from pipeline.scans.rig import station_to_site_matrix
from pipeline.surveys.point_cloud_io import (
    GROUND_CLASS,
    LAS_CREATION_DATE,
    LAS_SCALE_M,
    MARKER_CLASS,
    UNCLASSIFIED_CLASS,
    ClassifiedCloud,
    StationPose,
    classify_cloud,
    write_las,
    write_ply,
    write_station_clouds,
)
from tests.pipeline.test_synthesis import synthetic_scan

MARKERS = np.array([[3.0, 1.0, -0.9], [-2.5, 2.0, -0.9], [0.5, -4.0, -0.9], [-3.0, -2.5, -0.9]])
#: A 0.6 m rock: above the ground, too big for a marker.
BOX = (np.array([4.0, -3.0, -1.0]), np.array([4.6, -2.4, -0.4]))
#: Far from the origin, as UTM coordinates are: the LAS offsets must absorb them.
POSE = StationPose(station_to_site_matrix(0.7, 0.01, -0.02),
                   np.array([512345.6, 4201234.5, 1500.0]))
UTM_33N = ('PROJCS["WGS 84 / UTM zone 33N",GEOGCS["WGS 84",DATUM["WGS_1984",SPHEROID["WGS 84",'
           '6378137,298.257223563]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433]],'
           'PROJECTION["Transverse_Mercator"],PARAMETER["central_meridian",15],'
           'PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],'
           'UNIT["metre",1],AUTHORITY["EPSG","32633"]]')


@pytest.fixture(scope="module")
def station():
    """A synthetic station (4 markers of 0.1 m, one rock, ground at z = -1) and its chain."""
    scan = synthetic_scan(n_frames=120, azimuth_step_deg=0.8, noise_m=0.005, max_range_m=8.0,
                          spheres=[(c, 0.1) for c in MARKERS], boxes=[BOX], seed=3)
    cfg = build_config()
    result = process_station(scan, cfg)
    return scan, result, classify_cloud(scan, result, cfg.ground)


def test_marker_points_are_the_accepted_fits_inliers(station):
    _, result, cloud = station
    accepted = [c for c in result.candidates if c.accepted]
    assert len(accepted) == 4
    marker = cloud.classification == MARKER_CLASS
    assert marker.sum() == sum(c.fit.n_used for c in accepted)
    assert np.array_equal(marker, cloud.marker_index > 0)
    for m in cloud.markers:
        pts = cloud.xyz_m[cloud.marker_index == m["marker_index"]]
        true = MARKERS[np.argmin(np.linalg.norm(MARKERS - m["centre_m"], axis=1))]
        dist = np.linalg.norm(pts - true, axis=1)
        assert np.all(np.abs(dist - 0.1) < 0.03), (m, dist.min(), dist.max())
    # nothing else near a marker's surface is called a marker point... and nothing far from one
    near = np.min(np.linalg.norm(cloud.xyz_m[:, None] - MARKERS, axis=2), axis=1) < 0.15
    assert np.all(near[marker])


def test_ground_and_rock_classes(station):
    _, _, cloud = station
    xyz, cls = cloud.xyz_m, cloud.classification
    lo, hi = BOX
    on_rock = np.all((xyz > lo - 0.03) & (xyz < hi + 0.03), axis=1) & (xyz[:, 2] > -0.85)
    # a ground cell that only the rock's top reaches is ground to the chain (its lowest return)
    assert on_rock.sum() > 100 and np.mean(cls[on_rock] == UNCLASSIFIED_CLASS) > 0.5
    assert not np.any(cls[on_rock] == MARKER_CLASS)
    # the classes are the chain's ground stage, marker points aside
    ground = ~remove_ground(xyz, build_config().ground.cell_m, build_config().ground.min_height_m)
    assert np.array_equal(cls[cls != MARKER_CLASS] == GROUND_CLASS, ground[cls != MARKER_CLASS])
    far = np.min(np.linalg.norm(xyz[:, None, :2] - [*MARKERS[:, :2], (lo[:2] + hi[:2]) / 2],
                                axis=2), axis=1) > 0.8
    flat = far & (np.abs(xyz[:, 2] + 1.0) < 0.02)
    assert flat.sum() > 0.9 * far.sum() and np.all(cls[flat] == GROUND_CLASS)
    assert set(np.unique(cls)) == {UNCLASSIFIED_CLASS, GROUND_CLASS, MARKER_CLASS}


def test_las_round_trip_station_and_site_frames(station, tmp_path):
    _, _, cloud = station
    for pose, crs, expected in ((None, None, cloud.xyz_m),
                                (POSE, UTM_33N, POSE.to_site(cloud.xyz_m))):
        path = write_las(tmp_path / "c.las", cloud, pose, crs)
        las = laspy.read(path)
        h = las.header
        assert (str(h.version), h.point_format.id, h.point_count) == ("1.4", 6, len(expected))
        assert np.allclose(h.scales, LAS_SCALE_M) and h.creation_date == LAS_CREATION_DATE
        xyz = np.c_[las.x, las.y, las.z]
        assert np.max(np.abs(xyz - expected)) <= LAS_SCALE_M / 2 + 1e-9
        assert np.array_equal(las.classification, cloud.classification)
        for name in ("frame_index", "laser_id", "marker_index"):
            assert np.array_equal(las[name], getattr(cloud, name)), name
        meta = json.loads(h.vlrs.get_by_id("markerplan", [1])[0].record_data)
        assert meta["frame"] == ("station" if pose is None else "site")
        assert [m["marker_index"] for m in meta["markers"]] == [
            m["marker_index"] for m in cloud.markers]
        wkt = h.vlrs.get("WktCoordinateSystemVlr")
        assert h.global_encoding.wkt and [v.string for v in wkt] == ([crs] if crs else [])


def test_site_frame_markers_sit_on_their_true_site_centres(station, tmp_path):
    _, _, cloud = station
    las = laspy.read(write_las(tmp_path / "s.las", cloud, POSE))
    xyz = np.c_[las.x, las.y, las.z]
    true_site = POSE.to_site(MARKERS)
    for k in np.unique(las.marker_index[las.marker_index > 0]):
        dist = np.linalg.norm(xyz[las.marker_index == k][:, None] - true_site, axis=2)
        assert np.all(np.abs(dist.min(axis=1) - 0.1) < 0.03)
    assert np.allclose(las.header.offsets % 1000.0, 0.0)


def test_ply_round_trip(station, tmp_path):
    _, _, cloud = station
    path = write_ply(tmp_path / "c.ply", cloud, POSE, UTM_33N)
    ply = plyfile.PlyData.read(str(path))
    v = ply["vertex"].data
    assert ply.text is False and ply.byte_order == "<" and len(v) == len(cloud.xyz_m)
    assert np.array_equal(np.c_[v["x"], v["y"], v["z"]], POSE.to_site(cloud.xyz_m))
    for name in ("classification", "frame_index", "laser_id", "marker_index"):
        assert np.array_equal(v[name], getattr(cloud, name)), name
    assert "crs " + UTM_33N in ply.comments
    assert sum(c.startswith("marker_index ") for c in ply.comments) == len(cloud.markers)


def test_files_are_named_per_frame_and_byte_identical_across_runs(station, tmp_path):
    _, _, cloud = station
    digests = []
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        names = write_station_clouds(tmp_path / run, cloud, ("ply", "las"), POSE, UTM_33N)
        digests.append([hashlib.sha256((tmp_path / run / n).read_bytes()).hexdigest()
                        for n in names])
    assert names == ["S1.site.las", "S1.site.ply", "S1.station.las", "S1.station.ply"]
    assert digests[0] == digests[1]
    assert write_station_clouds(tmp_path / "a", cloud, ("las",)) == ["S1.station.las"]


def test_site_frame_is_computed_once_for_every_format(station, tmp_path, monkeypatch):
    """write_station_clouds transforms the cloud to the site frame once (not once per format)
    and writes the bytes write_las and write_ply write on their own."""
    _, _, cloud = station
    for fmt, write in (("las", write_las), ("ply", write_ply)):
        for frame, pose, crs in (("station", None, None), ("site", POSE, UTM_33N)):
            write(tmp_path / f"S1.{frame}.{fmt}", cloud, pose, crs)
    sizes = []
    to_site = StationPose.to_site
    monkeypatch.setattr(StationPose, "to_site",
                        lambda self, xyz: sizes.append(len(xyz)) or to_site(self, xyz))
    (tmp_path / "both").mkdir()
    names = write_station_clouds(tmp_path / "both", cloud, ("ply", "las"), POSE, UTM_33N)
    assert sorted(sizes) == sorted([len(cloud.markers), len(cloud.xyz_m)])  # centres, points
    for name in names:
        assert (tmp_path / "both" / name).read_bytes() == (tmp_path / name).read_bytes(), name


def test_bad_requests_are_refused(station, tmp_path):
    _, _, cloud = station
    with pytest.raises(ConfigError, match="unknown point-cloud format.*xyz.*las, ply"):
        write_station_clouds(tmp_path, cloud, ("las", "xyz"))
    wide = ClassifiedCloud("W", np.array([[0.0, 0, 0], [500e3, 0, 0]]), np.zeros(2, np.uint32),
                           np.zeros(2, np.uint8), np.ones(2, np.uint8), np.zeros(2, np.uint16), [])
    with pytest.raises(DataError, match="spans more than LAS holds"):
        write_las(tmp_path / "w.las", wide)
    with pytest.raises(DataError, match="no station_pose position_m"):
        StationPose.from_truth({"station_id": "S9", "station_pose": {"heading_rad": 0.0}})
