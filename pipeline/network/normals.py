"""The normal equations of the network adjustment: linearisation, assembly, Gauss-Newton
solve and the covariance of the parameters.

The model and its parameters are :mod:`pipeline.network.adjustment`'s (this module is its
numerical core and knows nothing of snooping or reporting). Parameters are ordered stations
first (6 each), then markers (3 each).

The normal equations are sparse (``scipy.sparse``, SuperLU), assembled from each observation's
9 x 9 block into a sparsity pattern fixed across iterations. A parameter the datum fixes gets a
unit row and column (its step is 0); the free datum's minimal constraints ``B dx = 0`` border
the system. The covariance (a priori: sigma0 = 1) comes from the normal matrix at
convergence with the markers eliminated first (their block is 3 x 3 block-diagonal, as in
bundle adjustment), so only a matrix of the stations' size is inverted; then either the full
array is formed (after removing one observation it can be downdated,
Sherman-Morrison-Woodbury) or only the blocks wanted
(:class:`pipeline.network.marginals.MarginalCovariance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg

from markerplan.errors import DataError
from pipeline.network.aids import AidModel, add_to_normal
from pipeline.network.design import axis_weight, pose_design_blocks
from pipeline.network.observations import NetworkObservations

#: A Gauss-Newton step below this (m or rad) ends the iteration: far below any sigma, and
#: convergence is quadratic for exact data, so the truth is then recovered to ~1e-14 m.
STEP_TOLERANCE = 1e-8

@dataclass
class Problem:
    """Everything of one adjustment that does not change between iterations."""

    obs: NetworkObservations
    prior_index: np.ndarray   # (q,) parameter observed directly by a pseudo-observation
    prior_value: np.ndarray   # (q,) its observed value (m or rad)
    prior_weight: np.ndarray  # (q,) 1 / sigma^2
    prior_is_heading: np.ndarray  # (q,) bool: misclosure wrapped to [-pi, pi)
    fixed: np.ndarray         # (u,) bool: parameters the 'station' datum fixes
    free_defects: np.ndarray  # (d,) defect directions the 'free' datum constrains
    #: (n,) factor on each observation's weight (robust weights, variance components); None: 1
    factor: np.ndarray | None = None
    #: "dense" (the full array) or "sparse" (marginal blocks: :mod:`pipeline.network.marginals`)
    covariance_kind: str = "dense"
    #: odometry and a biased heading reference (:class:`pipeline.network.aids.AidModel`); None
    aids: AidModel | None = None

    def weight(self) -> np.ndarray:
        """(n,) per-axis weight of each observation, ``factor * 3 / sigma^2``, 1/m^2."""
        w = axis_weight(self.obs.sigma_m)
        return w if self.factor is None else w * self.factor


@dataclass
class Solution:
    pose: np.ndarray
    markers: np.ndarray
    blocks: np.ndarray        # (n, 3, 9) design blocks at the solution
    columns: np.ndarray       # (n, 9) their parameter indices
    misclosure: np.ndarray    # (n, 3) f = t + R p - m at the solution
    prior_misclosure: np.ndarray
    covariance: np.ndarray | None
    n_constraints: int
    iterations: int
    converged: bool
    normal: sp.csc_matrix     # (bordered) normal matrix at the solution
    covariance_angles: np.ndarray | None = None  # (s, 3) angles the covariance is linearised at
    #: the covariance with the observations' own weights (differs from ``covariance`` under
    #: robust weights): the one the tests and reliability use
    ls_covariance: np.ndarray | None = None
    #: (m,) misclosure of the aids' rows (:mod:`pipeline.network.aids`) at the solution
    aid_misclosure: np.ndarray | None = None


def linearise(obs: NetworkObservations, pose: np.ndarray, markers: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Design blocks (n, 3, 9), their parameter columns (n, 9) (the station's 6 pose
    parameters, then the marker's x, y, z) and the misclosure ``f = t + R p - m`` (n, 3)."""
    n, s = obs.n, len(obs.station_ids)
    q, pose_block = pose_design_blocks(obs.xyz_m, pose[obs.station, 3:])
    f = pose[obs.station, :3] + q - markers[obs.marker]
    block = np.zeros((n, 3, 9))
    block[:, :, :6] = pose_block
    block[:, [0, 1, 2], [6, 7, 8]] = -1.0
    columns = np.concatenate([6 * obs.station[:, None] + np.arange(6),
                              6 * s + 3 * obs.marker[:, None] + np.arange(3)], axis=1)
    return block, columns, f


def defect_basis(pose: np.ndarray, markers: np.ndarray) -> np.ndarray:
    """(u, 4) parameter changes of a translation (x, y, z, 1 m) and a rotation about the vertical
    through the stations' centroid (1 rad): the datum defect."""
    s, k = pose.shape[0], markers.shape[0]
    centre = pose[:, :2].mean(axis=0)
    g = np.zeros((6 * s + 3 * k, 4))
    for rows, xy in ((6 * np.arange(s), pose[:, :2]), (6 * s + 3 * np.arange(k), markers[:, :2])):
        for axis in range(3):
            g[rows + axis, axis] = 1.0
        g[rows, 3] = -(xy[:, 1] - centre[1])
        g[rows + 1, 3] = xy[:, 0] - centre[0]
    g[6 * np.arange(s) + 3, 3] = 1.0
    return g


def inner_constraints(pose: np.ndarray, markers: np.ndarray, defects
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The free datum's defect directions and inner constraints for the ``defects`` ((d,) int
    into :data:`~pipeline.network.observations.DATUM_DEFECTS`).

    Returns
    -------
    g : (u, d) float
        The defect directions (:func:`defect_basis`).
    b : (d, u) float
        The minimal constraints ``B dx = 0``: ``g^T`` restricted to the stations' x, y, z and
        heading.
    """
    g = defect_basis(pose, markers)[:, np.asarray(defects, dtype=np.int64)]
    on_stations = np.zeros(g.shape[0], dtype=bool)
    on_stations[: 6 * pose.shape[0]] = np.tile([1, 1, 1, 1, 0, 0], pose.shape[0]) > 0
    return g, (g * on_stations[:, None]).T


def constraints(problem: Problem, pose: np.ndarray, markers: np.ndarray) -> np.ndarray:
    """(d, u) minimal constraints ``B dx = 0`` of the free datum (d = 0 for the others): the
    defect directions restricted to the stations' x, y, z and heading
    (:func:`inner_constraints`)."""
    return inner_constraints(pose, markers, problem.free_defects)[1]


def prior_misclosure(problem: Problem, params: np.ndarray) -> np.ndarray:
    f = params[problem.prior_index] - problem.prior_value
    return np.where(problem.prior_is_heading, (f + np.pi) % (2 * np.pi) - np.pi, f)


@dataclass
class Assembly:
    """Sparsity pattern of the (bordered) normal matrix of one set of observations, the same in
    every Gauss-Newton iteration: where each contribution goes in CSC storage."""

    keep: np.ndarray     # (n, 9, 9) bool: block entries that touch no fixed parameter
    prior: np.ndarray    # (q,) bool: pseudo-observations of parameters that are not fixed
    n_fixed: int
    slot: np.ndarray     # (e,) index into the CSC data of each contribution
    indices: np.ndarray  # CSC row indices
    indptr: np.ndarray   # CSC column pointers
    size: int            # u + number of constraints


def assembly(problem: Problem, columns: np.ndarray, b: np.ndarray) -> Assembly:
    """The pattern of :func:`normal_system`: observation blocks, priors, a unit diagonal for
    each fixed parameter, the border ``B`` (rows) and ``B^T`` (columns)."""
    u = problem.fixed.size
    size = u + b.shape[0]
    keep = ~(problem.fixed[columns][:, :, None] | problem.fixed[columns][:, None, :])
    fixed = np.flatnonzero(problem.fixed)
    prior = ~problem.fixed[problem.prior_index]
    border_r, border_c = np.nonzero(b)
    row = np.concatenate([np.broadcast_to(columns[:, :, None], keep.shape)[keep],
                          problem.prior_index[prior], fixed, u + border_r, border_c])
    col = np.concatenate([np.broadcast_to(columns[:, None, :], keep.shape)[keep],
                          problem.prior_index[prior], fixed, border_c, u + border_r])
    unique, slot = np.unique(col * size + row, return_inverse=True)
    return Assembly(keep, prior, fixed.size, slot, unique % size,
                     np.searchsorted(unique, np.arange(size + 1) * size), size)


def normal_system(problem: Problem, assembly: Assembly, blocks: np.ndarray,
                   columns: np.ndarray, f: np.ndarray, fp: np.ndarray, b: np.ndarray
                   ) -> tuple[sp.csc_matrix, np.ndarray]:
    """Normal equations of the Gauss-Newton step ``N dx = -A^T P f``, assembled from the
    observations' 9 x 9 blocks (sparse), bordered by the minimal constraints ``B`` when there
    are any. A parameter the datum fixes gets a unit row and column (its step is 0)."""
    u = problem.fixed.size
    weighted = blocks * problem.weight()[:, None, None]
    border = b[b != 0]
    values = np.concatenate([(weighted.transpose(0, 2, 1) @ blocks)[assembly.keep],
                             problem.prior_weight[assembly.prior], np.ones(assembly.n_fixed),
                             border, border])
    normal = sp.csc_matrix((np.bincount(assembly.slot, values, minlength=assembly.indices.size),
                            assembly.indices, assembly.indptr),
                           shape=(assembly.size, assembly.size))
    rhs = -(np.bincount(columns.ravel(), np.sum(weighted * f[:, :, None], axis=1).ravel(),
                        minlength=u)
            + np.bincount(problem.prior_index, problem.prior_weight * fp, minlength=u))
    rhs[problem.fixed] = 0.0
    return normal, np.concatenate([rhs, np.zeros(b.shape[0])])


def station_schur(normal: sp.csc_matrix, problem: Problem
                  ) -> tuple[np.ndarray, sp.csr_matrix, np.ndarray]:
    """The markers eliminated from the (bordered) normal matrix (Schur complement, as in bundle
    adjustment): their block ``N_mm`` is block-diagonal (3 x 3 per marker) and the border
    touches stations only.

    Returns
    -------
    q_ss : (6s, 6s) float
        The stations' covariance ``(N_ss - E N_ms)^-1`` (the bordered inverse's station block;
        rows of parameters the datum fixes not yet zeroed), m^2, rad^2.
    e : (6s, 3k) sparse float
        ``E = N_sm N_mm^-1``: then ``Q_sm = -Q_ss E`` and ``Q_mm = N_mm^-1 + E^T Q_ss E``.
    m_inv : (k, 3, 3) float
        Each marker's ``N_mm^-1`` block, m^2.

    Raises
    ------
    DataError
        A singular normal matrix.
    """
    fixed = problem.fixed
    u, ns = fixed.size, 6 * len(problem.obs.station_ids)
    normal = normal.tocsr()
    k = (u - ns) // 3
    x = np.r_[0:ns, u:normal.shape[0]]  # stations and border
    n_xm = normal[x][:, ns:u]
    n_mm = normal[ns:u][:, ns:u].tocoo()
    blocks = np.zeros((k, 3, 3))
    blocks[n_mm.row // 3, n_mm.row % 3, n_mm.col % 3] = n_mm.data
    m_inv = np.linalg.inv(blocks)
    e = n_xm @ sp.bsr_matrix((m_inv, np.arange(k), np.arange(k + 1)), shape=(3 * k, 3 * k))
    schur = normal[x][:, x].toarray() - (e @ n_xm.T).toarray()
    try:
        q_ss = np.linalg.inv(schur)[:ns, :ns]
    except np.linalg.LinAlgError:
        q_ss = np.full((ns, ns), np.nan)
    if not (np.isfinite(np.diag(q_ss)).all() and (np.diag(q_ss)[~fixed[:ns]] > 0).all()):
        raise DataError("the network's normal matrix is singular (a station tied only by "
                        "markers on one vertical line?)")
    return q_ss, sp.csr_matrix(e[:ns]), m_inv


def covariance_from_normal(normal: sp.csc_matrix, problem: Problem):
    """The covariance of the parameters: the upper-left block of the inverse of the
    (bordered) normal matrix, with the rows and columns of the parameters the datum fixes
    zeroed; m^2, rad^2.

    From :func:`station_schur` (one dense inverse of the stations' size, plus border):
    ``Q_sm = -Q_ss E`` and ``Q_mm = N_mm^-1 + E^T Q_ss E``.

    Parameters
    ----------
    normal : (u + d, u + d) sparse float
    problem : Problem

    Returns
    -------
    covariance : (u, u) float or MarginalCovariance
        With ``problem.covariance_kind`` ``"dense"`` the full array; ``"sparse"`` a
        :class:`pipeline.network.marginals.MarginalCovariance` (station, marker and observed
        station-marker blocks ready, any other computed on demand).
    """
    from pipeline.network.marginals import MarginalCovariance

    q_ss, e, m_inv = station_schur(normal, problem)
    fixed = problem.fixed
    if problem.covariance_kind == "sparse":
        return MarginalCovariance(q_ss, e, m_inv, fixed, problem.obs)
    u, ns = fixed.size, q_ss.shape[0]
    q_sm = -np.asarray((e.T @ q_ss).T)
    q_mm = -np.asarray(e.T @ q_sm)
    k = m_inv.shape[0]
    q_mm.reshape(k, 3, k, 3)[np.arange(k), :, np.arange(k), :] += m_inv
    cov = np.empty((u, u))
    cov[:ns, :ns], cov[:ns, ns:], cov[ns:, :ns], cov[ns:, ns:] = q_ss, q_sm, q_sm.T, q_mm
    cov[fixed, :] = 0.0
    cov[:, fixed] = 0.0
    return cov


def covariance_at(problem: Problem, sol: Solution):
    """The covariance (:func:`covariance_from_normal`) with ``problem``'s weights at ``sol``'s
    linearisation, m^2, rad^2 (e.g. the plain least-squares covariance at a robust
    solution)."""
    b = constraints(problem, sol.pose, sol.markers)
    normal, rhs = normal_system(problem, assembly(problem, sol.columns, b), sol.blocks,
                                sol.columns, sol.misclosure, sol.prior_misclosure, b)
    if problem.aids is not None:
        normal, _, _ = add_to_normal(problem.aids, problem.fixed, normal, rhs, sol.pose)
    return covariance_from_normal(normal, problem)


def downdated(covariance: np.ndarray, blocks: np.ndarray, columns: np.ndarray,
               weight: np.ndarray) -> np.ndarray:
    """Covariance after removing one point observation (Sherman-Morrison-Woodbury):
    ``Q + Q U (W^-1 - U^T Q U)^-1 U^T Q`` with ``U = A_i^T`` (u, 3); also under minimal
    constraints, since the border is unchanged.

    Parameters
    ----------
    covariance : (u, u) float or MarginalCovariance
        (:meth:`pipeline.network.marginals.MarginalCovariance.downdated` for the latter.)
    blocks : (3, 9) float
        The observation's design block.
    columns : (9,) int
    weight : (3,) float
        Its component weights, 1/m^2.
    """
    if not isinstance(covariance, np.ndarray):  # MarginalCovariance
        return covariance.downdated(blocks, columns, weight)
    qu = covariance[:, columns] @ blocks.T
    residual_cov = np.diag(1.0 / weight) - blocks @ qu[columns]
    return covariance + qu @ np.linalg.solve(residual_cov, qu.T)


def solve(problem: Problem, pose: np.ndarray, markers: np.ndarray, max_iterations: int,
           must_converge: bool = True) -> Solution:
    """Gauss-Newton from ``pose``/``markers`` to convergence (covariance left to the caller).

    Without convergence in ``max_iterations`` steps: DataError, or with ``must_converge=False``
    the last iterate (``converged`` False) — a blunder of metres makes Gauss-Newton converge
    slowly, and its w-tests at the iterate already point at it.
    """
    s = pose.shape[0]
    params = np.concatenate([pose.ravel(), markers.ravel()])
    u = params.size
    b = constraints(problem, pose, markers)
    step = np.full(1, np.inf)
    for iteration in range(1, max_iterations + 2):
        pose, markers = params[: 6 * s].reshape(s, 6), params[6 * s:].reshape(-1, 3)
        blocks, columns, f = linearise(problem.obs, pose, markers)
        if iteration == 1:
            pattern = assembly(problem, columns, b)
        fp = prior_misclosure(problem, params)
        normal, rhs = normal_system(problem, pattern, blocks, columns, f, fp, b)
        fa = None
        if problem.aids is not None:
            normal, rhs, fa = add_to_normal(problem.aids, problem.fixed, normal, rhs, pose)
        converged = np.abs(step).max() < STEP_TOLERANCE
        if converged or iteration > max_iterations:
            break
        try:
            step = scipy.sparse.linalg.splu(normal).solve(rhs)[:u]
        except RuntimeError:
            raise DataError("the network's normal equations are singular (a station tied only "
                            "by markers on one vertical line?)") from None
        params = params + step
    if must_converge and not converged:
        raise DataError(f"the adjustment did not converge in {max_iterations} iterations "
                        f"(last step {np.abs(step).max():.3g}); a blunder? (data snooping "
                        "finds it)")
    return Solution(pose, markers, blocks, columns, f, fp, None, b.shape[0], iteration - 1,
                     bool(converged), normal, aid_misclosure=fa)
