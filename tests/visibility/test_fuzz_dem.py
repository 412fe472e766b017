"""Fuzzing :func:`visibility.dem.read_dem`: a damaged or odd DEM file either reads into a DEM
with finite heights on square metric cells (nodata as a mask), or raises a one-line
:class:`~markerplan.errors.MarkerPlanError`, never anything else."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from markerplan.errors import MarkerPlanError
from visibility.dem import DEM, read_dem, write_dem

FAST = settings(max_examples=80, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])

ODD_FLOATS = st.sampled_from([0.0, 1.0, -2.5, 1e300, -1e300, np.nan, np.inf, -np.inf, 1e7])


def _check(path, fill=None, reproject=False):
    try:
        dem = read_dem(path, fill=fill, reproject=reproject)
    except MarkerPlanError as exc:
        assert "\n" not in str(exc), str(exc)
        return None
    assert isinstance(dem, DEM)
    assert np.isfinite(dem.heights_m).all()
    assert dem.heights_m.ndim == 2 and min(dem.shape) >= 2
    assert np.isfinite(dem.cell_size_m) and dem.cell_size_m > 0
    assert all(np.isfinite(dem.origin_m))
    if dem.valid is not None:  # nodata is a mask: some cells, never all or none, are invalid
        assert fill is None and dem.valid.shape == dem.shape
        assert 0 < dem.valid.sum() < dem.valid.size
    return dem


def _array(draw, shape_st, dtype_st):
    shape = draw(shape_st)
    dtype = draw(dtype_st)
    values = draw(st.lists(ODD_FLOATS, min_size=1, max_size=4))
    a = np.resize(np.array(values), int(np.prod(shape))).reshape(shape)
    with np.errstate(invalid="ignore", over="ignore"):
        try:
            return a.astype(dtype)
        except (ValueError, OverflowError):
            return a


@st.composite
def npz_members(draw):
    members = {}
    shapes = st.sampled_from([(4, 5), (2, 2), (1, 5), (5,), (), (3, 3, 2), (0, 4)])
    dtypes = st.sampled_from(["float64", "float32", "int16", "bool", "complex64", "U3"])
    choice = draw(st.sampled_from(["valid", "odd", "odd", "missing"]))
    if choice != "missing":
        members["heights_m"] = (np.full((4, 5), 1.0) if choice == "valid"
                                else _array(draw, shapes, dtypes))
    for name, valid in (("origin_m", np.array([10.0, -3.0])), ("cell_size_m", np.array(0.5))):
        choice = draw(st.sampled_from(["valid", "odd", "missing"]))
        if choice == "valid":
            members[name] = valid
        elif choice == "odd":
            members[name] = _array(draw, st.sampled_from([(), (1,), (2,), (3,), (2, 2)]),
                                   st.sampled_from(["float64", "int8", "U2", "bool"]))
    crs = draw(st.sampled_from([None, "", "EPSG:32633", "EPSG:4326", "EPSG:2229", "junk",
                                b"EPSG:32633", 5]))
    if crs is not None:
        members["crs"] = np.array(crs)
    return members


@FAST
@given(members=npz_members(), fill=st.sampled_from([None, "nearest"]))
def test_npz_members_are_read_or_refused(tmp_path_factory, members, fill):
    path = tmp_path_factory.mktemp("fuzz") / "d.npz"
    np.savez(path, **members)
    _check(path, fill)


def _valid_file(tmp_path_factory, suffix: str):
    x = np.arange(6.0)
    dem = DEM(np.add.outer(np.arange(5.0), x), (500000.0, 4000000.0), 2.0,
              crs=None)
    if suffix == ".tif":
        from rasterio.crs import CRS

        dem.crs = CRS.from_epsg(32633).to_wkt()
    return write_dem(tmp_path_factory.mktemp("fuzz") / f"d{suffix}", dem).read_bytes()


@pytest.fixture(scope="module")
def valid_bytes(tmp_path_factory):
    return {s: _valid_file(tmp_path_factory, s) for s in (".tif", ".npz")}


@FAST
@given(suffix=st.sampled_from([".tif", ".npz"]), cut=st.integers(0, 2000),
       junk=st.binary(min_size=1, max_size=16), truncate=st.booleans())
def test_damaged_dem_bytes_are_read_or_refused(tmp_path_factory, valid_bytes, suffix, cut, junk,
                                               truncate):
    data = valid_bytes[suffix]
    cut = min(cut, len(data))
    damaged = data[:cut] if truncate else data[:cut] + junk + data[cut + len(junk):]
    path = tmp_path_factory.mktemp("fuzz") / f"d{suffix}"
    path.write_bytes(damaged)
    _check(path)


@FAST
@given(crs=st.sampled_from([None, "EPSG:32633", "EPSG:4326", "EPSG:2229", "ESRI:103878"]),
       bands=st.integers(1, 3), cell=st.tuples(st.sampled_from([1.0, 2.0, -1.0, 0.5]),
                                                 st.sampled_from([-1.0, -2.0, 1.0, -0.5])),
       rotation=st.sampled_from([0.0, 0.2]), heights=st.lists(ODD_FLOATS, min_size=1,
                                                              max_size=3),
       dtype=st.sampled_from(["float64", "float32", "int16", "uint8", "complex64"]),
       shape=st.sampled_from([(2, 2), (1, 4), (5, 6)]), fill=st.sampled_from([None, "nearest"]),
       reproject=st.booleans())
def test_geotiff_variants_are_read_or_refused(tmp_path_factory, crs, bands, cell, rotation,
                                              heights, dtype, shape, fill, reproject):
    import rasterio
    from rasterio.transform import Affine

    h = np.resize(np.array(heights), shape[0] * shape[1]).reshape(shape)
    with np.errstate(invalid="ignore", over="ignore"):
        h = h.astype(dtype)
    path = tmp_path_factory.mktemp("fuzz") / "d.tif"
    t = Affine(cell[0], rotation, 1000.0, 0.0, cell[1], 2000.0)
    with rasterio.open(path, "w", driver="GTiff", height=shape[0], width=shape[1], count=bands,
                       dtype=dtype, crs=crs, transform=t) as dst:
        for b in range(1, bands + 1):
            dst.write(h, b)
    dem = _check(path, fill, reproject)
    if dem is None:
        return
    assert bands == 1
    if not reproject:  # refused unless metric, north-up and square
        assert rotation == 0.0 and abs(cell[0]) == abs(cell[1])
        assert crs not in ("EPSG:4326", "EPSG:2229")
    # the CRS changes (to a local metric one) only for a geographic or non-metre CRS
    assert (dem.source_crs is not None) == (reproject and crs in ("EPSG:4326", "EPSG:2229"))
