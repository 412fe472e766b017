"""The area of interest (AOI): a GeoJSON polygon on the DEM, site frame.

An AOI must lie inside the DEM's extent (the outer edges of its cells) and on measured
terrain: coverage cannot be predicted on nodata. Each refusal is one
:class:`~markerplan.errors.InputFileError` line naming `aoi_path`, the figures and the fix.
"""

from __future__ import annotations

import numpy as np
import shapely

from markerplan.errors import InputFileError
from planner.problem.candidates import load_polygons
from planner.problem.inputs import polygons_on_dem

#: How messages name the AOI file.
AOI_OPTION = "`aoi_path`"


def read_aoi(path, dem):
    """Read the AOI from a GeoJSON file and place it on the DEM.

    Parameters
    ----------
    path : str or Path
        GeoJSON Polygon(s) or MultiPolygon(s) in the DEM file's CRS (site frame, m; a
        reprojected DEM's source CRS, mapped like the other inputs by
        :func:`planner.problem.inputs.polygons_on_dem`). Several polygons are joined.
    dem : visibility.dem.DEM
        Terrain, site frame.

    Returns
    -------
    aoi : shapely Polygon or MultiPolygon
        Site frame, m.

    Raises
    ------
    InputFileError
        A malformed file (:func:`planner.problem.candidates.load_polygons`), an AOI reaching
        off the DEM's extent, or one with DEM cells on nodata.
    """
    what = f"{AOI_OPTION} {path}"
    aoi = shapely.union_all(polygons_on_dem(load_polygons(path, AOI_OPTION), dem))
    off_dem_problem(aoi, dem, what)
    nodata_problem(aoi, dem, what)
    return aoi


def off_dem_problem(aoi, dem, what: str) -> None:
    """Refuse an AOI (partly) outside the DEM's extent (its cells' outer edges, as a GeoTIFF's
    bounds), with the area off it and both bounds.

    Parameters
    ----------
    aoi : shapely Polygon or MultiPolygon
        Site frame, m.
    dem : visibility.dem.DEM
    what : str
        How the message names the AOI.

    Raises
    ------
    InputFileError
    """
    h = 0.5 * dem.cell_size_m
    xmin, xmax, ymin, ymax = np.add(dem.extent(), [-h, h, -h, h])
    off = aoi.difference(shapely.box(xmin, ymin, xmax, ymax)).area
    if off > 0:
        x0, y0, x1, y1 = aoi.bounds
        share = off / aoi.area
        raise InputFileError(
            f"{what}: {off:.1f} m^2 of the AOI ({share:.0%}) lies off the DEM (AOI "
            f"[{x0:.1f}, {x1:.1f}] x [{y0:.1f}, {y1:.1f}] m); draw it inside the DEM's extent "
            f"[{xmin:.1f}, {xmax:.1f}] x [{ymin:.1f}, {ymax:.1f}] m (site frame) or use a DEM "
            "covering it")


def nodata_problem(aoi, dem, what: str) -> None:
    """Refuse an AOI over DEM cells on nodata, with their number and share.

    A DEM cell counts as under the AOI when its centre lies within ``0.75`` cell of the AOI
    (every cell whose footprint touches the AOI, and a few corner cells more), so that every
    AOI grid cell's centre (:func:`planner.coverage.grid.aoi_grid`) falls in a checked cell.

    Parameters
    ----------
    aoi : shapely Polygon or MultiPolygon
        Site frame, m, inside the DEM's extent.
    dem : visibility.dem.DEM
    what : str
        How the message names the AOI.

    Raises
    ------
    InputFileError
    """
    if dem.valid is None:
        return
    under = aoi.buffer(0.75 * dem.cell_size_m)
    x, y = dem.grid_xy()
    x0, y0, x1, y1 = under.bounds
    cols = np.flatnonzero((x >= x0) & (x <= x1))
    rows = np.flatnonzero((y >= y0) & (y <= y1))
    gx, gy = np.meshgrid(x[cols], y[rows])
    inside = shapely.contains_xy(under, gx, gy)
    bad = inside & ~dem.valid[np.ix_(rows, cols)]
    n_in, n_bad = int(inside.sum()), int(bad.sum())
    if n_bad:
        bx, by = gx[bad], gy[bad]
        raise InputFileError(
            f"{what}: {n_bad} of the {n_in} DEM cells under the AOI ({n_bad / n_in:.0%}) lie "
            f"on DEM nodata (in [{bx.min():.1f}, {bx.max():.1f}] x [{by.min():.1f}, "
            f"{by.max():.1f}] m), where coverage cannot be predicted; draw the AOI on measured "
            "terrain or use a DEM with data there")
