"""Digital elevation models on a regular grid in the local site frame (W).

A :class:`DEM` stores heights at cell centres: cell ``[j, i]`` (row ``j``, column ``i``) is at
site coordinates ``(x0 + i * cell, y0 + j * cell)``. Rows run along +y, columns along +x
(so a GeoTIFF, whose first row is the northern edge, is flipped on reading and writing).

Files: ``.tif``/``.tiff`` through rasterio (CRS kept as WKT), ``.npz`` with members
``heights_m``, ``origin_m``, ``cell_size_m`` and ``crs``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplan.errors import ConfigError, DataError, InputFileError, OutputError

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
    """

    heights_m: np.ndarray
    origin_m: tuple[float, float]
    cell_size_m: float
    crs: str | None = None

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

    def slope_rad(self) -> np.ndarray:
        """Terrain slope of each cell (central differences), radians, shape (ny, nx)."""
        gy, gx = np.gradient(self.heights_m, self.cell_size_m)
        return np.arctan(np.hypot(gx, gy))


def _refuse_nan(heights: np.ndarray, source: str) -> None:
    bad = ~np.isfinite(heights)
    if bad.any():
        raise DataError(f"{source} has {int(bad.sum())} NaN/nodata cells of {heights.size}; "
                        "fill them (read_dem(..., fill='nearest') or --dem-fill nearest) or crop "
                        "the DEM")


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


def read_dem(path: str | Path, fill: str | None = None) -> DEM:
    """Read a DEM from a GeoTIFF (``.tif``/``.tiff``, first band) or ``.npz``.

    Parameters
    ----------
    path : str or Path
        DEM file. GeoTIFF pixels must be square; the CRS is kept.
    fill : {None, "nearest"}
        Policy for NaN/nodata cells; ``None`` refuses them.

    Returns
    -------
    dem : DEM
        Site frame = the file's map coordinates (GeoTIFF) or stored origin (``.npz``).

    Raises
    ------
    InputFileError
        Missing or unreadable file, unsupported suffix, non-square or rotated pixels.
    DataError
        NaN/nodata cells and ``fill=None``.
    """
    path = Path(path)
    if fill is not None and fill not in FILL_POLICIES:
        raise ConfigError(f"fill must be one of {', '.join(FILL_POLICIES)} or None, got {fill!r}")
    if not path.is_file():
        raise InputFileError(f"DEM file {path} does not exist; check the path")
    suffix = path.suffix.lower()
    if suffix in (".tif", ".tiff"):
        heights, origin, cell, crs = _read_tif(path)
    elif suffix == ".npz":
        heights, origin, cell, crs = _read_npz(path)
    else:
        raise InputFileError(f"DEM file {path} has suffix {suffix!r}; use .tif, .tiff or .npz")
    if fill is None:
        _refuse_nan(heights, f"DEM {path}")
    else:
        heights = fill_nodata(heights, fill)
    return DEM(heights, origin, cell, crs)


def _read_tif(path: Path) -> tuple[np.ndarray, tuple[float, float], float, str | None]:
    import rasterio

    try:
        with rasterio.open(path) as src:
            band = src.read(1, masked=True).astype(np.float64)
            t = src.transform
            crs = src.crs.to_wkt() if src.crs is not None else None
    except rasterio.errors.RasterioError as exc:
        raise InputFileError(f"DEM file {path} is not a readable GeoTIFF ({exc})") from exc
    if t.b != 0 or t.d != 0 or not np.isclose(abs(t.a), abs(t.e), rtol=1e-9):
        raise InputFileError(f"DEM {path}: pixels must be square and north-up, got transform "
                             f"{tuple(t)[:6]}; resample it first (e.g. gdalwarp -tr)")
    heights = np.ma.filled(band, np.nan)
    cell = abs(t.a)
    ny, nx = heights.shape
    x0 = t.c + 0.5 * t.a
    if t.e < 0:  # first row is the top (max y): flip so rows run along +y
        heights = heights[::-1]
        y0 = t.f + (ny - 0.5) * t.e
    else:
        y0 = t.f + 0.5 * t.e
    return heights, (x0, y0), cell, crs


def _read_npz(path: Path) -> tuple[np.ndarray, tuple[float, float], float, str | None]:
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in ("heights_m", "origin_m", "cell_size_m") if k not in z.files]
            if missing:
                raise InputFileError(f"DEM file {path} lacks {', '.join(missing)}; write it with "
                                     "visibility.dem.write_dem")
            crs = str(z["crs"]) if "crs" in z.files and str(z["crs"]) else None
            return (z["heights_m"].astype(np.float64), tuple(z["origin_m"].tolist()),
                    float(z["cell_size_m"]), crs)
    except (OSError, ValueError) as exc:
        raise InputFileError(f"DEM file {path} is not a readable .npz ({exc})") from exc


def write_dem(path: str | Path, dem: DEM) -> Path:
    """Write ``dem`` as a GeoTIFF (``.tif``/``.tiff``, float64, CRS kept) or ``.npz``.

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
            np.savez(path, heights_m=dem.heights_m, origin_m=np.array(dem.origin_m),
                     cell_size_m=np.array(dem.cell_size_m), crs=np.array(dem.crs or ""))
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
                   transform=transform, crs=dem.crs)
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(dem.heights_m[::-1], 1)
