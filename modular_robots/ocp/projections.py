"""trust-constr's projections, computed from the structure of its barrier subproblem.

Every iteration of trust-constr's interior point method projects onto the null space of the
barrier subproblem's Jacobian

``A = [[J_eq, 0], [J_ineq, S]]``  (``S = diag(s)``, the slacks),

by factoring the augmented system ``K = [[I, A^T], [A, 0]]``. SciPy factors ``K`` as a general
sparse matrix (SuperLU): for a shooting problem of 96 variables, 70 equality rows and 1016
inequality rows (two per two-sided row and bound) that is a 2198-unknown LU per iteration, and
it was the largest single cost of a solve.

Here the slack rows are eliminated by hand. For the unknowns ``(x, u)`` (variables and slack
steps) and multipliers ``(l_eq, l_in)``, with right-hand side ``(r_x, r_u, t_eq, t_in)``, the
slack rows give ``u = r_u - S l_in`` and ``J_ineq x - S^2 l_in = t_in - S r_u``. A row whose
slack is large (``s >= threshold``) is eliminated, ``l_in = S^-2 (J_ineq x - t_in + S r_u)``,
adding ``J_i^T J_i / s_i^2`` to the identity; a row whose slack is small keeps its multiplier, with
``-s_i^2`` on its diagonal, so no division by a vanishing slack enters the system (which is why
the plain normal equations of ``A`` were ill-conditioned). What is left is a dense symmetric
system of ``n_variables + n_eq + (small slacks)`` unknowns, 166-200 for that problem, factored by
LAPACK. Each solve is refined against the full system (the reduced one can be worse conditioned
than ``K``); the operators are SciPy's (``Z``, ``LS``, ``Y``), and ``tests/test_projections.py``
checks them against SciPy's own and against a dense QR.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg
from scipy import sparse
from scipy.sparse.linalg import LinearOperator

__all__ = ["SLACK_THRESHOLD", "BarrierKKT", "barrier_projections"]

#: Slacks at or above this value are eliminated (their weight ``1 / s^2`` is at most 1e4); smaller
#: ones keep their multiplier as an unknown of the dense system.
SLACK_THRESHOLD = 1e-2


class BarrierKKT:
    """The augmented system ``[[I, A^T], [A, 0]]`` of ``A = [[J_eq, 0], [J_ineq, diag(s)]]``,
    factored by its structure (see the module docstring).

    Parameters
    ----------
    A
        Sparse ``(n_eq + n_ineq, n_variables + n_ineq)`` matrix of that structure.
    n_variables
        Columns of ``A`` before the slacks'.
    threshold
        Slacks below it keep their multiplier in the dense system.

    Raises
    ------
    ValueError
        If ``A`` does not have that structure, or the system is singular.
    """

    def __init__(self, A, n_variables: int, threshold: float = SLACK_THRESHOLD):
        A = sparse.csr_array(A)
        m, n = A.shape
        ny = n_variables
        mi = n - ny
        me = m - mi
        if mi < 0 or me < 0:
            raise ValueError(f"A of shape {A.shape} has no barrier structure for {ny} variables")
        self.A, self.shape, self.ny, self.me, self.mi = A, (m, n), ny, me, mi
        left = A[:, :ny]
        slack_block = A[:, ny:].tocoo()
        if not (
            slack_block.nnz == mi
            and np.array_equal(np.sort(slack_block.row), np.arange(me, m))
            and np.array_equal(slack_block.col[np.argsort(slack_block.row)], np.arange(mi))
        ):
            raise ValueError("A's slack columns are not one diagonal block under the equality rows")
        s = np.empty(mi)
        s[slack_block.row - me] = slack_block.data
        self.s = s
        j_eq = left[:me].toarray()
        j_in = left[me:]
        small = np.abs(s) < threshold
        self._large, self._small = np.flatnonzero(~small), np.flatnonzero(small)
        j_large = j_in[self._large]
        self._j_large, self._s_large = j_large, s[self._large]
        self._j_small, self._s_small = j_in[self._small].toarray(), s[self._small]
        weighted = sparse.diags_array(1.0 / self._s_large) @ j_large  # S^-1 J on large slacks
        self._weighted_t = weighted.T.tocsr()
        self._a_t = A.T.tocsr()
        k = len(self._small)
        size = ny + me + k
        kkt = np.zeros((size, size))
        kkt[:ny, :ny] = (weighted.T @ weighted).toarray()
        kkt[np.arange(ny), np.arange(ny)] += 1.0
        kkt[:ny, ny : ny + me] = j_eq.T
        kkt[ny : ny + me, :ny] = j_eq
        kkt[:ny, ny + me :] = self._j_small.T
        kkt[ny + me :, :ny] = self._j_small
        kkt[np.arange(ny + me, size), np.arange(ny + me, size)] = -(self._s_small**2)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)  # singular: raised below
            self._lu = scipy.linalg.lu_factor(kkt, check_finite=False)
        if not np.all(np.diagonal(self._lu[0])):
            raise ValueError("the augmented system is singular (dependent constraint rows)")

    @property
    def dense_size(self) -> int:
        """Unknowns of the dense system."""
        return self._lu[0].shape[0]

    def solve(self, r: np.ndarray, t: np.ndarray, max_refin: int = 3, rtol: float = 1e-12):
        """``(z, w)`` with ``z + A^T w = r`` and ``A z = t``, refined (at most ``max_refin``
        times) until the residual is below ``rtol`` times the right-hand side's norm."""
        z, w = self._solve_once(r, t)
        bound = rtol * (np.linalg.norm(r) + np.linalg.norm(t))
        for _ in range(max_refin):
            res_r = r - z - self._a_t @ w
            res_t = t - self.A @ z
            if np.linalg.norm(res_r) + np.linalg.norm(res_t) <= bound:
                break
            dz, dw = self._solve_once(res_r, res_t)
            z, w = z + dz, w + dw
        return z, w

    def _solve_once(self, r: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ny, me = self.ny, self.me
        r_x, r_u = r[:ny], r[ny:]
        t_eq, t_in = t[:me], t[me:]
        large, small = self._large, self._small
        s_large, s_small = self._s_large, self._s_small
        g = t_in[large] / s_large - r_u[large]  # S^-1 (t_in - S r_u) on large slacks
        rhs = np.concatenate([r_x + self._weighted_t @ g, t_eq, t_in[small] - s_small * r_u[small]])
        w = scipy.linalg.lu_solve(self._lu, rhs, check_finite=False)
        x = w[:ny]
        l_in = np.empty(self.mi)
        l_in[small] = w[ny + me :]
        l_in[large] = (self._j_large @ x - t_in[large]) / s_large**2 + r_u[large] / s_large
        z = np.concatenate([x, r_u - self.s * l_in])
        return z, np.concatenate([w[ny : ny + me], l_in])


def barrier_projections(A, n_variables: int, max_refin: int = 3):
    """trust-constr's ``(Z, LS, Y)`` operators of ``A`` (SciPy's ``projections``) from a
    :class:`BarrierKKT`: ``Z x = x - A^T (A A^T)^-1 A x``, ``LS x = (A A^T)^-1 A x``,
    ``Y x = A^T (A A^T)^-1 x``, each from one solve of the augmented system refined (at most
    ``max_refin`` times) to a relative residual of 1e-12; SciPy refines ``Z`` only. Raises
    ``ValueError`` if ``A`` lacks the barrier structure or the system is singular."""
    kkt = BarrierKKT(A, n_variables)
    m, n = kkt.shape
    zeros_m, zeros_n = np.zeros(m), np.zeros(n)

    def null_space(x):
        return kkt.solve(np.ravel(x), zeros_m, max_refin)[0]

    def least_squares(x):
        return kkt.solve(np.ravel(x), zeros_m, max_refin)[1]

    def row_space(x):
        return kkt.solve(zeros_n, np.ravel(x), max_refin)[0]

    return (
        LinearOperator((n, n), null_space),
        LinearOperator((m, n), least_squares),
        LinearOperator((n, m), row_space),
    )
