"""trust-constr's canonical constraints by gathers (:mod:`modular_robots.ocp.canonical`) against
SciPy's own fancy-indexing code: bit-identical values and Jacobians for every kind of row (equal,
less, greater, two-sided, unbounded) and for a real paper-5kg problem with its variable bounds."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse
from scipy.optimize import Bounds, NonlinearConstraint
from scipy.optimize._constraints import PreparedConstraint
from scipy.optimize._trustregion_constr.canonical_constraint import CanonicalConstraint

from modular_robots.composition import Composition
from modular_robots.feasibility import check_composition
from modular_robots.ocp.candidate import composition_problem
from modular_robots.ocp.canonical import GatheredCanonical, canonical_rows
from modular_robots.scenario import load_scenario

from .conftest import PAPER_5KG

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
    x0 = np.zeros(N)
    fun, jac = random_function(4, 5)
    calls = []

    def changing_jac(x):  # a structure that grows by one entry on every call
        calls.append(1)
        dense = jac(x).toarray()
        dense[len(calls) % 5, len(calls) % N] = 7.0
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
    for k in range(1, 4):
        x = np.full(N, 0.1 * k)
        assert_same(ours, theirs, x)


def paper_problem():
    scenario = load_scenario(PAPER_5KG)
    composition = Composition.from_name("B-J1-L3-J1-L2-J1-L1-J1-L1-E2", scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    return composition_problem(
        composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )


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
