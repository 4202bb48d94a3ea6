"""Sparse matrix-vector products by the kernels SciPy's own products end in.

``matrix @ x`` on a SciPy sparse array checks and dispatches on every call (about 20 us of a
30 us product on a barrier Jacobian), and ``matrix.T @ x`` first builds the transposed array (a
constructor with its own checks, about 30 us more). For a CSR or CSC matrix of float64 entries
and a float64 vector these products call the same compiled kernel on the same arrays: a CSR
matrix's transpose is a CSC matrix with its very arrays, so ``csc_matvec`` on them is what
SciPy's ``matrix.T @ x`` computes. The results are SciPy's bit for bit; anything else (another
format or dtype, a vector of the wrong shape) goes to SciPy's product, with its checks. The
kernels are a private SciPy module: without them every product is SciPy's, and the installer
(:func:`~modular_robots.ocp._scipy.trust_constr.install`) checks them on a probe matrix first,
setting them aside with a warning if they are missing or compute otherwise.
"""

from __future__ import annotations

import numpy as np

try:  # SciPy's compiled sparse kernels, which ``matrix @ vector`` ends in
    from scipy.sparse import _sparsetools
except ImportError:  # pragma: no cover (a SciPy that moved them: the plain product)
    _sparsetools = None

__all__ = ["MatVec", "rmatvec"]

_TRANSPOSED = {"csr": "csc", "csc": "csr"}


class MatVec:
    """``matrix @ x`` (or ``matrix.T @ x`` with ``transpose``) for a fixed sparse ``matrix``."""

    def __init__(self, matrix, transpose: bool = False):
        self.matrix, self.transpose = matrix, transpose
        layout: str = getattr(matrix, "format", "")
        fast = _sparsetools is not None and layout in _TRANSPOSED and matrix.dtype == np.float64
        kernel_format = _TRANSPOSED.get(layout) if transpose else layout
        self.kernel = getattr(_sparsetools, f"{kernel_format}_matvec", None) if fast else None
        rows, columns = matrix.shape
        self.rows, self.columns = (columns, rows) if transpose else (rows, columns)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if self.kernel is None or x.dtype != np.float64 or x.shape != (self.columns,):
            return (self.matrix.T if self.transpose else self.matrix).dot(x)  # SciPy's product, with its checks
        m = self.matrix
        out = np.zeros(self.rows)
        self.kernel(self.rows, self.columns, m.indptr, m.indices, m.data, np.ascontiguousarray(x), out)
        return out


def rmatvec(matrix, x: np.ndarray) -> np.ndarray:
    """``matrix.T @ x``, bit for bit SciPy's (see the module docstring)."""
    return MatVec(matrix, transpose=True)(x)
