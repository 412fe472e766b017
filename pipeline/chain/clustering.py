"""Euclidean clustering: connected components of the "closer than tolerance" graph."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from markerplan.errors import ConfigError


def euclidean_clusters(xyz_m: np.ndarray, tolerance_m: float = 0.2, min_points: int = 5,
                       voxel_m: float | None = None) -> np.ndarray:
    """Label points by Euclidean clustering.

    Two points belong to one cluster when a chain of points links them with steps shorter
    than ``tolerance_m``. Clusters with fewer than ``min_points`` points are noise.

    Parameters
    ----------
    xyz_m : (N, 3) float
        Points, any frame, metres.
    tolerance_m : float
        Link distance, metres.
    min_points : int
        Smallest cluster kept (counted in points, not voxels).
    voxel_m : float, optional
        If given, link voxel centroids of this edge instead of points (default
        ``tolerance_m / 4``): identical clusters up to half a voxel, far fewer pairs.

    Returns
    -------
    labels : (N,) int
        Cluster label ``0..K-1`` (ordered by first point), ``-1`` for noise.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0, 0, 0], [0.1, 0, 0], [5, 0, 0], [5.1, 0, 0], [9, 0, 0.]])
    >>> euclidean_clusters(pts, 0.2, min_points=2).tolist()
    [0, 0, 1, 1, -1]
    """
    if xyz_m.ndim != 2 or xyz_m.shape[1] != 3:
        raise ConfigError(f"`xyz_m` must have shape (N, 3), got {xyz_m.shape}")
    if not tolerance_m > 0:
        raise ConfigError(f"clustering `tolerance_m` must be > 0 metres, got {tolerance_m}")
    if int(min_points) < 1:
        raise ConfigError(f"clustering `min_points` must be >= 1, got {min_points}")
    n = xyz_m.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    voxel = tolerance_m / 4 if voxel_m is None else voxel_m
    ijk = np.floor(xyz_m / voxel).astype(np.int64)
    ijk -= ijk.min(axis=0)
    dims = ijk.max(axis=0) + 1
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, first, inv = np.unique(keys, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    weight = np.bincount(inv)
    centroids = np.zeros((first.size, 3))
    np.add.at(centroids, inv, xyz_m)
    centroids /= weight[:, None]
    vox_labels = _components(centroids, tolerance_m, weight, min_points)
    labels = vox_labels[inv]
    ok = labels >= 0
    comp_ids, first_pt = np.unique(labels[ok], return_index=True)
    rank = np.empty(comp_ids.size, dtype=np.int64)
    rank[np.argsort(first_pt)] = np.arange(comp_ids.size)
    out = np.full(n, -1, dtype=np.int64)
    out[ok] = rank[np.searchsorted(comp_ids, labels[ok])]
    return out


def _components(xyz_m: np.ndarray, tolerance_m: float, weight: np.ndarray, min_points: int
                ) -> np.ndarray:
    """Connected components of weighted points; labels -1 where the total weight is small."""
    n = xyz_m.shape[0]
    pairs = cKDTree(xyz_m).query_pairs(tolerance_m, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])),
                       shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    counts = np.bincount(comp, weights=weight)
    return np.where(counts[comp] >= min_points, comp, -1)
