"""Predicted accuracy of stations and markers in network mode: the whole network's information.

Model (shared with :mod:`pipeline.network.adjustment`)
------------------------------------------------------
The observation model is :mod:`pipeline.network.design`, the one the adjustment uses. Every
station has 6 pose parameters (x, y, z, heading, roll, pitch,
:data:`pipeline.network.observations.POSE_PARAMETERS`); roll and pitch carry the
inclinometer's prior ``0 +- inclinometer_sigma_rad``. The datum is either the reference station
(the first by default) whose x, y, z and heading are fixed (the adjustment's ``"station"``
datum), or the problem's control points (a lander's fiducials,
:attr:`~planner.problem.usability.PlanProblem.site_control`: existing sites with known
coordinates ``+- sigma_c`` per axis, the adjustment's ``"control"`` datum), and then no station
is fixed, or nothing (a free network, the adjustment's ``"free"`` datum; below). Markers are
unknowns. Station ``s`` measures the marker at candidate site ``j`` with
per-axis weight ``w_sj = 3 / sigma_sj^2`` (:func:`pipeline.network.design.axis_weight`); its design
block ``H_sj`` (3 x 6) is :func:`pipeline.network.design.pose_design_blocks` linearised at the
nominal layout with heading and tilts 0, i.e. at the offset ``p = site - station`` along the
site axes. At a station heading ``psi`` the adjustment's roll and pitch are about the station's
own axes, the planner's about the site axes: a rotation by ``psi`` of the two tilt parameters,
which leaves every position covariance unchanged (the tilt prior is isotropic). On a curved
body the adjustment centres the tilt prior on the local vertical's deflection
(:mod:`pipeline.network.body`) instead of 0; a prior's centre changes no covariance, and the
design at tilts of d / R (0.03 deg at 800 m on the Moon) differs from the one at 0 by that
fraction, so the prediction here holds on every body.

Eliminating the marker's 3 coordinates (Schur complement) leaves the fixed positive
semi-definite contribution of site ``j`` on the poses of the stations ``S_j`` that can use it::

    J^(j) = sum_s w_s H_s^T H_s - (1 / T_j) (sum_s w_s H_s)^T (sum_s w_s H_s),  W_j = sum_s w_s

so the pose information of a layout ``x`` (0/1 per site) is ``J(x) = J_prior + sum_j x_j J^(j)``,
linear in the selection. ``v^T J^(j) v = sum_s w_s |a_s - a_bar|^2`` with ``a_s = H_s v_s`` and
``a_bar`` their ``w``-weighted mean: the weighted spread of what the stations would see of a
pose change ``v`` (:meth:`NetworkModel.site_coefficients` vectorises it over all pairs). A site
seen by one station only contributes nothing (its marker absorbs it): a network needs markers
that tie stations together. ``T_j = W_j`` for a marker; a control point's known coordinates add
their prior weight ``lambda_j = 1 / sigma_c^2`` per axis, ``T_j = W_j + lambda_j``, which adds
``(lambda_j / (W_j T_j)) |sum_s w_s a_s|^2`` to the spread: a control point seen by a single
station ties it to the datum (``sigma_c -> 0`` gives the known-control information
``sum_s w_s H_s^T H_s``). Control points are always in the layout (existing sites), so their
``J^(j)`` is a constant of every layout.

Errors
------
Station ``k``'s error is known-control mode's 95 % figure over the station's working disc
(:class:`planner.accuracy.figure.ErrorFigure`: the quantile of the worst error, or the
ellipsoid figure ``sqrt(chi2_3(0.95) max_q lambda_max(G(q) C_k G(q)^T))``), with the 6 x 6
block ``C_k`` of ``C = J^-1`` (zero rows for the datum's fixed parameters). A selected marker at
``j`` is estimated as the weighted mean of its stations' registered measurements (and, at a
control point, its known coordinates): covariance ``I / T_j + M_j C M_j^T`` with
``M_j = (1 / T_j) sum_s w_s H_s`` (:meth:`NetworkModel.marker_errors`). Control points are not
judged against the marker requirement: their accuracy is given.

Free network
------------
A free network fixes nothing: its observations are invariant to a translation of the whole
network and, without a heading reference, a rotation about the vertical (the datum defect,
:data:`pipeline.network.observations.DATUM_DEFECTS`). Internally the defect alone is fixed, x,
y, z of one station (the first) and its heading unless a heading reference observes it
(:meth:`~pipeline.network.observations.Datum.constrained_defects`' rule; odometry observes
relative headings only). Estimable quantities, a relative position with a heading reference or
a distance between stations or markers, do not depend on which minimal constraints are chosen.
Figures are reported datum-free: in the adjustment's free datum, the inner constraints on the
stations' centroid (and mean heading), reached from the internal covariance ``C`` by the
S-transformation ``C_free = P C P^T``, ``P = I - G (B G)^-1 B`` (``G`` the defect directions,
:func:`pipeline.network.normals.defect_basis`, ``B`` the constraints: ``G^T`` on the stations'
x, y, z and heading) (:meth:`NetworkModel.datum_free`). ``P`` is fixed by the geometry, so a
figure ``g^T C_free g`` is ``(P^T g)^T C (P^T g)``: convex and monotone in the information as
below, with the gradient ``P^T g`` (:meth:`NetworkModel.datum_free_gradients`).

Convexity and monotonicity
--------------------------
``h(J) = g^T J^-1 g`` is convex in ``J`` for every fixed ``g`` (``J -> J^-1`` is operator
convex), and a station's worst-case variance is the maximum of such functions over rim points
and directions (``g = G(q)^T u``), so its tangent at any ``J0`` (``v = J0^-1 g``,
``h0 = g^T v``) bounds it from below: ``h(J) >= 2 h0 - v^T J v``. The requirement implies
``h(J) <= b = a_k^2 / k`` (``a_k`` the station's allowance
:attr:`NetworkModel.allowed_station_m`, constant or growing with its distance from the datum;
``k`` = :attr:`~planner.accuracy.figure.ErrorFigure.cut_chi2`: exact for the ellipsoid
figure, a necessary condition for the quantile), hence the linear cut
``sum_j (v^T J^(j) v) x_j >= 2 h0 - b - v^T J_prior v`` (:meth:`NetworkModel.tangent_cuts`),
valid for every layout. Adding a site adds the PSD ``J^(j)``, so ``J`` grows in the Loewner
order, ``C`` shrinks, and no station's (or selected marker's) error ever grows: every subset of a
failing layout fails too, which makes the no-good cuts of :mod:`planner.program` valid (for
the quantile figure by Anderson's theorem, to the precision of its draws).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.sparse import csr_array
from scipy.sparse.csgraph import connected_components

from markerplan.errors import ConfigError
from pipeline.network.design import axis_weight, pose_design_blocks
from pipeline.network.observations import POSE_PARAMETERS, Datum
from planner.accuracy.aids import Odometry, pose_aids
from planner.accuracy.figure import ErrorFigure, error_figure
from planner.accuracy.network_covariance import NetworkCovariance
from planner.accuracy.network_tangents import NetworkTangents
from planner.accuracy.requirement import FREE_NETWORK, NetworkRequirement, datum_distances
from planner.problem.usability import PlanProblem

_CHUNK = 100_000
#: A Cholesky pivot below this fraction of its diagonal entry marks the information singular
#: (a station not tied to the datum).
SINGULAR_PIVOT = 1e-10


class NetworkModel(NetworkTangents):
    """A :class:`~planner.problem.usability.PlanProblem` as a network tied to a reference station.

    Parameters
    ----------
    problem : PlanProblem
    working_radius_m : float
        Radius of each station's working disc, m.
    inclinometer_sigma_rad : float
        Roll/pitch prior, rad (0: roll and pitch fixed).
    reference : int, optional
        Index of the datum station (x, y, z, heading fixed); default the first station, or
        none when the problem has control points (they are the datum).
    heading_prior_sigma_rad : float, optional
        A heading reference on every station (a sun sensor, a star tracker): its random
        1-sigma, rad (:mod:`planner.accuracy.aids`).
    figure : ErrorFigure, optional
        The 95 % figure of station and marker errors (default: the planner's default).
    requirement : NetworkRequirement, optional
        The allowed 95 % error, constant or growing with the distance from the reference
        (default: the planner's default, 0.10 m).
    heading_bias_sigma_rad : float
        The heading reference's common boresight bias, 1-sigma, rad.
    odometry : Odometry, optional
        Odometry between consecutive stations (in the problem's station order).
    free_datum : bool
        A free network (see the module doc): nothing fixed, no control points and no
        ``reference``.

    Attributes
    ----------
    reference : int or None
        The datum station; ``None`` with control points or a free datum.
    free_datum : bool
        A free network.
    datum_map : (6 s, 6 s) float or None
        ``P``, the S-transformation of the pose covariance to the free datum's inner
        constraints (``None`` unless ``free_datum``).
    control : (n,) bool
        The control points among the sites.
    site_prior_weight : (n,) float
        ``lambda_j``: a control point's prior weight per axis ``1 / sigma_c^2``, 1/m^2; 0 for
        every other site.
    datum_xyz : (3,) float
        The datum point distances are measured from: the reference station, or the control
        points' centroid (the lander), site frame, m.
    allowed_station_m : (s,) float
        Each station's allowed 95 % error, m (the requirement at its distance from the
        datum point).
    allowed_site_m : (n,) float
        Each candidate site's allowed 95 % marker error, m (``inf`` at control points).
    free : (P,) int
        Index into the ``6 s`` pose parameters of each free (estimated) parameter.
    aids : PoseAids
        The pose aids as pseudo-observations.
    prior_information : (P, P) float
        Their information ``J_prior`` on the free parameters.
    pair_station, pair_site : (p,) int
        Usable pairs, sorted by site then station.
    pair_index : (p,) int
        Each of them as an index into the problem's pairs.
    weight : (p,) float
        ``3 / sigma^2`` per axis, 1/m^2.
    design : (p, 3, 6) float
        ``H`` of each pair.
    site_weight : (n,) float
        ``W_j``; 0 for sites no station can use.
    site_total_weight : (n,) float
        ``T_j = W_j + lambda_j``.
    n_stations_seeing : (n,) int
        ``|S_j|``.
    """

    def __init__(self, problem: PlanProblem, working_radius_m: float,
                 inclinometer_sigma_rad: float, reference: int | None = None,
                 heading_prior_sigma_rad: float | None = None,
                 figure: ErrorFigure | None = None,
                 requirement: NetworkRequirement | None = None,
                 heading_bias_sigma_rad: float = 0.0,
                 odometry: Odometry | None = None, free_datum: bool = False) -> None:
        self.control = problem.site_control
        self.free_datum = bool(free_datum)
        if self.free_datum and (self.control.any() or reference is not None):
            raise ConfigError("a free network fixes nothing: drop the control points and "
                              "`reference_station`, or use their datum (`datum` = 'station')")
        if self.control.any():
            if reference is not None:
                raise ConfigError("control points are the datum and fix no station: drop "
                                  "`reference_station`, or the control points")
        elif reference is None and not self.free_datum:
            reference = 0
        elif reference is not None and not 0 <= reference < problem.n_stations:
            raise ConfigError(f"`reference` must index one of the {problem.n_stations} "
                              f"stations, got {reference!r}")
        self.problem = problem
        self.figure = figure or ErrorFigure()
        self.radius = float(working_radius_m)
        self.incl = float(inclinometer_sigma_rad)
        self.reference = None if reference is None else int(reference)
        self.requirement = requirement or NetworkRequirement()
        sigma_c = np.where(self.control, problem.site_control_sigma_m
                           if problem.site_control_sigma_m is not None else 1.0, 1.0)
        self.site_prior_weight = np.where(self.control, 1.0 / sigma_c**2, 0.0)
        self.datum_xyz = (problem.station_xyz.mean(axis=0) if self.free_datum
                          else problem.site_xyz[self.control].mean(axis=0)
                          if self.reference is None else problem.station_xyz[self.reference])
        #: (s,) and (n,) float: horizontal distances of the stations and sites from the datum, m
        self.station_distance_m = datum_distances(problem.station_xyz, self.datum_xyz)
        self.site_distance_m = datum_distances(problem.site_xyz, self.datum_xyz)
        self.allowed_station_m, self.allowed_site_m = self.allowances(self.requirement)
        s = problem.n_stations
        fixed = np.zeros((s, 6), bool)
        if self.reference is not None:
            fixed[self.reference, :4] = True
        #: bool: a heading reference observes every station's heading (odometry, relative only, does
        #: not count: PlanConfig.heading_observed's other meaning)
        self.heading_referenced = heading_prior_sigma_rad is not None
        self.datum_map = None
        if self.free_datum:  # fix the defect alone, internally (see the module doc)
            defects = np.asarray(Datum("free").constrained_defects(self.heading_referenced))
            fixed[0, defects] = True
            self.datum_map = _inner_constraint_map(problem.station_xyz, defects)
        if self.incl <= 0:
            fixed[:, 4:] = True
        self.free = np.flatnonzero(~fixed.ravel())
        #: (6 s,) int: each pose parameter's index among the free ones (-1: fixed)
        self.free_position = np.full(6 * s, -1)
        self.free_position[self.free] = np.arange(self.free.size)
        #: PoseAids: the inclinometer, heading reference and odometry as pseudo-observations
        self.aids = pose_aids(problem.station_xyz, self.incl, heading_prior_sigma_rad,
                              heading_bias_sigma_rad, odometry)
        #: (P, P) float: their information ``J_prior`` on the free parameters
        self.prior_information = self.aids.information(self.free)
        idx = np.flatnonzero(problem.pair_usable)
        idx = idx[np.lexsort((problem.pair_station[idx], problem.pair_site[idx]))]
        self.pair_index = idx
        self.pair_station = problem.pair_station[idx]
        self.pair_site = problem.pair_site[idx]
        self.weight = axis_weight(problem.pair_sigma_m[idx])
        _, self.design = pose_design_blocks(
            problem.site_xyz[self.pair_site] - problem.station_xyz[self.pair_station])
        n = problem.n_sites
        self.site_weight = np.bincount(self.pair_site, self.weight, minlength=n)
        self.site_total_weight = self.site_weight + self.site_prior_weight
        self.n_stations_seeing = np.bincount(self.pair_site, minlength=n)
        self.site_start = np.r_[0, np.cumsum(self.n_stations_seeing)]
        self._site_sum = csr_array((np.ones(self.pair_site.size),
                                    (self.pair_site, np.arange(self.pair_site.size))),
                                   shape=(n, self.pair_site.size))  # (n, p): sum over a site
        # ordered pairs (a, b) of pairs of one site, for the tying sites
        k = self.n_stations_seeing
        multi = np.flatnonzero(self.tying)
        reps = k[multi] ** 2
        site = np.repeat(multi, reps)
        off = np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps)
        kk = k[site]
        self.tie_site = site
        self.tie_a = self.site_start[site] + off // kk
        self.tie_b = self.site_start[site] + off % kk
        self.tie_coef = self.tie_coefficients(self.weight)

    def allowances(self, requirement: NetworkRequirement) -> tuple[np.ndarray, np.ndarray]:
        """What ``requirement`` allows each station ((s,) float) and each candidate site ((n,)
        float) at its distance from this network's datum, m (a check of a layout against a
        configuration other than the model's own: :func:`planner.accuracy.checks.
        evaluate_layout`)."""
        return (requirement.allowed_m(self.station_distance_m),
                np.where(self.control, np.inf, requirement.allowed_m(self.site_distance_m)))

    @property
    def datum_text(self) -> str:
        """The datum in words, for messages and reports: ``"station S1"`` or ``"the control
        points L1, L2, L3"``."""
        ids = self.problem.site_ids
        if self.free_datum:
            return FREE_NETWORK
        if self.reference is not None:
            return f"station {self.problem.station_ids[self.reference]}"
        names = [ids[j] for j in np.flatnonzero(self.control)]
        return "the control points " + ", ".join(names[:5]) + (
            f" (and {len(names) - 5} more)" if len(names) > 5 else "")

    def datum_record(self) -> dict:
        """The datum as ``plan.json`` and ``reduce.json`` record it (``network.datum``):
        ``kind`` (``"station"``, ``"control"`` or ``"free"``), ``reference_station``, the
        ``fixed`` parameters, the ``control`` points (id, site-frame xyz and sigma, m),
        ``datum_xyz_m`` (where distances are measured from: the stations' centroid in a free
        network) and ``description`` (:attr:`datum_text`; a free network's says what is
        fixed and how its figures are relative)."""
        p = self.problem
        station = self.reference is not None
        if self.free_datum:
            heading = "" if self.heading_referenced else " and mean heading"
            return {"kind": "free", "reference_station": None, "fixed": [], "control": [],
                    "datum_xyz_m": [float(v) for v in self.datum_xyz],
                    "description": (f"{self.datum_text}: nothing fixed; every figure is "
                                    f"relative, station figures in the inner constraints on "
                                    f"the stations' centroid{heading}")}
        return {"kind": "station" if station else "control",
                "reference_station": p.station_ids[self.reference] if station else None,
                "fixed": list(POSE_PARAMETERS[:4]) if station else [],
                "control": [{"marker_id": p.site_ids[j], "xyz_m": p.site_xyz[j].tolist(),
                             "sigma_m": float(p.site_control_sigma_m[j])}
                            for j in np.flatnonzero(self.control)],
                "datum_xyz_m": [float(v) for v in self.datum_xyz],
                "description": self.datum_text}

    def tie_coefficients(self, weight: np.ndarray) -> np.ndarray:
        """Each tie's ``delta_ab w_a - w_a w_b / T_j`` for the pairs' weights ``weight`` ((p,)
        or (k, p), 0 for a lost pair; 0 where a site keeps no pair): (t,) or (k, t)."""
        site_weight = (self._site_sum @ np.atleast_2d(weight).T).T.reshape(
            weight.shape[:-1] + (self.problem.n_sites,)) + self.site_prior_weight
        wa, wb = weight[..., self.tie_a], weight[..., self.tie_b]
        total = site_weight[..., self.tie_site]
        return np.where(self.tie_a == self.tie_b, wa, 0.0) \
            - wa * wb / np.where(total > 0, total, 1.0)

    # -- information and covariance ------------------------------------------------------------
    @property
    def n_params(self) -> int:
        return self.free.size

    @property
    def tying(self) -> np.ndarray:
        """(n,) bool: sites whose contribution ``J^(j)`` is not zero (seen by >= 2 stations, or
        a control point seen by one)."""
        return (self.n_stations_seeing >= 2) | (self.control & (self.n_stations_seeing >= 1))

    def information(self, x, kept: np.ndarray | None = None) -> np.ndarray:
        """Pose information ``J(x) = J_prior + sum_j x_j J^(j)`` of the free parameters.

        Parameters
        ----------
        x : (n,) bool or float
            Selection (or non-negative weights) of the candidate sites.
        kept : (p,) bool, optional
            Which usable pairs (in this model's pair order) are observed; the others are
            lost, and each ``J^(j)`` is built from its site's kept pairs (default: all kept).

        Returns
        -------
        J : (P, P) float
        """
        return self.site_information(x, kept) + self.prior_information

    def site_information(self, x, kept: np.ndarray | None = None) -> np.ndarray:
        """The sites' share of the information, ``sum_j x_j J^(j)`` (no prior), (P, P); ``x``
        and ``kept`` as in :meth:`information`."""
        x = np.asarray(x, dtype=float)
        coef = self.tie_coef if kept is None \
            else self.tie_coefficients(np.where(kept, self.weight, 0.0))
        n6 = 6 * self.problem.n_stations
        acc = np.zeros(n6 * n6)
        take = np.flatnonzero(x[self.tie_site] != 0)
        for lo in range(0, take.size, _CHUNK):
            t = take[lo:lo + _CHUNK]
            blocks, flat = self.tie_blocks(t)
            c = coef[t] * x[self.tie_site[t]]
            acc += np.bincount(flat.ravel(), (c[:, None, None] * blocks).ravel(),
                               minlength=n6 * n6)
        full = acc.reshape(n6, n6)
        j = full[np.ix_(self.free, self.free)]
        return 0.5 * (j + j.T)

    def tie_blocks(self, ties: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each tie's 6 x 6 block ``H_a^T H_b`` ((t, 6, 6)) and where its entries go in the
        flattened ``(6 s)^2`` pose matrix ((t, 6, 6) int), for tie indices ``ties``."""
        a, b = self.tie_a[ties], self.tie_b[ties]
        n6 = 6 * self.problem.n_stations
        blocks = np.einsum("qia,qib->qab", self.design[a], self.design[b])
        ra = 6 * self.pair_station[a][:, None] + np.arange(6)
        rb = 6 * self.pair_station[b][:, None] + np.arange(6)
        return blocks, ra[:, :, None] * n6 + rb[:, None, :]

    def covariance(self, j: np.ndarray) -> NetworkCovariance:
        """Covariance of the free parameters from the information ``j``, with undetermined
        stations (a rank-deficient ``j``: not tied to the datum, or heading free) flagged."""
        s = self.problem.n_stations
        n6 = 6 * s
        determined = np.ones(s, bool)
        c = None
        try:
            factor = scipy.linalg.cho_factor(j)
            # a pivot that is a vanishing fraction of its diagonal: numerically singular
            if np.min(np.diag(factor[0]) ** 2 / np.diag(j)) > SINGULAR_PIVOT:
                c = scipy.linalg.cho_solve(factor, np.eye(j.shape[0]))
        except np.linalg.LinAlgError:
            pass
        if c is None:
            scale = np.sqrt(np.maximum(np.diag(j), 1e-300))
            js = j / scale[:, None] / scale[None, :]
            lam, vec = np.linalg.eigh(js)
            null = lam <= 1e-10 * max(lam[-1], 1e-300)
            inv = np.where(null, 0.0, 1.0 / np.where(null, 1.0, lam))
            c = (vec * inv) @ vec.T / scale[:, None] / scale[None, :]
            determined = self.determined_by(vec[:, null])
        full = np.zeros((n6, n6))
        full[np.ix_(self.free, self.free)] = 0.5 * (c + c.T)
        return NetworkCovariance(full=full, determined=determined)

    def datum_free(self, cov: NetworkCovariance) -> NetworkCovariance:
        """``cov`` in the free datum's inner constraints, ``P C P^T`` (see the module doc); the
        covariance itself for the other datums."""
        if self.datum_map is None:
            return cov
        full = self.datum_map @ cov.full @ self.datum_map.T
        return NetworkCovariance(full=0.5 * (full + full.T), determined=cov.determined)

    def datum_free_gradients(self, g: np.ndarray) -> np.ndarray:
        """(m, 6 s) gradients ``g`` ((m, 6 s)) of figures of :meth:`datum_free`'s covariance
        as gradients of the internal one, ``g P`` (``g`` itself for the other datums)."""
        return g if self.datum_map is None else g @ self.datum_map

    def determined_by(self, null: np.ndarray) -> np.ndarray:
        """(s,) bool: the stations no null vector of the information moves (each pose
        parameter's row of ``null``, (P, d), has norm below ``1e-6``)."""
        moved = np.zeros(6 * self.problem.n_stations)
        moved[self.free] = np.linalg.norm(null, axis=1)
        return moved.reshape(-1, 6).max(axis=1) < 1e-6

    def site_factor(self, site: int) -> tuple[np.ndarray, np.ndarray]:
        """A low-rank factor of one site's information ``J^(j)``.

        ``J^(j) = B^T (D kron I_3) B`` with ``B`` the block diagonal of the ``m`` stations'
        ``H_s`` and ``D = diag(w) - w w^T / T_j`` (positive semi-definite, rank ``m - 1``; at a
        control point positive definite, rank ``m``); ``D = L L^T`` from its
        eigen-decomposition gives ``U = B^T (L kron I_3)``.

        Parameters
        ----------
        site : int
            Candidate site ``j``.

        Returns
        -------
        index : (6 m,) int
            The pose parameters (of all ``6 s``, fixed ones included) of the stations that use
            the site.
        factor : (6 m, r) float
            ``U`` with ``J^(j) = U U^T`` on ``index`` (``r = 3 (m - 1)``, ``3 m`` at a control
            point; 0 columns when the site does not tie). Rows of fixed parameters are to be
            ignored.
        """
        m = int(self.n_stations_seeing[site])
        if not self.tying[site]:
            lo = self.site_start[site]
            index = (6 * self.pair_station[lo:lo + m][:, None] + np.arange(6)).ravel()
            return index, np.zeros((index.size, 0))
        _, index, u = next(self.site_factors(np.array([site])))
        return index[0], u[0]

    def site_factors(self, sites: np.ndarray):
        """:meth:`site_factor` of many sites at once, grouped by how many stations use them.

        Parameters
        ----------
        sites : (k,) int
            Candidate sites; those that do not tie (:attr:`tying`) are skipped (no factor).

        Yields
        ------
        group : (g,) int
            The tying sites of ``sites`` that ``m`` stations use (one ``m`` and one kind, marker
            or control point, per group; ``m`` rising).
        index : (g, 6 m) int
            Each site's pose parameters, as :meth:`site_factor`.
        factor : (g, 6 m, r) float
            Each site's ``U``, as :meth:`site_factor` (``r = 3 (m - 1)``, or ``3 m`` for a group
            of control points).
        """
        sites = np.asarray(sites, dtype=np.int64)
        sites = sites[self.tying[sites]]
        seen = self.n_stations_seeing[sites]
        kind = self.control[sites]
        for m, control in sorted(set(zip(seen.tolist(), kind.tolist(), strict=True))):
            group = sites[(seen == m) & (kind == control)]
            pairs = self.site_start[group][:, None] + np.arange(m)  # (g, m)
            w = self.weight[pairs]
            d = w[:, :, None] * np.eye(m) - w[:, :, None] * w[:, None, :] \
                / self.site_total_weight[group][:, None, None]
            lam, vec = np.linalg.eigh(d)
            first = 0 if control else 1  # a marker's D has the null vector (1, ..., 1)
            root = vec[:, :, first:] * np.sqrt(np.maximum(lam[:, None, first:], 0.0))
            u = np.einsum("gaib,gak->gabki", self.design[pairs], root)  # (g, m, 6, m - 1, 3)
            index = (6 * self.pair_station[pairs][:, :, None] + np.arange(6)).reshape(
                group.size, -1)
            yield group, index, u.reshape(group.size, 6 * m, -1)

    def station_errors_from(self, cov: NetworkCovariance) -> np.ndarray:
        """(s,) 95 % station errors of a covariance, m (``inf`` where undetermined; in a free
        network datum-free, :meth:`datum_free`)."""
        err = self.figure.station_errors(
            self.datum_free(cov).station(np.arange(self.problem.n_stations)), self.radius)
        return np.where(cov.determined, err, np.inf)

    def stations_failing(self, errors_m: np.ndarray, allowed_m=None) -> np.ndarray:
        """(s,) bool: stations whose 95 % errors ``errors_m`` ((s,) m, ``inf`` where
        undetermined) exceed ``allowed_m`` (default :attr:`allowed_station_m`), or that the
        layout leaves undetermined (untied to the network: failing even where nothing is
        required relative to the datum)."""
        allowed = self.allowed_station_m if allowed_m is None else allowed_m
        return ~(np.isfinite(errors_m) & (errors_m <= allowed))

    def stations_within(self, cov: NetworkCovariance, allowed_m=None) -> np.ndarray:
        """(s,) bool: each station's 95 % error of a covariance is within ``allowed_m`` ((s,)
        m; default its allowance :attr:`allowed_station_m`), decided from its bracket where it
        can be (:meth:`~planner.accuracy.figure.ErrorFigure.station_within`)."""
        blocks = cov.station(np.arange(self.problem.n_stations))
        allowed = self.allowed_station_m if allowed_m is None else allowed_m
        return cov.determined & self.figure.station_within(blocks, self.radius, allowed)

    def markers_within(self, cov: NetworkCovariance, sites, allowed_m=None) -> np.ndarray:
        """(m,) bool: the markers at ``sites`` are within ``allowed_m`` ((m,) m; default their
        allowance :attr:`allowed_site_m`), decided as
        :meth:`~planner.accuracy.figure.ErrorFigure.point_within`."""
        sites = np.asarray(sites, dtype=np.int64).reshape(-1)
        allowed = self.allowed_site_m[sites] if allowed_m is None else allowed_m
        return self.figure.point_within(self.marker_covariances(cov, sites), allowed)

    def station_errors(self, selected) -> np.ndarray:
        """(s,) predicted 95 % error of every station with the layout ``selected``, m."""
        return self.station_errors_from(self.covariance(self.information(selected)))

    def loss_station_errors(self, selected, j: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray, list]:
        """Station errors after losing each one of a layout's selected tying markers.

        A marker seen by one station only adds nothing to the network's information, so
        losing it changes no station's accuracy; only tying markers are tried.

        Parameters
        ----------
        selected : (n,) bool
        j : (P, P) float
            The layout's information, ``information(selected)`` (callers have it already).

        Returns
        -------
        markers : (m,) int
            The selected tying sites, in site order.
        errors : (m, s) float
            95 % error of every station without marker ``markers[i]``, m (``inf`` where the
            loss leaves a station undetermined).
        covariances : list of NetworkCovariance, (m,)
            The pose covariance without each marker (for tangent cuts).
        """
        sel = np.asarray(selected, bool)
        markers = np.flatnonzero(sel & self.tying)
        errors = np.empty((markers.size, self.problem.n_stations))
        covariances = []
        for i, m in enumerate(markers):
            one = np.zeros(self.problem.n_sites)
            one[m] = 1.0
            cov = self.covariance(j - self.site_information(one))
            errors[i] = self.station_errors_from(cov)
            covariances.append(cov)
        return markers, errors, covariances

    def pairs_of(self, sites: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pair indices ((q,) int) of ``sites`` ((m,) int) and, for each, the position of its
        site in ``sites`` ((q,) int)."""
        k = self.n_stations_seeing[sites]
        pos = np.repeat(np.arange(sites.size), k)
        start = np.repeat(self.site_start[sites], k)
        off = np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
        return start + off, pos

    def marker_covariances(self, cov: NetworkCovariance, sites) -> np.ndarray:
        """(m, 3, 3) covariance of the markers at candidate sites ``sites``, m^2: ``I / T_j +
        M_j C M_j^T`` (every station that can use the site measures it). Sites no station
        can use (but control points: their prior), or seen from an undetermined station, get
        ``inf``."""
        sites = np.asarray(sites, dtype=np.int64).reshape(-1)
        out = np.zeros((sites.size, 3, 3))
        w_site = self.site_total_weight[sites]
        pairs, _ = self.pairs_of(sites)
        ka = self.n_stations_seeing[sites]
        # ordered pairs of pairs within each site
        reps = ka**2
        site_pos = np.repeat(np.arange(sites.size), reps)
        off = np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps)
        first = np.repeat(np.cumsum(ka) - ka, reps)
        kk = ka[site_pos]
        a = pairs[first + off // kk]
        b = pairs[first + off % kk]
        for lo in range(0, a.size, _CHUNK):
            aa, bb, sp_ = a[lo:lo + _CHUNK], b[lo:lo + _CHUNK], site_pos[lo:lo + _CHUNK]
            ia = 6 * self.pair_station[aa][:, None] + np.arange(6)
            ib = 6 * self.pair_station[bb][:, None] + np.arange(6)
            cab = cov.full[ia[:, :, None], ib[:, None, :]]
            f = self.weight[aa] * self.weight[bb] / w_site[sp_] ** 2
            blk = np.einsum("q,qia,qab,qjb->qij", f, self.design[aa], cab, self.design[bb])
            np.add.at(out, sp_, blk)
        out += np.where(w_site > 0, 1.0 / np.where(w_site > 0, w_site, 1.0), 0.0)[:, None, None] \
            * np.eye(3)
        out[(w_site <= 0) | self.undetermined_markers(cov, sites)] = np.inf
        return out

    def undetermined_markers(self, cov: NetworkCovariance, sites) -> np.ndarray:
        """(m,) bool: the markers at ``sites`` ((m,) int) seen from a station the covariance
        leaves undetermined."""
        sites = np.asarray(sites, dtype=np.int64).reshape(-1)
        pairs, pos = self.pairs_of(sites)
        out = np.zeros(sites.size, bool)
        np.logical_or.at(out, pos, ~cov.determined[self.pair_station[pairs]])
        return out

    def marker_errors(self, cov: NetworkCovariance, sites) -> np.ndarray:
        """(m,) 95 % error of the markers at ``sites``, relative to the datum, m (in a free
        network datum-free, :meth:`datum_free`)."""
        return self.figure.point_errors(self.marker_covariances(self.datum_free(cov), sites))

    # -- structure -----------------------------------------------------------------------------
    def ties(self, selected) -> np.ndarray:
        """(s, s) int: number of selected sites each pair of stations shares (diagonal 0)."""
        sel = np.asarray(selected, bool)
        use = sel[self.pair_site]
        st, si = self.pair_station[use], self.pair_site[use]
        s, n = self.problem.n_stations, self.problem.n_sites
        inc = csr_array((np.ones(st.size), (st, si)), shape=(s, n))
        t = (inc @ inc.T).toarray().astype(np.int64)
        np.fill_diagonal(t, 0)
        return t

    def connected_to_reference(self, selected) -> np.ndarray:
        """(s,) bool: stations linked to the datum (the reference station, a station that
        sees a control point, or in a free network the first station) by a chain of shared
        selected sites or odometry."""
        t = self.ties(selected) > 0
        link = self.aids.links()
        t[link[:, 0], link[:, 1]] = t[link[:, 1], link[:, 0]] = True
        _, comp = connected_components(csr_array(t), directed=False)
        if self.reference is not None or self.free_datum:  # a free network: its first station
            return comp == comp[self.reference or 0]
        sees = self.control[self.pair_site] & np.asarray(selected, bool)[self.pair_site]
        return np.isin(comp, comp[self.pair_station[sees]])


def _inner_constraint_map(station_xyz: np.ndarray, defects: np.ndarray) -> np.ndarray:
    """(6 s, 6 s) ``P = I - G (B G)^-1 B``: the S-transformation of a pose covariance to the
    inner constraints ``B`` (``G^T`` on the stations' x, y, z and heading) of the datum
    ``defects`` ((d,) int into :data:`pipeline.network.observations.DATUM_DEFECTS`), ``G`` the
    defect directions at ``station_xyz`` ((s, 3) m; headings 0, no markers;
    :func:`pipeline.network.normals.inner_constraints`)."""
    from pipeline.network.normals import inner_constraints

    s = station_xyz.shape[0]
    pose = np.zeros((s, 6))
    pose[:, :3] = station_xyz
    g, b = inner_constraints(pose, np.zeros((0, 3)), defects)
    return np.eye(6 * s) - g @ np.linalg.solve(b @ g, b)


def network_model(problem: PlanProblem, config) -> NetworkModel:
    """The :class:`NetworkModel` of a problem for a :class:`~planner.config.PlanConfig`
    (``working_radius_m``, ``inclinometer_sigma_rad``, ``reference_station``,
    ``heading_prior_sigma_rad``, ``heading_bias_sigma_deg``, ``odometry_percent``,
    ``odometry_heading_deg_per_m``, ``error_figure``, ``requirement_m``, ``requirement_ppm``,
    ``datum``).

    Raises
    ------
    ConfigError
        ``reference_station`` names no station of the problem, or is given with control
        points; a free ``datum`` with control points.
    """
    free = config.datum == "free"
    ref = None if (free or problem.site_control.any()) and config.reference_station is None \
        else Datum(reference_station=config.reference_station).resolve(problem.station_ids)
    return NetworkModel(problem, config.working_radius_m, config.inclinometer_sigma_rad,
                        reference=ref, heading_prior_sigma_rad=config.heading_prior_sigma_rad,
                        figure=error_figure(config),
                        requirement=NetworkRequirement.of(config),
                        heading_bias_sigma_rad=config.heading_bias_sigma_rad,
                        odometry=config.odometry, free_datum=free)
