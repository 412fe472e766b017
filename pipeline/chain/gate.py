"""The two-box gate and the re-search around each candidate.

Two-box gate: a cluster is a marker candidate when the large cube (default 0.30 m: a 0.20 m
sphere with noise) holds all but a few of its points (:data:`GATE_SPILL_FRACTION`: the
mixed-return tail a near sphere trails behind it) and those points do not fit inside the small
one (default 0.05 m: noise specks). Re-search: ground removal and clustering may cut marker
points away, so all points of the full cloud (ground included) within ``radius_m`` of each
candidate's centroid are taken again.
"""

from __future__ import annotations

import numpy as np

from markerplan.errors import ConfigError
from pipeline.kernels import in_wanted_bins

#: The gate's verdict on a cluster: a marker candidate, or why not.
GATE_VERDICTS = ("passed", "too_large", "too_small")

#: The share of a cluster's points that may spill out of the large cube: the mixed returns at a
#: near sphere's silhouette (the footprint straddles the sphere and the ground behind it, within
#: one pulse length) leave a tail of up to ~5 % of its points, up to 0.45 m behind it; a
#: boulder or a crater wall spills far more of its points out of a 0.30 m cube.
GATE_SPILL_FRACTION = 0.1


def gate_verdicts(xyz_m: np.ndarray, labels: np.ndarray, max_box_m: float = 0.30,
                  min_box_m: float = 0.05, spill_fraction: float = GATE_SPILL_FRACTION
                  ) -> np.ndarray:
    """The two-box gate's verdict on every cluster.

    The large cube is placed where it holds the most points of the cluster (per axis, the
    ``max_box_m`` window holding the most coordinates; the cube is the three windows): a
    cluster passes when the cube holds all but ``spill_fraction`` of its points, and those
    points do not fit the small cube. A cluster whose bounding box fits the large cube
    spills nothing, so it is judged as by its bounding box.

    Parameters
    ----------
    xyz_m : (N, 3) float
        Clustered points, metres.
    labels : (N,) int
        Cluster labels ``0..L-1`` from :func:`pipeline.chain.clustering.euclidean_clusters`
        (-1 = noise).
    max_box_m, min_box_m : float
        Edge of the large and the small cube, metres.
    spill_fraction : float
        Share of a cluster's points that may lie outside the large cube, in ``[0, 0.5)``
        (:data:`GATE_SPILL_FRACTION`; 0: the bounding box must fit).

    Returns
    -------
    verdicts : (L,) str
        One of :data:`GATE_VERDICTS` per label: ``"passed"``, ``"too_large"`` (more than
        ``spill_fraction`` of the points spill out of the large cube) or
        ``"too_small"`` (the points the large cube holds fit the small one).

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0, 0, 0], [0.1, 0.1, 0], [3, 0, 0], [3.01, 0, 0], [6, 0, 0], [7, 0, 0.]])
    >>> gate_verdicts(pts, np.array([0, 0, 1, 1, 2, 2])).tolist()
    ['passed', 'too_small', 'too_large']

    A compact cluster with a thin tail passes; the tail can be 10 % of the points.

    >>> cap = np.column_stack([np.linspace(0, 0.2, 18), np.zeros(18), np.zeros(18)])
    >>> tail = np.array([[0.6, 0, 0], [0.8, 0, 0]])
    >>> gate_verdicts(np.vstack([cap, tail]), np.zeros(20, dtype=int)).tolist()
    ['passed']
    """
    if not 0 < min_box_m < max_box_m:
        raise ConfigError(f"gate boxes must satisfy 0 < min_box_m < max_box_m, got "
                          f"{min_box_m}, {max_box_m}")
    if not 0 <= spill_fraction < 0.5:
        raise ConfigError(f"gate `spill_fraction` must be in [0, 0.5) (a share of a cluster's "
                          f"points), got {spill_fraction}")
    ok = labels >= 0
    k = int(labels[ok].max()) + 1 if ok.any() else 0
    lab = labels[ok]
    p = xyz_m[ok]
    lo = _densest_windows(p, lab, k, max_box_m)
    held = np.all((p >= lo[lab]) & (p <= lo[lab] + max_box_m), axis=1)
    n_points = np.bincount(lab, minlength=k)
    n_held = np.bincount(lab[held], minlength=k)
    low = np.full((k, 3), np.inf)
    high = np.full((k, 3), -np.inf)
    np.minimum.at(low, lab[held], p[held])
    np.maximum.at(high, lab[held], p[held])
    extent = (high - low).max(axis=1)  # -inf for a cluster the cube holds nothing of
    spills = n_held < (1.0 - spill_fraction) * n_points
    return np.where(spills, "too_large",
                    np.where(extent > min_box_m, "passed", "too_small")).astype("<U9")


def _densest_windows(xyz_m: np.ndarray, labels: np.ndarray, k: int, width_m: float
                     ) -> np.ndarray:
    """(k, 3) per cluster and axis, the start of the ``width_m`` window that holds the most
    of its coordinates (the lowest such start on ties)."""
    lo = np.zeros((k, 3))
    if not labels.size:
        return lo
    span = float(np.ptp(xyz_m, axis=0).max()) + 2 * width_m + 1.0  # keys of clusters apart
    for axis in range(3):
        v = xyz_m[:, axis] - xyz_m[:, axis].min()
        order = np.lexsort((v, labels))
        key = labels[order] * span + v[order]
        count = np.searchsorted(key, key + width_m, side="right") - np.arange(key.size)
        best = np.lexsort((-count, labels[order]))
        first = best[np.r_[True, np.diff(labels[order][best]) != 0]]
        lo[labels[order][first], axis] = xyz_m[order[first], axis]
    return lo


def two_box_gate(xyz_m: np.ndarray, labels: np.ndarray, max_box_m: float = 0.30,
                 min_box_m: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Clusters passing the two-box gate (:func:`gate_verdicts`).

    Parameters
    ----------
    xyz_m : (N, 3) float
        Clustered points, metres.
    labels : (N,) int
        Cluster labels from :func:`pipeline.chain.clustering.euclidean_clusters` (-1 = noise).
    max_box_m, min_box_m : float
        Edge of the large and the small cube, metres.

    Returns
    -------
    cluster_ids : (K,) int
        Labels of the passing clusters.
    centroids_m : (K, 3) float
        Their centroids, metres.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0, 0, 0], [0.1, 0.1, 0], [3, 0, 0], [3.01, 0, 0], [6, 0, 0], [7, 0, 0.]])
    >>> ids, c = two_box_gate(pts, np.array([0, 0, 1, 1, 2, 2]))
    >>> ids.tolist()
    [0]
    """
    ids = np.flatnonzero(gate_verdicts(xyz_m, labels, max_box_m, min_box_m) == "passed")
    if not ids.size:
        return ids.astype(np.int64), np.zeros((0, 3))
    ok = labels >= 0
    counts = np.bincount(labels[ok], minlength=int(ids.max()) + 1)
    sums = np.zeros((counts.size, 3))
    np.add.at(sums, labels[ok], xyz_m[ok])
    return ids.astype(np.int64), sums[ids] / counts[ids, None]


class RangeIndex:
    """Points bucketed by range and azimuth about the station origin, for radius searches.

    Each point gets a bucket ``range_bin * n_sectors + azimuth_sector`` (16-bit), sorted with a
    linear-time radix sort, so indexing ten million points costs a fraction of a second; a
    query scans only the buckets its sphere can touch.

    Parameters
    ----------
    xyz_m : (N, 3) float
        The full cloud, station frame, metres.
    range_m : (N,) float, optional
        ``|xyz_m|`` if already known.
    bin_m : float
        Range bin width, metres (ranges beyond ``bin_m * 32767 / n_sectors`` share one bin).
    n_sectors : int
        Azimuth sectors.
    """

    def __init__(self, xyz_m: np.ndarray, range_m: np.ndarray | None = None,
                 bin_m: float = 0.1, n_sectors: int = 32):
        rng = np.sqrt(np.einsum("ij,ij->i", xyz_m, xyz_m)) if range_m is None else range_m
        self.bin_m = float(bin_m)
        self.n_sectors = int(n_sectors)
        self.max_bin = np.iinfo(np.int16).max // self.n_sectors - 1
        rbin = np.minimum(rng / self.bin_m, self.max_bin).astype(np.int16)
        sector = self._sector(np.arctan2(xyz_m[:, 1], xyz_m[:, 0]))
        keys = rbin * np.int16(self.n_sectors) + sector.astype(np.int16)
        self.order = np.argsort(keys, kind="stable")
        counts = np.bincount(keys, minlength=(self.max_bin + 1) * self.n_sectors)
        self.starts = np.concatenate([[0], np.cumsum(counts)])
        self.xyz_m = xyz_m

    def _sector(self, azimuth_rad: np.ndarray) -> np.ndarray:
        s = np.floor((azimuth_rad + np.pi) / (2 * np.pi) * self.n_sectors).astype(np.int64)
        return np.clip(s, 0, self.n_sectors - 1)

    def within(self, centre_m: np.ndarray, radius_m: float) -> np.ndarray:
        """Indices (into the cloud, ascending) of points within ``radius_m`` of ``centre_m``."""
        centre_m = np.asarray(centre_m, dtype=float)
        r = float(np.linalg.norm(centre_m))
        lo = int(min(np.floor(max(r - radius_m, 0.0) / self.bin_m), self.max_bin))
        hi = int(min(np.floor((r + radius_m) / self.bin_m), self.max_bin))
        horiz = float(np.hypot(centre_m[0], centre_m[1]))
        if horiz <= radius_m:
            sectors = np.arange(self.n_sectors)
        else:
            half = np.arcsin(radius_m / horiz)
            az = np.arctan2(centre_m[1], centre_m[0])
            ends = np.array([az - half, az + half])
            ends = (ends + np.pi) % (2 * np.pi) - np.pi
            s0, s1 = self._sector(ends)
            sectors = (np.arange(s0, s0 + (s1 - s0) % self.n_sectors + 1) % self.n_sectors)
        chunks = []
        for b in range(lo, hi + 1):
            for s in sectors:
                key = b * self.n_sectors + int(s)
                chunks.append(self.order[self.starts[key]:self.starts[key + 1]])
        idx = np.concatenate(chunks) if chunks else np.zeros(0, dtype=np.int64)
        d2 = ((self.xyz_m[idx] - centre_m) ** 2).sum(axis=1)
        return np.sort(idx[d2 <= radius_m ** 2])


#: Margin added to the search radius by :func:`within_range_bands`, metres: far above the
#: round-off of a computed range (~1e-13 m at 1 km), so no point of a sphere is missed.
RANGE_BAND_MARGIN_M = 1e-6


def within_range_bands(range_m: np.ndarray, centres_m: np.ndarray, radius_m: float,
                       bin_m: float = 0.05) -> np.ndarray:
    """Indices of the points that may lie within ``radius_m`` of any of ``centres_m``.

    A point within ``radius_m`` of a centre has a range within ``radius_m`` of the centre's
    range (triangle inequality), so only the range bins that such bands touch are kept: a
    superset of every :meth:`RangeIndex.within` answer, found in a few passes over the ranges.
    Building the :class:`RangeIndex` of these points only (and mapping its indices back) gives
    the same re-search points as indexing the whole cloud, at a fraction of the cost.

    Parameters
    ----------
    range_m : (N,) float
        Range of each point from the station origin, metres (``|xyz|``).
    centres_m : (K, 3) float
        Search centres, station frame, metres.
    radius_m : float
        Search radius, metres.
    bin_m : float
        Width of the range bins, metres.

    Returns
    -------
    indices : (n,) int
        Ascending point indices.

    Examples
    --------
    >>> import numpy as np
    >>> within_range_bands(np.array([1.0, 5.0, 5.2, 9.0]), np.array([[5.0, 0, 0]]), 0.3).tolist()
    [1, 2]
    """
    centres = np.asarray(centres_m, dtype=float).reshape(-1, 3)
    if centres.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    reach = float(radius_m) + RANGE_BAND_MARGIN_M
    centre_range = np.linalg.norm(centres, axis=1)
    top = int(np.floor((centre_range.max() + reach) / bin_m)) + 1
    lo = np.clip(np.floor((centre_range - reach) / bin_m).astype(np.int64), 0, top)
    hi = np.clip(np.floor((centre_range + reach) / bin_m).astype(np.int64), 0, top)
    cover = np.zeros(top + 2, dtype=np.int64)
    np.add.at(cover, lo, 1)
    np.add.at(cover, hi + 1, -1)
    wanted = np.append(np.cumsum(cover)[:top + 1] > 0, False)
    return in_wanted_bins(np.ascontiguousarray(range_m, dtype=float), float(bin_m), wanted)


def research(index: RangeIndex, centroids_m: np.ndarray, radius_m: float = 0.3
             ) -> list[np.ndarray]:
    """Re-extract all points within ``radius_m`` of each centroid (ground included).

    Parameters
    ----------
    index : RangeIndex
        The full cloud.
    centroids_m : (K, 3) float
        Candidate centroids, metres.
    radius_m : float
        Search radius, metres.

    Returns
    -------
    members : list of (n_k,) int arrays
        Cloud indices per candidate.
    """
    if not radius_m > 0:
        raise ConfigError(f"re-search `radius_m` must be > 0 metres, got {radius_m}")
    return [index.within(c, radius_m) for c in np.asarray(centroids_m).reshape(-1, 3)]
