"""Self-calibration of the three mounting offsets from direct/reverse observations.

The tilted VLP-16 sweeps a vertical circle; the half of the circle on the turntable's +y side
("direct" face, sensor ``x >= 0``) and the half on its -y side ("reverse" face) see every
azimuth once per turn: a location seen directly by the frame at turntable angle ``theta`` is
seen in reverse by the frame at ``theta + pi``, as in direct/reverse theodolite observations.
With the correct offsets the two half-clouds coincide; each offset breaks them apart in its
own way (station frame):

- vertical-axis error ``e``: the direct face turns by ``+e`` and the reverse face by ``-e``
  about the horizontal axis normal to the scan plane -> the ground seen by the two faces tilts
  apart by ``2e`` (large lever arm);
- L-frame tilt ``t``: the faces turn by ``+-t`` about the horizontal axis in the scan plane ->
  the fanned-out lasers see the ground tilt apart sideways;
- axis offset ``d``: the faces shift by ``+-Rz(theta) d`` horizontally -> invisible on level
  ground, but the known-diameter spheres seen by the two faces give two centres ``2 Rz d``
  apart.

So (:func:`estimate_rotation_offsets`) ``e`` and ``t`` are found by a point-to-plane ICP
between the faces whose unknowns are the two angles themselves (not a generic 6-DoF pose),
and (:func:`estimate_axis_offset`) ``d`` by making the per-face fixed-radius sphere centres
agree. Both are Gauss-Newton least squares with numeric Jacobians of the exact rig model
(:mod:`pipeline.scans.rig`); uncertainties are the formal ``s^2 (J^T J)^-1`` of the final step.

An axis-offset estimate is applied only when the spheres resolve it
(:func:`resolved_axis_offset`): a few spheres at 10-20 m give per-face centre differences of
3-7 mm and an estimate whose own sigma is 1-3 mm, so with no offset at all the estimate
scatters by millimetres around zero. It is tested against the start value with its covariance
(a Wald chi-square, 2 degrees of freedom); below ``axis_offset_chi2`` the data cannot tell it
from the start value, which is kept (the estimate and its chi-square are still reported).
:func:`largest_shift_m` bounds how far two sets of offsets move a return, which decides
whether the chain must detect the candidates again.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from markerplan.errors import ConfigError, DataError
from pipeline.scans.rig import MountingOffsets, sensor_to_station, sensor_to_turntable_rotation
from pipeline.scans.scan_format import StationScan
from pipeline.sphere_centres.geometric_sphere_fit import lsq_fixed_radius


@dataclass(frozen=True)
class CalibrationConfig:
    """Settings of the self-calibration.

    Attributes
    ----------
    sample_points : int
        Direct-face points used as ICP queries.
    reference_points : int
        Reverse-face points the planes are fitted to.
    neighbours : int
        Reverse-face neighbours per local plane.
    min_range_m, max_range_m : float
        Only points in this range band (metres) take part in the ICP.
    iterations : int
        Maximum ICP / sphere Gauss-Newton iterations.
    min_face_points : int
        Points each face must have on a sphere for it to count in the axis-offset fit.
    sphere_outlier_chi2 : float
        A sphere whose whitened direct-minus-reverse centre difference exceeds this chi-square
        (2 degrees of freedom; default 13.8 = the 99.9 % quantile), after scaling by the robust
        reduced chi-square when that exceeds 1, is dropped from the axis-offset fit and the fit
        repeated (a rock or a clipped marker that passed the quality gate on a smeared cloud).
    axis_offset_chi2 : float
        An axis-offset estimate is applied only when its chi-square against the start value
        (2 degrees of freedom, its own covariance) exceeds this (default 9.21 = the 99 %
        quantile; 0 applies every estimate). :func:`resolved_axis_offset`.
    seed : int
        Seed of the point subsampling.
    """

    sample_points: int = 20000
    reference_points: int = 300000
    neighbours: int = 10
    min_range_m: float = 1.5
    max_range_m: float = 25.0
    iterations: int = 10
    min_face_points: int = 8
    sphere_outlier_chi2: float = 13.8
    axis_offset_chi2: float = 9.21
    seed: int = 0

    def validate(self) -> CalibrationConfig:
        for name in ("sample_points", "reference_points", "neighbours", "iterations",
                     "min_face_points"):
            if int(getattr(self, name)) < 1:
                raise ConfigError(f"calibration `{name}` must be >= 1, got {getattr(self, name)}")
        if self.neighbours < 3:
            raise ConfigError(f"calibration `neighbours` must be >= 3, got {self.neighbours}")
        if not 0 <= self.min_range_m < self.max_range_m:
            raise ConfigError("calibration needs 0 <= min_range_m < max_range_m, got "
                              f"{self.min_range_m}, {self.max_range_m}")
        if not self.sphere_outlier_chi2 > 0:
            raise ConfigError("calibration `sphere_outlier_chi2` must be > 0, got "
                              f"{self.sphere_outlier_chi2}")
        if not self.axis_offset_chi2 >= 0:
            raise ConfigError("calibration `axis_offset_chi2` must be >= 0, got "
                              f"{self.axis_offset_chi2}")
        return self


def direct_face(scan: StationScan) -> np.ndarray:
    """Mask of points seen by the direct face (sensor ``x >= 0``, turntable +y side)."""
    return scan.xyz_sensor_m[:, 0] >= 0


#: Largest gap in the turntable's angles self-calibration accepts, radians: beyond half a
#: turn the direct and reverse faces no longer see the same scene.
MAX_TURN_GAP_RAD = np.pi


def largest_turn_gap_rad(turntable_angle_rad: np.ndarray) -> float:
    """Largest angle of the turn that no frame starts in, radians.

    Parameters
    ----------
    turntable_angle_rad : (F,) float
        Turntable angle of each frame, radians (any order, any number of turns).

    Returns
    -------
    gap : float
        In ``(0, 2 pi]``; ``2 pi`` for a single angle.

    Examples
    --------
    >>> round(float(np.degrees(largest_turn_gap_rad(np.radians([0.0, 90.0, 180.0])))), 6)
    180.0
    >>> round(float(np.degrees(largest_turn_gap_rad(np.zeros(3)))), 6)
    360.0
    """
    a = np.sort(np.mod(np.asarray(turntable_angle_rad, dtype=float), 2 * np.pi))
    gaps = np.diff(np.append(a, a[0] + 2 * np.pi))
    return float(gaps.max())


def _with_angles(offsets: MountingOffsets, p: np.ndarray) -> MountingOffsets:
    return replace(offsets, vertical_axis_error_rad=float(p[0]), lframe_tilt_rad=float(p[1]))


def _positions(scan: StationScan, idx: np.ndarray, offsets: MountingOffsets) -> np.ndarray:
    return sensor_to_station(scan.xyz_sensor_m[idx], scan.frame_index[idx],
                             scan.turntable_angle_rad, offsets)


def estimate_rotation_offsets(scan: StationScan, offsets: MountingOffsets | None = None,
                              config: CalibrationConfig | None = None
                              ) -> tuple[MountingOffsets, np.ndarray, int, float]:
    """Vertical-axis error and L-frame tilt by direct/reverse point-to-plane ICP.

    Parameters
    ----------
    scan : StationScan
        One station; frames must cover a full turn so both faces see the scene.
    offsets : MountingOffsets, optional
        Start values (the axis offset is held fixed at its value here).
    config : CalibrationConfig, optional

    Returns
    -------
    offsets : MountingOffsets
        With the two angles estimated.
    covariance : (2, 2) float
        Formal covariance of (vertical_axis_error_rad, lframe_tilt_rad), rad^2.
    n_pairs : int
        Plane pairs in the final step.
    rms_m : float
        RMS point-to-plane residual, metres.

    Raises
    ------
    DataError
        If the frames leave more than half a turn unscanned (:data:`MAX_TURN_GAP_RAD`), or
        either face has too few points in the range band for a plane fit.
    """
    cfg = (config or CalibrationConfig()).validate()
    offsets = MountingOffsets() if offsets is None else offsets
    gap = largest_turn_gap_rad(scan.turntable_angle_rad)
    if gap > MAX_TURN_GAP_RAD:
        raise DataError(f"scan {scan.station_id}: its {scan.n_frames} frame(s) leave "
                        f"{np.degrees(gap):.0f} deg of the turn unscanned; self-calibration "
                        "needs frames over a full turn: skip it (`calibrate=False`: known or zero "
                        "offsets) or give the turntable's angle log")
    face = direct_face(scan)
    band = (scan.range_m >= cfg.min_range_m) & (scan.range_m <= cfg.max_range_m)
    idx_a = np.flatnonzero(band & face)
    idx_b = np.flatnonzero(band & ~face)
    if idx_a.size < 100 or idx_b.size < 100:
        raise DataError(f"scan {scan.station_id}: only {idx_a.size} direct and {idx_b.size} "
                        "reverse points in the calibration range band; self-calibration needs "
                        "frames over a full turn (or pass known offsets)")
    gen = np.random.default_rng(cfg.seed)
    a = np.sort(gen.choice(idx_a, min(idx_a.size, cfg.sample_points), replace=False))
    b = np.sort(gen.choice(idx_b, min(idx_b.size, cfg.reference_points), replace=False))
    p = np.array([offsets.vertical_axis_error_rad, offsets.lframe_tilt_rad], dtype=float)
    h = 1e-5
    cov = np.full((2, 2), np.nan)
    n_pairs, rms = 0, float("nan")
    neighbours = NearestNeighbours(cfg.neighbours)
    # the samples' sensor-frame points and frames, gathered once
    xyz_a, frame_a = scan.xyz_sensor_m[a], scan.frame_index[a]
    xyz_b, frame_b = scan.xyz_sensor_m[b], scan.frame_index[b]

    def station(xyz: np.ndarray, frame: np.ndarray, off: MountingOffsets) -> np.ndarray:
        return sensor_to_station(xyz, frame, scan.turntable_angle_rad, off)

    for _ in range(cfg.iterations):
        off = _with_angles(offsets, p)
        pa, pb = station(xyz_a, frame_a, off), station(xyz_b, frame_b, off)
        dist, nn = neighbours.query(pa, pb)
        # np.take: the rows pb[nn] holds, in half the time of fancy indexing
        centroid, normal, ok = _local_planes(np.take(pb, nn, axis=0), dist)
        r0 = _plane_residuals(pa, centroid, normal)
        ok &= _inliers(r0, ok)
        if ok.sum() < 50:
            raise DataError(f"scan {scan.station_id}: only {int(ok.sum())} direct/reverse plane "
                            "pairs; the scene is too sparse for self-calibration")
        jac = np.empty((int(ok.sum()), 2))
        # the shifted reverse face is needed only at the neighbours of the pairs kept
        used, local = np.unique(nn[ok].ravel(), return_inverse=True)
        local = local.reshape(-1, nn.shape[1])
        for k in range(2):
            pk = p.copy()
            pk[k] += h
            offk = _with_angles(offsets, pk)
            rk = _plane_residuals(station(xyz_a[ok], frame_a[ok], offk),
                                  np.take(station(xyz_b[used], frame_b[used], offk), local,
                                          axis=0).mean(axis=1),
                                  normal[ok])
            jac[:, k] = (rk - r0[ok]) / h
        step, *_ = np.linalg.lstsq(jac, -r0[ok], rcond=None)
        p = p + step
        res = r0[ok] + jac @ step
        n_pairs = int(ok.sum())
        rms = float(np.sqrt(np.mean(res ** 2)))
        cov = rms ** 2 * np.linalg.pinv(jac.T @ jac)
        if np.max(np.abs(step)) < 1e-6:
            break
    return _with_angles(offsets, p), cov, n_pairs, rms


class NearestNeighbours:
    """The ``k`` nearest of moving points ``pb`` to moving queries ``pa``, reusing one tree.

    Every :meth:`query` returns what a fresh ``cKDTree(pb).query(pa, k)`` returns (the same
    neighbours in the same order, the same distances to the bit; only exact ties could be
    ordered differently), but the ICP's points move little between its later iterations, so
    the tree is built only when the answer cannot be proved from the last search. That search
    found ``k + spare`` candidates of each query point as it was then (``pa0``) among the
    reference points as they were when the tree was built (``pb0``), the farthest at
    ``reach``. Since then every point of ``pb`` has moved by at most ``drift`` and a query
    point by ``moved``, so (triangle inequality) no point outside its candidates is nearer
    than ``reach - moved - drift``: where the ``k``-th nearest candidate, at the new
    positions, is nearer than that, the candidates hold the answer. For the few query points
    where that fails, every point of the tree within that ``k``-th distance plus ``drift`` is
    a candidate (a ball search); if many fail (:attr:`REBUILD_FRACTION`), the tree is built
    again at the new positions.

    Parameters
    ----------
    k : int
        Neighbours per query point.
    spare : int
        Extra candidates kept per query point.
    """

    #: Fraction of failing query points above which the tree is built again.
    REBUILD_FRACTION = 0.01
    #: Safety margin of the bounds against round-off of the distances, metres.
    MARGIN_M = 1e-9

    def __init__(self, k: int, spare: int = 6) -> None:
        self.k, self.spare = k, spare
        self.tree: cKDTree | None = None
        self.builds = 0

    def query(self, pa: np.ndarray, pb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances and indices of the ``k`` nearest points of ``pb`` to each of ``pa``.

        Parameters
        ----------
        pa : (m, 3) float
            Query points, metres (the same points, moved, at every call; a new array each
            time: the last ones are kept, not copied).
        pb : (n, 3) float
            Reference points, metres (likewise).

        Returns
        -------
        dist : (m, k) float
            Distances, ascending, metres.
        nn : (m, k) int
            Indices into ``pb``.
        """
        if self.tree is not None:
            drift = float(np.sqrt(np.max(_squared_norms(pb - self.pb0))))
            dist, nn, bad = self._from_candidates(pa, pb, drift)
            rows = np.flatnonzero(bad)
            if rows.size <= self.REBUILD_FRACTION * bad.size:
                for i in rows:
                    dist[i], nn[i] = self._ball(pa[i], pb, dist[i, -1] + drift)
                return dist, nn
        # unbalanced, uncompacted: a third of the build time of the default tree, same
        # neighbours
        self.tree = cKDTree(pb, balanced_tree=False, compact_nodes=False)
        self.builds += 1
        self.pb0, self.pa0 = pb, pa
        size = max(self.k, min(self.k + self.spare, pb.shape[0]))
        dist, self.candidates = self.tree.query(pa, k=size, workers=-1)
        self.reach = dist[:, -1]
        return dist[:, :self.k], self.candidates[:, :self.k].copy()

    def _from_candidates(self, pa: np.ndarray, pb: np.ndarray, drift: float
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ``k`` nearest candidates of each query point, and where that is unproven."""
        dist = _distances(pa[:, None, :], np.take(pb, self.candidates, axis=0))
        order = np.argsort(dist, axis=1, kind="stable")[:, :self.k]
        dist = np.take_along_axis(dist, order, axis=1)
        moved = np.sqrt(_squared_norms(pa - self.pa0))
        bad = ~(dist[:, -1] < self.reach - moved - drift - self.MARGIN_M)
        return dist, np.take_along_axis(self.candidates, order, axis=1), bad

    def _ball(self, q: np.ndarray, pb: np.ndarray, radius_m: float
              ) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest points of ``pb`` to ``q`` (3,) among those whose tree position
        is within ``radius_m`` of ``q``."""
        cand = np.asarray(self.tree.query_ball_point(q, radius_m + self.MARGIN_M), dtype=np.intp)
        dist = _distances(q, pb[cand])
        order = np.argsort(dist, kind="stable")[:self.k]
        return dist[order], cand[order]


def _distances(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Euclidean distances ``|p - q|`` over the last axis (length 3, broadcast), metres.

    Summed in cKDTree's order (x, then y, then z), so they are its distances to the bit.
    """
    d = p - q
    d *= d
    return np.sqrt(d[..., 0] + d[..., 1] + d[..., 2])


def _squared_norms(v: np.ndarray) -> np.ndarray:
    """Squared Euclidean norm (n,) of each row of ``v`` (n, 3)."""
    return np.einsum("ij,ij->i", v, v)


def _local_planes(neigh: np.ndarray, dist: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Planes through neighbourhoods of points.

    Parameters
    ----------
    neigh : (m, k, 3) float
        The ``k`` neighbours of each of ``m`` points, metres.
    dist : (m, k) float
        Their distances from the point, ascending, metres.

    Returns
    -------
    centroid : (m, 3) float
        Mean of each neighbourhood, metres.
    normal : (m, 3) float
        Unit normal of its least-squares plane.
    usable : (m,) bool
        Planar (smallest eigenvalue below 5 % of the middle one) and compact (farthest
        neighbour within 0.3 m or twice the spread).
    """
    centroid = neigh.mean(axis=1)
    centred = neigh - centroid[:, None, :]
    cov = np.einsum("mki,mkj->mij", centred, centred)
    w, v = np.linalg.eigh(cov)
    normal = v[:, :, 0]
    spread = np.sqrt(np.maximum(w[:, 2], 0) / neigh.shape[1])
    planar = w[:, 0] < 0.05 * w[:, 1]
    near = dist[:, -1] < np.maximum(0.3, 2 * spread)
    return centroid, normal, planar & near & np.isfinite(dist[:, -1])


def _plane_residuals(pa: np.ndarray, centroid: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Signed distances (m,) of points ``pa`` (m, 3) from planes through ``centroid`` (m, 3)
    with unit ``normal`` (m, 3), metres."""
    return np.einsum("mi,mi->m", pa - centroid, normal)


def _inliers(r: np.ndarray, ok: np.ndarray) -> np.ndarray:
    med = np.median(r[ok])
    mad = 1.4826 * np.median(np.abs(r[ok] - med))
    return np.abs(r - med) < 3 * max(mad, 1e-6)


def _centre_covariance(points_m: np.ndarray, centre_m: np.ndarray, radius_m: float
                       ) -> np.ndarray:
    """Formal covariance (3, 3) of a fixed-radius centre fit: ``s^2 (U^T U)^-1``."""
    d = points_m - centre_m
    u = d / np.linalg.norm(d, axis=1)[:, None]
    r = np.linalg.norm(d, axis=1) - radius_m
    s2 = float(r @ r) / max(r.size - 3, 1)
    return s2 * np.linalg.pinv(u.T @ u) + 1e-12 * np.eye(3)


def estimate_axis_offset(scan: StationScan, offsets: MountingOffsets,
                         sphere_members: list[np.ndarray], radius_m: float,
                         centres_m: np.ndarray, config: CalibrationConfig | None = None
                         ) -> tuple[MountingOffsets, np.ndarray, int, float]:
    """Horizontal axis offset from the consistency of known-diameter spheres.

    Each sphere is fitted (radius fixed) twice, from its direct-face and from its reverse-face
    points; the offset ``(dx, dy)`` is chosen so the two centres agree horizontally, each
    sphere's difference weighted by the inverse of its formal covariance. Spheres whose
    difference stays inconsistent with that covariance (``config.sphere_outlier_chi2``) are
    dropped and the fit repeated, keeping at least two. The returned covariance is scaled by
    the reduced chi-square when that exceeds 1.

    Parameters
    ----------
    scan : StationScan
    offsets : MountingOffsets
        Current estimate (angles are held fixed).
    sphere_members : list of (n_k,) int arrays
        Scan point indices of each accepted sphere (inliers of its centre fit).
    radius_m : float
        Known sphere radius, metres.
    centres_m : (K, 3) float
        Current centre of each sphere (start of the per-face fits), station frame.
    config : CalibrationConfig, optional

    Returns
    -------
    offsets : MountingOffsets
        With ``axis_offset_m`` estimated (unchanged when no sphere qualifies).
    covariance : (2, 2) float
        Formal covariance of (dx, dy), m^2 (NaN when no sphere qualifies).
    n_spheres : int
        Spheres used (after outlier rejection).
    rms_m : float
        RMS horizontal centre difference of the spheres used, after the fit, metres.
    """
    cfg = (config or CalibrationConfig()).validate()
    face = direct_face(scan)
    spheres = []
    for members, c in zip(sphere_members, np.asarray(centres_m).reshape(-1, 3), strict=True):
        fa, fb = members[face[members]], members[~face[members]]
        if fa.size >= cfg.min_face_points and fb.size >= cfg.min_face_points:
            spheres.append((fa, fb, c))
    if not spheres:
        return offsets, np.full((2, 2), np.nan), 0, float("nan")
    all_idx = np.concatenate([np.r_[fa, fb] for fa, fb, _ in spheres])

    def face_fits(d: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        off = replace(offsets, axis_offset_m=(float(d[0]), float(d[1])))
        pos = _positions(scan, all_idx, off)
        out, start = [], 0
        for fa, fb, c in spheres:
            pa = pos[start:start + fa.size]
            pb = pos[start + fa.size:start + fa.size + fb.size]
            start += fa.size + fb.size
            out.append((pa, lsq_fixed_radius(pa, radius_m, c), pb,
                        lsq_fixed_radius(pb, radius_m, c)))
        return out

    # weights: inverse covariance of each horizontal centre difference (near, dense markers
    # count more than far, sparse ones), computed once at the start values
    whiten = []
    for pa, ca, pb, cb in face_fits(np.asarray(offsets.axis_offset_m, dtype=float)):
        cov_diff = (_centre_covariance(pa, ca, radius_m) + _centre_covariance(pb, cb, radius_m))
        whiten.append(np.linalg.cholesky(np.linalg.inv(cov_diff[:2, :2])).T)

    def per_sphere(d: np.ndarray) -> np.ndarray:
        """(K, 2) whitened horizontal centre differences."""
        return np.array([w @ (ca - cb)[:2] for w, (_, ca, _, cb)
                         in zip(whiten, face_fits(d), strict=True)])

    d = np.asarray(offsets.axis_offset_m, dtype=float)
    keep = np.ones(len(spheres), dtype=bool)
    while True:
        d, cov = _gauss_newton_2d(lambda x, k=keep: per_sphere(x)[k].ravel(), d,
                                  cfg.iterations)
        chi2 = np.sum(per_sphere(d) ** 2, axis=1)
        # robust reduced chi-square of the kept spheres (median of chi2_2 is 1.386)
        scale = max(float(np.median(chi2[keep])) / 1.386, 1.0)
        outliers = keep & (chi2 > cfg.sphere_outlier_chi2 * scale)
        if not outliers.any() or keep.sum() - outliers.sum() < 2:
            break
        keep = keep & ~outliers
    diffs = np.array([(ca - cb)[:2] for _, ca, _, cb in face_fits(d)])[keep]
    rms = float(np.sqrt(np.mean(diffs ** 2)))
    return (replace(offsets, axis_offset_m=(float(d[0]), float(d[1]))), cov, int(keep.sum()),
            rms)


def _gauss_newton_2d(residuals, d0: np.ndarray, iterations: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Minimise ``|residuals(d)|^2`` over a 2-vector ``d`` by Gauss-Newton with a forward
    difference Jacobian; returns ``d`` and its formal covariance, scaled by the reduced
    chi-square when that exceeds 1."""
    d = np.asarray(d0, dtype=float)
    h = 1e-4
    cov = np.full((2, 2), np.nan)
    for _ in range(iterations):
        r0 = residuals(d)
        jac = np.column_stack([(residuals(d + h * e) - r0) / h for e in np.eye(2)])
        step, *_ = np.linalg.lstsq(jac, -r0, rcond=None)
        d = d + step
        res = r0 + jac @ step
        dof = max(res.size - 2, 1)
        cov = max(res @ res / dof, 1.0) * np.linalg.pinv(jac.T @ jac)
        if np.max(np.abs(step)) < 1e-6:
            break
    return d, cov


def resolved_axis_offset(start: MountingOffsets, estimate: MountingOffsets,
                         covariance: np.ndarray, chi2_limit: float
                         ) -> tuple[MountingOffsets, float]:
    """The estimate when the data resolve it from the start value, else the start value.

    Parameters
    ----------
    start : MountingOffsets
        The prior axis offset (the calibrate stage's start value: a known offset, or zero).
    estimate : MountingOffsets
        From :func:`estimate_axis_offset` (its angles are kept either way).
    covariance : (2, 2) float
        Of the estimate's ``axis_offset_m``, m^2 (NaN: no sphere qualified).
    chi2_limit : float
        ``CalibrationConfig.axis_offset_chi2``.

    Returns
    -------
    offsets : MountingOffsets
        ``estimate``, or ``estimate`` with the start's axis offset.
    chi2 : float
        ``(d - d0)^T C^-1 (d - d0)``; NaN when the covariance is unknown (then the start is
        kept) and infinite when it is singular and ``d != d0``.

    Examples
    --------
    >>> start = MountingOffsets()
    >>> est = MountingOffsets(axis_offset_m=(0.003, 0.0))
    >>> off, chi2 = resolved_axis_offset(start, est, np.diag([0.002, 0.001]) ** 2, 9.21)
    >>> off.axis_offset_m, round(chi2, 2)
    ((0.0, 0.0), 2.25)
    >>> resolved_axis_offset(start, est, np.diag([0.0005, 0.001]) ** 2, 9.21)[0].axis_offset_m
    (0.003, 0.0)
    """
    diff = np.subtract(estimate.axis_offset_m, start.axis_offset_m)
    cov = np.asarray(covariance, dtype=float)
    if not np.all(np.isfinite(cov)):
        return replace(estimate, axis_offset_m=start.axis_offset_m), float("nan")
    try:
        chi2 = float(diff @ np.linalg.solve(cov, diff))
    except np.linalg.LinAlgError:
        chi2 = float("inf") if np.any(diff) else 0.0
    if chi2 > chi2_limit:
        return estimate, chi2
    return replace(estimate, axis_offset_m=start.axis_offset_m), chi2


def largest_shift_m(a: MountingOffsets, b: MountingOffsets, range_m: float) -> float:
    """Bound on how far a return moves between the clouds synthesised with ``a`` and ``b``.

    A return at sensor-frame ``p`` (``|p| <= range_m``) lands at
    ``Rz(theta) (R(a) p + d(a))`` (:func:`pipeline.scans.rig.frame_poses`), so it moves by at most
    ``||R(b) - R(a)||_2 range_m + |d(b) - d(a)|``.

    Parameters
    ----------
    a, b : MountingOffsets
    range_m : float
        Largest range of the returns considered, metres.

    Returns
    -------
    shift_m : float
        Metres.

    Examples
    --------
    >>> a = MountingOffsets()
    >>> round(largest_shift_m(a, MountingOffsets(axis_offset_m=(0.003, 0.004)), 60.0), 6)
    0.005
    >>> round(largest_shift_m(a, MountingOffsets(lframe_tilt_rad=1e-4), 60.0), 6)
    0.006
    """
    rotation = np.linalg.norm(sensor_to_turntable_rotation(b) - sensor_to_turntable_rotation(a),
                              2)
    return float(rotation * range_m + np.hypot(*np.subtract(b.axis_offset_m, a.axis_offset_m)))
