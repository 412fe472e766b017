"""The two convex fits (cvxpy): least squares for the mean 3D error and quantile regression
(pinball loss) for the envelope, both under the basis's sign and non-negativity constraints.

A fitter is built once per basis and refitted many times (cross-validation folds, bootstrap
replicates) by changing cvxpy parameters only, so the problem is compiled once:

- :class:`MeanFitter` solves ``min ||y - phi b||^2`` through its p x p reduction
  ``min ||R b - c||^2`` with ``R^T R = phi^T phi`` and ``R^T c = phi^T y`` (same minimisers,
  size independent of the number of rows);
- :class:`QuantileFitter` solves ``min sum rho_tau(y - phi b)`` as the linear program
  ``phi b + u - v = y``, ``u, v >= 0``, ``min tau sum u + (1 - tau) sum v``.

Targets and features are divided by fixed scales (median |y|, column max |phi|) before
solving so the solver's tolerances mean the same for millimetre and decimetre errors.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from markerplan.errors import DataError

_OK = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


@dataclass(frozen=True)
class Constraints:
    """Linear constraints shared by both fits.

    Attributes
    ----------
    nonneg : (p,) bool
        Coefficients constrained ``>= 0``.
    rows : (k, p) float
        ``rows @ b >= 0`` (non-negativity of the model over its whole input space).
    """

    nonneg: np.ndarray
    rows: np.ndarray


@dataclass(frozen=True)
class Scaling:
    """Fixed scales of target and features (from the full data of one basis)."""

    y: float
    x: np.ndarray

    @classmethod
    def from_data(cls, phi: np.ndarray, y: np.ndarray) -> Scaling:
        sy = float(np.median(np.abs(y))) or float(np.abs(y).max()) or 1.0
        sx = np.abs(phi).max(axis=0)
        sx[sx == 0] = 1.0
        return cls(sy, sx)


class MeanFitter:
    """Constrained least squares of the mean 3D error, reusable across row subsets.

    Parameters
    ----------
    cons : Constraints
    scaling : Scaling
    solver : str
        cvxpy solver name.
    """

    def __init__(self, cons: Constraints, scaling: Scaling, solver: str) -> None:
        p = scaling.x.size
        self._scaling, self._solver = scaling, solver
        self._r = cp.Parameter((p, p))
        self._c = cp.Parameter(p)
        self._b = cp.Variable(p)
        self._problem = cp.Problem(cp.Minimize(cp.sum_squares(self._r @ self._b - self._c)),
                                   _constraints(self._b, cons, scaling.x))
        self.status: str | None = None  # status of the last solve

    def fit(self, phi: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Coefficients for rows ``phi`` (n, p) and 3D errors ``y`` (n,), metres."""
        a = phi / self._scaling.x
        gram = a.T @ a
        h = a.T @ (y / self._scaling.y)
        lam, vec = np.linalg.eigh(gram)
        keep = lam > lam.max() * 1e-12
        root = np.zeros_like(lam)
        root[keep] = np.sqrt(lam[keep])
        self._r.value = root[:, None] * vec.T
        inv_root = np.zeros_like(lam)
        inv_root[keep] = 1.0 / root[keep]
        self._c.value = inv_root * (vec.T @ h)
        b = _solve(self._problem, self._b, self._solver, "mean-error least squares")
        self.status = self._problem.status
        return b * self._scaling.y / self._scaling.x


class QuantileFitter:
    """Constrained quantile regression; problems are cached per row count for reuse.

    Parameters
    ----------
    cons : Constraints
    scaling : Scaling
    tau : float
        Quantile level in (0, 1).
    solver : str
    """

    def __init__(self, cons: Constraints, scaling: Scaling, tau: float, solver: str) -> None:
        self._cons, self._scaling, self._tau, self._solver = cons, scaling, tau, solver
        self._cache: dict[int, tuple[cp.Problem, cp.Variable, cp.Parameter, cp.Parameter]] = {}
        self.status: str | None = None  # status of the last solve

    def fit(self, phi: np.ndarray, y: np.ndarray, reuse: bool = False) -> np.ndarray:
        """Coefficients for rows ``phi`` (n, p) and errors ``y`` (n,).

        ``reuse=True`` compiles a parametric problem for this row count once and re-solves it
        on later calls with the same count (bootstrap replicates); otherwise the data enter
        as constants, which compiles faster for a one-off fit.
        """
        a = phi / self._scaling.x
        t = y / self._scaling.y
        if reuse:
            if a.shape[0] not in self._cache:
                xp, yp = cp.Parameter(a.shape), cp.Parameter(a.shape[0])
                problem, b = self._build(xp, yp, a.shape)
                self._cache[a.shape[0]] = (problem, b, xp, yp)
            problem, b, xp, yp = self._cache[a.shape[0]]
            xp.value, yp.value = a, t
        else:
            problem, b = self._build(a, t, a.shape)
        coef = _solve(problem, b, self._solver, "quantile regression")
        self.status = problem.status
        return coef * self._scaling.y / self._scaling.x

    def _build(self, a, t, shape: tuple[int, int]) -> tuple[cp.Problem, cp.Variable]:
        n, p = shape
        b = cp.Variable(p)
        u = cp.Variable(n, nonneg=True)
        v = cp.Variable(n, nonneg=True)
        objective = cp.Minimize(self._tau * cp.sum(u) + (1 - self._tau) * cp.sum(v))
        constraints = [a @ b + u - v == t, *_constraints(b, self._cons, self._scaling.x)]
        return cp.Problem(objective, constraints), b


def pinball(residual: np.ndarray, tau: float) -> np.ndarray:
    """Pinball loss ``rho_tau`` of residuals ``y - prediction``."""
    return np.maximum(tau * residual, (tau - 1) * residual)


def _constraints(b: cp.Variable, cons: Constraints, scale_x: np.ndarray) -> list:
    out = [(cons.rows / scale_x) @ b >= 0]
    if cons.nonneg.any():
        out.append(b[np.flatnonzero(cons.nonneg)] >= 0)
    return out


def _solve(problem: cp.Problem, b: cp.Variable, solver: str, what: str) -> np.ndarray:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # cvxpy bound propagation noise
            problem.solve(solver=solver)
    except cp.error.SolverError as exc:
        raise DataError(f"{what}: solver {solver} failed ({exc}); check the table for extreme "
                        "values or try another solver") from None
    if problem.status not in _OK or b.value is None:
        raise DataError(f"{what}: solver {solver} returned status {problem.status!r}; check the "
                        "table for extreme values or try another solver")
    return np.asarray(b.value, float)
