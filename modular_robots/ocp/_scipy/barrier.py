"""trust-constr's barrier-subproblem Jacobian ``[[J_eq, 0], [J_ineq, diag(s)]]`` by puts into a
structure worked out once.

At every point whose Jacobian it needs, SciPy's ``BarrierSubproblem._assemble_sparse_jacobian``
stacks ``J_eq`` over ``J_ineq`` (a sparse ``vstack``), builds the slack columns' indices with
masks and converts them in a new CSR array. A shooting problem's Jacobians keep one sparsity
structure through a solve, so :class:`BarrierJacobian` works the structure out once, by SciPy's
own assembly, and then only copies the values and slacks into their places: the same matrix, bit
for bit, and the same index dtype. A structure whose assembly by puts does not reproduce SciPy's
(checked once per structure, on distinct probe values) is left to SciPy's code.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import sparse

__all__ = ["BarrierJacobian"]


class BarrierJacobian:
    """Assembles barrier Jacobians, keeping the last sparsity structure's layout."""

    def __init__(self):
        self._key: tuple | None = None
        self._places: tuple | None = None

    def __call__(self, J_eq, J_ineq, s: np.ndarray, n_vars: int, scipy_assemble: Callable):
        """``[[J_eq, 0], [J_ineq, diag(s)]]`` for CSR ``J_eq`` and ``J_ineq`` of ``n_vars`` columns.

        ``scipy_assemble(J_eq, J_ineq, s)`` is SciPy's assembly: it defines each new structure
        and serves whatever puts cannot.
        """
        if not (getattr(J_eq, "format", None) == getattr(J_ineq, "format", None) == "csr"):
            return scipy_assemble(J_eq, J_ineq, s)
        if not self._fits(J_eq, J_ineq, n_vars):
            self._learn(J_eq, J_ineq, s, n_vars, scipy_assemble)
            return scipy_assemble(J_eq, J_ineq, s)
        if self._places is None:  # a structure whose puts did not reproduce SciPy's
            return scipy_assemble(J_eq, J_ineq, s)
        return self._put(J_eq, J_ineq, s)

    def _fits(self, J_eq, J_ineq, n_vars: int) -> bool:
        key = self._key
        return (
            key is not None
            and key[0] == (n_vars, J_eq.shape, J_ineq.shape)
            and all(np.array_equal(a, b) for a, b in zip(key[1], _structure(J_eq, J_ineq), strict=True))
        )

    def _learn(self, J_eq, J_ineq, s, n_vars: int, scipy_assemble: Callable) -> None:
        """Remember the structure of ``(J_eq, J_ineq)`` and, if puts reproduce SciPy's assembly of
        it bit for bit, where the values go. The check assembles distinct probe values (every
        entry and slack its own number), so that no two places can be confused."""
        self._key = (
            (n_vars, J_eq.shape, J_ineq.shape),
            tuple(a.copy() for a in _structure(J_eq, J_ineq)),
        )
        self._places = None
        n_eq, n_ineq = J_eq.shape[0], J_ineq.shape[0]
        probe_eq, probe_ineq = J_eq.copy(), J_ineq.copy()
        probe_eq.data = np.arange(1.0, J_eq.nnz + 1)
        probe_ineq.data = np.arange(J_eq.nnz + 1.0, J_eq.nnz + J_ineq.nnz + 1)
        probe_s = -np.arange(1.0, np.size(s) + 1)
        assembled = scipy_assemble(probe_eq, probe_ineq, probe_s)
        if not (sparse.issparse(assembled) and assembled.format == "csr" and n_ineq > 0):
            return
        slack = np.zeros(assembled.nnz, dtype=bool)
        slack[assembled.indptr[n_eq + 1 :] - 1] = True
        entries = np.flatnonzero(~slack)
        if entries.size != J_eq.nnz + J_ineq.nnz:
            return
        self._places = (
            np.flatnonzero(slack),
            entries[: J_eq.nnz],
            entries[J_eq.nnz :],
            assembled.indices.copy(),
            assembled.indptr.copy(),
            assembled.shape,
        )
        if not _identical(self._put(probe_eq, probe_ineq, probe_s), assembled):
            self._places = None

    def _put(self, J_eq, J_ineq, s):
        places = self._places
        assert places is not None  # _put follows a learnt structure
        slack, eq, ineq, indices, indptr, shape = places
        data = np.empty(indices.size)
        data[eq] = J_eq.data
        data[ineq] = J_ineq.data
        data[slack] = s
        return sparse.csr_array((data, indices.copy(), indptr.copy()), shape=shape)


def _structure(J_eq, J_ineq) -> tuple[np.ndarray, ...]:
    return J_eq.indptr, J_eq.indices, J_ineq.indptr, J_ineq.indices


def _identical(a, b) -> bool:
    """The same CSR matrix, bit for bit: values, indices and their dtypes, shape."""
    pairs = zip((a.data, a.indices, a.indptr), (b.data, b.indices, b.indptr), strict=True)
    return a.shape == b.shape and all(x.dtype == y.dtype and x.tobytes() == y.tobytes() for x, y in pairs)
