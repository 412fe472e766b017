"""The AOI read onto the DEM and its grid: refusals, alignment, normals."""

import json

import numpy as np
import pytest
import shapely

from markerplan.errors import ConfigError, DataError, InputFileError
from planner.coverage.aoi import read_aoi
from planner.coverage.grid import MAX_AOI_CELLS, aoi_grid
from planner.outputs.stand_map import stand_grid
from visibility.dem import DEM


def write_polygons(path, *rings):
    feats = [{"type": "Feature", "properties": {},
              "geometry": {"type": "Polygon", "coordinates": [r]}} for r in rings]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    return path


def square(x0, y0, x1, y1):
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]


DEM20 = DEM(np.zeros((41, 41)), (0.0, 0.0), 0.5)  # extent [0, 20] x [0, 20] m


def test_read_aoi_joins_polygons(tmp_path):
    p = write_polygons(tmp_path / "aoi.geojson", square(1, 1, 5, 5), square(10, 10, 12, 13))
    aoi = read_aoi(p, DEM20)
    assert aoi.geom_type == "MultiPolygon" and aoi.area == pytest.approx(22.0)


def test_aoi_off_dem_names_area_and_extent(tmp_path):
    p = write_polygons(tmp_path / "aoi.geojson", square(15, 5, 25, 10))
    with pytest.raises(InputFileError) as e:
        read_aoi(p, DEM20)
    msg = str(e.value)
    assert "`aoi_path`" in msg and "\n" not in msg
    # the DEM's cells reach 0.25 m beyond their centres' rectangle [0, 20] m
    assert "23.8 m^2 of the AOI (48%) lies off the DEM" in msg
    assert "extent [-0.2, 20.2] x [-0.2, 20.2] m" in msg and "draw it inside" in msg


@pytest.mark.parametrize("cell_m", [0.5, 1.0, 1.5])
def test_aoi_on_the_dem_edges_is_accepted(tmp_path, cell_m):
    """An AOI drawn on the DEM's outer edges (a GeoTIFF's bounds) is on the DEM, and so are
    its grid's cell centres."""
    aoi = read_aoi(write_polygons(tmp_path / "aoi.geojson", square(-0.25, -0.25, 20.25, 20.25)),
                   DEM20)
    g = aoi_grid(DEM20, aoi, cell_m)
    assert DEM20.contains(g.centre_xy_m).all() and len(g) * g.cell_area_m2 > 390


def test_aoi_on_nodata_names_share(tmp_path):
    valid = np.ones((41, 41), bool)
    valid[:, 30:] = False  # x >= 15 m
    dem = DEM(np.zeros((41, 41)), (0.0, 0.0), 0.5, valid=valid)
    p = write_polygons(tmp_path / "aoi.geojson", square(10.1, 5.1, 19.9, 9.9))
    with pytest.raises(InputFileError) as e:
        read_aoi(p, dem)
    msg = str(e.value)
    # DEM cells within 0.75 cell (0.375 m) of the AOI: x 10..20 (21 columns) x y 5..10
    # (11 rows); on nodata x >= 15 (11 columns)
    assert "121 of the 231 DEM cells under the AOI (52%) lie on DEM nodata" in msg
    assert "`aoi_path`" in msg and "draw the AOI on measured terrain" in msg
    assert read_aoi(write_polygons(tmp_path / "ok.geojson", square(1, 1, 14, 9)), dem).area > 0


@pytest.mark.parametrize("cell_m", [0.5, 1.0, 1.5])
def test_an_aoi_read_aoi_accepts_gives_a_grid(tmp_path, cell_m):
    """Whatever AOI passes the nodata check, its grid's cell centres stand on valid cells
    (AOIs ending 0..0.5 m short of a nodata strip at x >= 15 m)."""
    valid = np.ones((41, 41), bool)
    valid[:, 30:] = False
    dem = DEM(np.zeros((41, 41)), (0.0, 0.0), 0.5, valid=valid)
    accepted = 0
    for k, x1 in enumerate(np.linspace(14.3, 15.0, 15)):
        p = write_polygons(tmp_path / f"aoi{k}.geojson", square(3.0, 3.0, x1, 9.0))
        try:
            aoi = read_aoi(p, dem)
        except InputFileError:
            continue
        accepted += 1
        assert len(aoi_grid(dem, aoi, cell_m)) > 0
    assert 3 < accepted < 15


def test_malformed_aoi_names_setting(tmp_path):
    p = tmp_path / "aoi.geojson"
    p.write_text('{"type": "Point", "coordinates": [1, 2]}')
    with pytest.raises(InputFileError, match="`aoi_path`"):
        read_aoi(p, DEM20)


@pytest.mark.parametrize("cell_m, k", [(0.5, 1), (1.0, 2), (1.6, 3)])
def test_grid_aligned_with_stand_grid(cell_m, k):
    """The AOI grid is a window of the DEM-aligned stand-map grid of k x k DEM cells."""
    aoi = shapely.Polygon([(2.2, 3.1), (17.0, 4.0), (9.0, 16.3)])
    g = aoi_grid(DEM20, aoi, cell_m)
    xy, transform = stand_grid(DEM20, k)
    assert g.cell_m == k * 0.5 and g.cell_area_m2 == (k * 0.5) ** 2
    # the window's corner is a corner of the stand grid's cells
    col = (g.transform[2] - transform[2]) / g.cell_m
    row = (transform[5] - g.transform[5]) / g.cell_m
    assert col == round(col) and row == round(row)
    window = xy[int(row):int(row) + g.shape[0], int(col):int(col) + g.shape[1]].reshape(-1, 2)
    np.testing.assert_allclose(g.centre_xy_m, window[g.cell_index])
    inside = shapely.contains_xy(aoi, window[:, 0], window[:, 1])
    np.testing.assert_array_equal(np.flatnonzero(inside), g.cell_index)
    assert g.centre_xy_m[0, 1] >= g.centre_xy_m[-1, 1]  # north first


def test_grid_normals_and_heights_on_a_tilted_plane():
    """z = 0.3 x - 0.2 y: every cell's normal is (-0.3, 0.2, 1) normalised, its ground the
    plane's height (cells reaching past the DEM's edge included)."""
    x, y = DEM20.grid_xy()
    gx, gy = np.meshgrid(x, y)
    dem = DEM(0.3 * gx - 0.2 * gy, (0.0, 0.0), 0.5)
    g = aoi_grid(dem, shapely.box(0, 0, 20, 20), 1.5)
    n = np.array([-0.3, 0.2, 1.0]) / np.linalg.norm([-0.3, 0.2, 1.0])
    np.testing.assert_allclose(g.normal, np.broadcast_to(n, g.normal.shape), atol=1e-12)
    np.testing.assert_allclose(g.ground_z_m, 0.3 * g.centre_xy_m[:, 0]
                               - 0.2 * g.centre_xy_m[:, 1], atol=1e-12)


def test_grid_normal_of_a_bump_faces_away():
    """A Gaussian hill at (10, 10): cells east of it lean east (normal x > 0)."""
    x, y = DEM20.grid_xy()
    gx, gy = np.meshgrid(x, y)
    dem = DEM(np.exp(-((gx - 10) ** 2 + (gy - 10) ** 2) / 8.0), (0.0, 0.0), 0.5)
    g = aoi_grid(dem, shapely.box(11, 9.5, 13, 10.5), 1.0)
    assert np.all(g.normal[:, 0] > 0.1) and np.all(np.abs(g.normal[:, 1]) < 0.05)


def test_grid_guards():
    with pytest.raises(ConfigError, match="`cell_m`"):
        aoi_grid(DEM20, shapely.box(1, 1, 5, 5), -1.0)
    big = DEM(np.zeros((3000, 3000)), (0.0, 0.0), 0.5)
    with pytest.raises(ConfigError, match=f"more than the {MAX_AOI_CELLS} accepted; raise"):
        aoi_grid(big, shapely.box(1, 1, 1400, 1400), 0.5)
    with pytest.raises(DataError, match="no 2 m cell centre"):
        aoi_grid(DEM20, shapely.box(1.1, 1.1, 1.2, 1.2), 2.0)
