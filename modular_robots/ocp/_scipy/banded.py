"""LU of a sparse symmetric matrix that is banded but for a few dense rows and columns.

The reduced augmented system of a shooting problem (:mod:`.projections`) couples each node's
variables and rows with its neighbours' only, except the free durations, whose columns meet
every row of their phase. Taken out as a border, the rest orders into a band whose width does
not depend on the number of nodes (about 45 for a six-joint arm, from 172 to 1,579 unknowns),
so factoring it costs time linear in the nodes where a dense LU costs their cube.

``K = [[M, B], [B^T, C]]`` (``B`` the border's columns) is solved by block elimination: ``M``
banded (reverse Cuthill-McKee order, LAPACK's ``gbtrf`` with partial pivoting), ``X = M^-1 B``,
the Schur complement ``C - B^T X`` dense. Its accuracy is that of the two LUs; the caller refines
its solves against the whole system.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy import sparse
from scipy.sparse.csgraph import reverse_cuthill_mckee

__all__ = ["BorderedBandLU", "border_columns"]

_gbtrf, _gbtrs = scipy.linalg.lapack.dgbtrf, scipy.linalg.lapack.dgbtrs
_getrf, _getrs = scipy.linalg.lapack.dgetrf, scipy.linalg.lapack.dgetrs


def border_columns(K: sparse.csr_array) -> np.ndarray:
    """Columns of ``K`` with far more entries than the typical one (more than four times the
    median and 20 more): the durations' columns of a shooting problem."""
    counts = np.diff(K.indptr)
    return np.flatnonzero(counts > 4 * np.median(counts) + 20)


class BorderedBandLU:
    """Factor the symmetric sparse ``K`` as a band plus a border of ``border`` columns.

    Raises
    ------
    ValueError
        If the band or the Schur complement is singular.
    """

    def __init__(self, K: sparse.csr_array, border: np.ndarray | None = None):
        n = K.shape[0]
        border = border_columns(K) if border is None else np.asarray(border, dtype=np.intp)
        inner = np.ones(n, dtype=bool)
        inner[border] = False
        rest = np.flatnonzero(inner)
        M = K[rest][:, rest].tocsr()
        order = reverse_cuthill_mckee(sparse.csr_matrix(M), symmetric_mode=True)
        self._rest, self._border = rest[order], border
        M = M[order][:, order].tocoo()
        lower = int(np.max(M.row - M.col, initial=0))
        upper = int(np.max(M.col - M.row, initial=0))
        band = np.zeros((2 * lower + upper + 1, M.shape[0]))
        band[lower + upper + M.row - M.col, M.col] = M.data
        lu, piv, info = _gbtrf(band, lower, upper, overwrite_ab=True)
        if info != 0:
            raise ValueError("the banded part of the augmented system is singular")
        self._band = (lu, lower, upper, piv)
        self.bandwidth = lower + upper + 1
        self._schur = None
        if len(border):
            B = K[self._rest][:, border].toarray()
            C = K[border][:, border].toarray()
            self._x = self._band_solve(B)
            self._b_t = B.T.copy()
            slu, spiv, info = _getrf(C - self._b_t @ self._x)
            if info != 0:
                raise ValueError("the border's Schur complement is singular")
            self._schur = (slu, spiv)

    def _band_solve(self, rhs: np.ndarray) -> np.ndarray:
        lu, lower, upper, piv = self._band
        return _gbtrs(lu, lower, upper, rhs, piv)[0]

    def __call__(self, rhs: np.ndarray) -> np.ndarray:
        """``K^-1 rhs``."""
        out = np.empty_like(rhs)
        y = self._band_solve(rhs[self._rest])
        if self._schur is not None:
            xb, _ = _getrs(*self._schur, rhs[self._border] - self._b_t @ y)
            y -= self._x @ xb
            out[self._border] = xb
        out[self._rest] = y
        return out
