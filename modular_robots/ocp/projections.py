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
        A = A if isinstance(A, sparse.csr_array) else sparse.csr_array(A)
        A.sort_indices()
        m, n = A.shape
        ny = n_variables
        mi = n - ny
        me = m - mi
        if mi < 0 or me < 0:
            raise ValueError(f"A of shape {A.shape} has no barrier structure for {ny} variables")
        if not np.all(np.isfinite(A.data)):
            raise ValueError("A has non-finite entries")  # SciPy's path raises it to the solver
        self.A, self.shape, self.ny, self.me, self.mi = A, (m, n), ny, me, mi
        # The slack entries, straight from the CSR arrays: one per inequality row, on the diagonal.
        per_row = np.diff(A.indptr)
        slack = A.indices >= ny
        if not (
            np.count_nonzero(slack) == mi
            and np.array_equal(np.repeat(np.arange(m), per_row)[slack], np.arange(me, m))
            and np.array_equal(A.indices[slack], np.arange(ny, n))
        ):
            raise ValueError("A's slack columns are not one diagonal block under the equality rows")
        self.s = s = A.data[slack]
        shift = np.concatenate([np.zeros(me + 1, dtype=A.indptr.dtype), np.arange(1, mi + 1, dtype=A.indptr.dtype)])
        j = sparse.csr_array((A.data[~slack], A.indices[~slack], A.indptr - shift), shape=(m, ny))
        j_in = j[me:]
        large = np.abs(s) >= threshold
        self._small = np.flatnonzero(~large)
        #: 1/s on the eliminated rows, 0 on the others (whose rows the dense system keeps)
        self._inv_s = np.divide(1.0, s, out=np.zeros(mi), where=large)
        self._large = large.astype(float)
        self._j_in = j_in
        weighted = sparse.csr_array(  # S^-1 J on eliminated rows, zero rows elsewhere
            (j_in.data * np.repeat(self._inv_s, np.diff(j_in.indptr)), j_in.indices, j_in.indptr), shape=j_in.shape
        )
        self._weighted_t = weighted.T
        self._a_t = A.T
        self._s_small = s[self._small]
        j_small = j_in[self._small].toarray()
        j_eq = j[:me].toarray()
        k = len(self._small)
        size = ny + me + k
        kkt = np.zeros((size, size))
        dense = weighted.toarray()
        kkt[:ny, :ny] = dense.T @ dense  # BLAS beats a sparse product here (0.27 vs 0.40 ms)
        kkt[np.arange(ny), np.arange(ny)] += 1.0
        kkt[:ny, ny : ny + me] = j_eq.T
        kkt[ny : ny + me, :ny] = j_eq
        kkt[:ny, ny + me :] = j_small.T
        kkt[ny + me :, :ny] = j_small
        kkt[np.arange(ny + me, size), np.arange(ny + me, size)] = -(self._s_small**2)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)  # singular: raised below
            self._lu = scipy.linalg.lu_factor(kkt, overwrite_a=True, check_finite=False)
        if not np.all(np.diagonal(self._lu[0])):
            raise ValueError("the augmented system is singular (dependent constraint rows)")

    @property
    def dense_size(self) -> int:
        """Unknowns of the dense system."""
        return self._lu[0].shape[0]

    def solve(self, r: np.ndarray, t: np.ndarray, max_refin: int = 3, rtol: float = 1e-12):
        """``(z, w)`` with ``z + A^T w = r`` and ``A z = t``, refined (at most ``max_refin``
        times) until the residual is below ``rtol`` times the right-hand side's norm; a
        refinement that does not lower the residual is dropped and ends the refining."""
        z, w = self._solve_once(r, t)
        bound = rtol * (np.linalg.norm(r) + np.linalg.norm(t))
        best, smallest = (z, w), np.inf
        for k in range(max_refin + 1):
            res_r = r - z - self._a_t @ w
            res_t = t - self.A @ z
            size = np.linalg.norm(res_r) + np.linalg.norm(res_t)
            if size >= smallest:
                break
            best, smallest = (z, w), size
            if size <= bound or k == max_refin:
                break
            dz, dw = self._solve_once(res_r, res_t)
            z, w = z + dz, w + dw
        return best

    def _solve_once(self, r: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ny, me, small, inv_s = self.ny, self.me, self._small, self._inv_s
        r_x, r_u = r[:ny], r[ny:]
        t_eq, t_in = t[:me], t[me:]
        g = t_in * inv_s - r_u * self._large  # S^-1 (t_in - S r_u) on eliminated rows
        rhs = np.concatenate([r_x + self._weighted_t @ g, t_eq, t_in[small] - self._s_small * r_u[small]])
        w = scipy.linalg.lu_solve(self._lu, rhs, check_finite=False)
        x = w[:ny]
        l_in = (self._j_in @ x - t_in) * inv_s**2 + r_u * inv_s
        l_in[small] = w[ny + me :]
        return np.concatenate([x, r_u - self.s * l_in]), np.concatenate([w[ny : ny + me], l_in])


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

    return (  # a LinearOperator without a dtype finds it by applying itself to zeros: a solve each
        LinearOperator((n, n), null_space, dtype=float),
        LinearOperator((m, n), least_squares, dtype=float),
        LinearOperator((n, m), row_space, dtype=float),
    )
