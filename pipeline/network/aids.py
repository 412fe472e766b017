"""Pose aids of the network adjustment: odometry between consecutive stations and a heading
reference with a common boresight bias, as observations of the station poses.

- **Odometry** (:class:`OdometryReadings`): for each pair of consecutive stations ``k``,
  ``k + 1`` in drive order, the measured pose of ``k + 1`` in the levelled frame of ``k``:
  ``dp`` (3,) and ``dpsi``. The observation equations (non-linear, linearised exactly at each
  Gauss-Newton iterate) are

      Rz(psi_k)^T (t_(k+1) - t_k) - dp = e_p,   e_p ~ N(0, (ratio d)^2 I3)
      wrap(psi_(k+1) - psi_k - dpsi) = e_psi,   e_psi ~ N(0, (rate d)^2)

  with ``d = |dp|`` the distance the odometry measured (m), ``ratio`` and ``rate`` the
  settings' ``odometry_ratio`` and ``odometry_heading_rad_per_m``. A **closed** traverse (the
  rover drives from the last station back through the route start to the first) adds one
  more reading of the same form, the pose of the first station in the levelled frame of the
  last, whose ``d`` is the distance driven along the closing legs
  (:attr:`OdometryReadings.loop_driven_m`, longer than the straight ``|dp|``). The position rows'
  derivatives are ``Rz(psi_k)^T`` (t_(k+1)), ``-Rz(psi_k)^T`` (t_k) and
  ``Rz(psi_k)^T S^T (t_(k+1) - t_k)`` (psi_k, ``S`` the 90-degree turn about z): the position
  error is isotropic, so the information ``A^T W A`` does not depend on the frame and equals
  the planner's (:mod:`planner.accuracy.aids`, linearised at headings 0).
- **Heading reference** (:class:`HeadingReadings` or, without readings, the nominal headings):
  each station's heading read with a random error (1-sigma ``sigma_r``) plus one boresight bias
  common to all (1-sigma ``sigma_b``). The bias is eliminated: the heading rows are correlated,
  weight ``(I - c 1 1^T) / sigma_r^2`` with ``c = sigma_b^2 / (sigma_r^2 + s sigma_b^2)``
  (Sherman-Morrison), an ``s x s`` block on the headings. The stations' covariance is dense
  already (:func:`pipeline.network.normals.covariance_from_normal`), so the block costs nothing
  there, and the parameters stay those of the plain model.

:class:`AidModel` holds them resolved for one adjustment; :func:`add_to_normal` adds their
``A^T W A`` and ``-A^T W f`` to the normal equations of :mod:`pipeline.network.normals`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from markerplan.errors import ConfigError
from pipeline.network.observations import MIN_SIGMA


def wrap(angle_rad):
    """Angles wrapped to [-pi, pi).

    >>> float(wrap(np.array(3 * np.pi / 2)))
    -1.5707963267948966
    """
    return (angle_rad + np.pi) % (2 * np.pi) - np.pi


@dataclass(frozen=True)
class OdometryReadings:
    """Relative poses measured by the rover's odometry between consecutive stations, and on a
    closed traverse from the last station back to the first.

    Attributes
    ----------
    order : (s,) int
        Station indices (into ``NetworkObservations.station_ids``) in drive order; each station
        at most once (a subset of the stations is allowed).
    delta_xyz_m : (p, 3) float
        Row ``i < s - 1``: position of station ``order[i + 1]`` in the levelled frame of
        ``order[i]``, m; on a closed traverse row ``s - 1`` (``p = s``): position of
        ``order[0]`` in the levelled frame of ``order[-1]`` (the closing reading).
    delta_heading_rad : (p,) float
        Its heading less that of the station it is read from, rad.
    loop_driven_m : float or None
        Distance the rover drove for the closing reading (from ``order[-1]`` back through the
        route start to ``order[0]``), m; ``None``: an open traverse (``p = s - 1``).
    """

    order: np.ndarray
    delta_xyz_m: np.ndarray
    delta_heading_rad: np.ndarray
    loop_driven_m: float | None = None

    def __post_init__(self):
        order = np.asarray(self.order)
        dp = np.asarray(self.delta_xyz_m, dtype=float)
        dpsi = np.asarray(self.delta_heading_rad, dtype=float)
        if order.ndim != 1 or order.size < 2 or not np.issubdtype(order.dtype, np.integer):
            raise ConfigError(f"odometry `order` must be (s,) int with s >= 2, got "
                              f"{order.shape} {order.dtype}")
        if np.unique(order).size != order.size:
            raise ConfigError("odometry `order` lists a station twice; give each station once")
        loop = self.loop_driven_m
        if loop is not None and not (isinstance(loop, int | float | np.number)
                                     and not isinstance(loop, bool) and math.isfinite(loop)
                                     and loop > 0):
            raise ConfigError(f"odometry `loop_driven_m` must be a finite distance > 0 m, got "
                              f"{loop!r:.40}")
        p = order.size - (loop is None)
        if dp.shape != (p, 3) or dpsi.shape != (p,):
            raise ConfigError(f"odometry needs `delta_xyz_m` ({p}, 3) and `delta_heading_rad` "
                              f"({p},), got {dp.shape} and {dpsi.shape}")
        if not (np.isfinite(dp).all() and np.isfinite(dpsi).all()):
            raise ConfigError("odometry relative poses must be finite")
        step = np.linalg.norm(dp[:order.size - 1], axis=1)
        if np.any(step <= 0):
            i = int(np.flatnonzero(step <= 0)[0])
            raise ConfigError(f"odometry step {i} (stations {order[i]} and {order[i + 1]}) "
                              "drove no distance, so its sigma is 0; drop the repeated station")
        object.__setattr__(self, "order", order.astype(np.int64))
        object.__setattr__(self, "delta_xyz_m", dp)
        object.__setattr__(self, "delta_heading_rad", dpsi)
        object.__setattr__(self, "loop_driven_m", None if loop is None else float(loop))

    @property
    def pairs(self) -> np.ndarray:
        """(p, 2) int: the stations ``(from, to)`` of each reading.

        >>> OdometryReadings([2, 0, 1], [[1.0, 0, 0]] * 3, [0.0] * 3, 5.0).pairs.tolist()
        [[2, 0], [0, 1], [1, 2]]
        """
        to = np.roll(self.order, -1)[:self.delta_xyz_m.shape[0]]
        return np.column_stack([self.order[:to.size], to])

    @property
    def driven_m(self) -> np.ndarray:
        """(p,) float: the distance driven for each reading, m: the measured ``|dp|`` between
        consecutive stations (the least the rover drives), ``loop_driven_m`` for the closing
        reading."""
        d = np.linalg.norm(self.delta_xyz_m, axis=1)
        if self.loop_driven_m is not None:
            d[-1] = self.loop_driven_m
        return d

    @classmethod
    def from_poses(cls, order, position_m, heading_rad,
                   loop_driven_m: float | None = None) -> OdometryReadings:
        """The relative poses between consecutive dead-reckoned poses (and with
        ``loop_driven_m``, the closing reading from the last pose to the first).

        Parameters
        ----------
        order : (s,) int
        position_m : (s, 3) float
            Dead-reckoned positions in drive order (row ``i`` is station ``order[i]``), m.
        heading_rad : (s,) float
        loop_driven_m : float, optional
            The closing legs' distance driven, m; ``None``: an open traverse.

        Examples
        --------
        >>> r = OdometryReadings.from_poses([0, 1], [[0, 0, 0], [0, 2, 0]], [np.pi / 2, np.pi])
        >>> np.round(r.delta_xyz_m, 12).tolist(), round(float(r.delta_heading_rad[0]), 6)
        ([[2.0, 0.0, 0.0]], 1.570796)
        >>> r = OdometryReadings.from_poses([0, 1], [[0, 0, 0], [0, 2, 0]], [np.pi / 2, np.pi],
        ...                                 loop_driven_m=3.0)
        >>> np.round(r.delta_xyz_m[1], 12).tolist(), r.driven_m.tolist()
        ([-0.0, 2.0, 0.0], [2.0, 3.0])
        """
        p = np.asarray(position_m, dtype=float)
        h = np.asarray(heading_rad, dtype=float)
        if loop_driven_m is not None:
            p, h = np.vstack([p, p[:1]]), np.append(h, h[:1])
        d = np.diff(p, axis=0)
        c, s = np.cos(h[:-1]), np.sin(h[:-1])
        local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
        return cls(np.asarray(order), local, wrap(np.diff(h)), loop_driven_m)


@dataclass(frozen=True)
class HeadingReadings:
    """Each station's heading as the heading reference read it (bias included), rad, (s,)."""

    heading_rad: np.ndarray

    def __post_init__(self):
        h = np.asarray(self.heading_rad, dtype=float)
        if h.ndim != 1 or not np.isfinite(h).all():
            raise ConfigError(f"heading readings must be finite (s,), got shape {h.shape}")
        object.__setattr__(self, "heading_rad", h)


@dataclass
class AidModel:
    """The aids of one adjustment, resolved: their rows, measurements and weight.

    Attributes
    ----------
    n_stations : int
    pairs : (p, 2) int
        The stations ``(from, to)`` of each odometry reading (:attr:`OdometryReadings.pairs`;
        empty without).
    delta_xyz_m, delta_heading_rad : (p, 3), (p,) float
        Their measured relative poses.
    position_sigma_m, heading_sigma_rad : (p,) float or None
        1-sigma per axis and of the heading (None: no such rows).
    heading_value_rad : (s,) float or None
        The heading readings (None: no heading rows).
    weight : (m, m) scipy.sparse.csr_array
        ``W`` of all rows: odometry position (3 per pair), odometry heading (1 per pair),
        then the stations' headings.
    """

    n_stations: int
    pairs: np.ndarray
    delta_xyz_m: np.ndarray
    delta_heading_rad: np.ndarray
    position_sigma_m: np.ndarray | None
    heading_sigma_rad: np.ndarray | None
    heading_value_rad: np.ndarray | None
    weight: sp.csr_array

    @property
    def n_rows(self) -> int:
        return self.weight.shape[0]

    def linearise(self, pose: np.ndarray) -> tuple[sp.csr_array, np.ndarray]:
        """Design ``A`` (m, 6 s) and misclosure ``f`` (m,) at ``pose`` (s, 6)."""
        rows, cols, vals, f = [], [], [], []
        r = 0
        k, j = self.pairs[:, 0], self.pairs[:, 1]
        if self.position_sigma_m is not None:
            psi = pose[k, 3]
            c, s = np.cos(psi), np.sin(psi)
            rt = np.stack([np.column_stack([c, s, 0 * c]), np.column_stack([-s, c, 0 * c]),
                           np.tile([0.0, 0.0, 1.0], (k.size, 1))], axis=1)  # Rz(psi_k)^T
            d = pose[j, :3] - pose[k, :3]
            f.append((np.einsum("pij,pj->pi", rt, d) - self.delta_xyz_m).ravel())
            lever = np.einsum("pij,pj->pi", rt, np.column_stack([d[:, 1], -d[:, 0], 0 * c]))
            for i in range(k.size):
                for axis in range(3):
                    row = r + 3 * i + axis
                    for a in range(3):
                        if rt[i, axis, a] != 0.0:
                            rows += [row, row]
                            cols += [6 * j[i] + a, 6 * k[i] + a]
                            vals += [rt[i, axis, a], -rt[i, axis, a]]
                    rows.append(row)
                    cols.append(6 * k[i] + 3)
                    vals.append(lever[i, axis])
            r += 3 * k.size
        if self.heading_sigma_rad is not None:
            f.append(wrap(pose[j, 3] - pose[k, 3] - self.delta_heading_rad))
            rows += np.repeat(r + np.arange(k.size), 2).tolist()
            cols += np.column_stack([6 * j + 3, 6 * k + 3]).ravel().tolist()
            vals += [1.0, -1.0] * k.size
            r += k.size
        if self.heading_value_rad is not None:
            s = self.n_stations
            f.append(wrap(pose[:, 3] - self.heading_value_rad))
            rows += (r + np.arange(s)).tolist()
            cols += (6 * np.arange(s) + 3).tolist()
            vals += [1.0] * s
            r += s
        design = sp.csr_array((vals, (rows, cols)), shape=(r, 6 * self.n_stations))
        return design, np.concatenate(f) if f else np.zeros(0)


def aid_model(n_stations: int, odometry: OdometryReadings | None,
              odometry_ratio: float | None, odometry_heading_rad_per_m: float | None,
              heading_value_rad: np.ndarray | None, heading_sigma_rad: float | None,
              heading_bias_sigma_rad: float | None) -> AidModel | None:
    """The :class:`AidModel` of the aids given; None when there are none.

    ``heading_value_rad`` with ``heading_sigma_rad`` and a boresight bias
    ``heading_bias_sigma_rad`` (None: no heading rows here; the adjustment's diagonal heading
    prior handles a heading reference without a bias). Odometry needs at least one of
    ``odometry_ratio`` (1-sigma per axis per metre driven) and ``odometry_heading_rad_per_m``.
    """
    s = n_stations
    use_heading = heading_bias_sigma_rad is not None and heading_value_rad is not None
    if odometry is None and not use_heading:
        return None
    sigmas, blocks = [], []
    pairs = np.zeros((0, 2), np.int64)
    dp, dpsi = np.zeros((0, 3)), np.zeros(0)
    pos_sig = head_sig = None
    if odometry is not None:
        if np.any(odometry.order >= s) or np.any(odometry.order < 0):
            raise ConfigError(f"odometry `order` must index the {s} stations, got "
                              f"{odometry.order.tolist()!s:.60}")
        if odometry_ratio is None and odometry_heading_rad_per_m is None:
            raise ConfigError("odometry readings need their sigmas: set odometry_ratio and/or "
                              "odometry_heading_rad_per_m")
        pairs, driven = odometry.pairs, odometry.driven_m
        dp, dpsi = odometry.delta_xyz_m, odometry.delta_heading_rad
        if odometry_ratio is not None:
            pos_sig = np.maximum(odometry_ratio * driven, MIN_SIGMA)
            sigmas.append(np.repeat(pos_sig, 3))
        if odometry_heading_rad_per_m is not None:
            head_sig = np.maximum(odometry_heading_rad_per_m * driven, MIN_SIGMA)
            sigmas.append(head_sig)
    if sigmas:
        blocks.append(sp.diags_array(1.0 / np.concatenate(sigmas) ** 2))
    if use_heading:
        r2, b2 = heading_sigma_rad**2, heading_bias_sigma_rad**2
        c = b2 / (r2 + s * b2)
        blocks.append(sp.csr_array((np.eye(s) - c) / r2))
    weight = sp.csr_array(sp.block_diag(blocks, format="csr"))
    return AidModel(s, pairs, dp, dpsi, pos_sig, head_sig,
                    np.asarray(heading_value_rad, float) if use_heading else None, weight)


def add_to_normal(aids: AidModel, fixed: np.ndarray, normal, rhs: np.ndarray,
                  pose: np.ndarray) -> tuple[object, np.ndarray, np.ndarray]:
    """The normal equations with the aids' ``A^T W A`` and ``-A^T W f`` added.

    Parameters
    ----------
    aids : AidModel
    fixed : (u,) bool
        Parameters the datum fixes (their rows and columns get nothing).
    normal : (size, size) sparse
        The (bordered) normal matrix, ``size >= u``.
    rhs : (size,) float
    pose : (s, 6) float
        The iterate to linearise at.

    Returns
    -------
    normal : (size, size) scipy.sparse.csc_matrix
    rhs : (size,) float
    misclosure : (m,) float
        ``f`` of the aids' rows at ``pose``.
    """
    design, f = aids.linearise(pose)
    ns = design.shape[1]
    keep = sp.diags_array((~fixed[:ns]).astype(float))
    a = sp.csr_array(design @ keep)
    wa = aids.weight @ a
    size = normal.shape[0]
    block = sp.csc_matrix((a.T @ wa).tocoo(), shape=(ns, ns))
    block.resize((size, size))
    rhs = rhs.copy()
    rhs[:ns] -= wa.T @ f
    return sp.csc_matrix(normal + block), rhs, f


def aids_iv(n_stations: int, settings, odometry: OdometryReadings | None,
            heading: HeadingReadings | None) -> None:
    """Check that the aids given to the adjustment fit its settings (ConfigError naming the
    fix otherwise); ``settings`` an :class:`~pipeline.network.adjustment.AdjustmentSettings`."""
    if odometry is not None and not isinstance(odometry, OdometryReadings):
        raise ConfigError(f"`odometry` must be OdometryReadings, got {type(odometry).__name__}")
    if heading is not None and not isinstance(heading, HeadingReadings):
        raise ConfigError(f"`heading` must be HeadingReadings, got {type(heading).__name__}")
    has_sigmas = (settings.odometry_ratio is not None
                  or settings.odometry_heading_rad_per_m is not None)
    if has_sigmas and odometry is None:
        raise ConfigError("odometry sigmas are set but no odometry readings are given; give "
                          "them or drop odometry_ratio/odometry_heading_rad_per_m")
    if heading is not None:
        if settings.heading_prior_sigma_rad is None:
            raise ConfigError("heading readings need heading_prior_sigma_rad (their sigma)")
        if heading.heading_rad.shape != (n_stations,):
            raise ConfigError(f"heading readings must be given for all {n_stations} stations, "
                              f"got {heading.heading_rad.shape[0]}")


#: Columns of an odometry file: dead-reckoned poses in drive order (site frame, m, degrees).
ODOMETRY_COLUMNS = ("id", "x_m", "y_m", "z_m", "heading_deg")


@dataclass(frozen=True)
class DeadReckonedPoses:
    """Dead-reckoned station poses in drive order, as an odometry file gives them.

    Attributes
    ----------
    ids : tuple of str
        Station ids in drive order.
    position_m : (s, 3) float
    heading_rad : (s,) float
    """

    ids: tuple[str, ...]
    position_m: np.ndarray
    heading_rad: np.ndarray

    def readings(self, station_ids) -> OdometryReadings:
        """The relative poses between consecutive poses, as :class:`OdometryReadings` of the
        network whose stations are ``station_ids`` (every id of the file must be one)."""
        station_ids = list(station_ids)
        unknown = [i for i in self.ids if i not in station_ids]
        if unknown:
            from markerplan.errors import InputFileError

            raise InputFileError(f"odometry stations {', '.join(unknown[:4])} are not stations of "
                              "the network; drop their rows from the odometry file")
        order = np.array([station_ids.index(i) for i in self.ids], dtype=np.int64)
        return OdometryReadings.from_poses(order, self.position_m, self.heading_rad)


def read_odometry(path) -> DeadReckonedPoses:
    """Dead-reckoned poses from a CSV ``id,x_m,y_m,z_m,heading_deg``, one row per station in
    the order the rover drove them (site frame, m, degrees).

    Raises
    ------
    InputFileError
        Missing file or columns, fewer than 2 rows, repeated or empty ids, non-finite numbers,
        two consecutive rows at one position.
    """
    from markerplan.errors import InputFileError
    from markerplan.reading import finite_number, read_csv, unique_ids

    what = f"odometry file {path}"
    header, rows = read_csv(path, what, ODOMETRY_COLUMNS,
                            "give one row per station in drive order: id,x_m,y_m,z_m,heading_deg")
    if len(rows) < 2:
        raise InputFileError(f"{what}: {len(rows)} station(s); odometry needs at least 2 rows "
                             "(id,x_m,y_m,z_m,heading_deg) in drive order")
    col = {c: header.index(c) for c in ODOMETRY_COLUMNS}
    ids = unique_ids([r[col["id"]].strip() for r in rows], what)
    values = np.array([[finite_number(r[col[c]], f"{what} row {line} {c}")
                        for c in ODOMETRY_COLUMNS[1:]] for line, r in enumerate(rows, start=2)])
    step = np.linalg.norm(np.diff(values[:, :3], axis=0), axis=1)
    if np.any(step <= 0):
        i = int(np.flatnonzero(step <= 0)[0])
        raise InputFileError(f"{what} rows {i + 2} and {i + 3} ({ids[i]}, {ids[i + 1]}): one "
                             "position, so no distance driven; drop the repeated station")
    return DeadReckonedPoses(tuple(ids), values[:, :3], np.radians(values[:, 3]))


#: Columns of a heading file: each station's heading as the heading reference read it (site
#: frame, degrees, the boresight bias included).
HEADING_COLUMNS = ("id", "heading_deg")


@dataclass(frozen=True)
class MeasuredHeadings:
    """The heading reference's readings per station, as a heading file gives them.

    Attributes
    ----------
    ids : tuple of str
        Station ids, in the file's order.
    heading_rad : (s,) float
        Their readings, site frame, rad.
    """

    ids: tuple[str, ...]
    heading_rad: np.ndarray

    def readings(self, station_ids) -> HeadingReadings:
        """The readings of the network whose stations are ``station_ids`` (in its order), as
        :class:`HeadingReadings`: every station of the network needs one, and every id of the
        file must be one of its stations."""
        from markerplan.errors import InputFileError

        station_ids = list(station_ids)
        unknown = [i for i in self.ids if i not in station_ids]
        if unknown:
            raise InputFileError(f"heading readings of {', '.join(unknown[:4])}: not stations "
                                 "of the network; drop their rows from the heading file")
        missing = [i for i in station_ids if i not in self.ids]
        if missing:
            raise InputFileError(f"station(s) {', '.join(missing[:4])} have no heading reading; "
                                 "give one row (id,heading_deg) per station adjusted")
        return HeadingReadings(self.heading_rad[[self.ids.index(i) for i in station_ids]])


def read_headings(path) -> MeasuredHeadings:
    """Heading readings from a CSV ``id,heading_deg``, one row per station (site frame,
    degrees).

    Raises
    ------
    InputFileError
        Missing file or columns, no rows, repeated or empty ids, non-finite numbers.
    """
    from markerplan.errors import InputFileError
    from markerplan.reading import finite_number, read_csv, unique_ids

    what = f"heading file {path}"
    header, rows = read_csv(path, what, HEADING_COLUMNS,
                            "give one row per station: id,heading_deg")
    if not rows:
        raise InputFileError(f"{what}: no rows; give one row per station: id,heading_deg")
    col = {c: header.index(c) for c in HEADING_COLUMNS}
    ids = unique_ids([r[col["id"]].strip() for r in rows], what)
    degrees = [finite_number(r[col["heading_deg"]], f"{what} row {line} heading_deg", 1e6)
               for line, r in enumerate(rows, start=2)]
    return MeasuredHeadings(tuple(ids), np.radians(degrees))
