"""Reading DEMs in any raster format GDAL reads, in Earth and lunar CRSs, reprojected on
request, and by window (:func:`visibility.dem.read_dem`)."""

from __future__ import annotations

import numpy as np
import pytest

from markerplan.errors import ConfigError, DataError, InputFileError
from visibility.dem import DEM, WINDOW_PAD_CELLS, read_dem, to_dem_xy, write_dem

UTM = "EPSG:32633"


def _crs(code: str) -> str:
    from rasterio.crs import CRS

    return CRS.from_user_input(code).to_wkt()


def _dem(crs: str | None = UTM) -> DEM:
    """8 x 6 cells of 1 m, heights exact in decimal text and float32, one nodata cell."""
    h = np.add.outer(0.25 * np.arange(6), 0.5 * np.arange(8)) + 100.0
    valid = np.ones(h.shape, bool)
    valid[2, 3] = False
    return DEM(h, (500000.5, 4000000.5), 1.0, None if crs is None else _crs(crs), valid=valid)


def _geotiff(path, heights: np.ndarray, transform, crs, nodata=None, dtype="float32", **kw):
    """Write ``heights`` (file row order: north first) as a one-band GeoTIFF."""
    import rasterio

    with rasterio.open(path, "w", driver="GTiff", height=heights.shape[0],
                       width=heights.shape[1], count=1, dtype=dtype, crs=crs,
                       transform=transform, nodata=nodata, **kw) as dst:
        dst.write(heights.astype(dtype), 1)
    return path


def _same(a: DEM, b: DEM) -> None:
    from rasterio.crs import CRS

    assert a.origin_m == pytest.approx(b.origin_m, abs=1e-9)
    assert a.cell_size_m == pytest.approx(b.cell_size_m, rel=1e-12)
    np.testing.assert_array_equal(a.heights_m, b.heights_m)
    np.testing.assert_array_equal(a.valid_mask(), b.valid_mask())
    assert CRS.from_wkt(a.crs).to_dict() == CRS.from_wkt(b.crs).to_dict()


# --- formats ------------------------------------------------------------------------------


def test_esri_ascii_grid_reads_as_the_geotiff(tmp_path):
    import rasterio.shutil

    tif = write_dem(tmp_path / "d.tif", _dem())
    rasterio.shutil.copy(tif, tmp_path / "d.asc", driver="AAIGrid")
    assert (tmp_path / "d.asc").read_text().split()[:4] == ["ncols", "8", "nrows", "6"]
    _same(read_dem(tmp_path / "d.asc"), read_dem(tif))


def test_vrt_reads_as_the_geotiff_it_points_at(tmp_path):
    import rasterio

    tif = write_dem(tmp_path / "d.tif", _dem())
    with rasterio.open(tif) as src:
        geotransform = ", ".join(repr(v) for v in src.transform.to_gdal())
        srs = src.crs.to_wkt()
    (tmp_path / "d.vrt").write_text(f"""<VRTDataset rasterXSize="8" rasterYSize="6">
  <SRS>{srs.replace('"', "&quot;")}</SRS>
  <GeoTransform>{geotransform}</GeoTransform>
  <VRTRasterBand dataType="Float64" band="1">
    <NoDataValue>nan</NoDataValue>
    <SimpleSource>
      <SourceFilename relativeToVRT="1">d.tif</SourceFilename>
      <SourceBand>1</SourceBand>
    </SimpleSource>
  </VRTRasterBand>
</VRTDataset>
""")
    _same(read_dem(tmp_path / "d.vrt"), read_dem(tif))


# the IAU_2015 Moon CRSs (sphere R = 1737.4 km): equirectangular (clon 0), north and south
# polar stereographic
@pytest.mark.parametrize("code", ["IAU_2015:30110", "IAU_2015:30130", "IAU_2015:30135"])
def test_isis3_cube_in_a_lunar_crs_reads_as_the_geotiff(tmp_path, code):
    import rasterio.shutil
    from rasterio.crs import CRS

    dem = _dem(code)
    h = np.where(dem.valid, dem.heights_m, -3.4028226550889045e38)[::-1]  # ISIS3 float32 NULL
    tif = _geotiff(tmp_path / "m.tif", h, _file_transform(dem), dem.crs, nodata=h.min())
    rasterio.shutil.copy(tif, tmp_path / "m.cub", driver="ISIS3")
    cube = read_dem(tmp_path / "m.cub")
    _same(cube, read_dem(tif))
    np.testing.assert_array_equal(cube.valid, dem.valid)  # nodata kept as the mask
    np.testing.assert_array_equal(cube.heights_m[dem.valid], dem.heights_m[dem.valid])
    got = CRS.from_wkt(cube.crs).to_dict()
    assert got["R"] == 1737400 and got["proj"] == CRS.from_user_input(code).to_dict()["proj"]
    assert CRS.from_wkt(cube.crs).linear_units_factor[1] == 1.0  # metres (ISIS3 names no unit)


def _file_transform(dem: DEM):
    from rasterio.transform import from_origin

    ny, _ = dem.shape
    x0, y0 = dem.origin_m
    c = dem.cell_size_m
    return from_origin(x0 - 0.5 * c, y0 + (ny - 0.5) * c, c, c)


def test_pds3_label_with_raw_image_reads(tmp_path):
    """A PDS3 detached label (``.lbl``) over a raw ``.img``: GDAL's PDS driver reads it (it
    writes none, so the label is written here by hand)."""
    dem = _dem(None)
    h = np.where(dem.valid, dem.heights_m, -3.4028226550889045e38)[::-1].astype("<f4")
    (tmp_path / "m.img").write_bytes(h.tobytes())
    (tmp_path / "m.lbl").write_text("""PDS_VERSION_ID = PDS3
RECORD_TYPE = FIXED_LENGTH
RECORD_BYTES = 32
FILE_RECORDS = 6
^IMAGE = ("m.img", 1)
OBJECT = IMAGE
  LINES = 6
  LINE_SAMPLES = 8
  SAMPLE_TYPE = PC_REAL
  SAMPLE_BITS = 32
  BANDS = 1
  MISSING_CONSTANT = 16#FF7FFFFB#
END_OBJECT = IMAGE
OBJECT = IMAGE_MAP_PROJECTION
  MAP_PROJECTION_TYPE = "EQUIRECTANGULAR"
  TARGET_NAME = MOON
  A_AXIS_RADIUS = 1737.4 <KM>
  B_AXIS_RADIUS = 1737.4 <KM>
  C_AXIS_RADIUS = 1737.4 <KM>
  CENTER_LATITUDE = 0.0 <DEG>
  CENTER_LONGITUDE = 0.0 <DEG>
  LINE_FIRST_PIXEL = 1
  SAMPLE_FIRST_PIXEL = 1
  MAP_SCALE = 0.001 <KM/PIXEL>
  LINE_PROJECTION_OFFSET = 200.5 <PIXEL>
  SAMPLE_PROJECTION_OFFSET = -99.5 <PIXEL>
END_OBJECT = IMAGE_MAP_PROJECTION
END
""")
    from rasterio.crs import CRS

    got = read_dem(tmp_path / "m.lbl")
    # GDAL's PDS driver: left edge -(SAMPLE_PROJECTION_OFFSET + 0.5) = 99 px, top edge
    # LINE_PROJECTION_OFFSET + 0.5 = 201 px, 1 m each: bottom-left cell centre (99.5, 195.5)
    assert got.origin_m == pytest.approx((99.5, 195.5))
    assert got.cell_size_m == pytest.approx(1.0)
    np.testing.assert_array_equal(got.heights_m[got.valid], dem.heights_m[dem.valid])
    np.testing.assert_array_equal(got.valid, dem.valid)
    d = CRS.from_wkt(got.crs).to_dict()
    assert d["proj"] == "eqc" and d["R"] == 1737400


# --- CRSs -------------------------------------------------------------------------------


def test_geographic_refused_with_the_fix_or_reprojected_on_the_moon(tmp_path):
    """IAU_2015:30100 (Moon, degrees): refused naming --reproject and gdalwarp; reprojected,
    a transverse Mercator grid on the lunar sphere with square cells of the smaller side."""
    from rasterio.crs import CRS
    from rasterio.transform import from_origin

    deg = 1 / 1024  # 29.6 m north-south on the Moon; x cos(lat 45 deg) = 20.9 m east-west
    lon, lat = np.meshgrid(10 + deg * (np.arange(40) + 0.5), 45 - deg * (np.arange(30) + 0.5))
    h = 300.0 * (lon - 10) - 500.0 * (lat - 45)  # a plane in degrees
    path = _geotiff(tmp_path / "moon.tif", h, from_origin(10, 45, deg, deg), _crs("IAU_2015:30100"),
                    dtype="float64")
    with pytest.raises(InputFileError, match=r"geographic \(degrees\).*`reproject`.*gdalwarp"):
        read_dem(path)
    dem = read_dem(path, reproject=True)
    local = CRS.from_wkt(dem.crs).to_dict()
    assert local["proj"] == "tmerc" and local["R"] == 1737400
    assert (local["lon_0"], local["lat_0"]) == pytest.approx((10 + 20 * deg, 45 - 15 * deg))
    east_west_m = np.radians(deg) * 1737400 * np.cos(np.radians(45 - 15 * deg))
    assert dem.cell_size_m == pytest.approx(east_west_m, rel=1e-6)
    assert CRS.from_wkt(dem.source_crs).is_geographic
    # source cell centres, moved into the DEM's frame, on the plane: bilinear resampling of a
    # plane is exact up to the map's curvature over one cell (far below 1 mm here)
    inner = (slice(2, -2), slice(2, -2))
    xy = to_dem_xy(dem, np.column_stack([lon[inner].ravel(), lat[inner].ravel()]))
    assert dem.valid_at(xy).all()
    np.testing.assert_allclose(dem.height_at(xy), h[inner].ravel(), atol=1e-3)
    assert not dem.valid_mask().all()  # corners of the local grid outside the source footprint


def test_non_metre_crs_refused_with_the_fix(tmp_path):
    from rasterio.transform import from_origin

    path = _geotiff(tmp_path / "ft.tif", np.ones((4, 4)), from_origin(6e6, 2e6, 3, 3),
                    "EPSG:2229")
    with pytest.raises(InputFileError, match="US survey foot, not metres.*`reproject`"):
        read_dem(path)
    dem = read_dem(path, reproject=True)
    assert dem.cell_size_m == pytest.approx(3 * 1200 / 3937, rel=1e-3)  # 3 US survey feet
    assert dem.source_crs is not None


def test_non_square_cells_refused_or_resampled_to_the_smaller_side(tmp_path):
    from rasterio.transform import from_origin

    x = 500000 + 2.0 * (np.arange(10) + 0.5)
    y = 4000000 - 1.0 * (np.arange(12) + 0.5)
    h = 0.1 * (x[None, :] - 500000) + 0.3 * (4000000 - y[:, None])  # a plane
    path = _geotiff(tmp_path / "ns.tif", h, from_origin(500000, 4000000, 2.0, 1.0), UTM,
                    dtype="float64")
    with pytest.raises(InputFileError, match=r"cells must be square, got 2 x 1; pass "
                                             r"`reproject`.*gdalwarp -tr"):
        read_dem(path)
    dem = read_dem(path, reproject=True)
    assert dem.cell_size_m == 1.0 and dem.source_crs is None and dem.shape == (12, 20)
    assert dem.origin_m == (500000.5, 3999988.5)
    _same_crs = read_dem(write_dem(tmp_path / "sq.tif", dem))
    assert _same_crs.crs == dem.crs
    pts = np.column_stack([x[1:-1].repeat(10), np.tile(y[1:-1], 8)])
    np.testing.assert_array_equal(to_dem_xy(dem, pts), pts)
    np.testing.assert_allclose(dem.height_at(pts), 0.1 * (pts[:, 0] - 500000)
                               + 0.3 * (4000000 - pts[:, 1]), atol=1e-9)


def test_real_geographic_dem_reprojected(tmp_path):
    """matplotlib's Jacksboro fault DEM (real, 3 arc-second cells, degrees) as an EPSG:4326
    GeoTIFF: refused without reproject; reprojected to square metre cells of the smaller
    native side (3" east-west at 36.6 N) whose heights at the source cell centres lie within
    the source heights around each."""
    from matplotlib.cbook import get_sample_data
    from rasterio.crs import CRS
    from rasterio.transform import from_origin

    with get_sample_data("jacksboro_fault_dem.npz") as z:  # "ymin" is the northern edge
        h, deg, west, north = z["elevation"], float(z["dx"]), float(z["xmin"]), float(z["ymin"])
    assert deg == pytest.approx(3 / 3600) and h.shape == (344, 403)
    t = from_origin(west, north, deg, deg)
    path = _geotiff(tmp_path / "jacksboro.tif", h, t, "EPSG:4326", dtype="int16")
    with pytest.raises(InputFileError, match="`reproject`"):
        read_dem(path)
    dem = read_dem(path, reproject=True)
    assert CRS.from_wkt(dem.crs).to_dict()["proj"] == "tmerc"
    # WGS84 at 36.59 N: 3" = 92.5 m north-south, 74.6 m east-west (x cos(lat) x N/M)
    assert dem.cell_size_m == pytest.approx(74.57, abs=0.05)
    assert dem.shape == pytest.approx((428, 404), abs=2)  # 344 x 92.5 m / 74.6 m rows
    rng = np.random.default_rng(13)
    r, c = rng.integers(1, h.shape[0] - 1, 300), rng.integers(1, h.shape[1] - 1, 300)
    lon, lat = t @ (c + 0.5, r + 0.5)
    xy = to_dem_xy(dem, np.column_stack([lon, lat]))
    assert dem.valid_at(xy).all()
    got = dem.height_at(xy)
    # bilinear twice (GDAL onto the grid, then height_at at the point) is a convex
    # combination of source heights within one source cell of the point: bounded by the
    # 3 x 3 source neighbourhood (nearest-neighbour would break this bound too, so a plane
    # checks the interpolation itself: test_geographic_refused_...)
    lo = np.array([h[a - 1:a + 2, b - 1:b + 2].min() for a, b in zip(r, c, strict=True)])
    hi = np.array([h[a - 1:a + 2, b - 1:b + 2].max() for a, b in zip(r, c, strict=True)])
    assert np.all((got >= lo - 1e-6) & (got <= hi + 1e-6))
    assert np.median(np.abs(got - h[r, c])) < 5.0  # metres, on relief of 236..1076 m
    # a window in the file's own units (degrees), read then reprojected around its centre
    part = read_dem(path, reproject=True, window=(-84.30, -84.25, 36.55, 36.60))
    local = CRS.from_wkt(part.crs).to_dict()
    assert (local["lon_0"], local["lat_0"]) == pytest.approx((-84.275, 36.575), abs=2 * deg)
    assert part.cell_size_m == pytest.approx(dem.cell_size_m, rel=1e-3)
    assert part.shape[0] * part.shape[1] < 0.04 * dem.shape[0] * dem.shape[1]  # 64 x 64 read
    inside = (lon > -84.30) & (lon < -84.25) & (lat > 36.55) & (lat < 36.60)
    assert inside.sum() >= 2
    xy = to_dem_xy(part, np.column_stack([lon[inside], lat[inside]]))
    assert part.valid_at(xy).all()
    assert np.all((part.height_at(xy) >= lo[inside] - 1e-6)
                  & (part.height_at(xy) <= hi[inside] + 1e-6))


def test_dem_source_crs_needs_crs():
    with pytest.raises(DataError, match="source_crs"):
        DEM(np.zeros((2, 2)), (0, 0), 1.0, source_crs=_crs(UTM))


# --- windows ---------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".tif", ".npz"])
def test_window_read_is_the_crop_of_the_full_read(tmp_path, suffix):
    rng = np.random.default_rng(3)
    valid = rng.random((40, 50)) > 0.1
    dem = DEM(rng.normal(size=(40, 50)), (500000.5, 4000000.5), 1.0, _crs(UTM), valid=valid)
    path = write_dem(tmp_path / f"d{suffix}", dem)
    full = read_dem(path)
    win = read_dem(path, window=(500010.2, 500020.7, 4000005.0, 4000030.0))
    i0, j0 = (int(round(w - f)) for w, f in zip(win.origin_m, full.origin_m, strict=True))
    # cells covering x 500010.2..500020.7 are columns 10..20, y 4000005..4000030 rows 5..29
    # (an edge on a cell border takes the cell inside), then the pad on each side
    pad = WINDOW_PAD_CELLS
    assert (i0, j0) == (10 - pad, 5 - pad)
    assert win.shape == (30 - 5 + 2 * pad, 21 - 10 + 2 * pad)
    crop = (slice(j0, j0 + win.shape[0]), slice(i0, i0 + win.shape[1]))
    np.testing.assert_array_equal(win.valid_mask(), full.valid_mask()[crop])
    np.testing.assert_array_equal(win.heights_m[win.valid_mask()], full.heights_m[crop][
        full.valid_mask()[crop]])
    # clipped at the raster's edge; missing it is an error
    corner = read_dem(path, window=(499000.0, 500001.0, 3999000.0, 4000001.0))
    assert corner.origin_m == full.origin_m and corner.shape == (1 + pad, 1 + pad)
    with pytest.raises(DataError, match="misses the DEM"):
        read_dem(path, window=(0.0, 10.0, 0.0, 10.0))
    for bad in ((1.0, 0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (0.0, np.nan, 0.0, 1.0), "abcd"):
        with pytest.raises(ConfigError, match="window must be 4 finite numbers"):
            read_dem(path, window=bad)


def test_big_raster_read_by_window_stays_small(tmp_path):
    """A 20000 x 20000 float32 GeoTIFF (1.6 GB in memory; tiled and sparse on disk) is refused
    whole and read by window in well under 1 MB of numpy memory."""
    import tracemalloc

    import rasterio
    from rasterio.transform import from_origin
    from rasterio.windows import Window

    n = 20000
    with rasterio.open(tmp_path / "big.tif", "w", driver="GTiff", height=n, width=n, count=1,
                       dtype="float32", crs=UTM, transform=from_origin(500000, 4020000, 1, 1),
                       tiled=True, blockxsize=256, blockysize=256, compress="deflate",
                       sparse_ok=True, nodata=-9999) as dst:
        dst.write(np.arange(512 * 512, dtype="float32").reshape(512, 512), 1,
                  window=Window(10000, 10000, 512, 512))
    assert (tmp_path / "big.tif").stat().st_size < 2_000_000
    with pytest.raises(DataError, match="20000 x 20000 cells.*read a window"):
        read_dem(tmp_path / "big.tif")
    window = (510100.0, 510200.0, 4009700.0, 4009800.0)
    read_dem(tmp_path / "big.tif", window=window)  # imports and GDAL caches before measuring
    tracemalloc.start()
    try:
        dem = read_dem(tmp_path / "big.tif", window=window)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert dem.shape == (104, 104) and dem.valid is None
    assert peak < 1_000_000, peak
    # cell [0, 0] at (510098.5, 4009698.5): file row 10301, column 10098 -> written 301, 98
    assert dem.origin_m == (510098.5, 4009698.5) and dem.heights_m[0, 0] == 301 * 512 + 98
