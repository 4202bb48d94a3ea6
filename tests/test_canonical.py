"""trust-constr's canonical constraints by gathers (:mod:`modular_robots.ocp._scipy.canonical`) against
SciPy's own fancy-indexing code: bit-identical values and Jacobians for every kind of row (equal,
less, greater, two-sided, unbounded) and for a real paper-5kg problem with its variable bounds."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse
from scipy.optimize import Bounds, NonlinearConstraint
from scipy.optimize._constraints import PreparedConstraint
from scipy.optimize._trustregion_constr.canonical_constraint import CanonicalConstraint

from modular_robots.ocp._scipy.canonical import GatheredCanonical, canonical_rows

from .helpers.problems import paper_problem

N = 7


def random_function(seed: int, m: int):
    """A nonlinear ``c(x)`` of ``m`` rows with a sparse Jacobian of fixed structure."""
    rng = np.random.default_rng(seed)
    mask = sparse.random_array((m, N), density=0.4, random_state=rng, format="csr")
    mask.data[:] = 1.0
    weights = rng.normal(size=(m, N))

    def fun(x):
        return weights @ np.sin(x) + 0.1 * np.arange(m)

    def jac(x):
        dense = weights * np.cos(x)
        return sparse.csr_matrix((dense[mask.nonzero()], mask.indices, mask.indptr), shape=(m, N))

    return fun, jac


def no_hessian(x, v):
    return sparse.csr_array((x.size, x.size))


KINDS = {  # lb, ub of each row kind
    "equal": (0.5, 0.5),
    "less": (-np.inf, 1.0),
    "greater": (-1.0, np.inf),
    "two-sided": (-1.0, 2.0),
    "free": (-np.inf, np.inf),
}


def bounds_of(kinds: list[str]) -> tuple[np.ndarray, np.ndarray]:
    return np.array([KINDS[k][0] for k in kinds]), np.array([KINDS[k][1] for k in kinds])


CASES = {
    "all equal": ["equal"] * 4,
    "all less": ["less"] * 3 + ["free"],
    "all greater": ["greater", "free", "greater"],
    "all two-sided": ["two-sided"] * 5,
    "mixed": ["two-sided", "equal", "less", "free", "greater", "two-sided", "equal"],
}


def prepared(kinds: list[str], seed: int, x0: np.ndarray) -> PreparedConstraint:
    fun, jac = random_function(seed, len(kinds))
    lb, ub = bounds_of(kinds)
    return PreparedConstraint(NonlinearConstraint(fun, lb, ub, jac=jac, hess=no_hessian), x0, sparse_jacobian=True)


def assert_same(ours, scipy_form, x):
    (e1, i1), (e2, i2) = ours.fun(x), scipy_form.fun(x)
    assert e1.tobytes() == e2.tobytes() and i1.tobytes() == i2.tobytes()
    for a, b in zip(ours.jac(x), scipy_form.jac(x), strict=True):
        a, b = sparse.csr_array(a), sparse.csr_array(b)
        assert a.shape == b.shape
        assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
        assert a.data.tobytes() == b.data.tobytes()


@pytest.mark.parametrize("case", sorted(CASES))
def test_gathered_rows_are_scipys_bit_for_bit(case):
    rng = np.random.default_rng(3)
    x0 = rng.normal(size=N)
    constraints = [prepared(CASES[case], 1, x0), prepared(CASES["mixed"], 2, x0)]
    constraints.append(PreparedConstraint(Bounds(-np.ones(N), np.r_[np.ones(N - 1), np.inf]), x0, sparse_jacobian=True))
    ours = GatheredCanonical.concatenate([GatheredCanonical.from_PreparedConstraint(c) for c in constraints], True)
    theirs = CanonicalConstraint.concatenate(
        [CanonicalConstraint.from_PreparedConstraint(c) for c in constraints], True
    )
    assert (ours.n_eq, ours.n_ineq) == (theirs.n_eq, theirs.n_ineq)
    for x in (x0, rng.normal(size=N), rng.normal(size=N)):
        assert_same(ours, theirs, x)


def test_canonical_rows_follow_scipys_order():
    """Less, greater, then the upper and the lower side of every two-sided row."""
    lb, ub = bounds_of(CASES["mixed"])
    eq, ineq, sign, bound = canonical_rows(lb, ub)
    assert eq.tolist() == [1, 6]
    assert ineq.tolist() == [2, 4, 0, 5, 0, 5]
    assert sign.tolist() == [1, -1, 1, 1, -1, -1]
    assert bound.tolist() == [1.0, -1.0, 2.0, 2.0, -1.0, -1.0]


def test_a_jacobian_whose_structure_changes_is_laid_out_again():
    """Each evaluation's Jacobian has one entry more, outside the previous structure."""
    x0 = np.zeros(N)
    fun, jac = random_function(4, 5)
    outside = np.argwhere(jac(x0).toarray() == 0)
    calls = []

    def changing_jac(x):
        calls.append(1)
        dense = jac(x).toarray()
        for row, col in outside[: len(calls)]:
            dense[row, col] = 7.0 + x[col]
        return sparse.csr_matrix(dense)

    constraint = PreparedConstraint(
        NonlinearConstraint(fun, *bounds_of(CASES["mixed"][:5]), jac=changing_jac, hess=no_hessian), x0, True
    )
    bounds = PreparedConstraint(Bounds(-np.ones(N), np.ones(N)), x0, sparse_jacobian=True)
    ours = GatheredCanonical.concatenate(
        [GatheredCanonical.from_PreparedConstraint(c) for c in (constraint, bounds)], True
    )
    theirs = CanonicalConstraint.concatenate(
        [CanonicalConstraint.from_PreparedConstraint(c) for c in (constraint, bounds)], True
    )
    assert len(outside) >= 4
    for k in range(1, 4):
        x = np.full(N, 0.1 * k)
        assert_same(ours, theirs, x)


def jacobian_of(kind: str):
    """A Jacobian with its indices reversed within rows (``unsorted``), with every entry split in
    two (``duplicates``), or ``dense``."""
    fun, jac = random_function(6, 5)

    def unsorted(x):
        J = jac(x).tocsr()
        for r in range(J.shape[0]):
            lo, hi = J.indptr[r], J.indptr[r + 1]
            J.indices[lo:hi], J.data[lo:hi] = J.indices[lo:hi][::-1].copy(), J.data[lo:hi][::-1].copy()
        J.has_sorted_indices = False
        return J

    def duplicates(x):
        J = jac(x).tocsr()
        half = 0.5 * J.data
        data = np.column_stack([half, J.data - half]).ravel()
        return sparse.csr_matrix((data, np.repeat(J.indices, 2), 2 * J.indptr), shape=J.shape)

    return fun, {"unsorted": unsorted, "duplicates": duplicates, "dense": lambda x: jac(x).toarray()}[kind]


@pytest.mark.parametrize("case", ["unsorted", "duplicates", "dense", "no bounded row", "NaN bound"])
def test_unusual_constraints_are_as_scipy_has_them(case):
    """Jacobians that are not canonical CSR, a dense one, a constraint with no bounded row
    (which SciPy never evaluates) and a NaN bound (SciPy drops that row of a one-sided
    constraint)."""
    x0 = np.linspace(-0.5, 0.5, N)
    kinds = CASES["mixed"][:5]
    fun, jac = random_function(6, 5)
    if case in ("unsorted", "duplicates", "dense"):
        fun, jac = jacobian_of(case)
    lb, ub = bounds_of(["free"] * 5 if case == "no bounded row" else kinds)
    if case == "NaN bound":
        lb, ub = bounds_of(["less"] * 5)
        ub[2] = np.nan
    calls = []

    def counted_jac(x):
        calls.append(1)
        return jac(x)

    sparse_jacobian = case != "dense"
    prepared_all = [
        PreparedConstraint(NonlinearConstraint(fun, lb, ub, jac=counted_jac, hess=no_hessian), x0, sparse_jacobian),
        prepared(CASES["mixed"], 1, x0) if sparse_jacobian else None,
        PreparedConstraint(Bounds(-np.ones(N), np.ones(N)), x0, sparse_jacobian),
    ]
    prepared_all = [c for c in prepared_all if c is not None]
    ours = GatheredCanonical.concatenate(
        [GatheredCanonical.from_PreparedConstraint(c) for c in prepared_all], sparse_jacobian
    )
    theirs = CanonicalConstraint.concatenate(
        [CanonicalConstraint.from_PreparedConstraint(c) for c in prepared_all], sparse_jacobian
    )
    assert (ours.n_eq, ours.n_ineq) == (theirs.n_eq, theirs.n_ineq)
    calls.clear()
    for x in (x0, x0 + 0.1):
        if case == "dense":
            for a, b in zip(ours.jac(x), theirs.jac(x), strict=True):
                assert np.asarray(a).tobytes() == np.asarray(b).tobytes()
        else:
            assert_same(ours, theirs, x)
    if case == "no bounded row":
        assert calls == []


def test_the_jacobians_handed_out_are_the_callers_to_change():
    """trust-constr may sort or edit a Jacobian in place; the next one must not change with it."""
    x0 = np.linspace(-0.5, 0.5, N)
    prepared_all = [prepared(CASES["mixed"], 1, x0), prepared(CASES["all two-sided"], 2, x0)]
    ours = GatheredCanonical.concatenate([GatheredCanonical.from_PreparedConstraint(c) for c in prepared_all], True)
    theirs = CanonicalConstraint.concatenate(
        [CanonicalConstraint.from_PreparedConstraint(c) for c in prepared_all], True
    )
    for J in ours.jac(x0):
        J.indices[:] = 0
        J.indptr[:] = 0
    assert_same(ours, theirs, x0 + 0.1)


def test_a_shooting_problems_rows_are_scipys_bit_for_bit():
    problem = paper_problem()
    y0 = problem.initial_guess()
    constraint = NonlinearConstraint(
        lambda y: problem.evaluate(y).constraints,
        problem.constraint_lower,
        problem.constraint_upper,
        jac=problem.constraint_jacobian,
        hess=no_hessian,
    )
    prepared_all = [
        PreparedConstraint(constraint, y0, sparse_jacobian=True),
        PreparedConstraint(Bounds(problem.variable_lower, problem.variable_upper), y0, sparse_jacobian=True),
    ]
    ours = GatheredCanonical.concatenate([GatheredCanonical.from_PreparedConstraint(c) for c in prepared_all], True)
    theirs = CanonicalConstraint.concatenate(
        [CanonicalConstraint.from_PreparedConstraint(c) for c in prepared_all], True
    )
    assert ours.n_eq > 0 and ours.n_ineq > problem.n_constraints
    rng = np.random.default_rng(0)
    for y in (y0, y0 + 1e-3 * rng.normal(size=y0.size)):
        assert_same(ours, theirs, y)
