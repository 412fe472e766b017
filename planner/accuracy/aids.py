"""Pose aids of a network: what the rover knows of its poses besides the markers.

Each aid is a pseudo-observation of the pose parameters (:data:`pipeline.network.observations.
POSE_PARAMETERS` of every station, site frame), linear at the nominal layout (headings and tilts
0, site axes, as :mod:`planner.accuracy.network` linearises the markers):

- the **inclinometer**: each station's roll and pitch observed as 0, 1-sigma
  ``inclinometer_sigma_rad`` (independent);
- a **heading reference** (sun sensor, star tracker, :data:`HEADING_AIDS`): each station's
  heading observed with a random error (1-sigma ``random_sigma_rad``, independent per station)
  plus one **boresight bias** common to every station (1-sigma ``bias_sigma_rad``: how well the
  sensor's mounting to the LiDAR is calibrated). The bias is eliminated, so the heading
  observations are correlated: covariance ``sigma_r^2 I + sigma_b^2 1 1^T``, whose inverse is
  ``(I - c 1 1^T) / sigma_r^2`` with ``c = sigma_b^2 / (sigma_r^2 + s sigma_b^2)``
  (Sherman-Morrison). With the datum station's heading fixed only differences of headings are
  observed, so a large bias leaves each heading about ``sqrt(2) sigma_r``;
- **odometry** between consecutive stations (the order the stations are listed in: the order
  the rover drives them): the pose of station ``k + 1`` in the levelled frame of station ``k``,
  ``Rz(psi_k)^T (t_(k+1) - t_k)`` and ``psi_(k+1) - psi_k``, with a 1-sigma per axis growing
  with the distance driven (``position_ratio * d``, and ``heading_rad_per_m * d`` for the
  heading), ``d`` the straight distance between the two stations (the least the rover drives).
  Linearised at ``psi_k = 0`` the position rows are ``dt_(k+1) - dt_k + (d_y, -d_x, 0) dpsi_k``
  with ``(d_x, d_y)`` the offset between them; the error is isotropic per axis, so the frame
  the odometry reports in does not change the information;
- on a **closed traverse** (:attr:`Odometry.loop_m`: the rover drives from the last station
  back to the route start, the lander, and leaves it for the first) one more reading of the
  same form, the pose of the first station in the levelled frame of the last, its 1-sigma
  growing with the distance driven along the two closing legs (last station -> start ->
  first station). The lander is no station of the network (nothing else observes it, and the
  datum is the reference station or control points), so the two legs are one relative
  reading: the rover's dead reckoning carried through the lander. Like a leg between
  consecutive stations it is one drive whose error grows with its length (``ratio * d`` on
  the whole of it: as conservative as the consecutive rows, which take one leg's drift as
  independent of the next's), and the closing legs are the route's driven distance, not the
  straight distance from the last station to the first.

The odometry and heading-reference rows are the adjustment's own
(:func:`pipeline.network.aids.aid_model`, at noise-free readings of the nominal layout), so the
planner and ``adjust`` share one model of them. Their information ``J_prior = A^T W A``
(:attr:`PoseAids.information`) is a constant of the layout: the network's information stays
``J_prior + sum_j x_j J^(j)``, linear in the selection, and every cut of
:mod:`planner.accuracy.network` keeps its validity. Odometry ties every station
to the datum, so with it no station is ever cut off (:meth:`PoseAids.links`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from markerplan.errors import ConfigError
from pipeline.network.aids import OdometryReadings, aid_model

#: Heading reference classes: name -> (random 1-sigma, boresight bias 1-sigma), degrees. A fine
#: sun sensor reads the sun's azimuth to about 0.1 deg, mounted to about 0.05 deg; a star
#: tracker reads attitude to about 10 arcsec, its boresight calibrated to the LiDAR to about
#: 20 arcsec. Either figure can be set on its own (``heading_prior_sigma_deg``,
#: ``heading_bias_sigma_deg``).
HEADING_AIDS: dict[str, tuple[float, float]] = {
    "sun-sensor": (0.1, 0.05),
    "star-tracker": (10.0 / 3600.0, 20.0 / 3600.0),
}


@dataclass(frozen=True)
class Odometry:
    """The rover's odometry between consecutive stations.

    Attributes
    ----------
    position_ratio : float or None
        1-sigma per axis of the relative position, per metre driven (e.g. 0.02: 2 %);
        ``None``: no position rows.
    heading_rad_per_m : float or None
        1-sigma of the relative heading, rad per metre driven; ``None``: no heading row.
    loop_m : float or None
        A closed traverse: the distance driven from the last station back to the first (through
        the route start), m, whose reading of the first station from the last closes the
        network; ``None``: an open traverse.
    """

    position_ratio: float | None = None
    heading_rad_per_m: float | None = None
    loop_m: float | None = None

    @property
    def any(self) -> bool:
        return self.position_ratio is not None or self.heading_rad_per_m is not None


@dataclass(frozen=True)
class PoseAids:
    """The aids of a network as pseudo-observations of all ``6 s`` pose parameters.

    Attributes
    ----------
    design : (m, 6 s) scipy.sparse.csr_array
        ``A``: each pseudo-observation's row (fixed parameters included).
    weight : (m, m) scipy.sparse.csr_array
        ``W``: their weight matrix (block diagonal; the heading block dense when it has a
        boresight bias), 1/m^2 and 1/rad^2.
    position_links : (p, 2) int
        Stations the odometry ties in position: consecutive ones, and the last with the first
        on a closed traverse (empty without position rows).
    """

    design: sp.csr_array
    weight: sp.csr_array
    position_links: np.ndarray

    def information(self, free: np.ndarray) -> np.ndarray:
        """``J_prior = A^T W A`` on the free parameters ``free`` ((P,) int into the ``6 s``):
        (P, P) float."""
        a = self.design[:, free]
        j = (a.T @ (self.weight @ a)).toarray()
        return 0.5 * (j + j.T)

    def redundancy(self, covariance: np.ndarray, free: np.ndarray) -> tuple[np.ndarray,
                                                                             np.ndarray]:
        """Redundancy numbers ``diag(I - A C A^T W)`` of the rows that bear on the free
        parameters (their own design or, through a correlated weight, another row's).

        Parameters
        ----------
        covariance : (P, P) float
            ``C`` of the free parameters.
        free : (P,) int

        Returns
        -------
        rows : (r,) int
            The rows judged.
        redundancy : (r,) float
            Their redundancy numbers, clipped to [0, 1].
        """
        a = self.design[:, free]
        bears = np.asarray(abs(self.weight @ a).sum(axis=1)).ravel() > 0
        rows = np.flatnonzero(bears)
        ar = a[rows]
        aca = ar @ (ar @ covariance).T  # (r, r) = A C A^T
        w = self.weight[rows][:, rows].toarray()
        return rows, np.clip(1.0 - np.einsum("ik,ki->i", aca, w), 0.0, 1.0)

    def links(self) -> np.ndarray:
        """(p, 2) int: station pairs the odometry ties in position (empty without it)."""
        return self.position_links


def pose_aids(station_xyz: np.ndarray, inclinometer_sigma_rad: float,
              heading_sigma_rad: float | None = None, heading_bias_sigma_rad: float = 0.0,
              odometry: Odometry | None = None) -> PoseAids:
    """The :class:`PoseAids` of a network of stations: the tilt rows, then the odometry and
    heading-reference rows of the adjustment's own model
    (:func:`pipeline.network.aids.aid_model`, linearised at the nominal layout with headings 0:
    noise-free readings of it).

    Parameters
    ----------
    station_xyz : (s, 3) float
        Nominal station positions, site frame, m, in the order the rover visits them.
    inclinometer_sigma_rad : float
        Roll and pitch prior, rad; 0: no tilt rows (the caller fixes roll and pitch).
    heading_sigma_rad : float, optional
        Random 1-sigma of the heading reference, rad; ``None``: no heading reference.
    heading_bias_sigma_rad : float
        1-sigma of the heading reference's common boresight bias, rad.
    odometry : Odometry, optional
        With :attr:`Odometry.loop_m`, the closing reading too (from the last station to the
        first; none with a single station).

    Returns
    -------
    PoseAids

    Raises
    ------
    ConfigError
        A boresight bias without a heading reference, or two consecutive stations at one
        position (no distance driven for the odometry's sigma).
    """
    xyz = np.asarray(station_xyz, dtype=float)
    s = xyz.shape[0]
    if heading_bias_sigma_rad > 0 and heading_sigma_rad is None:
        raise ConfigError("a heading boresight bias needs a heading reference; set "
                          "heading_prior_sigma_deg or heading_aid, or drop heading_bias_sigma_deg")
    odo = odometry or Odometry()
    readings = None
    if odo.any and s > 1:
        driven = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
        if np.any(driven <= 0):
            k = int(np.flatnonzero(driven <= 0)[0])
            raise ConfigError(f"stations {k} and {k + 1} (in the order given) stand at one "
                              "position, so the odometry has no distance driven; remove the "
                              "duplicate station or drop the odometry")
        readings = OdometryReadings.from_poses(np.arange(s), xyz, np.zeros(s), odo.loop_m)
    heading = heading_sigma_rad is not None
    model = aid_model(s, readings, odo.position_ratio, odo.heading_rad_per_m,
                      np.zeros(s) if heading else None, heading_sigma_rad,
                      heading_bias_sigma_rad if heading else None)
    designs, weights = [], []
    if inclinometer_sigma_rad > 0:
        tilt = (6 * np.arange(s)[:, None] + np.array([4, 5])).ravel()
        designs.append(sp.csr_array((np.ones(tilt.size), (np.arange(tilt.size), tilt)),
                                    shape=(tilt.size, 6 * s)))
        weights.append(sp.diags_array(np.full(tilt.size, inclinometer_sigma_rad**-2.0)))
    links = np.zeros((0, 2), np.int64)
    if model is not None:
        pose = np.zeros((s, 6))
        pose[:, :3] = xyz
        designs.append(model.linearise(pose)[0])
        weights.append(model.weight)
        if model.position_sigma_m is not None:
            links = model.pairs
    if not designs:
        return PoseAids(sp.csr_array((0, 6 * s)), sp.csr_array((0, 0)), links)
    return PoseAids(sp.csr_array(sp.vstack(designs, format="csr")),
                    sp.csr_array(sp.block_diag(weights, format="csr")), links)


def closing_distance_m(position_m: np.ndarray, loop_m: float, kept) -> float:
    """The closing legs' distance of a closed traverse that keeps only some of its stations:
    the rover still drives every stop, so the reading from the last kept station to the first
    spans ``loop_m`` plus the straight steps between the stations left out at either end (the
    least the rover drives, as between consecutive stations).

    Parameters
    ----------
    position_m : (s, 3) float
        The traverse's stations in drive order, m.
    loop_m : float
        Its closing legs' distance (last station -> start -> first station), m.
    kept : (k,) int
        Indices of the stations kept, increasing, ``k >= 2``.

    Returns
    -------
    float
        m.

    Examples
    --------
    >>> xyz = np.array([[0.0, 0, 0], [3, 0, 0], [3, 4, 0], [0, 4, 0]])
    >>> closing_distance_m(xyz, 10.0, [0, 1, 2, 3]), closing_distance_m(xyz, 10.0, [1, 2])
    (10.0, 16.0)
    """
    kept = np.asarray(kept)
    step = np.linalg.norm(np.diff(np.asarray(position_m, dtype=float), axis=0), axis=1)
    return float(loop_m + step[kept[-1]:].sum() + step[:kept[0]].sum())


def heading_aid_sigmas_deg(aid: str | None) -> tuple[float, float] | None:
    """The (random, bias) 1-sigma of a heading reference class, degrees; ``None`` for none.

    >>> [round(v * 3600) for v in heading_aid_sigmas_deg("star-tracker")]
    [10, 20]
    """
    if aid is None:
        return None
    if aid not in HEADING_AIDS:
        raise ConfigError(f"`heading_aid` must be one of {', '.join(map(repr, HEADING_AIDS))}, "
                          f"got {aid!r:.40}; or set heading_prior_sigma_deg yourself")
    return HEADING_AIDS[aid]

