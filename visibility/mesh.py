"""DEM -> triangle mesh recentred to a local origin (Embree works in float32)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from visibility.dem import DEM


@dataclass
class LocalMesh:
    """A triangle mesh in a local frame: ``p_site = vertices_local + origin_m``.

    Attributes
    ----------
    vertices_local : (v, 3) float32
        Vertices relative to ``origin_m``, metres.
    faces : (f, 3) int32
        Vertex indices of each triangle.
    origin_m : (3,) float64
        Site-frame position of the local origin, metres.
    """

    vertices_local: np.ndarray
    faces: np.ndarray
    origin_m: np.ndarray

    @property
    def n_triangles(self) -> int:
        return int(self.faces.shape[0])


def dem_origin(dem: DEM) -> np.ndarray:
    """A local origin for ``dem``: centre of its extent at its mean height, site frame (3,)."""
    xmin, xmax, ymin, ymax = dem.extent()
    return np.array([(xmin + xmax) / 2, (ymin + ymax) / 2, float(dem.heights_m.mean())])


def dem_to_mesh(dem: DEM, origin_m: np.ndarray | None = None) -> LocalMesh:
    """Triangulate ``dem``: each cell between four centres becomes two triangles.

    Parameters
    ----------
    dem : DEM
    origin_m : (3,) float, optional
        Local origin, site frame; default :func:`dem_origin`.

    Returns
    -------
    mesh : LocalMesh
        ``2 (ny - 1)(nx - 1)`` triangles; the diagonal alternates per cell (checkerboard)
        so no direction is favoured.
    """
    origin = dem_origin(dem) if origin_m is None else np.asarray(origin_m, dtype=float)
    ny, nx = dem.shape
    x, y = dem.grid_xy()
    vx = np.broadcast_to((x - origin[0])[None, :], (ny, nx))
    vy = np.broadcast_to((y - origin[1])[:, None], (ny, nx))
    vertices = np.stack([vx, vy, dem.heights_m - origin[2]], axis=-1).reshape(-1, 3)
    idx = np.arange(ny * nx, dtype=np.int64).reshape(ny, nx)
    a, b = idx[:-1, :-1], idx[:-1, 1:]
    c, d = idx[1:, :-1], idx[1:, 1:]
    flip = ((np.arange(ny - 1)[:, None] + np.arange(nx - 1)[None, :]) % 2).astype(bool)
    t1 = np.where(flip[..., None], np.stack([a, b, c], -1), np.stack([a, b, d], -1))
    t2 = np.where(flip[..., None], np.stack([b, d, c], -1), np.stack([a, d, c], -1))
    faces = np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)]).astype(np.int32)
    return LocalMesh(vertices.astype(np.float32), faces, origin)


def icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit icosphere (vertices on the unit sphere).

    Returns
    -------
    vertices : (v, 3) float64
    faces : (f, 3) int64
        ``f = 20 * 4**subdivisions``.
    """
    t = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
                 dtype=float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = v[uniq[:, 0]] + v[uniq[:, 1]]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = inv.reshape(3, -1) + len(v)
        v = np.concatenate([v, mid])
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        ab, bc, ca = m[0], m[1], m[2]
        f = np.concatenate([np.stack([a, ab, ca], 1), np.stack([b, bc, ab], 1),
                            np.stack([c, ca, bc], 1), np.stack([ab, bc, ca], 1)])
    return v, f


def inscribed_radius_ratio(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Smallest distance from the centre to a face plane of a unit icosphere (< 1)."""
    tri = vertices[faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return float(np.min(np.abs(np.einsum("ij,ij->i", n, tri[:, 0]))))
