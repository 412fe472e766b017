"""Where the rover may drive and stop: a trafficability grid over the DEM.

A :class:`TrafficMap` is a grid of nodes aligned with the DEM: node ``[r, c]`` sits on DEM
cell ``[k * r, k * c]`` (``k`` = ``grid_m / cell_size_m``, a whole number), so it is at site
coordinates ``(x0 + c * grid_m, y0 + r * grid_m)``. A node is trafficable when the rover,
centred there, stands on measured terrain, outside every keep-out polygon and crater interior,
on a footprint whose best-fit plane is no steeper than ``max_slope_deg`` and whose RMS residual
about that plane is at most ``max_roughness_m``, and at least ``hazard_standoff_m`` from every
node that fails one of these rules. Each non-trafficable node records its first failing reason
(:data:`REASONS`, in that priority order).

The plane is fitted by least squares over the square window of DEM cells centred on the node
whose side is the odd number of cells nearest to ``footprint_m`` (box filters of the window's
moments, so the whole DEM is fitted at once).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import shapely
from scipy import ndimage

from markerplan.errors import ConfigError

__all__ = ["LIMITS", "REASONS", "TrafficMap", "TrafficSettings", "trafficable_map"]

#: The settings a message names when too little ground is trafficable.
LIMITS = "`max_slope_deg`, `max_roughness_m` or `hazard_standoff_m`"

#: Why a node is not trafficable, in priority order (a node records the first that applies);
#: code ``k + 1`` in :attr:`TrafficMap.reason` is ``REASONS[k]``, 0 is trafficable.
REASONS = ("nodata or edge", "keep-out", "crater interior", "slope", "roughness", "standoff")


@dataclass(frozen=True)
class TrafficSettings:
    """What ground a small lunar rover can drive and stop on.

    Attributes
    ----------
    footprint_m : float
        Side of the square over which slope and roughness are judged, metres: the rover's wheel
        base. Default 1.5 m, a small lunar rover (Yutu-2 is 1.5 m x 1.0 m; VIPER 1.5 m) with
        the LiDAR turntable mast on it.
    max_slope_deg : float
        Steepest best-fit plane over the footprint the rover may drive and level the turntable
        on, degrees. Default 15 deg: below the 20-25 deg that rovers of this class are rated to
        climb on regolith (Yutu-2: 20 deg), a margin for wheel slip and for scanning from a
        stable stance.
    max_roughness_m : float
        Largest RMS residual of the DEM about the footprint's best-fit plane, metres. Default
        0.03 m: a rock 0.3 m across, buried by 30 % (0.21 m high), alone in a 1.5 m footprint
        gives 0.030 m (a spherical cap on a 0.1 m grid, fitted like here); 0.2 m is the obstacle
        height a rover of this class is rated to cross (Yutu-2: 0.2 m). On the ``default``
        preset (2 cm RMS micro-relief at 1 m) it leaves 1.7 % of the nodes too rough, those
        among the rocks; 0.06 m would let 0.45 m rocks pass. On an orbital-grade DEM (height
        error 0.3 m RMS) the error itself is that rough: raise it to about 0.2 m there.
    hazard_standoff_m : float
        Every node closer than this to a non-trafficable node is not trafficable either,
        metres. Default 0.5 m: the footprint already keeps the rover's body off the hazard;
        the standoff adds the rover's localisation drift between stops and a few cells of the
        planning DEM's horizontal error (planning on the 2 m posts of an orbital DEM needs
        about 2 m).
    grid_m : float
        Node spacing of the map, metres; a whole number of DEM cells. Default 0.5 m: fine enough
        to thread between the metre-scale craters of the presets, coarse enough that the
        ground-path graph of a 300 m site has under a million nodes.
    """

    footprint_m: float = 1.5
    max_slope_deg: float = 15.0
    max_roughness_m: float = 0.03
    hazard_standoff_m: float = 0.5
    grid_m: float = 0.5

    def __post_init__(self) -> None:
        for name in ("footprint_m", "grid_m"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"`{name}` must be a positive number of metres, got {v!r}")
        for name in ("max_roughness_m", "hazard_standoff_m"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"`{name}` must be zero or a positive number of metres, "
                                  f"got {v!r}")
        if not (0 < self.max_slope_deg < 90):
            raise ConfigError(f"`max_slope_deg` must lie in (0, 90) degrees, got "
                              f"{self.max_slope_deg!r}")


@dataclass(frozen=True)
class TrafficMap:
    """Trafficable nodes on a grid aligned with the DEM, site frame.

    Attributes
    ----------
    trafficable : (nr, nc) bool
        Whether the rover may drive and stop at each node.
    reason : (nr, nc) uint8
        0 where trafficable, else ``1 + k`` for the first failing rule ``REASONS[k]``.
    origin_m : tuple of float
        ``(x0, y0)``: site coordinates of node ``[0, 0]`` (the DEM's cell ``[0, 0]``), metres.
    grid_m : float
        Node spacing, metres.
    settings : TrafficSettings
        The rules applied.
    """

    trafficable: np.ndarray
    reason: np.ndarray
    origin_m: tuple[float, float]
    grid_m: float
    settings: TrafficSettings

    @property
    def shape(self) -> tuple[int, int]:
        return self.trafficable.shape  # type: ignore[return-value]

    def node_xy(self) -> np.ndarray:
        """(nr * nc, 2) site coordinates of every node, row-major (rows along +y), metres."""
        nr, nc = self.shape
        xx, yy = np.meshgrid(self.origin_m[0] + self.grid_m * np.arange(nc),
                             self.origin_m[1] + self.grid_m * np.arange(nr))
        return np.column_stack([xx.ravel(), yy.ravel()])

    def window(self, xmin: float, xmax: float, ymin: float, ymax: float) -> TrafficMap:
        """The map's nodes within a rectangle (site frame, metres; at least one node).

        Drives over the window stay inside it: a window around the area the rover works in
        keeps the ground-path graph small on a large site.

        Examples
        --------
        >>> tm = TrafficMap(np.ones((5, 6), bool), np.zeros((5, 6), np.uint8), (0.0, 0.0), 1.0,
        ...                 TrafficSettings())
        >>> w = tm.window(1.2, 3.0, 0.0, 1.4)
        >>> w.shape, w.origin_m
        ((2, 3), (1.0, 0.0))
        """
        nr, nc = self.shape
        c0, c1 = (int(np.clip(np.rint((v - self.origin_m[0]) / self.grid_m), 0, nc - 1))
                  for v in (xmin, xmax))
        r0, r1 = (int(np.clip(np.rint((v - self.origin_m[1]) / self.grid_m), 0, nr - 1))
                  for v in (ymin, ymax))
        rows, cols = slice(r0, r1 + 1), slice(c0, c1 + 1)
        return replace(self, trafficable=self.trafficable[rows, cols],
                       reason=self.reason[rows, cols],
                       origin_m=(self.origin_m[0] + c0 * self.grid_m,
                                 self.origin_m[1] + r0 * self.grid_m))

    def node_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The nearest node of each point and whether the point lies on the grid.

        Parameters
        ----------
        xy : (n, 2) float
            Site-frame points, metres.

        Returns
        -------
        flat : (n,) int64
            Row-major index of the nearest node (clipped onto the grid).
        on_grid : (n,) bool
            Whether the point lies within half a node spacing of the grid's nodes.
        """
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        nr, nc = self.shape
        c = np.rint((xy[:, 0] - self.origin_m[0]) / self.grid_m)
        r = np.rint((xy[:, 1] - self.origin_m[1]) / self.grid_m)
        on_grid = (c >= 0) & (c < nc) & (r >= 0) & (r < nr)
        c = np.clip(np.nan_to_num(c), 0, nc - 1).astype(np.int64)
        r = np.clip(np.nan_to_num(r), 0, nr - 1).astype(np.int64)
        return r * nc + c, on_grid

    def trafficable_at(self, xy: np.ndarray) -> np.ndarray:
        """(n,) bool: whether each point's nearest node is trafficable (False off the grid)."""
        flat, on_grid = self.node_of(xy)
        return on_grid & self.trafficable.ravel()[flat]

    def why_not(self, xy: np.ndarray) -> list[str]:
        """Each point's reason for not being trafficable (``""`` where it is; ``"off the
        DEM"`` off the grid)."""
        flat, on_grid = self.node_of(xy)
        codes = self.reason.ravel()[flat]
        return [("" if k == 0 else REASONS[k - 1]) if inside else "off the DEM"
                for k, inside in zip(codes.tolist(), on_grid.tolist(), strict=True)]

    def nearest_trafficable(self, xy: np.ndarray) -> np.ndarray:
        """(n, 2) the trafficable node nearest to each point, site frame, metres.

        Raises
        ------
        ConfigError
            If no node is trafficable.
        """
        from scipy.spatial import cKDTree

        nodes = self.node_xy()[self.trafficable.ravel()]
        if not len(nodes):
            raise ConfigError(f"no ground is trafficable; relax {LIMITS}")
        return nodes[cKDTree(nodes).query(np.atleast_2d(xy))[1]]

    def counts(self) -> dict[str, int]:
        """Node count per outcome: ``"trafficable"`` and each of :data:`REASONS`."""
        n = np.bincount(self.reason.ravel(), minlength=len(REASONS) + 1)
        return {"trafficable": int(n[0]), **{r: int(n[k + 1]) for k, r in enumerate(REASONS)}}


def trafficable_map(dem, settings: TrafficSettings = TrafficSettings(), craters=(),
                    keepouts=()) -> TrafficMap:
    """Trafficable ground of a DEM.

    Parameters
    ----------
    dem : visibility.dem.DEM
        Terrain, site frame; nodes whose footprint reaches nodata or past the DEM's edge are
        not trafficable ("nodata or edge").
    settings : TrafficSettings
    craters : sequence
        Objects with ``centre_xy_m`` and ``diameter_m`` (:class:`visibility.terrain.Crater`);
        nodes inside a rim crest (closer than ``diameter_m / 2`` to the centre) are "crater
        interior".
    keepouts : sequence of shapely Polygon
        Areas the rover must not enter (site frame), e.g. from
        :func:`planner.problem.candidates.load_polygons`.

    Returns
    -------
    traffic : TrafficMap

    Raises
    ------
    ConfigError
        ``grid_m`` not a whole number of DEM cells, or a footprint smaller than a node spacing
        or than 3 DEM cells.

    Examples
    --------
    >>> from visibility.dem import DEM
    >>> x = np.arange(40) * 0.1
    >>> dem = DEM(np.tile(np.tan(np.radians(10.0)) * x, (40, 1)), (0.0, 0.0), 0.1)
    >>> tm = trafficable_map(dem, TrafficSettings(footprint_m=0.5, hazard_standoff_m=0.0))
    >>> tm.shape, tm.counts()["trafficable"], tm.counts()["nodata or edge"]
    ((8, 8), 49, 15)
    """
    k, half = _trafficable_iv(dem, settings)
    cell = dem.cell_size_m
    h = dem.heights_m
    w = 2 * half + 1
    u = cell * np.arange(-half, half + 1)
    box = np.ones(w) / w

    def smooth(a, kx, ky):
        return ndimage.correlate1d(ndimage.correlate1d(a, kx, axis=1, mode="nearest"), ky,
                                   axis=0, mode="nearest")

    mean = smooth(h, box, box)
    suu = float(np.mean(u ** 2))
    gx = smooth(h, u / w / suu, box)
    gy = smooth(h, box, u / w / suu)
    var = smooth(h * h, box, box) - mean ** 2 - suu * (gx ** 2 + gy ** 2)
    sub = (slice(0, None, k), slice(0, None, k))
    slope = np.arctan(np.hypot(gx[sub], gy[sub]))
    rough = np.sqrt(np.maximum(var[sub], 0.0))
    on_data = ndimage.minimum_filter(dem.valid_mask().astype(np.uint8), size=w, mode="constant",
                                     cval=0)[sub].astype(bool)
    grid_m = k * cell
    nr, nc = slope.shape
    reason = np.zeros((nr, nc), np.uint8)

    def mark(mask, name):
        reason[(reason == 0) & mask] = REASONS.index(name) + 1

    mark(~on_data, "nodata or edge")
    xx, yy = np.meshgrid(dem.origin_m[0] + grid_m * np.arange(nc),
                         dem.origin_m[1] + grid_m * np.arange(nr))
    if len(keepouts):
        mark(shapely.intersects_xy(shapely.union_all(list(keepouts)), xx, yy), "keep-out")
    mark(_crater_interiors(craters, xx, yy, dem.origin_m, grid_m), "crater interior")
    mark(slope > np.radians(settings.max_slope_deg), "slope")
    mark(rough > settings.max_roughness_m, "roughness")
    if settings.hazard_standoff_m > 0 and (reason > 0).any():
        dist = ndimage.distance_transform_edt(reason == 0, sampling=grid_m)
        mark(dist <= settings.hazard_standoff_m, "standoff")
    return TrafficMap(trafficable=reason == 0, reason=reason, origin_m=dem.origin_m,
                      grid_m=grid_m, settings=settings)


def _trafficable_iv(dem, settings: TrafficSettings) -> tuple[int, int]:
    """Check the settings against the DEM: ``(k, half)``, the node stride and the footprint
    window's half-width, in DEM cells."""
    if not isinstance(settings, TrafficSettings):
        raise ConfigError(f"`settings` must be a TrafficSettings, got {type(settings).__name__}")
    cell = dem.cell_size_m
    k = int(round(settings.grid_m / cell))
    if k < 1 or abs(k * cell - settings.grid_m) > 1e-6 * cell:
        raise ConfigError(f"`grid_m` {settings.grid_m:g} m must be a whole number of DEM cells "
                          f"({cell:g} m); use e.g. {max(k, 1) * cell:g}")
    half = int(round((settings.footprint_m / cell - 1) / 2))  # window: 2 half + 1 cells
    if half < 1 or settings.footprint_m < settings.grid_m:
        raise ConfigError(f"`footprint_m` {settings.footprint_m:g} m must span at least 3 DEM "
                          f"cells ({3 * cell:g} m) and one node spacing (`grid_m` "
                          f"{settings.grid_m:g} m); raise `footprint_m`")
    return k, half


def _crater_interiors(craters, xx: np.ndarray, yy: np.ndarray, origin_m, grid_m: float
                      ) -> np.ndarray:
    """(nr, nc) bool: nodes strictly inside some crater's rim crest (each crater tested only
    over its bounding box of nodes)."""
    inside = np.zeros(xx.shape, bool)
    nr, nc = xx.shape
    for c in craters:
        cx, cy = c.centre_xy_m
        r = 0.5 * c.diameter_m
        c0 = max(int(np.floor((cx - r - origin_m[0]) / grid_m)), 0)
        c1 = min(int(np.ceil((cx + r - origin_m[0]) / grid_m)) + 1, nc)
        r0 = max(int(np.floor((cy - r - origin_m[1]) / grid_m)), 0)
        r1 = min(int(np.ceil((cy + r - origin_m[1]) / grid_m)) + 1, nr)
        if c0 >= c1 or r0 >= r1:
            continue
        box = (slice(r0, r1), slice(c0, c1))
        inside[box] |= np.hypot(xx[box] - cx, yy[box] - cy) < r
    return inside
