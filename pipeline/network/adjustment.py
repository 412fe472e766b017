"""Network adjustment: station poses and marker centres estimated together from many stations.

Model
-----
Station ``s`` has the pose ``(x, y, z, heading, roll, pitch)``
(:data:`pipeline.network.observations.POSE_PARAMETERS`) in the site frame; marker ``j`` the
centre ``m_j``. A marker centre ``p`` measured by the station in its levelled station frame
gives the observation equation

    t_s + Rz(heading_s) Ry(pitch_s) Rx(roll_s) p - m_j = e,   e ~ N(0, sigma^2 / 3 I3)

whose design blocks and weights are :mod:`pipeline.network.design` (shared with the planner's
predicted accuracy). Roll and pitch are the inclinometer's residual errors: unknowns with the
prior ``0 +- inclinometer_sigma_rad`` each, because a tilt error is common to all of a station's
observations (correlated), which treating it as noise would ignore. On a curved body
(``settings.body``, :mod:`pipeline.network.body`) the inclinometer levels to the local vertical,
which leans away from the site frame's tangent point by about ``d / R``; the prior is then
``deflection +- inclinometer_sigma_rad``, the deflection taken at each station's initial
position and heading (a position error ``delta`` moves it by ``delta / R``: 0.6 microrad per m
on the Moon, 0.003 sigma of a 0.01 deg inclinometer). The prior's centre changes no
covariance: the planner's predicted accuracy (:mod:`planner.accuracy.network`) is the same on
every body. The rotation is exact
(``pipeline.scans.rig.station_to_site_matrix``) and linearised at each iterate. An optional heading
prior (sun sensor) observes each heading around its reading (or nominal value); odometry
between consecutive stations and the heading's boresight bias are :mod:`pipeline.network.aids`.
The observations, the datum
(what fixes the network's 4-DoF defect) and the nominal poses are
:mod:`pipeline.network.observations`.

Solution
--------
Gauss-Newton on the sparse normal equations, and the covariance of the parameters, are
:mod:`pipeline.network.normals`. Between data-snooping rounds the covariance is downdated for
the removed observation (Sherman-Morrison-Woodbury); the final solution's covariance is
computed afresh.

Initial values come from :class:`NominalPoses` (odometry or the plan) when given; otherwise the
network is chained outward from the reference station, each station placed by a closed-form
weighted 2D Procrustes fit (heading and 3D translation) on the markers already placed, which
needs at least two shared markers — the same rule that decides whether a station is tied.
Reliability (redundancy numbers, w-tests, data snooping, MDBs) is in
:mod:`pipeline.network.reliability`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from markerplan.errors import ConfigError, DataError, InputFileError
from pipeline.network import normals
from pipeline.network import robust as robust_
from pipeline.network.aids import HeadingReadings, OdometryReadings, aid_model, aids_iv
from pipeline.network.design import axis_weight
from pipeline.network.initial import chained_initial as _chained_initial
from pipeline.network.initial import markers_from_poses as _markers_from_poses
from pipeline.network.observations import (
    Datum,
    NetworkObservations,
    NominalPoses,
)
from pipeline.network.reliability import (
    PointTests,
    Rejection,
    data_snooping,
    non_centrality,
    observation_reliability,
    point_non_centrality,
    point_tests,
    residual_blocks,
)
from pipeline.network.settings import SPARSE_ABOVE_PARAMETERS, AdjustmentSettings
from pipeline.network.variance import VarianceComponent, observation_groups, variance_components
from pipeline.scans.rig import fit_heading_shift, rot_z

#: chi-square 95 % quantile, 3 degrees of freedom: the 95 % ellipsoid's scale.
ELLIPSOID_CHI2_95 = float(chi2.ppf(0.95, 3))

#: Between data-snooping rounds the covariance is downdated while no station angle moved more
#: than this since it was computed (the design changes by about that fraction; w by less).
_DOWNDATE_ANGLE_RAD = 1e-3


@dataclass
class NetworkAdjustment:
    """Result of :func:`adjust`. Parameters are ordered stations first (6 each, in
    :data:`~pipeline.network.observations.POSE_PARAMETERS` order), then markers (x, y, z each).

    Attributes
    ----------
    observations : NetworkObservations
        The observations kept (after data snooping; all of them with robust estimation).
    pose : (s, 6) float
        Station poses, site frame, m and rad (heading wrapped to [-pi, pi)).
    marker_xyz_m : (k, 3) float
        Marker centres, site frame, m.
    covariance : (6s + 3k, 6s + 3k) float or MarginalCovariance
        A-priori covariance (sigma0 = 1) relative to the datum, with the robust weights when
        there are any; m^2, rad^2. Rows of parameters the datum fixes are zero. The full array,
        or with ``settings.covariance`` sparse its marginal blocks
        (:class:`pipeline.network.marginals.MarginalCovariance`, indexed alike).
    residuals_m : (n, 3) float
        ``m_j - (t_s + R_s p)`` per kept observation, site-frame axes, m.
    redundancy, w_test, mdb_m, mdb_effect_m, point, mdb_point_m
        See :class:`pipeline.network.reliability.ObservationReliability` (kept observations),
        with the observations' own weights (not the robust ones). ``point`` is the test of
        each point observation, the statistic data snooping and the robust weights use (under
        robust weights: each observation against the solution of all the others,
        :func:`~pipeline.network.reliability.point_tests`).
    sigma0_squared : float
        A-posteriori variance factor (pseudo-observations included; robust weights applied);
        nan when ``dof == 0``.
    dof : int
        Degrees of freedom (redundancy; observations of robust weight 0 not counted).
    iterations : int
        Gauss-Newton iterations of the last solution.
    robust_weight : (n,) float
        The robust weight factor of each kept observation, in [0, 1] (ones without ``robust``).
    robust_rounds : int
        Reweighting rounds of the robust estimation (0 without).
    rejected : list of Rejection
        Observations removed by data snooping, in order.
    variance_components : list of VarianceComponent
        Estimated variance factors of the groups of ``settings.variance_components`` (empty
        without); a diagnostic: the solution and covariance keep the error model's weights.
    datum : Datum
    settings : AdjustmentSettings
    """

    observations: NetworkObservations
    pose: np.ndarray
    marker_xyz_m: np.ndarray
    covariance: np.ndarray
    residuals_m: np.ndarray
    redundancy: np.ndarray
    w_test: np.ndarray
    mdb_m: np.ndarray
    mdb_effect_m: np.ndarray
    sigma0_squared: float
    dof: int
    iterations: int
    point: PointTests
    mdb_point_m: np.ndarray
    robust_weight: np.ndarray
    robust_rounds: int = 0
    rejected: list[Rejection] = field(default_factory=list)
    variance_components: list[VarianceComponent] = field(default_factory=list)
    datum: Datum = field(default_factory=Datum)
    settings: AdjustmentSettings = field(default_factory=AdjustmentSettings)

    def _station_index(self, station: int | str) -> int:
        ids = self.observations.station_ids
        return ids.index(station) if isinstance(station, str) else int(station)

    def station_covariance(self, station: int | str) -> np.ndarray:
        """(6, 6) covariance of a station's pose (index or id), m^2 / rad^2."""
        i = 6 * self._station_index(station)
        return self.covariance[i:i + 6, i:i + 6]

    def marker_covariance(self, marker: int | str) -> np.ndarray:
        """(3, 3) covariance of a marker's centre (index or id), m^2."""
        ids = self.observations.marker_ids
        j = 6 * len(self.observations.station_ids) + 3 * (
            ids.index(marker) if isinstance(marker, str) else int(marker))
        return self.covariance[j:j + 3, j:j + 3]

    @staticmethod
    def ellipsoid(cov3: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """95 % error ellipsoid of a point with covariance ``cov3``.

        Parameters
        ----------
        cov3 : (3, 3) float
            Covariance, m^2.

        Returns
        -------
        semi_axes_m : (3,) float
            ``sqrt(chi2_3(0.95) * eigenvalue)``, ascending, m.
        axes : (3, 3) float
            Unit axis directions as columns, in the same order.

        Examples
        --------
        >>> a, v = NetworkAdjustment.ellipsoid(np.diag([1e-4, 4e-4, 1e-4]))
        >>> np.round(a, 4).tolist(), np.abs(v[:, 2]).round(3).tolist()
        ([0.028, 0.028, 0.0559], [0.0, 1.0, 0.0])
        """
        lam, vec = np.linalg.eigh(np.asarray(cov3, dtype=float))
        return np.sqrt(ELLIPSOID_CHI2_95 * np.clip(lam, 0.0, None)), vec


def tie_order(obs: NetworkObservations, keep: np.ndarray, reference: int
              ) -> tuple[list[int], list[int]]:
    """Stations in the order they can be tied to the reference, and those that cannot.

    A station is tied when it shares at least 2 markers with the stations already tied.

    Parameters
    ----------
    obs : NetworkObservations
    keep : (n,) bool
        Observations to use.
    reference : int
        Index of the reference station.

    Returns
    -------
    order : list of int
        Tied station indices, reference first, in the order they are tied.
    untied : list of int
        The other station indices.
    """
    s, k = len(obs.station_ids), len(obs.marker_ids)
    seen = np.zeros((s, k), dtype=bool)
    seen[obs.station[keep], obs.marker[keep]] = True
    placed = np.zeros(k, dtype=bool)
    shared = np.zeros(s, dtype=int)  # markers each station shares with the placed ones
    order, untied = [], np.ones(s, dtype=bool)
    best = reference
    while True:
        order.append(best)
        untied[best] = False
        new = seen[best] & ~placed
        placed |= new
        shared += seen[:, new].sum(axis=1)
        if not untied.any():
            break
        best = int(np.argmax(np.where(untied, shared, -1)))
        if shared[best] < 2:
            break
    return order, np.flatnonzero(untied).tolist()


def _check_tied(obs: NetworkObservations, keep: np.ndarray, reference: int) -> list[int]:
    order, untied = tie_order(obs, keep, reference)
    if untied:
        names = ", ".join(obs.station_ids[i] for i in untied)
        raise InputFileError(f"stations {names} share fewer than 2 markers with the part of the "
                             f"network holding the reference {obs.station_ids[reference]}")
    return order


def _adjust_iv(obs, datum, settings, nominal, odometry, heading) -> int:
    if not isinstance(obs, NetworkObservations):
        raise ConfigError(f"`obs` must be NetworkObservations, got {type(obs).__name__}")
    s = len(obs.station_ids)
    if s == 0:
        raise InputFileError("the network has no stations")
    reference = datum.resolve(obs.station_ids)
    missing = [c.marker_id for c in datum.control if c.marker_id not in obs.marker_ids]
    if missing:
        raise ConfigError(f"control points {', '.join(missing)} are not markers of the network")
    if nominal is not None and nominal.heading_rad.shape != (s,):
        raise ConfigError(f"nominal poses must be given for all {s} stations, got "
                          f"{nominal.heading_rad.shape[0]}")
    if settings.heading_prior_sigma_rad is not None and nominal is None and heading is None:
        raise ConfigError("a heading prior (heading_prior_sigma_rad) needs nominal poses "
                          "or heading readings (its centre)")
    aids_iv(s, settings, odometry, heading)
    return reference


def tilt_prior_centre(settings: AdjustmentSettings, pose: np.ndarray, reference: int
                      ) -> np.ndarray:
    """Centre of the roll and pitch priors: the local vertical's deflection on
    ``settings.body`` at ``pose`` (module doc).

    Parameters
    ----------
    settings : AdjustmentSettings
    pose : (s, 6) float
        Station poses to take the deflection at (the initial values), site frame, m and rad.
    reference : int
        The reference station, whose horizontal position is the default tangent point.

    Returns
    -------
    tilt_rad : (s, 2) float
        ``(roll, pitch)`` of each station, rad (zeros on the plane).
    """
    tangent = (pose[reference, :2] if settings.tangent_point_m is None
               else settings.tangent_point_m)
    return settings.body.vertical_tilt(pose[:, :3], pose[:, 3], tangent)


def _problem(obs: NetworkObservations, datum: Datum, settings: AdjustmentSettings,
             nominal: NominalPoses | None, reference: int, start_pose: np.ndarray,
             odometry: OdometryReadings | None = None,
             readings: HeadingReadings | None = None) -> normals.Problem:
    """Pseudo-observations and datum constraints; refuses a datum that leaves a defect free
    (:meth:`~pipeline.network.observations.Datum.constrained_defects`). The tilt priors are
    centred at :func:`tilt_prior_centre` of ``start_pose`` (s, 6)."""
    s = len(obs.station_ids)
    stations = np.arange(s)
    index = [6 * stations + 4, 6 * stations + 5]
    tilt = tilt_prior_centre(settings, start_pose, reference)
    value = [tilt[:, 0], tilt[:, 1]]
    weight = [np.full(2 * s, settings.inclinometer_sigma_rad**-2.0)]
    heading = [np.zeros(2 * s, dtype=bool)]
    centre = (readings if readings is not None else nominal).heading_rad if (
        readings is not None or nominal is not None) else None
    if settings.heading_prior_sigma_rad is not None and settings.heading_bias_sigma_rad is None:
        index.append(6 * stations + 3)
        value.append(centre)
        weight.append(np.full(s, settings.heading_prior_sigma_rad**-2.0))
        heading.append(np.ones(s, dtype=bool))
    for c in datum.control:
        index.append(6 * s + 3 * obs.marker_ids.index(c.marker_id) + np.arange(3))
        value.append(c.xyz_m)
        weight.append(c.sigma_m**-2.0)
        heading.append(np.zeros(3, dtype=bool))
    problem = normals.Problem(obs, np.concatenate(index), np.concatenate(value),
                       np.concatenate(weight), np.concatenate(heading),
                       np.zeros(6 * s + 3 * len(obs.marker_ids), dtype=bool),
                       np.zeros(0, dtype=int))
    problem.aids = aid_model(s, odometry, settings.odometry_ratio,
                             settings.odometry_heading_rad_per_m, centre,
                             settings.heading_prior_sigma_rad, settings.heading_bias_sigma_rad)
    if datum.kind == "station":
        problem.fixed[6 * reference + np.arange(4)] = True
    sparse = (settings.covariance == "sparse" or settings.covariance == "auto"
              and problem.fixed.size > SPARSE_ABOVE_PARAMETERS)
    problem.covariance_kind = "sparse" if sparse else "dense"
    problem.free_defects = np.asarray(
        datum.constrained_defects(settings.heading_prior_sigma_rad is not None), dtype=int)
    return problem


def _initial(obs: NetworkObservations, datum: Datum, nominal: NominalPoses | None,
             order: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Initial poses (s, 6) and markers (k, 3), site frame (see the module doc)."""
    reference = order[0]
    if datum.reference_pose is not None:
        reference_pose = np.asarray(datum.reference_pose)
    elif nominal is not None:
        reference_pose = np.append(nominal.position_m[reference], nominal.heading_rad[reference])
    else:
        reference_pose = np.zeros(4)
    if nominal is None:
        pose, markers = _chained_initial(obs, order, reference_pose)
        if datum.control:
            idx = [obs.marker_ids.index(c.marker_id) for c in datum.control]
            control_xyz = np.array([c.xyz_m for c in datum.control])
            control_weight = np.array([1.0 / np.sum(c.sigma_m**2) for c in datum.control])
            heading, t, _, _ = fit_heading_shift(markers[idx], control_xyz, control_weight)
            pose[:, :3] = t + pose[:, :3] @ rot_z(heading).T
            pose[:, 3] += heading
            markers = t + markers @ rot_z(heading).T
        return pose, markers
    pose = np.zeros((len(obs.station_ids), 6))
    pose[:, :3], pose[:, 3] = nominal.position_m, nominal.heading_rad
    pose[reference, :4] = reference_pose
    return pose, _markers_from_poses(obs, pose)


def _snooped(problem: normals.Problem, obs: NetworkObservations, settings: AdjustmentSettings,
             reference: int, start: tuple[np.ndarray, np.ndarray]
             ) -> tuple[normals.Solution, np.ndarray, list[Rejection]]:
    """Least squares with data snooping: the last solution (its covariance at its own
    linearisation), the observations kept and those removed."""
    snooping = settings.snooping and settings.max_rejections > 0
    solved_keep = np.ones(obs.n, dtype=bool)

    def solve(keep, previous):
        # After a removal the covariance is downdated (normals.downdated) while the solution's
        # angles (the design depends on no other parameter) stay within _DOWNDATE_ANGLE_RAD of
        # those it was computed at; otherwise, e.g. once a blunder of metres is out, afresh.
        problem.obs = obs.subset(keep)
        begin = start if previous is None else (previous.pose, previous.markers)
        sol = normals.solve(problem, *begin, settings.max_iterations, must_converge=not snooping)
        if (previous is not None and np.abs(sol.pose[:, 3:] - previous.covariance_angles).max()
                < _DOWNDATE_ANGLE_RAD):
            row = int(np.flatnonzero(solved_keep & ~keep)[0])
            i = int(np.count_nonzero(solved_keep[:row]))
            sol.covariance = normals.downdated(previous.covariance, previous.blocks[i],
                                               previous.columns[i],
                                               np.full(3, axis_weight(obs.sigma_m[row])))
            sol.covariance_angles = previous.covariance_angles
        else:
            sol.covariance = normals.covariance_from_normal(sol.normal, problem)
            sol.covariance_angles = sol.pose[:, 3:].copy()
        solved_keep[:] = keep
        return sol, _tests(problem, sol, sol.covariance)

    def removable(keep, i):
        trial = keep.copy()
        trial[i] = False
        return (np.any(obs.marker[trial] == obs.marker[i])
                and not tie_order(obs, trial, reference)[1])

    sol, keep, rejected = data_snooping(
        solve, obs.n, settings.alpha0, settings.max_rejections if snooping else 0, removable)
    if not sol.converged:
        tests = _tests(problem, sol, sol.covariance)
        i = int(np.flatnonzero(keep)[np.argmax(tests.w)])
        raise DataError(f"the adjustment did not converge in {settings.max_iterations} "
                        f"iterations after {len(rejected)} removals by data snooping; the "
                        f"largest point-test w ({tests.w.max():.3g}) is at station "
                        f"{obs.station_ids[obs.station[i]]}, marker "
                        f"{obs.marker_ids[obs.marker[i]]}")
    if not np.array_equal(sol.covariance_angles, sol.pose[:, 3:]):  # downdated: afresh
        sol.covariance = normals.covariance_from_normal(sol.normal, problem)
    return sol, keep, [Rejection(obs.station_ids[obs.station[i]], obs.marker_ids[obs.marker[i]],
                                 w, r, statistic, dof) for i, w, statistic, dof, r in rejected]


def _tests(problem: normals.Problem, sol: normals.Solution, covariance: np.ndarray,
           rho: np.ndarray | None = None) -> PointTests:
    """The point tests of ``problem.obs`` at ``sol``, whose ``covariance`` has the weights of
    the observations times ``rho`` (None: 1)."""
    weight = np.repeat(axis_weight(problem.obs.sigma_m[:, None]), 3, axis=1)
    return point_tests(residual_blocks(sol.blocks, sol.columns, covariance), weight,
                       -sol.misclosure, rho)


def _reweighted(problem: normals.Problem, settings: AdjustmentSettings,
                start: tuple[np.ndarray, np.ndarray]
                ) -> tuple[normals.Solution, np.ndarray, PointTests, int]:
    """Robust estimation from plain least squares (IGG-III from Huber's solution): the solution
    with the final weights (its ``covariance`` with them, ``ls_covariance`` with the
    observations' own), the weight factors, the point tests they came from and the rounds.

    A blunder of metres keeps Gauss-Newton from converging with the first weights; as in data
    snooping, the tests at its last iterate already point at the blunder, and only the final
    solution must converge."""
    tests: list[PointTests] = []

    def solve(rho, previous):
        problem.factor = np.maximum(rho, robust_.WEIGHT_FLOOR)
        begin = start if previous is None else (previous.pose, previous.markers)
        sol = normals.solve(problem, *begin, settings.max_iterations, must_converge=False)
        sol.covariance = normals.covariance_from_normal(sol.normal, problem)
        tests[:] = [_tests(problem, sol, sol.covariance, rho)]
        return sol, tests[0].w

    k0, k1 = settings.robust_k0, settings.robust_k1
    sol, rho, _, rounds = robust_.reweighted(
        solve, lambda w: robust_.robust_weights(w, "huber", k0, k1),
        solve(np.ones(problem.obs.n), None))
    if settings.robust == "igg3":
        sol, rho, _, more = robust_.reweighted(
            solve, lambda w: robust_.robust_weights(w, "igg3", k0, k1), (sol, tests[0].w))
        rounds += more
    final = tests[0]
    if not sol.converged:
        raise DataError(f"the robust adjustment did not converge in {settings.max_iterations} "
                        f"iterations with its final weights; the largest point-test w "
                        f"({final.w.max():.3g}) is at station "
                        f"{problem.obs.station_ids[problem.obs.station[np.argmax(final.w)]]}")
    problem.factor = None
    sol.ls_covariance = normals.covariance_at(problem, sol)
    problem.factor = np.maximum(rho, robust_.WEIGHT_FLOOR)
    return sol, rho, final, rounds


def _components(problem: normals.Problem, sol: normals.Solution, by: str,
                max_iterations: int) -> list[VarianceComponent]:
    """Variance components of ``problem``'s observations grouped ``by`` station or range,
    re-adjusting from ``sol`` (``problem.factor`` restored afterwards)."""
    obs, base = problem.obs, problem.factor
    group, names = observation_groups(obs.station, obs.station_ids,
                                      np.linalg.norm(obs.xyz_m, axis=1), by)
    current = [sol]

    def solve(scale):
        problem.factor = (1.0 if base is None else base) / scale
        if np.any(scale != 1.0):
            current[0] = normals.solve(problem, current[0].pose, current[0].markers,
                                       max_iterations)
        fit = current[0]
        cov = normals.covariance_from_normal(fit.normal, problem)
        weight = problem.weight()
        aqa = residual_blocks(fit.blocks, fit.columns, cov)
        r = np.clip(1.0 - weight[:, None] * np.diagonal(aqa, axis1=1, axis2=2), 0.0, 1.0)
        return weight * np.sum(fit.misclosure**2, axis=1), r.sum(axis=1)

    try:
        return variance_components(solve, group, names)
    finally:
        problem.factor = base


def adjust(obs: NetworkObservations, datum: Datum = Datum(),  # noqa: B008 (frozen)
           settings: AdjustmentSettings = AdjustmentSettings(),  # noqa: B008 (frozen)
           nominal: NominalPoses | None = None, odometry: OdometryReadings | None = None,
           heading: HeadingReadings | None = None) -> NetworkAdjustment:
    """Adjust a network of stations and markers; test it and deal with blunders (data
    snooping or robust estimation); optionally estimate variance components.

    Parameters
    ----------
    obs : NetworkObservations
        Marker centres measured by the stations (levelled station frames).
    datum : Datum
        What fixes the network (default: the first station).
    settings : AdjustmentSettings
        Priors, test levels, limits, robust estimator, variance-component groups.
    nominal : NominalPoses or None
        Nominal poses (initial values, heading-prior centre); None chains initial values from
        the reference station.
    odometry, heading : OdometryReadings, HeadingReadings or None
        Pose aids (:mod:`pipeline.network.aids`): relative poses between consecutive stations
        (sigmas from ``settings.odometry_*``) and the heading reference's readings (the heading
        prior's centre instead of the nominal headings).

    Returns
    -------
    NetworkAdjustment

    Raises
    ------
    InputFileError
        Stations that share fewer than 2 markers with the reference's part of the network
        (named), or malformed observations.
    ConfigError
        Unknown reference station or control ids, a datum that leaves a defect free (named),
        a heading prior without nominal poses.
    DataError
        Singular normal equations, no convergence (Gauss-Newton, robust reweighting or
        variance components).

    Notes
    -----
    Each point observation is tested as one 3-dimensional group
    (:class:`~pipeline.network.reliability.PointTests`). Data snooping (``settings.snooping``)
    removes the observation with the largest normalised statistic ``w > Phi^-1(1 - alpha0 /
    2)`` (the smallest p-value) and re-adjusts, up to ``settings.max_rejections`` times. It
    stops early, keeping the observation, when removing it would leave a station tied by fewer
    than two markers or its marker with no observation; its ``w`` then stays above the
    critical value for the report to show. With ``settings.robust`` nothing is removed: the
    weights of the observations are reweighted by their ``w`` (:mod:`pipeline.network.robust`).

    Examples
    --------
    >>> from pipeline.network.simulation import simulated_network
    >>> obs, truth = simulated_network(n_stations=4, seed=1)
    >>> result = adjust(obs, settings=AdjustmentSettings(snooping=False),
    ...                 nominal=truth.nominal)
    >>> result.pose.shape, result.covariance.shape == (6 * 4 + 3 * len(obs.marker_ids),) * 2
    ((4, 6), True)
    >>> bool(np.abs(result.marker_xyz_m - truth.marker_xyz_m).max() < 0.05)
    True
    """
    reference = _adjust_iv(obs, datum, settings, nominal, odometry, heading)
    order = _check_tied(obs, np.ones(obs.n, dtype=bool), reference)
    start = _initial(obs, datum, nominal, order)
    problem = _problem(obs, datum, settings, nominal, reference, start[0], odometry, heading)
    rejected: list[Rejection] = []
    rounds, robust_tests = 0, None
    if settings.robust is None:
        sol, keep, rejected = _snooped(problem, obs, settings, reference, start)
        sol.ls_covariance = sol.covariance
        rho = np.ones(int(keep.sum()))
    else:
        problem.obs = obs
        sol, rho, robust_tests, rounds = _reweighted(problem, settings, start)
    kept = problem.obs
    s, k = len(obs.station_ids), len(obs.marker_ids)
    position_columns = np.concatenate([6 * np.arange(s)[:, None], 6 * s + 3 * np.arange(k)[:, None]]
                                      ) + np.arange(3)
    w = np.repeat(axis_weight(kept.sigma_m[:, None]), 3, axis=1)
    rel = observation_reliability(sol.blocks, sol.columns, w, sol.ls_covariance,
                                  -sol.misclosure, position_columns,
                                  non_centrality(settings.alpha0, settings.beta0),
                                  point_non_centrality(settings.alpha0, settings.beta0),
                                  robust_tests)
    dof = (3 * int(np.count_nonzero(rho)) + problem.prior_index.size - problem.fixed.size
           + problem.fixed.sum() + sol.n_constraints)
    vpv = float(np.sum(rho[:, None] * w * sol.misclosure**2)
                + problem.prior_weight @ sol.prior_misclosure**2)
    if problem.aids is not None:  # the aids' rows (pipeline.network.aids)
        dof += problem.aids.n_rows
        vpv += float(sol.aid_misclosure @ (problem.aids.weight @ sol.aid_misclosure))
    components = ([] if settings.variance_components is None else
                  _components(problem, sol, settings.variance_components,
                              settings.max_iterations))
    pose = sol.pose.copy()
    pose[:, 3] = (pose[:, 3] + np.pi) % (2 * np.pi) - np.pi
    return NetworkAdjustment(
        observations=kept, pose=pose, marker_xyz_m=sol.markers, covariance=sol.covariance,
        residuals_m=-sol.misclosure, redundancy=rel.redundancy, w_test=rel.w_test,
        mdb_m=rel.mdb_m, mdb_effect_m=rel.mdb_effect_m,
        sigma0_squared=vpv / dof if dof > 0 else float("nan"), dof=int(dof),
        iterations=sol.iterations, point=rel.point, mdb_point_m=rel.mdb_point_m,
        robust_weight=rho, robust_rounds=rounds, rejected=rejected,
        variance_components=components, datum=datum, settings=settings)
