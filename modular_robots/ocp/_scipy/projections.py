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
the plain normal equations of ``A`` were ill-conditioned). What is left is a symmetric system
of ``n_variables + n_eq + (small slacks)`` unknowns, 166-200 for that problem. Below
:data:`BANDED_FROM` unknowns it is factored dense by LAPACK; above, where a dense LU's cube of
the nodes dominated a solve (0.4 s of an iteration at 64 nodes), as a band with a border
(:mod:`.banded`): each node's unknowns meet only their neighbours', the durations' columns aside,
so the band's width does not grow with the nodes and the factorisation is linear in them. Each
solve is refined against the full system (the reduced one can be worse conditioned than ``K``).
Every product with ``J_ineq`` is one with its rows kept (:mod:`.signed_rows`): trust-constr
writes each two-sided row and bound twice, ``J_i`` and ``-J_i``, nearly half of its entries. The
operators are SciPy's (``Z``, ``LS``, ``Y``), and ``tests/test_projections.py`` and
``tests/test_projections_banded.py`` check them against SciPy's own, a dense QR and each other.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable

import numpy as np
import scipy.linalg
from scipy import sparse
from scipy.sparse.linalg import LinearOperator

from .banded import BorderedBandLU
from .products import MatVec
from .signed_rows import SignedRows

__all__ = ["SLACK_THRESHOLD", "BarrierKKT", "barrier_projections"]

_getrf, _getrs = scipy.linalg.lapack.dgetrf, scipy.linalg.lapack.dgetrs

#: Reduced systems of at least this many unknowns are factored as a band with a border: above
#: it the band is faster, below it the dense LU (a factorisation takes 2.7-3.3 ms banded and
#: 1.3-1.6 ms dense at 170 unknowns, 4.4-4.8 and 7.9-8.7 ms at 380; ``bench_nodes``' problems).
BANDED_FROM = 256

#: Slacks at or above this value are eliminated (their weight ``1 / s^2`` is at most 1e4); smaller
#: ones keep their multiplier as an unknown of the reduced system.
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
        Slacks below it keep their multiplier in the reduced system.
    banded
        Factor the reduced system as a band with a border (:mod:`.banded`) rather than dense;
        by default when it has at least :data:`BANDED_FROM` unknowns. A band or border found
        singular falls back to the dense LU.

    Raises
    ------
    ValueError
        If ``A`` does not have that structure, or the system is singular.
    """

    def __init__(self, A, n_variables: int, threshold: float = SLACK_THRESHOLD, banded: bool | None = None):
        A = A if isinstance(A, sparse.csr_array) else sparse.csr_array(A)
        if not A.has_canonical_format:  # sorted, duplicates summed; the caller's matrix untouched
            A = A.copy()
            A.sum_duplicates()
        if not np.all(np.isfinite(A.data)):
            raise ValueError("A has non-finite entries")  # SciPy's path raises it to the solver
        layout = _layout(A, n_variables)
        ny, me, mi = layout.ny, layout.me, layout.mi
        self.A, self.shape, self.ny, self.me, self.mi = A, A.shape, ny, me, mi
        data = A.data
        self.s = s = data[layout.slack]
        j_in_data = data[layout.in_take]
        rows, (stacked_indices, stacked_indptr) = layout.signed_rows(j_in_data)
        self._rows = rows
        large = np.abs(s) >= threshold
        self._small = small = np.flatnonzero(~large)
        #: 1/s on the eliminated rows, 0 on the others (whose rows the dense system keeps)
        self._inv_s = np.divide(1.0, s, out=np.zeros(mi), where=large)
        self._large = large.astype(float)
        kept = rows.kept(j_in_data)
        self._c, self._c_t = MatVec(kept), MatVec(kept, transpose=True)
        eq_data = data[layout.eq_take]
        self._eq = MatVec(sparse.csr_array((eq_data, layout.eq_indices, layout.eq_indptr), shape=(me, ny)))
        # [J_eq; C]: A's transposed product sums the equality rows' terms, then the inequality rows'
        stacked = sparse.csr_array(
            (np.concatenate([eq_data, kept.data]), stacked_indices, stacked_indptr), shape=(me + rows.n_kept, ny)
        )
        self._stacked, self._stacked_t = MatVec(stacked), MatVec(stacked, transpose=True)
        self._s_small = s[small]
        self.size = ny + me + len(small)
        #: ``E^T S^-2``: the weight of each kept row of ``J_ineq`` in the normal matrix
        weights = rows.gather_weights(self._inv_s**2)
        parts = (layout, data, j_in_data, kept, weights, small)
        if banded is None:
            banded = self.size >= BANDED_FROM
        factor: Callable[[np.ndarray], np.ndarray] | None = None
        if banded:
            with contextlib.suppress(ValueError):  # a singular band or border: the dense LU decides
                factor = BorderedBandLU(_reduced_sparse(self, *parts))
        self._factor = factor if factor is not None else _dense_factor(self, *parts)
        #: Whether the reduced system was factored as a band with a border.
        self.banded = isinstance(self._factor, BorderedBandLU)

    def solve(self, r: np.ndarray, t: np.ndarray, max_refin: int = 3, rtol: float = 1e-12):
        """``(z, w)`` with ``z + A^T w = r`` and ``A z = t``, refined (at most ``max_refin``
        times) until the residual is below ``rtol`` times the right-hand side's norm; a
        refinement that does not lower the residual is dropped and ends the refining."""
        z, w, known = self._solve_once(r, t)
        j_x: np.ndarray | None = known
        bound = rtol * (_norm(r) + _norm(t))
        best, smallest = (z, w), np.inf
        for k in range(max_refin + 1):
            res_r = r - z - self._a_t(w)
            res_t = t - self._a(z, j_x)
            size = _norm(res_r) + _norm(res_t)
            if size >= smallest:
                break
            best, smallest = (z, w), size
            if size <= bound or k == max_refin:
                break
            dz, dw, _ = self._solve_once(res_r, res_t)
            z, w, j_x = z + dz, w + dw, None
        return best

    def _j_in(self, x: np.ndarray) -> np.ndarray:
        """``J_ineq x``, bit for bit the plain product."""
        return self._rows.expand(self._c(x))

    def _j_in_t(self, g: np.ndarray) -> np.ndarray:
        """``J_ineq^T g``."""
        return self._c_t(self._rows.gather(g))

    def _a(self, z: np.ndarray, j_x: np.ndarray | None = None) -> np.ndarray:
        """``A z``; ``j_x`` is ``J_ineq x`` if known."""
        x, u = z[: self.ny], z[self.ny :]
        if j_x is None:
            both = self._stacked(x)
            eq_x, j_x = both[: self.me], self._rows.expand(both[self.me :])
        else:
            eq_x = self._eq(x)
        return np.concatenate([eq_x, j_x + self.s * u])

    def _a_t(self, w: np.ndarray) -> np.ndarray:
        """``A^T w``."""
        l_in = w[self.me :]
        x = self._stacked_t(np.concatenate([w[: self.me], self._rows.gather(l_in)]))
        return np.concatenate([x, self.s * l_in])

    def _solve_once(self, r: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One solve by the reduced system: ``(z, w)`` and ``J_ineq x`` (``x`` the first part of ``z``)."""
        ny, me, small, inv_s = self.ny, self.me, self._small, self._inv_s
        r_x, r_u = r[:ny], r[ny:]
        t_eq, t_in = t[:me], t[me:]
        g = t_in * inv_s - r_u * self._large  # S^-1 (t_in - S r_u) on eliminated rows
        rhs = np.concatenate([r_x + self._j_in_t(g * inv_s), t_eq, t_in[small] - self._s_small * r_u[small]])
        w = self._factor(rhs)
        x = w[:ny]
        j_x = self._j_in(x)
        l_in = (j_x - t_in) * inv_s**2 + r_u * inv_s
        l_in[small] = w[ny + me :]
        return np.concatenate([x, r_u - self.s * l_in]), np.concatenate([w[ny : ny + me], l_in]), j_x


def _dense_factor(kkt: BarrierKKT, layout, data, j_in_data, kept, weights, small):
    """The reduced system as a dense array, LU-factored by LAPACK: its solve."""
    ny, me, mi, k = kkt.ny, kkt.me, kkt.mi, len(small)
    size = ny + me + k
    rows, cols, values = _small_rows(layout, j_in_data, small, mi)
    j_small = np.zeros((k, ny))
    j_small[rows, cols] = values
    j_eq = np.zeros((me, ny))
    j_eq.flat[layout.eq_flat] = data[layout.eq_take]
    signed = kkt._rows
    dense = np.zeros(kept.shape)
    dense[signed.entry_rows, signed.indices] = kept.data
    kkt_matrix = np.zeros((size, size))
    kkt_matrix[:ny, :ny] = dense.T @ (dense * weights[:, None])  # BLAS beats a sparse product here
    kkt_matrix[np.arange(ny), np.arange(ny)] += 1.0
    kkt_matrix[:ny, ny : ny + me] = j_eq.T
    kkt_matrix[ny : ny + me, :ny] = j_eq
    kkt_matrix[:ny, ny + me :] = j_small.T
    kkt_matrix[ny + me :, :ny] = j_small
    kkt_matrix[np.arange(ny + me, size), np.arange(ny + me, size)] = -(kkt._s_small**2)
    lu, piv, info = _getrf(kkt_matrix, overwrite_a=True)  # scipy.linalg.lu_factor's LAPACK call, without its checks
    if info != 0 or not np.all(np.diagonal(lu)):
        raise ValueError("the augmented system is singular (dependent constraint rows)")

    def solve(rhs: np.ndarray) -> np.ndarray:
        return _getrs(lu, piv, rhs)[0]  # scipy.linalg.lu_solve's LAPACK call, without its checks

    return solve


def _reduced_sparse(kkt: BarrierKKT, layout, data, j_in_data, kept, weights, small) -> sparse.csr_array:
    """The reduced system (the dense one of :func:`_dense_factor`) as a sparse matrix, symmetric
    but for rounding (``C^T (w C)`` rounds its two triangles apart, by about 1e-16 relative); the
    band takes its border's lower block as the upper one's transpose, and each solve is refined
    against ``A`` itself."""
    ny, me, mi, k = kkt.ny, kkt.me, kkt.mi, len(small)
    scaled = kept.data * weights[kkt._rows.entry_rows]
    weighted = sparse.csr_array((scaled, kept.indices, kept.indptr), shape=kept.shape)
    normal = (kept.T @ weighted).tocoo()
    eq_rows, eq_cols = np.divmod(layout.eq_flat, ny)
    rows, small_cols, small_values = _small_rows(layout, j_in_data, small, mi)
    small_rows = ny + me + rows
    diagonal = np.arange(ny)
    small_diagonal = np.arange(ny + me, ny + me + k)
    rows = np.concatenate([normal.row, diagonal, ny + eq_rows, eq_cols, small_rows, small_cols, small_diagonal])
    cols = np.concatenate([normal.col, diagonal, eq_cols, ny + eq_rows, small_cols, small_rows, small_diagonal])
    values = np.concatenate(
        [
            normal.data,
            np.ones(ny),
            data[layout.eq_take],
            data[layout.eq_take],
            small_values,
            small_values,
            -(kkt._s_small**2),
        ]
    )
    size = ny + me + k
    return sparse.coo_array((values, (rows, cols)), shape=(size, size)).tocsr()  # duplicates summed


def _small_rows(layout, j_in_data, small, mi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The entries of the inequality rows whose slack is small (their multipliers stay in the
    reduced system): rows numbered among those rows (in ``small``'s order), columns, values."""
    rank = np.full(mi, -1)
    rank[small] = np.arange(len(small))
    in_small = rank[layout.in_row]
    kept = in_small >= 0
    return in_small[kept], layout.in_indices[kept], j_in_data[kept]


def _norm(x: np.ndarray) -> float:
    """``np.linalg.norm(x)`` of a float64 vector, computed as it computes it (``sqrt(x . x)`` of
    the vector made contiguous), without its dispatch."""
    x = x.ravel(order="K")
    return math.sqrt(x.dot(x))


class _Layout:
    """Where the entries of a barrier Jacobian of one sparsity structure go: its slacks, the
    equality rows' and the inequality rows' entries (positions in ``A.data``, and in the dense
    ``J_eq`` and ``J_ineq``). A solve keeps one structure, so it is worked out once per solve."""

    def __init__(self, A: sparse.csr_array, ny: int):
        m, n = A.shape
        mi = n - ny
        me = m - mi
        if mi < 0 or me < 0:
            raise ValueError(f"A of shape {A.shape} has no barrier structure for {ny} variables")
        per_row = np.diff(A.indptr)
        row = np.repeat(np.arange(m), per_row)
        slack = A.indices >= ny
        if not (
            np.count_nonzero(slack) == mi
            and np.array_equal(row[slack], np.arange(me, m))
            and np.array_equal(A.indices[slack], np.arange(ny, n))
        ):
            raise ValueError("A's slack columns are not one diagonal block under the equality rows")
        self.indptr, self.indices = A.indptr.copy(), A.indices.copy()
        self.shape, self.ny, self.me, self.mi = A.shape, ny, me, mi
        self.slack = np.flatnonzero(slack)
        self.eq_take = np.flatnonzero(~slack & (row < me))
        self.eq_flat = row[self.eq_take] * ny + A.indices[self.eq_take]
        self.in_take = np.flatnonzero(~slack & (row >= me))
        self.in_row = row[self.in_take] - me
        self.in_indices = A.indices[self.in_take]
        self.in_indptr = np.concatenate([[0], np.cumsum(per_row[me:] - 1)]).astype(A.indptr.dtype)
        self.eq_indices = A.indices[self.eq_take]
        self.eq_indptr = A.indptr[: me + 1].copy()
        self._signed_rows: tuple[SignedRows, tuple[np.ndarray, np.ndarray]] | None = None

    def signed_rows(self, j_in_data: np.ndarray) -> tuple[SignedRows, tuple[np.ndarray, np.ndarray]]:
        """``J_ineq``'s rows as signed copies of the rows kept ``C``, for its values ``j_in_data``
        (the last ones found if they still hold), and the structure ``(indices, indptr)`` of
        ``[J_eq; C]``."""
        found = self._signed_rows
        if found is None or not found[0].holds(j_in_data):
            rows = SignedRows(self.in_indptr, self.in_indices, j_in_data, self.ny)
            indptr = np.concatenate([self.eq_indptr, rows.indptr[1:] + self.eq_indptr[-1]])
            stacked = (np.concatenate([self.eq_indices, rows.indices]), indptr.astype(self.eq_indptr.dtype))
            found = self._signed_rows = (rows, stacked)
        return found

    def fits(self, A: sparse.csr_array, ny: int) -> bool:
        return (
            ny == self.ny
            and A.shape == self.shape
            and np.array_equal(A.indptr, self.indptr)
            and np.array_equal(A.indices, self.indices)
        )


_last_layout = threading.local()


def _layout(A: sparse.csr_array, ny: int) -> _Layout:
    """The layout of ``A``'s structure: the thread's last one if ``A`` has it."""
    layout = getattr(_last_layout, "layout", None)
    if layout is None or not layout.fits(A, ny):
        layout = _last_layout.layout = _Layout(A, ny)
    return layout


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
