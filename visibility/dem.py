"""Digital elevation models on a regular grid in the local site frame (W).

A :class:`DEM` stores heights at cell centres: cell ``[j, i]`` (row ``j``, column ``i``) is at
site coordinates ``(x0 + i * cell, y0 + j * cell)``. Rows run along +y, columns along +x
(so a GeoTIFF, whose first row is the northern edge, is flipped on reading and writing).

Files (:func:`read_dem`): any one-band raster GDAL reads, through rasterio (GeoTIFF, ESRI ASCII
grid, VRT, ISIS3/PDS cubes; CRS kept as WKT; read whole or by window; reprojected to a local
metric grid on request), and ``.npz`` with members ``heights_m``, ``origin_m``,
``cell_size_m``, ``crs`` and optionally ``valid``. Nodata is a mask (:attr:`DEM.valid`).
:func:`write_dem` writes GeoTIFF or ``.npz``.
"""

from __future__ import annotations

import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from markerplan.errors import ConfigError, DataError, InputFileError, OutputError
from markerplan.reading import MAX_ABS_COORDINATE_M, finite_number

FILL_POLICIES = ("nearest",)


@dataclass
class DEM:
    """Heights on a regular grid, site frame.

    Attributes
    ----------
    heights_m : (ny, nx) float64
        Height of each cell centre, metres.
    origin_m : tuple of float
        ``(x0, y0)``: site-frame coordinate of cell centre ``[0, 0]``, metres.
    cell_size_m : float
        Grid spacing, metres (square cells).
    crs : str or None
        Coordinate reference system as WKT, when known.
    valid : (ny, nx) bool or None
        Which cells hold measured terrain; ``None``: every cell. Heights under invalid
        (nodata) cells are filled (e.g. :func:`fill_nodata`) so that a mesh is complete, but
        they are not terrain: nothing may stand on them (see :meth:`valid_at`).
    source_crs : str or None
        WKT of the file's own CRS when :func:`read_dem` reprojected it into ``crs`` (a local
        metric CRS), else ``None``; :func:`to_dem_xy` maps that CRS's coordinates into the
        DEM's. Not written by :func:`write_dem` (the written file is in ``crs``).
    """

    heights_m: np.ndarray
    origin_m: tuple[float, float]
    cell_size_m: float
    crs: str | None = None
    valid: np.ndarray | None = None
    source_crs: str | None = None

    def __post_init__(self) -> None:
        self.heights_m = np.asarray(self.heights_m, dtype=np.float64)
        if self.heights_m.ndim != 2 or min(self.heights_m.shape) < 2:
            raise DataError(f"DEM heights_m must be a 2-D grid of at least 2 x 2 cells, got shape "
                            f"{self.heights_m.shape}")
        if not (np.isfinite(self.cell_size_m) and self.cell_size_m > 0):
            raise DataError(f"DEM cell_size_m must be a positive number, got {self.cell_size_m}")
        self.origin_m = (float(self.origin_m[0]), float(self.origin_m[1]))
        self.cell_size_m = float(self.cell_size_m)
        _refuse_nan(self.heights_m, "DEM")
        if self.valid is not None:
            self.valid = np.asarray(self.valid, dtype=bool)
            if self.valid.shape != self.heights_m.shape:
                raise DataError(f"DEM valid mask has shape {self.valid.shape}, heights_m "
                                f"{self.heights_m.shape}; give one flag per cell")
            if not self.valid.any():
                raise DataError("DEM has no valid cell at all; check the nodata value")
            if self.valid.all():
                self.valid = None
        if self.source_crs is not None and self.crs is None:
            raise DataError("DEM source_crs is set but crs is not; a reprojected DEM knows "
                            "the CRS it was reprojected into")

    @property
    def shape(self) -> tuple[int, int]:
        return self.heights_m.shape  # type: ignore[return-value]

    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` of the cell centres, site frame, metres."""
        ny, nx = self.shape
        x0, y0 = self.origin_m
        return (x0, x0 + (nx - 1) * self.cell_size_m, y0, y0 + (ny - 1) * self.cell_size_m)

    def grid_xy(self) -> tuple[np.ndarray, np.ndarray]:
        """Cell-centre coordinates: ``x`` (nx,) and ``y`` (ny,), site frame, metres."""
        ny, nx = self.shape
        return (self.origin_m[0] + self.cell_size_m * np.arange(nx),
                self.origin_m[1] + self.cell_size_m * np.arange(ny))

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """Whether each point lies inside the grid's cell-centre rectangle.

        Parameters
        ----------
        xy : (n, 2) float
            Site-frame points, metres.

        Returns
        -------
        inside : (n,) bool
        """
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        xmin, xmax, ymin, ymax = self.extent()
        return ((xy[:, 0] >= xmin) & (xy[:, 0] <= xmax)
                & (xy[:, 1] >= ymin) & (xy[:, 1] <= ymax))

    def require_inside(self, xy: np.ndarray, ids, label: str, fix: str) -> None:
        """Raise unless every point lies on the grid (:meth:`contains`) and on measured
        terrain (:meth:`valid_at`): stations and markers stand on data, never on nodata.

        Parameters
        ----------
        xy : (n, 2) float
            Site-frame points, metres.
        ids : sequence of str
            Their ids, for the message.
        label : str
            What they are (``"station"``, ``"marker"``).
        fix : str
            The message's advice.

        Raises
        ------
        DataError
            Names the first point outside (with the DEM's extent and ``fix``) or on nodata,
            and its position.
        """
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        inside = self.contains(xy)
        if not inside.all():
            k = int(np.flatnonzero(~inside)[0])
            xmin, xmax, ymin, ymax = self.extent()
            raise DataError(f"{label} {ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m lies "
                            f"outside the DEM [{xmin:.1f}, {xmax:.1f}] x [{ymin:.1f}, "
                            f"{ymax:.1f}] m; {fix}")
        on_data = self.valid_at(xy)
        if not on_data.all():
            k = int(np.flatnonzero(~on_data)[0])
            raise DataError(f"{label} {ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m stands on "
                            f"DEM nodata (no measured terrain there); a {label} must stand on "
                            "data: move it onto the DEM's valid area or use a DEM with data "
                            "there")

    def height_at(self, xy: np.ndarray) -> np.ndarray:
        """Bilinear height at site-frame points.

        Parameters
        ----------
        xy : (n, 2) float
            Points inside the DEM (see :meth:`contains`), metres.

        Returns
        -------
        z : (n,) float64
            Heights, metres.

        Raises
        ------
        DataError
            If a point lies outside the DEM.
        """
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        inside = self.contains(xy)
        if not inside.all():
            bad = xy[~inside][0]
            xmin, xmax, ymin, ymax = self.extent()
            raise DataError(f"point ({bad[0]:.3f}, {bad[1]:.3f}) m lies outside the DEM "
                            f"[{xmin:.2f}, {xmax:.2f}] x [{ymin:.2f}, {ymax:.2f}] m; move it "
                            "inside or use a larger DEM")
        ny, nx = self.shape
        fx = (xy[:, 0] - self.origin_m[0]) / self.cell_size_m
        fy = (xy[:, 1] - self.origin_m[1]) / self.cell_size_m
        i = np.clip(np.floor(fx).astype(np.int64), 0, nx - 2)
        j = np.clip(np.floor(fy).astype(np.int64), 0, ny - 2)
        u, v = fx - i, fy - j
        h = self.heights_m
        return ((1 - u) * (1 - v) * h[j, i] + u * (1 - v) * h[j, i + 1]
                + (1 - u) * v * h[j + 1, i] + u * v * h[j + 1, i + 1])

    def valid_mask(self) -> np.ndarray:
        """(ny, nx) bool: which cells hold measured terrain (all of them when
        :attr:`valid` is ``None``)."""
        if self.valid is None:
            return np.ones(self.shape, dtype=bool)
        return self.valid

    def valid_at(self, xy: np.ndarray) -> np.ndarray:
        """Whether each point lies on measured terrain: inside the grid (:meth:`contains`)
        and every cell of its bilinear stencil valid.

        Parameters
        ----------
        xy : (n, 2) float
            Site-frame points, metres.

        Returns
        -------
        on_data : (n,) bool

        Examples
        --------
        >>> valid = np.ones((3, 3), bool); valid[2, 2] = False
        >>> dem = DEM(np.zeros((3, 3)), (0.0, 0.0), 1.0, valid=valid)
        >>> dem.valid_at(np.array([[0.5, 0.5], [1.5, 1.5], [5.0, 0.0]])).tolist()
        [True, False, False]
        """
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        inside = self.contains(xy)
        if self.valid is None:
            return inside
        ny, nx = self.shape
        fx = (xy[:, 0] - self.origin_m[0]) / self.cell_size_m
        fy = (xy[:, 1] - self.origin_m[1]) / self.cell_size_m
        i = np.clip(np.floor(np.nan_to_num(fx)).astype(np.int64), 0, nx - 2)
        j = np.clip(np.floor(np.nan_to_num(fy)).astype(np.int64), 0, ny - 2)
        v = self.valid
        return inside & v[j, i] & v[j, i + 1] & v[j + 1, i] & v[j + 1, i + 1]

    def slope_rad(self) -> np.ndarray:
        """Terrain slope of each cell (central differences), radians, shape (ny, nx)."""
        gy, gx = np.gradient(self.heights_m, self.cell_size_m)
        return np.arctan(np.hypot(gx, gy))


#: Fix named by :class:`DEM` for NaN cells (library users build DEMs from arrays).
_ARRAY_NODATA_FIX = ("fill them and mark them invalid (DEM(fill_nodata(h, 'nearest'), ..., "
                     "valid=np.isfinite(h))), or read the file with visibility.dem.read_dem")
#: Largest grid read (cells); 1e8 float64 heights are 800 MB.
MAX_DEM_CELLS = 100_000_000


def _refuse_nan(heights: np.ndarray, source: str, fix: str = _ARRAY_NODATA_FIX) -> None:
    bad = ~np.isfinite(heights)
    if bad.any():
        raise DataError(f"{source} has {int(bad.sum())} NaN/nodata cells of {heights.size}; "
                        f"{fix}")


def fill_nodata(heights: np.ndarray, policy: str) -> np.ndarray:
    """Fill NaN cells of a height grid.

    Parameters
    ----------
    heights : (ny, nx) float
        Heights with NaN at nodata cells.
    policy : {"nearest"}
        ``"nearest"``: each NaN takes the height of the nearest valid cell.

    Returns
    -------
    filled : (ny, nx) float64
    """
    if policy not in FILL_POLICIES:
        raise ConfigError(f"fill must be one of {', '.join(FILL_POLICIES)} or None, got {policy!r}")
    from scipy import ndimage

    heights = np.asarray(heights, dtype=np.float64)
    bad = ~np.isfinite(heights)
    if bad.all():
        raise DataError("DEM has no valid cells at all; nothing to fill from")
    if not bad.any():
        return heights
    idx = ndimage.distance_transform_edt(bad, return_distances=False, return_indices=True)
    return heights[tuple(idx)]


def read_dem(path: str | Path, fill: str | None = None, what: str | None = None,
             nodata_fix: str | None = None, *, reproject: bool = False,
             window: tuple[float, float, float, float] | None = None) -> DEM:
    """Read a DEM from any one-band raster GDAL reads, or from our ``.npz``.

    Rasters (through rasterio): GeoTIFF, ESRI ASCII grid (``.asc``), VRT, ISIS3 cubes
    (``.cub``), PDS labels (``.lbl``/``.img``) and every other GDAL raster format; the CRS is
    kept as WKT (projected Earth CRSs such as UTM, lunar CRSs of the ``IAU_2015:301xx``
    family, or none: the site frame). Nodata (the file's nodata value, NaN, inf) is a mask,
    not an error: those cells get the height of the nearest valid cell (:func:`fill_nodata`),
    so that meshes are complete, and :attr:`DEM.valid` marks the measured ones.

    Parameters
    ----------
    path : str or Path
        DEM file: heights in metres. Cells must be square, north-up and in metres (a
        projected CRS or none) unless ``reproject``.
    fill : {None, "nearest"}
        ``None``: nodata cells are filled and marked invalid. ``"nearest"``: they are filled
        the same way and taken as terrain (``valid`` is ``None``: every cell).
    what : str, optional
        How messages name the input (default ``"DEM <path>"``), e.g. ``"--dem dem.tif"``.
    nodata_fix : str, optional
        Ignored (nodata is no longer refused); kept until every caller drops it.
    reproject : bool
        Resample a grid that is not metric and square: a geographic (degree) or non-metre
        CRS goes to a local transverse Mercator CRS centred on the grid, on the CRS's own
        ellipsoid or sphere (Earth or Moon), with square cells of the smaller native cell
        side in metres; rotated or non-square cells in a metric CRS go to square cells of
        the smaller side in the same CRS. Bilinear; nodata and cells outside the source
        footprint become invalid. :attr:`DEM.source_crs` then records the file's CRS
        (:func:`to_dem_xy` maps its coordinates into the DEM's).
    window : (xmin, xmax, ymin, ymax) float, optional
        Read only the cells covering this rectangle, in the file's own CRS units (metres, or
        degrees for a geographic file), plus a :data:`WINDOW_PAD_CELLS` pad, clipped to the
        raster; large rasters are read by window without loading the rest.

    Returns
    -------
    dem : DEM
        Site frame = the file's map coordinates (or the local CRS when reprojected), or the
        stored origin (``.npz``).

    Raises
    ------
    InputFileError
        Missing, empty, corrupt or unreadable file, several bands, a non-numeric band, no
        georeferencing; unless ``reproject``: a geographic or non-metre CRS, rotated or
        non-square cells (the message names ``--reproject`` and gdalwarp); ``.npz`` members
        missing or of the wrong shape or type; non-finite or absurd origin or cell size.
    DataError
        Every cell nodata, heights beyond +-1e8 m, a grid smaller than 2 x 2 or larger than
        :data:`MAX_DEM_CELLS`, a ``window`` that misses the raster.
    ConfigError
        Unknown ``fill``; a ``window`` that is not 4 finite numbers with min < max.

    Examples
    --------
    >>> import tempfile, os
    >>> dem = DEM(np.arange(12.0).reshape(3, 4), (500.5, 20.5), 1.0)
    >>> path = write_dem(os.path.join(tempfile.mkdtemp(), "d.npz"), dem)
    >>> read_dem(path, window=(501.0, 501.2, 21.0, 21.0)).heights_m.shape  # padded, clipped
    (3, 4)
    """
    del nodata_fix
    path = Path(path)
    what = what or f"DEM {path}"
    _read_dem_iv(path, fill, window, what)
    if path.suffix.lower() == ".npz":
        raster = _read_npz(path, what, window)
    else:
        raster = _read_gdal(path, what, window)
    raster, source_crs = _metric_square(raster, reproject, what)
    heights, origin, cell = _site_grid(raster, what)
    _heights_iv(heights, what)
    valid = np.isfinite(heights)
    if not valid.any():
        raise DataError(f"{what}: every cell is nodata (NaN/inf or the nodata value); check "
                        "the nodata value (e.g. gdal_edit.py -a_nodata) and the file")
    heights = fill_nodata(np.where(valid, heights, np.nan), "nearest")
    crs = None if raster.crs is None else raster.crs.to_wkt()
    return DEM(heights, origin, cell, crs, valid=None if fill == "nearest" else valid,
               source_crs=source_crs)


def to_dem_xy(dem: DEM, xy: np.ndarray) -> np.ndarray:
    """Points given in the DEM file's own CRS, in the DEM's site frame.

    Identity unless :func:`read_dem` reprojected the file (``dem.source_crs`` set): then
    e.g. station longitudes/latitudes in degrees become local metres.

    Parameters
    ----------
    dem : DEM
    xy : (n, 2) float
        Points in the file's CRS units (metres, or degrees for a geographic file).

    Returns
    -------
    xy_dem : (n, 2) float64
        The points in the DEM's frame (``dem.crs``), metres.

    Examples
    --------
    >>> to_dem_xy(DEM(np.zeros((2, 2)), (0.0, 0.0), 1.0), [[1.0, 2.0]]).tolist()
    [[1.0, 2.0]]
    """
    xy = np.array(xy, dtype=np.float64, ndmin=2)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise DataError(f"xy must have shape (n, 2), got {xy.shape}")
    if dem.source_crs is None or len(xy) == 0:
        return xy
    from rasterio.crs import CRS
    from rasterio.warp import transform

    xs, ys = transform(CRS.from_wkt(dem.source_crs), CRS.from_wkt(dem.crs), xy[:, 0], xy[:, 1])
    return np.column_stack([xs, ys])


#: Cells read beyond a ``window`` on every side (bilinear stencils and slopes at its edge).
WINDOW_PAD_CELLS = 2
#: CRS under which a grid without one is resampled (the site frame, metres).
_SITE_FRAME_WKT = ('ENGCRS["site frame",EDATUM["site"],CS[Cartesian,2],'
                   'AXIS["x",east,ORDER[1],LENGTHUNIT["metre",1]],'
                   'AXIS["y",north,ORDER[2],LENGTHUNIT["metre",1]]]')
#: Ellipsoid or sphere parameters of a PROJ dict, kept by the local CRS of a reprojection.
_SHAPE_KEYS = ("datum", "ellps", "R", "a", "b", "rf", "f", "towgs84")
#: How a refusal names the way out on reading (the CLI option, then the library call).
_REPROJECT_FIX = "pass --reproject (read_dem(..., reproject=True)) to resample it"


class _Raster(NamedTuple):
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


def _read_dem_iv(path: Path, fill: str | None, window, what: str) -> None:
    if fill is not None and fill not in FILL_POLICIES:
        raise ConfigError(f"fill must be one of {', '.join(FILL_POLICIES)} or None, got {fill!r}")
    if window is not None:
        w = np.asarray(window, dtype=float) if np.ndim(window) == 1 else np.zeros(0)
        if w.shape != (4,) or not np.isfinite(w).all() or w[0] > w[1] or w[2] > w[3]:
            raise ConfigError(f"window must be 4 finite numbers (xmin, xmax, ymin, ymax) with "
                              f"min <= max, got {window!r:.80}")
    if not path.exists():
        raise InputFileError(f"{what}: file does not exist; check the path")
    if path.is_dir():
        raise InputFileError(f"{what}: is a folder; give the raster file (for an ArcInfo "
                             "binary grid, its hdr.adf) or an .npz")
    if path.stat().st_size == 0:
        raise InputFileError(f"{what}: file is empty; give a raster GDAL reads (GeoTIFF, .asc, "
                             "VRT, ISIS3/PDS cube) or an .npz DEM")


def _heights_iv(heights: np.ndarray, what: str) -> None:
    """Shape, size and magnitude of a height grid (NaN/nodata cells are the mask's)."""
    if heights.ndim != 2 or min(heights.shape) < 2:
        raise DataError(f"{what}: a DEM needs a 2-D grid of at least 2 x 2 cells, got shape "
                        f"{heights.shape}")
    finite = heights[np.isfinite(heights)]
    if finite.size and np.abs(finite).max() > MAX_ABS_COORDINATE_M:
        worst = finite[np.abs(finite).argmax()]
        raise DataError(f"{what}: heights must lie within +-{MAX_ABS_COORDINATE_M:g} m, got "
                        f"{worst:g}; check the units, and declare the nodata value if that is "
                        "one (e.g. gdal_edit.py -a_nodata)")


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


def _read_gdal(path: Path, what: str, window) -> _Raster:
    """One band of a raster GDAL reads, nodata as NaN, over ``window`` (or all of it)."""
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
                return _Raster(np.ma.filled(band, np.nan), t, src.crs)
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


def _read_npz(path: Path, what: str, window) -> _Raster:
    """Our ``.npz`` as a raster (rows along +y), cells outside its ``valid`` member NaN."""
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
    return _Raster(heights, transform, _npz_crs(arrays.get("crs"), what, fix))


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


def _metric_square(raster: _Raster, reproject: bool, what: str
                   ) -> tuple[_Raster, str | None]:
    """The grid if metric, north-up and square; else refused, or resampled (``reproject``)
    with the file's CRS as WKT when it changed (else None)."""
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


def _local_crs(raster: _Raster, what: str):
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


def _reproject(raster: _Raster, what: str) -> tuple[_Raster, str | None]:
    """Bilinear resampling onto square metric cells (see :func:`read_dem`, ``reproject``)."""
    import math

    from rasterio.crs import CRS
    from rasterio.transform import Affine
    from rasterio.warp import Resampling, reproject, transform, transform_bounds

    src_crs = raster.crs if raster.crs is not None else CRS.from_wkt(_SITE_FRAME_WKT)
    metric = _crs_problem(raster.crs) is None
    dst_crs = src_crs if metric else _local_crs(raster, what)
    t = raster.transform
    rows, cols = raster.heights.shape
    # the smaller side, in metres, of the cell at the grid's centre
    steps = [t @ (cols / 2 + dc, rows / 2 + dr) for dc, dr in ((0, 0), (1, 0), (0, 1))]
    xs, ys = transform(src_crs, dst_crs, [p[0] for p in steps], [p[1] for p in steps])
    cell = min(math.hypot(xs[k] - xs[0], ys[k] - ys[0]) for k in (1, 2))
    corners = [t @ (c, r) for c in (0, cols) for r in (0, rows)]
    left, bottom, right, top = transform_bounds(
        src_crs, dst_crs, min(p[0] for p in corners), min(p[1] for p in corners),
        max(p[0] for p in corners), max(p[1] for p in corners), densify_pts=21)
    left, top = math.floor(left / cell) * cell, math.ceil(top / cell) * cell
    width, height = math.ceil((right - left) / cell), math.ceil((top - bottom) / cell)
    _check_cells(height, width, f"{what} reprojected")
    heights = np.full((height, width), np.nan)
    dst_transform = Affine(cell, 0.0, left, 0.0, -cell, top)
    reproject(raster.heights, heights, src_transform=t, src_crs=src_crs,
              dst_transform=dst_transform, dst_crs=dst_crs, src_nodata=np.nan,
              dst_nodata=np.nan, resampling=Resampling.bilinear)
    if metric:
        return _Raster(heights, dst_transform, raster.crs), None
    return _Raster(heights, dst_transform, dst_crs), raster.crs.to_wkt()


def _site_grid(raster: _Raster, what: str
               ) -> tuple[np.ndarray, tuple[float, float], float]:
    """Heights with rows along +y and columns along +x, origin (cell ``[0, 0]`` centre) and
    cell size of a north-up square grid, metres."""
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


def write_dem(path: str | Path, dem: DEM) -> Path:
    """Write ``dem`` as a GeoTIFF (``.tif``/``.tiff``, float64, CRS kept) or ``.npz``.

    The valid mask is kept: a GeoTIFF holds NaN under invalid cells and declares NaN its
    nodata value; an ``.npz`` holds the filled heights and a ``valid`` member (only when some
    cell is invalid). :func:`read_dem` reads both back to the same DEM.

    Raises
    ------
    OutputError
        Unsupported suffix or unwritable location.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    try:
        if suffix in (".tif", ".tiff"):
            _write_tif(path, dem)
        elif suffix == ".npz":
            mask = {} if dem.valid is None else {"valid": dem.valid}
            np.savez(path, heights_m=dem.heights_m, origin_m=np.array(dem.origin_m),
                     cell_size_m=np.array(dem.cell_size_m), crs=np.array(dem.crs or ""),
                     **mask)
        else:
            raise OutputError(f"DEM output {path} has suffix {suffix!r}; use .tif, .tiff or .npz")
    except OSError as exc:
        if isinstance(exc, OutputError):
            raise
        raise OutputError(f"cannot write DEM {path} ({exc}); choose a writable path") from exc
    return path


def _write_tif(path: Path, dem: DEM) -> None:
    import rasterio
    from rasterio.transform import Affine

    ny, nx = dem.shape
    c = dem.cell_size_m
    x0, y0 = dem.origin_m
    top = y0 + (ny - 0.5) * c
    transform = Affine(c, 0.0, x0 - 0.5 * c, 0.0, -c, top)
    profile = dict(driver="GTiff", height=ny, width=nx, count=1, dtype="float64",
                   transform=transform, crs=dem.crs,
                   nodata=None if dem.valid is None else np.nan)
    heights = np.where(dem.valid_mask(), dem.heights_m, np.nan)
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(heights[::-1], 1)
