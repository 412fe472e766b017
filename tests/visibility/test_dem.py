"""DEM type, bilinear heights, NaN policy and file round-trips."""

import numpy as np
import pytest

from markerplan.errors import DataError, InputFileError
from visibility.dem import DEM, read_dem, write_dem


def _plane(nx=21, ny=11, cell=0.5):
    x = np.arange(nx) * cell + 10.0
    y = np.arange(ny) * cell - 3.0
    return DEM(0.1 * x[None, :] - 0.2 * y[:, None] + 5.0, (10.0, -3.0), cell)


def test_bilinear_height_is_exact_on_a_plane():
    dem = _plane()
    rng = np.random.default_rng(0)
    xy = np.column_stack([rng.uniform(10, 20, 100), rng.uniform(-3, 2, 100)])
    np.testing.assert_allclose(dem.height_at(xy), 0.1 * xy[:, 0] - 0.2 * xy[:, 1] + 5.0)
    assert dem.extent() == (10.0, 20.0, -3.0, 2.0)
    np.testing.assert_allclose(dem.slope_rad(), np.arctan(np.hypot(0.1, 0.2)))


def test_outside_points_refused():
    dem = _plane()
    assert not dem.contains(np.array([[9.0, 0.0]]))[0]
    with pytest.raises(DataError, match="outside the DEM"):
        dem.height_at(np.array([[9.0, 0.0]]))


def test_nan_array_refused_but_nan_file_cells_are_a_mask(tmp_path):
    h = _plane().heights_m.copy()
    h[3, 4] = np.nan
    with pytest.raises(DataError, match="1 NaN/nodata cells of 231; fill them and mark them"):
        DEM(h, (0, 0), 1.0)
    np.savez(tmp_path / "d.npz", heights_m=h, origin_m=np.array([0.0, 0.0]),
             cell_size_m=np.array(1.0), crs=np.array(""))
    masked = read_dem(tmp_path / "d.npz")
    assert np.isfinite(masked.heights_m).all()
    assert masked.heights_m[3, 4] in {h[2, 4], h[4, 4], h[3, 3], h[3, 5]}
    assert np.flatnonzero(~masked.valid_mask()).tolist() == [3 * 21 + 4]
    np.testing.assert_array_equal(masked.heights_m[masked.valid], h[np.isfinite(h)])
    # the point at the cell and its stencil neighbours are off data, one cell away is on it
    assert masked.valid_at(np.array([[4.0, 3.0], [3.5, 2.5], [5.5, 3.0], [2.0, 3.0]])
                           ).tolist() == [False, False, True, True]
    filled = read_dem(tmp_path / "d.npz", fill="nearest")  # filled cells taken as terrain
    assert filled.valid is None
    np.testing.assert_array_equal(filled.heights_m, masked.heights_m)


def test_station_on_nodata_refused_naming_it():
    valid = np.ones((11, 21), bool)
    valid[5, 10] = False
    dem = DEM(np.zeros((11, 21)), (0.0, 0.0), 1.0, valid=valid)
    dem.require_inside(np.array([[1.0, 1.0], [12.0, 5.0]]), ["A", "B"], "station", "fix")
    with pytest.raises(DataError, match=r"^station B at \(9.50, 5.00\) m stands on DEM nodata"):
        dem.require_inside(np.array([[1.0, 1.0], [9.5, 5.0]]), ["A", "B"], "station", "fix")
    with pytest.raises(DataError, match="outside the DEM .* fix$"):
        dem.require_inside(np.array([[30.0, 1.0]]), ["A"], "station", "fix")


# a terrestrial UTM zone and the lunar south-pole stereographic projection of LOLA DEMs
@pytest.mark.parametrize("crs", ["EPSG:32633", "ESRI:103878"])
def test_geotiff_round_trip_keeps_crs_and_geometry(tmp_path, crs):
    from rasterio.crs import CRS

    dem = _plane()
    dem.crs = CRS.from_user_input(crs).to_wkt()
    write_dem(tmp_path / "d.tif", dem)
    back = read_dem(tmp_path / "d.tif")
    got, want = CRS.from_wkt(back.crs), CRS.from_user_input(crs)
    # GeoTIFF keys may re-express the same projection (k=1 <-> lat_ts=-90): compare its parts
    for key in ("proj", "zone", "lat_0", "lon_0", "R", "ellps", "datum", "units"):
        assert got.to_dict().get(key) == want.to_dict().get(key), key
    assert want.to_wkt().split('"')[1] == got.to_wkt().split('"')[1]  # the CRS name
    assert back.origin_m == pytest.approx(dem.origin_m)
    assert back.cell_size_m == dem.cell_size_m
    np.testing.assert_array_equal(back.heights_m, dem.heights_m)


def _nodata_tif(path, h, nodata):
    import rasterio
    from rasterio.transform import Affine

    with rasterio.open(path, "w", driver="GTiff", height=h.shape[0], width=h.shape[1], count=1,
                       dtype=h.dtype, nodata=nodata,
                       transform=Affine(1.0, 0.0, 0.0, 0.0, -1.0, h.shape[0])) as dst:
        dst.write(h, 1)


def test_geotiff_nodata_is_a_mask_and_round_trips(tmp_path):
    h = np.arange(20, dtype="float32").reshape(4, 5)
    h[0, 0] = h[3, 4] = -9999  # file rows run north to south: DEM rows 3 and 0
    _nodata_tif(tmp_path / "n.tif", h, -9999)
    dem = read_dem(tmp_path / "n.tif")
    assert np.argwhere(~dem.valid).tolist() == [[0, 4], [3, 0]]
    # filled from one of the two nearest valid cells (file [0, 1], [1, 0]; [3, 3], [2, 4])
    assert dem.heights_m[3, 0] in (1.0, 5.0) and dem.heights_m[0, 4] in (18.0, 14.0)
    np.testing.assert_array_equal(dem.heights_m[dem.valid], h[::-1][h[::-1] != -9999])
    for suffix in (".tif", ".npz"):
        back = read_dem(write_dem(tmp_path / f"back{suffix}", dem))
        np.testing.assert_array_equal(back.valid, dem.valid)
        np.testing.assert_array_equal(back.heights_m, dem.heights_m)
    assert read_dem(tmp_path / "n.tif", fill="nearest").valid is None
    import rasterio

    with rasterio.open(tmp_path / "back.tif") as src:
        assert np.isnan(src.nodata) and np.isnan(src.read(1)[0, 0])


def test_all_nodata_refused(tmp_path):
    _nodata_tif(tmp_path / "n.tif", np.full((3, 4), -9999, dtype="int16"), -9999)
    with pytest.raises(DataError, match="every cell is nodata.*check the nodata value"):
        read_dem(tmp_path / "n.tif")


def test_npz_round_trip_and_bad_files(tmp_path):
    dem = _plane()
    write_dem(tmp_path / "d.npz", dem)
    back = read_dem(tmp_path / "d.npz")
    np.testing.assert_array_equal(back.heights_m, dem.heights_m)
    assert back.crs is None
    with pytest.raises(InputFileError, match="does not exist"):
        read_dem(tmp_path / "missing.tif")
    (tmp_path / "x.csv").write_text("1,2\n")
    with pytest.raises(InputFileError, match="not a raster GDAL can read"):
        read_dem(tmp_path / "x.csv")


def test_crop_keeps_the_grid_and_covers_the_rectangle():
    rng = np.random.default_rng(3)
    valid = np.ones((40, 50), bool)
    valid[:5] = False
    dem = DEM(rng.normal(size=(40, 50)), (100.0, -20.0), 0.25, crs=None, valid=valid)
    tile = dem.crop(103.1, 106.9, -18.6, -15.05)
    x, y = tile.grid_xy()
    assert x[0] <= 103.1 and x[-1] >= 106.9 and y[0] <= -18.6 and y[-1] >= -15.05
    assert x[2] > 103.1 and x[-2] < 106.9  # at most two cells of margin below, one above
    i0 = round((x[0] - 100.0) / 0.25)
    j0 = round((y[0] + 20.0) / 0.25)
    assert i0 % 2 == 0 and j0 % 2 == 0  # the whole mesh's diagonals (checkerboard from [0, 0])
    ny, nx = tile.shape
    np.testing.assert_array_equal(tile.heights_m, dem.heights_m[j0:j0 + ny, i0:i0 + nx])
    np.testing.assert_array_equal(tile.valid_mask(), valid[j0:j0 + ny, i0:i0 + nx])
    assert not dem.crop(101.0, 103.0, -20.0, -18.0).valid_mask().all()  # nodata rows kept
    pts = np.column_stack([rng.uniform(103.1, 106.9, 50), rng.uniform(-18.6, -15.05, 50)])
    np.testing.assert_array_equal(tile.height_at(pts), dem.height_at(pts))
    edge = dem.crop(-1e3, 1e3, -1e3, 1e3)  # clipped to the grid
    assert edge.shape == dem.shape
    with pytest.raises(DataError, match="misses the DEM"):
        dem.crop(0.0, 1.0, 0.0, 1.0)
