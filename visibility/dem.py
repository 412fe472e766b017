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

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplan.errors import ConfigError, DataError, InputFileError, OutputError
from markerplan.reading import MAX_ABS_COORDINATE_M
from visibility.dem_raster import (
    MAX_DEM_CELLS,
    WINDOW_PAD_CELLS,
    metric_square,
    read_gdal,
    read_npz,
    site_grid,
)

__all__ = ["DEM", "FILL_POLICIES", "MAX_DEM_CELLS", "WINDOW_PAD_CELLS", "fill_nodata",
           "read_dem", "read_dem_by_window", "to_dem_xy", "write_dem"]

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

    def crop(self, xmin: float, xmax: float, ymin: float, ymax: float) -> DEM:
        """The sub-grid whose triangles cover the rectangle, clipped to the grid (a tile).

        Cells are kept whole and on the same grid (no resampling), and the tile starts on an even
        row and column, so its mesh is made of the same triangles as the whole DEM's mesh over
        the rectangle (the diagonals' checkerboard of :func:`visibility.mesh.dem_to_mesh` runs
        from cell ``[0, 0]``).

        Parameters
        ----------
        xmin, xmax, ymin, ymax : float
            Rectangle to cover, site frame, metres.

        Returns
        -------
        tile : DEM
            Same cell size, CRS and source CRS; heights and valid mask cut out; at most two cells
            beyond the rectangle on its low sides and one on its high sides.

        Raises
        ------
        DataError
            The rectangle misses the grid, or covers only nodata.

        Examples
        --------
        >>> dem = DEM(np.arange(100.0).reshape(10, 10), (0.0, 0.0), 1.0)
        >>> t = dem.crop(2.5, 4.0, 0.0, 1.2)
        >>> t.origin_m, t.shape
        ((2.0, 0.0), (3, 3))
        """
        x0, y0 = self.origin_m
        ny, nx = self.shape
        c = self.cell_size_m
        i0 = max(int(np.floor((xmin - x0) / c)), 0)
        i0 -= i0 % 2
        i1 = min(int(np.ceil((xmax - x0) / c)), nx - 1)
        j0 = max(int(np.floor((ymin - y0) / c)), 0)
        j0 -= j0 % 2
        j1 = min(int(np.ceil((ymax - y0) / c)), ny - 1)
        if i1 - i0 < 1 or j1 - j0 < 1:
            raise DataError(f"the rectangle x {xmin:g}..{xmax:g}, y {ymin:g}..{ymax:g} m misses "
                            "the DEM; keep stations and markers on the DEM")
        rows, cols = slice(j0, j1 + 1), slice(i0, i1 + 1)
        return DEM(self.heights_m[rows, cols], (x0 + i0 * c, y0 + j0 * c), c, crs=self.crs,
                   valid=None if self.valid is None else self.valid[rows, cols],
                   source_crs=self.source_crs)

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
            need = ""
            if len(xy) > 1:
                (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0)
                need = (f"the {len(xy)} {label}s need [{x0:.1f}, {x1:.1f}] x [{y0:.1f}, "
                        f"{y1:.1f}] m; ")
            raise DataError(f"{label} {ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m lies "
                            f"outside the DEM {self._size_text()}; {need}{fix}")
        on_data = self.valid_at(xy)
        if not on_data.all():
            k = int(np.flatnonzero(~on_data)[0])
            raise DataError(f"{label} {ids[k]} at ({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) m stands on "
                            f"DEM nodata (no measured terrain there); a {label} must stand on "
                            "data: move it onto the DEM's valid area or use a DEM with data "
                            "there")

    def _size_text(self) -> str:
        """The grid's size and extent for messages: ``(ny x nx cells of c m) [xmin, xmax] x
        [ymin, ymax] m`` (cell centres, site frame)."""
        ny, nx = self.shape
        xmin, xmax, ymin, ymax = self.extent()
        return (f"({ny} x {nx} cells of {self.cell_size_m:g} m) [{xmin:.1f}, {xmax:.1f}] x "
                f"[{ymin:.1f}, {ymax:.1f}] m")

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
        i, j, u, v = self._stencil(xy)
        h = self.heights_m
        return ((1 - u) * (1 - v) * h[j, i] + u * (1 - v) * h[j, i + 1]
                + (1 - u) * v * h[j + 1, i] + u * v * h[j + 1, i + 1])

    def _stencil(self, xy: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The bilinear stencil of each point: lower-left cell ``(i, j)`` (column, row; the
        stencil is cells ``i, i + 1`` by ``j, j + 1``, clipped onto the grid) and the point's
        fractions ``(u, v)`` across it (in [0, 1] for points on the grid).

        Parameters
        ----------
        xy : (n, 2) float
            Site-frame points, metres (NaN allowed: its stencil is a clipped placeholder).

        Returns
        -------
        i, j : (n,) int64
        u, v : (n,) float64
        """
        ny, nx = self.shape
        fx = (xy[:, 0] - self.origin_m[0]) / self.cell_size_m
        fy = (xy[:, 1] - self.origin_m[1]) / self.cell_size_m
        i = np.clip(np.floor(np.nan_to_num(fx)).astype(np.int64), 0, nx - 2)
        j = np.clip(np.floor(np.nan_to_num(fy)).astype(np.int64), 0, ny - 2)
        return i, j, fx - i, fy - j

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
        i, j, _, _ = self._stencil(xy)
        v = self.valid
        return inside & v[j, i] & v[j, i + 1] & v[j + 1, i] & v[j + 1, i + 1]

    def slope_rad(self) -> np.ndarray:
        """Terrain slope of each cell (central differences), radians, shape (ny, nx)."""
        gy, gx = np.gradient(self.heights_m, self.cell_size_m)
        return np.arctan(np.hypot(gx, gy))


#: Fix named by :class:`DEM` for NaN cells (library users build DEMs from arrays).
_ARRAY_NODATA_FIX = ("fill them and mark them invalid (DEM(fill_nodata(h, 'nearest'), ..., "
                     "valid=np.isfinite(h))), or read the file with visibility.dem.read_dem")


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
             *, reproject: bool = False,
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
        Unknown ``fill``; a ``window`` that is not 4 finite numbers with min <= max.

    Examples
    --------
    A window of one cell's width (column 1, row 1), padded by 2 cells and clipped:

    >>> import os, tempfile
    >>> dem = DEM(np.arange(30.0).reshape(5, 6), (500.5, 20.5), 1.0)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = write_dem(os.path.join(folder, "d.npz"), dem)
    ...     part = read_dem(path, window=(501.2, 501.4, 21.6, 21.8))
    >>> part.origin_m, part.shape
    ((500.5, 20.5), (4, 4))
    """
    path = Path(path)
    what = what or f"DEM {path}"
    _read_dem_iv(path, fill, window, what)
    if path.suffix.lower() == ".npz":
        raster = read_npz(path, what, window)
    else:
        raster = read_gdal(path, what, window)
    raster, source_crs = metric_square(raster, reproject, what)
    heights, origin, cell = site_grid(raster, what)
    _heights_iv(heights, what)
    valid = np.isfinite(heights)
    if not valid.any():
        raise DataError(f"{what}: every cell is nodata (NaN/inf or the nodata value); check "
                        "the nodata value (e.g. gdal_edit.py -a_nodata) and the file")
    heights = fill_nodata(np.where(valid, heights, np.nan), "nearest")
    crs = None if raster.crs is None else raster.crs.to_wkt()
    return DEM(heights, origin, cell, crs, valid=None if fill == "nearest" else valid,
               source_crs=source_crs)


def read_dem_by_window(path: str | Path, window: tuple[float, float, float, float] | None,
                       fill: str | None = None, what: str | None = None, *,
                       reproject: bool = False) -> tuple[DEM, tuple | None]:
    """:func:`read_dem` by ``window`` when that part holds data, else whole: how a DEM too
    large to read whole is read around the points that use it (stations and what they see).

    A window that finds no data means those points stand off the DEM's data (or the file is
    refused whatever part is read, e.g. for its CRS); the whole file is then read so that the
    one-line error names the real cause (the point, the CRS) rather than the window.

    Parameters
    ----------
    path, fill, what, reproject
        As :func:`read_dem`.
    window : (xmin, xmax, ymin, ymax) float or None
        As :func:`read_dem`, file CRS units; ``None``: read whole.

    Returns
    -------
    dem : DEM
    window : (xmin, xmax, ymin, ymax) float or None
        The window ``dem`` was read by; ``None``: the whole file.

    Raises
    ------
    InputFileError, DataError, ConfigError
        As :func:`read_dem` reading the whole file.
    """
    if window is not None:
        try:
            return read_dem(path, fill, what, reproject=reproject, window=window), window
        except DataError:
            pass
    return read_dem(path, fill, what, reproject=reproject), None


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


def _read_dem_iv(path: Path, fill: str | None, window, what: str) -> None:
    if fill is not None and fill not in FILL_POLICIES:
        raise ConfigError(f"fill must be one of {', '.join(FILL_POLICIES)} or None, got {fill!r}")
    if window is not None:
        try:
            w = np.asarray(window, dtype=float)
        except (TypeError, ValueError):
            w = np.zeros(0)
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
