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


def test_nan_refused_with_the_fix_named(tmp_path):
    h = _plane().heights_m.copy()
    h[3, 4] = np.nan
    with pytest.raises(DataError, match="fill='nearest'"):
        DEM(h, (0, 0), 1.0)
    np.savez(tmp_path / "d.npz", heights_m=h, origin_m=np.array([0.0, 0.0]),
             cell_size_m=np.array(1.0), crs=np.array(""))
    with pytest.raises(DataError, match="1 NaN"):
        read_dem(tmp_path / "d.npz")
    filled = read_dem(tmp_path / "d.npz", fill="nearest")
    assert np.isfinite(filled.heights_m).all()
    assert filled.heights_m[3, 4] in {h[2, 4], h[4, 4], h[3, 3], h[3, 5]}


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


def test_geotiff_nodata_refused(tmp_path):
    import rasterio
    from rasterio.transform import Affine

    h = np.ones((4, 5), dtype="float32")
    h[0, 0] = -9999
    with rasterio.open(tmp_path / "n.tif", "w", driver="GTiff", height=4, width=5, count=1,
                       dtype="float32", nodata=-9999,
                       transform=Affine(1.0, 0.0, 0.0, 0.0, -1.0, 4.0)) as dst:
        dst.write(h, 1)
    with pytest.raises(DataError, match="nodata"):
        read_dem(tmp_path / "n.tif")
    assert read_dem(tmp_path / "n.tif", fill="nearest").heights_m.min() == 1.0


def test_npz_round_trip_and_bad_files(tmp_path):
    dem = _plane()
    write_dem(tmp_path / "d.npz", dem)
    back = read_dem(tmp_path / "d.npz")
    np.testing.assert_array_equal(back.heights_m, dem.heights_m)
    assert back.crs is None
    with pytest.raises(InputFileError, match="does not exist"):
        read_dem(tmp_path / "missing.tif")
    (tmp_path / "x.csv").write_text("1,2\n")
    with pytest.raises(InputFileError, match="suffix"):
        read_dem(tmp_path / "x.csv")
