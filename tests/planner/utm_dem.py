"""A synthetic DEM as a real survey delivers one: UTM coordinates, nodata around an irregular
measured area, for the tests of planning on real DEMs."""

import numpy as np

from visibility.dem import DEM

#: The DEM's lower-left cell centre: easting, northing in EPSG:32633 (UTM 33N), m.
ORIGIN = (500_000.0, 4_100_000.0)
#: Cell size, m; the grid is 80 m x 80 m.
CELL = 0.5
#: Stations on measured terrain: (id, easting offset, northing offset) from ORIGIN, m; S4
#: stands east of the nodata gap, the others west of it.
STATIONS = (("S1", 22.0, 40.0), ("S2", 40.0, 30.0), ("S3", 50.0, 44.0), ("S4", 67.0, 40.0))


def local_grid() -> tuple[np.ndarray, np.ndarray]:
    """Cell-centre offsets from :data:`ORIGIN`: ``x``, ``y`` (161, 161), m."""
    u = np.arange(161) * CELL
    return np.meshgrid(u, u)


def utm_mask() -> np.ndarray:
    """(161, 161) bool: an ellipse of measured terrain with a notch cut in from the north and a
    nodata gap (x 58-60 m, y 25-50 m) inside it; nodata all around."""
    x, y = local_grid()
    valid = ((x - 40) / 36) ** 2 + ((y - 40) / 30) ** 2 <= 1.0
    valid &= ~((x >= 36) & (x <= 44) & (y >= 52))
    valid &= ~((x >= 58) & (x <= 60) & (y >= 25) & (y <= 50))
    return valid


def utm_dem() -> DEM:
    """The 80 m x 80 m DEM at 0.5 m cells in EPSG:32633 with :func:`utm_mask` as its valid
    cells; gentle bumps (slopes below 5 degrees)."""
    from rasterio.crs import CRS

    x, y = local_grid()
    heights = 0.2 * np.sin(x / 5.0) + 0.15 * np.cos(y / 4.0)
    return DEM(heights, ORIGIN, CELL, CRS.from_epsg(32633).to_wkt(), valid=utm_mask())


def write_stations(path) -> None:
    """:data:`STATIONS` as a stations CSV in UTM coordinates."""
    rows = [f"{sid},{ORIGIN[0] + dx:.1f},{ORIGIN[1] + dy:.1f}" for sid, dx, dy in STATIONS]
    path.write_text("id,x_m,y_m\n" + "\n".join(rows) + "\n")
