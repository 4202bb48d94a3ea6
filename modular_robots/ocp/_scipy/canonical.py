"""trust-constr's canonical constraints (``c_eq(x) = 0``, ``c_ineq(x) <= 0``) as gathers.

trust-constr turns every constraint ``lb <= c(x) <= ub`` (and the bounds) into canonical rows:
equalities ``c - lb``, one-sided rows ``c - ub`` or ``lb - c``, and both of those for a two-sided
row. SciPy does it per evaluation by fancy-indexing the values and the sparse Jacobian for each
kind of row and stacking the results, about ten sparse matrices built per Jacobian. The rows it
picks depend only on the bounds, and a shooting problem's Jacobian has a fixed structure, so here
the canonical values are one gather of the constraints' values, and the canonical Jacobians one
gather of their Jacobians' data into a structure built once (rebuilt if the structure changes).

The arithmetic is SciPy's, term by term (``lb - c`` is computed as ``(-c) - (-lb)``, which IEEE
rounds identically), so the values and Jacobians are bit-identical to SciPy's;
``tests/test_canonical.py`` checks it for every kind of row.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import sparse
from scipy.optimize._trustregion_constr.canonical_constraint import CanonicalConstraint

from .signed_rows import row_entries

__all__ = ["GatheredCanonical", "canonical_rows"]


def canonical_rows(lb: np.ndarray, ub: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The canonical rows trust-constr makes of ``lb <= c <= ub``, in its order.

    Returns
    -------
    eq_rows
        Rows of ``c`` that are equalities (``c - lb = 0``).
    ineq_rows, ineq_sign, ineq_bound
        Rows of ``c``, their sign and bound: the canonical inequality is
        ``sign * c[row] - sign * bound <= 0``.
    """
    lb, ub = np.asarray(lb, dtype=float), np.asarray(ub, dtype=float)
    rows = np.arange(lb.size)
    none = np.empty(0, dtype=int)
    lb_inf, ub_inf = lb == -np.inf, ub == np.inf
    if np.all(lb_inf) and np.all(ub_inf):
        groups: list[tuple[np.ndarray, float, np.ndarray]] = []
        eq = none
    elif np.all(lb == ub):
        groups, eq = [], rows
    elif np.all(lb_inf):
        groups, eq = [(rows[~ub_inf], 1.0, ub)], none
    elif np.all(ub_inf):
        groups, eq = [(rows[~lb_inf], -1.0, lb)], none
    else:  # SciPy's interval case: less, greater, then both sides of the two-sided rows
        two_sided = (lb != ub) & ~lb_inf & ~ub_inf
        eq = np.flatnonzero(lb == ub)
        groups = [
            (np.flatnonzero(lb_inf & ~ub_inf), 1.0, ub),
            (np.flatnonzero(ub_inf & ~lb_inf), -1.0, lb),
            (np.flatnonzero(two_sided), 1.0, ub),
            (np.flatnonzero(two_sided), -1.0, lb),
        ]
    ineq = np.concatenate([g[0] for g in groups] or [none])
    sign = np.concatenate([np.full(g[0].size, g[1]) for g in groups] or [np.empty(0)])
    bound = np.concatenate([g[2][g[0]] for g in groups] or [np.empty(0)])
    return eq, ineq, sign, bound


class _Gather:
    """The canonical fun and jac of constraints ``(cfun, lb, ub)``, stacked as SciPy stacks them."""

    def __init__(self, sources, n: int):
        self.functions = [cfun for cfun, _, _ in sources]
        self.n = n
        eq, ineq, sign, bound, lower = [], [], [], [], []
        offset = 0
        for _, lb, ub in sources:
            e, i, s, b = canonical_rows(lb, ub)
            eq.append(e + offset)
            ineq.append(i + offset)
            sign.append(s)
            bound.append(b)
            lower.append(np.asarray(lb, dtype=float)[e])
            offset += np.size(lb)
        self.eq_rows, self.ineq_rows = np.concatenate(eq), np.concatenate(ineq)
        self.eq_value = np.concatenate(lower)
        self.ineq_sign = np.concatenate(sign)
        self.ineq_signed_bound = self.ineq_sign * np.concatenate(bound)
        self._structure: tuple | None = None

    def fun(self, x):
        f = np.concatenate([cfun.fun(x) for cfun in self.functions])
        ineq = f[self.ineq_rows]
        ineq *= self.ineq_sign
        ineq -= self.ineq_signed_bound
        return f[self.eq_rows] - self.eq_value, ineq

    def jac(self, x):
        """The canonical Jacobians, or None if a constraint's Jacobian is not CSR (SciPy's own code
        then handles it). Unsorted indices and duplicate entries are kept, as SciPy keeps them."""
        jacobians = [cfun.jac(x) for cfun in self.functions]
        if not all(sparse.issparse(J) and J.format == "csr" for J in jacobians):
            return None
        key = [(J.indptr, J.indices) for J in jacobians]
        if self._structure is None or not _same_structure(self._structure[0], key):
            self._structure = ([(p.copy(), i.copy()) for p, i in key], self._layout(jacobians))
        (eq_take, eq_indices, eq_indptr), (in_take, in_negated, in_indices, in_indptr) = self._structure[1]
        data = np.concatenate([J.data for J in jacobians])
        ineq_data = data[in_take]
        np.negative(ineq_data, out=ineq_data, where=in_negated)  # SciPy's -J, sign bit and all
        return (  # index arrays copied: the caller may sort or change them in place
            sparse.csr_array((data[eq_take], eq_indices.copy(), eq_indptr.copy()), shape=(self.eq_rows.size, self.n)),
            sparse.csr_array((ineq_data, in_indices.copy(), in_indptr.copy()), shape=(self.ineq_rows.size, self.n)),
        )

    def _layout(self, jacobians):
        starts = [0]
        for J in jacobians:  # the stacked rows' extents in the stacked data
            starts.extend((J.indptr[1:] + starts[-1]).tolist())
        indptr = np.asarray(starts)
        indices = np.concatenate([J.indices for J in jacobians])

        def pick(rows):
            take, extents = row_entries(indptr, rows)
            return take, indices[take], extents.astype(indices.dtype)

        eq_take, eq_indices, eq_indptr = pick(self.eq_rows)
        in_take, in_indices, in_indptr = pick(self.ineq_rows)
        in_negated = np.repeat(self.ineq_sign < 0, np.diff(in_indptr))
        return (eq_take, eq_indices, eq_indptr), (in_take, in_negated, in_indices, in_indptr)


def _same_structure(cached, key) -> bool:
    return len(cached) == len(key) and all(
        np.array_equal(p, q) and np.array_equal(i, j) for (p, i), (q, j) in zip(cached, key, strict=True)
    )


def _gatherable(source) -> bool:
    """False for what SciPy treats apart: a constraint with no bounded row (SciPy never evaluates
    it) or with NaN bounds."""
    if source is None:
        return False
    _, lb, ub = source
    lb, ub = np.asarray(lb, dtype=float), np.asarray(ub, dtype=float)
    return not (np.isnan(lb).any() or np.isnan(ub).any() or (np.all(lb == -np.inf) and np.all(ub == np.inf)))


class GatheredCanonical(CanonicalConstraint):
    """SciPy's :class:`CanonicalConstraint` whose concatenation evaluates by gathers.

    Every instance made from a prepared constraint keeps its ``(fun, lb, ub)``; a concatenation
    of such instances with sparse Jacobians takes SciPy's Hessian and feasibility mask and gets
    its values and Jacobians from :func:`canonical_rows`. SciPy's own code serves a Jacobian
    that is not CSR, a constraint with no bounded row and NaN bounds.
    """

    @classmethod
    def from_PreparedConstraint(cls, constraint):
        canonical = super().from_PreparedConstraint(constraint)
        lb, ub = constraint.bounds
        canonical.source = (constraint.fun, lb, ub)
        return canonical

    @classmethod
    def concatenate(cls, canonical_constraints, sparse_jacobian):
        canonical = super().concatenate(canonical_constraints, sparse_jacobian)
        sources: list[Any] = [getattr(c, "source", None) for c in canonical_constraints]
        if not sparse_jacobian or not sources or not all(_gatherable(s) for s in sources):
            return canonical
        gather = _Gather(sources, sources[0][0].n)
        scipy_jac = canonical.jac

        def jac(x):
            return gather.jac(x) or scipy_jac(x)

        canonical.fun, canonical.jac = gather.fun, jac
        return canonical
