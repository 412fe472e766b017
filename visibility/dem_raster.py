"""A DEM file's raster as a metric grid of square cells (the reading side of
:func:`visibility.dem.read_dem`).

Reads one band of any raster GDAL reads (through rasterio) or our ``.npz``, whole or by
window, with nodata as NaN; checks that the cells are square, north-up and in metres, and
otherwise refuses them or resamples them (a local transverse Mercator CRS for a geographic or
non-metre one, on the CRS's own ellipsoid or sphere); turns the result into the DEM's layout
(rows along +y, columns along +x).
"""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from markerplan.errors import DataError, InputFileError
from markerplan.reading import finite_number

#: Largest grid read (cells); 1e8 float64 heights are 800 MB.
MAX_DEM_CELLS = 100_000_000

#: Cells read beyond a ``window`` on every side (bilinear stencils and slopes at its edge).
WINDOW_PAD_CELLS = 2
#: CRS under which a grid without one is resampled (the site frame, metres).
_SITE_FRAME_WKT = ('ENGCRS["site frame",EDATUM["site"],CS[Cartesian,2],'
                   'AXIS["x",east,ORDER[1],LENGTHUNIT["metre",1]],'
                   'AXIS["y",north,ORDER[2],LENGTHUNIT["metre",1]]]')
#: Ellipsoid or sphere parameters of a PROJ dict, kept by the local CRS of a reprojection.
_SHAPE_KEYS = ("datum", "ellps", "R", "a", "b", "rf", "f", "towgs84")
#: How a refusal names the way out on reading (the CLI option, then the library call).
_REPROJECT_FIX = "pass `reproject` (read_dem(..., reproject=True)) to resample it"


class Raster(NamedTuple):
    """A height grid as stored: rows and columns in the file's order.

    Attributes
    ----------
    heights : (rows, cols) float64
        Heights, NaN at nodata.
    transform : affine.Affine
        Cell corner ``(col, row)`` to the file's coordinates.
    crs : rasterio.crs.CRS or None
        The file's CRS; ``None``: the site frame, metres.
    """

    heights: np.ndarray
    transform: Any
    crs: Any


def _check_cells(ny: int, nx: int, what: str) -> None:
    if ny * nx > MAX_DEM_CELLS:
        raise DataError(f"{what}: {ny} x {nx} cells is more than the {MAX_DEM_CELLS:.0e} this "
                        "reads; read a window of it, or crop or coarsen it (e.g. gdalwarp "
                        "-te ... or -tr ...)")


def _window(transform, rows: int, cols: int, window: tuple[float, float, float, float],
            what: str):
    """The rasterio ``Window`` of the cells covering ``window`` (file CRS units), padded by
    :data:`WINDOW_PAD_CELLS` and clipped to the ``rows`` x ``cols`` grid, and its transform."""
    import math

    from rasterio.transform import Affine
    from rasterio.windows import Window

    xmin, xmax, ymin, ymax = (float(v) for v in window)
    inverse = ~transform
    corners = [inverse @ (x, y) for x in (xmin, xmax) for y in (ymin, ymax)]  # (col, row)
    c0, c1 = min(c for c, _ in corners), max(c for c, _ in corners)
    r0, r1 = min(r for _, r in corners), max(r for _, r in corners)
    if r0 > rows or c0 > cols or r1 < 0 or c1 < 0:
        raise DataError(f"{what}: window [{xmin:g}, {xmax:g}] x [{ymin:g}, {ymax:g}] misses the "
                        "DEM; give a window inside the DEM, in the file's CRS units")
    pad = WINDOW_PAD_CELLS
    r0, c0 = max(math.floor(r0) - pad, 0), max(math.floor(c0) - pad, 0)
    r1, c1 = min(math.ceil(r1) + pad, rows), min(math.ceil(c1) + pad, cols)
    return Window(c0, r0, c1 - c0, r1 - r0), transform @ Affine.translation(c0, r0)


def read_gdal(path: Path, what: str,
              window: tuple[float, float, float, float] | None) -> Raster:
    """One band of a raster GDAL reads, nodata as NaN.

    Parameters
    ----------
    path : Path
        Any raster GDAL opens (GeoTIFF, ``.asc``, VRT, ISIS3, PDS, ...), one band.
    what : str
        How messages name the input.
    window : (xmin, xmax, ymin, ymax) float or None
        Read only the cells covering it (file CRS units) plus :data:`WINDOW_PAD_CELLS`,
        clipped to the raster; ``None``: all of it.

    Returns
    -------
    raster : Raster
        Heights (float64, NaN at nodata) in the file's row order, with the window's transform.

    Raises
    ------
    InputFileError
        Unreadable file, several bands, a non-numeric band, no georeferencing.
    DataError
        More than :data:`MAX_DEM_CELLS` cells to read; a window missing the raster.
    """
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioError
    from rasterio.transform import Affine
    from rasterio.windows import Window

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as src:
                if src.count != 1:
                    raise InputFileError(f"{what}: has {src.count} bands; a DEM is one band of "
                                         "heights, extract it first (e.g. gdal_translate -b 1 "
                                         "in.tif heights.tif)")
                try:
                    kind = np.dtype(src.dtypes[0]).kind
                except TypeError:
                    kind = "c"
                if kind not in "iuf":
                    raise InputFileError(f"{what}: band type {src.dtypes[0]} is not a real "
                                         "number; heights must be integers or floats")
                t = src.transform
                if src.crs is None and t == Affine.identity() and not src.gcps[0]:
                    raise InputFileError(f"{what}: has no georeferencing (no geotransform); "
                                         "set it (e.g. gdal_translate -a_ullr) or write the DEM "
                                         "with visibility.dem.write_dem")
                win, t = ((Window(0, 0, src.width, src.height), t) if window is None
                          else _window(t, src.height, src.width, window, what))
                _check_cells(int(win.height), int(win.width), what)
                band = src.read(1, window=win, masked=True).astype(np.float64)
                return Raster(np.ma.filled(band, np.nan), t, src.crs)
    except RasterioError as exc:
        raise InputFileError(f"{what}: not a raster GDAL can read ({_one_line(exc)}); give a "
                             "GeoTIFF, ESRI ASCII grid, VRT, ISIS3/PDS cube or an .npz DEM"
                             ) from exc
    except MemoryError:
        raise DataError(f"{what}: too large to read into memory; read a window of it, or crop "
                        "or coarsen it") from None


#: Exceptions numpy and zipfile raise on a corrupt ``.npz``.
_NPZ_ERRORS = (OSError, ValueError, EOFError, KeyError, TypeError, NotImplementedError,
               zipfile.BadZipFile, zlib.error)
_NPZ_MEMBERS = ("heights_m", "origin_m", "cell_size_m")


def read_npz(path: Path, what: str,
             window: tuple[float, float, float, float] | None) -> Raster:
    """Our ``.npz`` (members ``heights_m``, ``origin_m``, ``cell_size_m``, ``crs``, optional
    ``valid``) as a raster, cropped to ``window`` like :func:`read_gdal`.

    Returns
    -------
    raster : Raster
        Heights (float64) with rows along +y, NaN where ``valid`` is False.

    Raises
    ------
    InputFileError
        Unreadable archive, members missing or of the wrong shape or type, a non-finite or
        non-positive origin or cell size, a ``crs`` that is no CRS.
    DataError
        More than :data:`MAX_DEM_CELLS` cells; a window missing the grid.
    """
    from rasterio.transform import Affine

    fix = "write it with visibility.dem.write_dem"
    try:
        z = np.load(path, allow_pickle=False)
    except _NPZ_ERRORS as exc:
        raise InputFileError(f"{what}: not a readable .npz ({_one_line(exc)}); {fix}") from exc
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise InputFileError(f"{what}: is a single .npy array, not an .npz archive with members "
                             f"{', '.join(_NPZ_MEMBERS)}; {fix}")
    with z:
        missing = [k for k in _NPZ_MEMBERS if k not in z.files]
        if missing:
            raise InputFileError(f"{what}: lacks member(s) {', '.join(missing)} (has "
                                 f"{', '.join(z.files)[:80] or 'none'}); {fix}")
        try:
            arrays = {k: z[k] for k in (*_NPZ_MEMBERS, "crs", "valid") if k in z.files}
        except _NPZ_ERRORS as exc:
            raise InputFileError(f"{what}: a member cannot be read ({_one_line(exc)}); "
                                 f"{fix}") from exc
    heights, origin, cell = (arrays[k] for k in _NPZ_MEMBERS)
    if heights.ndim != 2 or heights.dtype.kind not in "iuf":
        raise InputFileError(f"{what}: heights_m must be a 2-D array of numbers, got shape "
                             f"{heights.shape} dtype {heights.dtype}; {fix}")
    _check_cells(*heights.shape, what)
    if origin.shape != (2,) or origin.dtype.kind not in "iuf":
        raise InputFileError(f"{what}: origin_m must be 2 numbers (x0, y0), got shape "
                             f"{origin.shape} dtype {origin.dtype}; {fix}")
    if cell.size != 1 or cell.dtype.kind not in "iuf":
        raise InputFileError(f"{what}: cell_size_m must be one number, got shape {cell.shape} "
                             f"dtype {cell.dtype}; {fix}")
    valid = arrays.get("valid")
    if valid is not None and (valid.shape != heights.shape or valid.dtype != bool):
        raise InputFileError(f"{what}: valid must be a bool array shaped like heights_m "
                             f"{heights.shape}, got shape {valid.shape} dtype {valid.dtype}; "
                             f"{fix}")
    x0 = finite_number(float(origin[0]), f"{what}: origin x")
    y0 = finite_number(float(origin[1]), f"{what}: origin y")
    c = finite_number(float(cell.reshape(())), f"{what}: cell size")
    if c <= 0:
        raise InputFileError(f"{what}: cell size must be > 0 m, got {c:g}; check the file's "
                             "georeferencing")
    heights = heights.astype(np.float64)
    if valid is not None:
        heights[~valid] = np.nan
    transform = Affine(c, 0.0, x0 - 0.5 * c, 0.0, c, y0 - 0.5 * c)
    if window is not None:
        win, transform = _window(transform, *heights.shape, window, what)
        heights = heights[win.toslices()]
    return Raster(heights, transform, _npz_crs(arrays.get("crs"), what, fix))


def _npz_crs(c: np.ndarray | None, what: str, fix: str):
    """The ``crs`` member (WKT, a code such as ``EPSG:32633``, or empty) as a rasterio CRS."""
    if c is None:
        return None
    if c.size != 1 or c.dtype.kind not in "US":
        raise InputFileError(f"{what}: crs must be one string (WKT, or empty), got shape "
                             f"{c.shape} dtype {c.dtype}; {fix}")
    text = str(c.reshape(()).item().decode("utf-8", "replace") if c.dtype.kind == "S"
               else c.reshape(()).item())
    if not text:
        return None
    from rasterio.crs import CRS
    from rasterio.errors import CRSError

    try:
        return CRS.from_user_input(text)
    except CRSError as exc:
        raise InputFileError(f"{what}: crs {text[:40]!r} is not a CRS (give WKT, an EPSG "
                             f"code or an empty string); {fix}") from exc


def _crs_problem(crs) -> tuple[str, str] | None:
    """Why a rasterio CRS is not metric (what, and the GDAL fix), or None (metric, or
    ``None``: the site frame)."""
    from rasterio.errors import CRSError

    if crs is None:
        return None
    name = (crs.to_string() or "of the file")[:60]
    if crs.is_geographic:
        return (f"CRS {name} is geographic (degrees), but DEM cells and heights must be "
                "metres", "reproject it first, e.g. gdalwarp -t_srs EPSG:326NN in.tif "
                "out.tif (NN: your UTM zone)")
    try:
        unit, factor = crs.linear_units_factor
    except CRSError:  # no linear unit to read (local or engineering CRS): taken as metres
        return None
    if not np.isclose(factor, 1.0):
        return (f"CRS {name} has units of {unit}, not metres",
                "reproject it to a metric CRS first (gdalwarp -t_srs ...)")
    return None


def _cell_problem(t) -> tuple[str, str] | None:
    """Why a geotransform's cells are not north-up squares (what, and the GDAL fix), or None."""
    if t.b != 0 or t.d != 0:
        return (f"cells must be north-up, got a rotated or sheared transform {tuple(t)[:6]}",
                "resample it first (e.g. gdalwarp)")
    if not np.isclose(abs(t.a), abs(t.e), rtol=1e-9):
        return (f"cells must be square, got {abs(t.a):g} x {abs(t.e):g}",
                "resample to square cells first (e.g. gdalwarp -tr 1 1 in.tif out.tif)")
    return None


def metric_square(raster: Raster, reproject: bool, what: str
                  ) -> tuple[Raster, str | None]:
    """The grid on square, north-up cells in metres.

    Parameters
    ----------
    raster : Raster
    reproject : bool
        Resample a grid that is not (see :func:`visibility.dem.read_dem`) instead of
        refusing it.
    what : str
        How messages name the input.

    Returns
    -------
    raster : Raster
        ``raster`` itself when already metric and square, else the resampled grid.
    source_crs : str or None
        WKT of the file's CRS when the CRS changed (geographic or non-metre), else ``None``.

    Raises
    ------
    InputFileError
        A non-finite or degenerate geotransform; unless ``reproject``, a geographic or
        non-metre CRS or rotated or non-square cells (naming ``--reproject`` and gdalwarp); a
        CRS naming no ellipsoid or sphere to reproject on.
    DataError
        A resampled grid of more than :data:`MAX_DEM_CELLS` cells.
    """
    t = raster.transform
    if not all(np.isfinite(v) for v in tuple(t)[:6]):
        raise InputFileError(f"{what}: geotransform {tuple(t)[:6]} is not finite; fix the "
                             "file's georeferencing")
    if t.a * t.e - t.b * t.d == 0:
        raise InputFileError(f"{what}: cell size must be > 0 m, got the degenerate transform "
                             f"{tuple(t)[:6]}; check the file's georeferencing")
    problem = _crs_problem(raster.crs) or _cell_problem(t)
    if problem is None:
        return raster, None
    if not reproject:
        raise InputFileError(f"{what}: {problem[0]}; {_REPROJECT_FIX} to a local metric grid "
                             f"of square cells, or {problem[1]}")
    return _reproject(raster, what)


def _local_crs(raster: Raster, what: str):
    """Transverse Mercator (metres) centred on the grid, on the file CRS's ellipsoid/sphere."""
    from rasterio.crs import CRS
    from rasterio.warp import transform

    d = raster.crs.to_dict()
    shape = {k: d[k] for k in _SHAPE_KEYS if k in d}
    if not shape:
        raise InputFileError(f"{what}: CRS {raster.crs.to_string()[:60]} names no ellipsoid or "
                             "sphere to reproject on; reproject it first (gdalwarp -t_srs ...)")
    rows, cols = raster.heights.shape
    cx, cy = raster.transform @ (cols / 2, rows / 2)
    (lon,), (lat,) = transform(raster.crs, CRS.from_dict({"proj": "longlat", **shape}),
                               [cx], [cy])
    return CRS.from_dict({"proj": "tmerc", "lat_0": round(lat, 6), "lon_0": round(lon, 6),
                          "k": 1, "x_0": 0, "y_0": 0, **shape, "units": "m"})


def _reproject(raster: Raster, what: str) -> tuple[Raster, str | None]:
    """Bilinear resampling onto square metric cells (see :func:`read_dem`, ``reproject``)."""
    from rasterio.crs import CRS
    from rasterio.errors import CRSError, RasterioError
    from rasterio.warp import Resampling, reproject

    src_crs = raster.crs if raster.crs is not None else CRS.from_wkt(_SITE_FRAME_WKT)
    metric = _crs_problem(raster.crs) is None
    if not metric and raster.crs.is_geographic:
        rows, cols = raster.heights.shape
        lats = [(raster.transform @ (c, r))[1] for c in (0, cols) for r in (0, rows)]
        if max(abs(v) for v in lats) > 90:
            raise InputFileError(f"{what}: spans latitudes {min(lats):g} to {max(lats):g} "
                                 "degrees, beyond +-90; check the file's georeferencing")
    try:
        dst_crs = src_crs if metric else _local_crs(raster, what)
        dst_transform, shape = _target_grid(raster, src_crs, dst_crs, what)
        heights = np.full(shape, np.nan)
        reproject(raster.heights, heights, src_transform=raster.transform, src_crs=src_crs,
                  dst_transform=dst_transform, dst_crs=dst_crs, src_nodata=np.nan,
                  dst_nodata=np.nan, resampling=Resampling.bilinear)
    except (CRSError, RasterioError) as exc:
        raise InputFileError(f"{what}: cannot reproject it ({_one_line(exc)}); check the file's "
                             "georeferencing, or reproject it first (gdalwarp -t_srs ...)"
                             ) from exc
    if metric:
        return Raster(heights, dst_transform, raster.crs), None
    return Raster(heights, dst_transform, dst_crs), raster.crs.to_wkt()


def _target_grid(raster: Raster, src_crs, dst_crs, what: str):
    """Transform and ``(rows, cols)`` of the resampled grid: square cells of the smaller side,
    in metres, of the source cell at the grid's centre; covering the source's bounds; cell
    edges on multiples of the cell size."""
    import math

    from rasterio.transform import Affine
    from rasterio.warp import transform, transform_bounds

    t = raster.transform
    rows, cols = raster.heights.shape
    steps = [t @ (cols / 2 + dc, rows / 2 + dr) for dc, dr in ((0, 0), (1, 0), (0, 1))]
    xs, ys = transform(src_crs, dst_crs, [p[0] for p in steps], [p[1] for p in steps])
    cell = min(math.hypot(xs[k] - xs[0], ys[k] - ys[0]) for k in (1, 2))
    corners = [t @ (c, r) for c in (0, cols) for r in (0, rows)]
    left, bottom, right, top = transform_bounds(
        src_crs, dst_crs, min(p[0] for p in corners), min(p[1] for p in corners),
        max(p[0] for p in corners), max(p[1] for p in corners), densify_pts=21)
    if not (math.isfinite(cell) and cell > 0
            and all(math.isfinite(v) for v in (left, bottom, right, top))):
        raise InputFileError(f"{what}: cannot reproject it (cell {cell:g}, bounds {left:g}, "
                             f"{bottom:g}, {right:g}, {top:g} in the local CRS); check the "
                             "file's georeferencing")
    left, top = math.floor(left / cell) * cell, math.ceil(top / cell) * cell
    width, height = math.ceil((right - left) / cell), math.ceil((top - bottom) / cell)
    _check_cells(height, width, f"{what} reprojected")
    return Affine(cell, 0.0, left, 0.0, -cell, top), (height, width)


def site_grid(raster: Raster, what: str
              ) -> tuple[np.ndarray, tuple[float, float], float]:
    """A north-up square grid (:func:`metric_square`) in the DEM's layout.

    Returns
    -------
    heights : (ny, nx) float64
        Rows along +y, columns along +x; NaN at nodata.
    origin : (float, float)
        Centre of cell ``[0, 0]``, metres.
    cell : float
        Cell side, metres.
    """
    t = raster.transform
    heights = raster.heights
    cell = finite_number(abs(t.a), f"{what}: cell size")
    ny, nx = heights.shape
    if t.a > 0:
        x0 = t.c + 0.5 * t.a
    else:  # first column is the right edge (max x): flip so columns run along +x
        heights = heights[:, ::-1]
        x0 = t.c + (nx - 0.5) * t.a
    if t.e < 0:  # first row is the top (max y): flip so rows run along +y
        heights = heights[::-1]
        y0 = t.f + (ny - 0.5) * t.e
    else:
        y0 = t.f + 0.5 * t.e
    return (heights, (finite_number(x0, f"{what}: origin x"),
                      finite_number(y0, f"{what}: origin y")), cell)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:200] or type(exc).__name__


