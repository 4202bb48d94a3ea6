"""The parts of trust-constr that :mod:`modular_robots.ocp._scipy.trust_constr` takes over: only in a
solver's thread, and the bit-identical ones (canonical constraints, barrier function) leave a
whole solve's iterates bit for bit as SciPy's code makes them."""

from __future__ import annotations

import threading
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import sparse
from scipy.optimize import SR1, Bounds
from scipy.optimize._constraints import PreparedConstraint
from scipy.optimize._differentiable_functions import VectorFunction
from scipy.optimize._trustregion_constr import minimize_trustregion_constr, qp_subproblem, tr_interior_point
from scipy.optimize._trustregion_constr.canonical_constraint import CanonicalConstraint

from modular_robots.ocp._scipy import barrier, boxes, canonical, sqp, trust_constr
from modular_robots.ocp.solver import _SR1

from .helpers.problems import history, paper_problem


@pytest.fixture(autouse=True, scope="module")
def installed():
    """The replacements in place, as a solver puts them before its first solve."""
    return trust_constr.install()


class Subproblem:  # what BarrierSubproblem._compute_function reads of its instance
    barrier_parameter = 1e-3
    enforce_feasibility = np.array([False, True, False, False, False, False])


SLACKS = {
    "interior": np.array([1e-9, 0.5, 3.0, 1e3, 2e-4, 7.0]),
    "at and past the bound": np.array([0.0, 0.5, -1e-12, 2.0, -3.0, 1.0]),
    "not a number": np.array([np.nan, 0.5, 1.0, 2.0, np.inf, 1.0]),
}


@pytest.mark.parametrize("case", sorted(SLACKS))
def test_the_barrier_function_is_scipys_bit_for_bit(case):
    """Its value, and the slacks it overwrites where feasibility is enforced."""
    c_ineq = -np.linspace(0.1, 0.6, 6)
    their_s = SLACKS[case].copy()
    with np.errstate(invalid="ignore"):  # inf - inf in the "not a number" case
        theirs = trust_constr.scipy_barrier_function(Subproblem(), 2.5, c_ineq, their_s)
    our_s = SLACKS[case].copy()
    seen = {}

    def in_solver_thread():
        trust_constr.mark_solver_thread(6)
        with np.errstate(invalid="ignore"):
            seen["ours"] = trust_constr.barrier_function(Subproblem(), 2.5, c_ineq, our_s)

    thread = threading.Thread(target=in_solver_thread)
    thread.start()
    thread.join()
    assert np.float64(seen["ours"]).tobytes() == np.float64(theirs).tobytes()
    assert our_s.tobytes() == their_s.tobytes() and our_s[1] == -c_ineq[1]


def test_outside_a_solver_thread_everything_is_scipys(monkeypatch):
    calls = []
    monkeypatch.setattr(trust_constr, "scipy_barrier_function", lambda *args: calls.append(args) or 0.0)
    assert not trust_constr.in_solver_thread()
    monkeypatch.setattr(trust_constr, "scipy_barrier_jacobian", lambda *args: calls.append(args))
    monkeypatch.setattr(trust_constr, "scipy_hessian_update", lambda *args: calls.append(args))
    monkeypatch.setattr(trust_constr, "scipy_box_intersections", lambda *args: calls.append(args))
    trust_constr.box_intersections(np.zeros(2), np.ones(2), -np.ones(2), np.ones(2))
    trust_constr.barrier_function(Subproblem(), 1.0, np.zeros(6), np.ones(6))
    J_eq, J_ineq, s = _jacobians(np.random.default_rng(1))
    trust_constr.barrier_jacobian(SimpleNamespace(n_vars=12), J_eq, J_ineq, s)
    trust_constr.hessian_update(SimpleNamespace(H_updated=False, _orig_hess=SR1()))
    assert len(calls) == 4
    canonical = trust_constr.SolverCanonical.concatenate([CanonicalConstraint.empty(3)] * 2, True)
    assert type(canonical) is CanonicalConstraint
    bounds = PreparedConstraint(Bounds(-np.ones(3), np.ones(3)), np.zeros(3), sparse_jacobian=True)
    assert type(trust_constr.SolverCanonical.from_PreparedConstraint(bounds)) is CanonicalConstraint


def test_a_solve_is_scipys_iterate_for_iterate_without_the_bit_identical_hooks(monkeypatch):
    problem = paper_problem()
    used = {"gathers": 0, "barrier": 0, "puts": 0, "updates": 0, "boxes": 0}
    gathered_jac, barrier_function = canonical._Gather.jac, trust_constr.barrier_function
    put, rmatvec = barrier.BarrierJacobian._put, trust_constr.rmatvec
    fast_boxes = trust_constr.fast_box_intersections

    def counted(name, function, solver_thread_only=False):
        def call(*args):
            used[name] += trust_constr.in_solver_thread() or not solver_thread_only
            return function(*args)

        return call

    monkeypatch.setattr(canonical._Gather, "jac", counted("gathers", gathered_jac))
    monkeypatch.setattr(
        tr_interior_point.BarrierSubproblem,
        "_compute_function",
        counted("barrier", barrier_function, solver_thread_only=True),
    )
    monkeypatch.setattr(barrier.BarrierJacobian, "_put", counted("puts", put))
    monkeypatch.setattr(trust_constr, "rmatvec", counted("updates", rmatvec))
    monkeypatch.setattr(trust_constr, "fast_box_intersections", counted("boxes", fast_boxes))
    monkeypatch.setattr(sqp, "box_intersections", counted("boxes", fast_boxes))
    ours = history(problem)
    assert min(used.values()) > 10, used  # every hook did run
    monkeypatch.setattr(minimize_trustregion_constr, "CanonicalConstraint", trust_constr.ScipyCanonical)
    for owner, name, scipys in (
        (tr_interior_point.BarrierSubproblem, "_compute_function", trust_constr.scipy_barrier_function),
        (
            tr_interior_point.BarrierSubproblem,
            "_assemble_sparse_jacobian",
            trust_constr.scipy_barrier_jacobian,
        ),
        (VectorFunction, "_update_hess", trust_constr.scipy_hessian_update),
        (qp_subproblem, "box_intersections", trust_constr.scipy_box_intersections),
        (sqp, "box_intersections", trust_constr.scipy_box_intersections),
    ):
        monkeypatch.setattr(owner, name, scipys)
    assert history(problem) == ours
    assert ours[0] > 10


def test_every_replacement_is_in_place_on_this_scipy(installed):
    """A SciPy that moved one of the replaced names would keep its own (slower) code."""
    assert installed.complete and installed.hooks == (
        "projections",
        "canonical constraints",
        "barrier function",
        "SQP loop",
        "barrier Jacobian",
        "quasi-Newton update",
        "box intersections",
    )
    assert minimize_trustregion_constr.CanonicalConstraint is trust_constr.SolverCanonical
    subproblem = tr_interior_point.BarrierSubproblem
    assert subproblem._compute_function is trust_constr.barrier_function
    assert subproblem._assemble_sparse_jacobian is trust_constr.barrier_jacobian
    assert VectorFunction._update_hess is trust_constr.hessian_update
    assert qp_subproblem.box_intersections is trust_constr.box_intersections


def test_the_quasi_newton_hessian_is_scipys_sr1_and_silent_on_an_unchanged_gradient():
    """The same matrix as SciPy's SR1 after every update; where the gradient did not change (a
    rejected step) both keep the matrix, and only SciPy's warns."""
    rng = np.random.default_rng(3)
    ours, theirs = _SR1(), SR1()
    for hessian in (ours, theirs):
        hessian.initialize(4, "hess")
    partly_zero, tiny = rng.normal(size=4) * [1.0, 0.0, 1.0, 0.0], np.full(4, 1e-12)
    for dg in (rng.normal(size=4), partly_zero, tiny, rng.normal(size=4)):
        dx = rng.normal(size=4)
        ours.update(dx, dg)
        theirs.update(dx, dg)
        np.testing.assert_array_equal(ours.get_matrix(), theirs.get_matrix())
    before = ours.get_matrix().copy()
    dx = rng.normal(size=4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ours.update(dx, np.zeros(4))
    with pytest.warns(UserWarning, match="delta_grad == 0.0"):
        theirs.update(dx, np.zeros(4))
    np.testing.assert_array_equal(ours.get_matrix(), before)
    np.testing.assert_array_equal(theirs.get_matrix(), before)


def _jacobians(rng, n_vars=12, n_eq=4, n_ineq=9, density=0.4):
    def random(rows):
        return sparse.csr_array(sparse.random_array((rows, n_vars), density=density, random_state=rng))

    return random(n_eq), random(n_ineq), 10.0 ** rng.uniform(-9, 2, n_ineq)


def _scipy_assembly(n_vars, n_eq, n_ineq):
    subproblem = SimpleNamespace(n_vars=n_vars, n_eq=n_eq, n_ineq=n_ineq)
    return lambda J_eq, J_ineq, s: trust_constr.scipy_barrier_jacobian(subproblem, J_eq, J_ineq, s)


def _stored_otherwise(J, how: str):
    """``J`` with the same rows stored otherwise: each row's entries reversed, or each entry split
    in two duplicates, or its indices as int64."""
    if how == "unsorted":
        indices, data = J.indices.copy(), J.data.copy()
        for start, end in zip(J.indptr[:-1], J.indptr[1:]):
            indices[start:end], data[start:end] = indices[start:end][::-1], data[start:end][::-1]
        return sparse.csr_array((data, indices, J.indptr.copy()), shape=J.shape)
    if how == "duplicates":
        per_row = np.diff(J.indptr)
        indptr = np.concatenate([[0], np.cumsum(2 * per_row)])
        return sparse.csr_array((np.repeat(0.5 * J.data, 2), np.repeat(J.indices, 2), indptr), shape=J.shape)
    J = J.copy()
    J.indices, J.indptr = J.indices.astype(np.int64), J.indptr.astype(np.int64)
    return J


@pytest.mark.parametrize("stored", ["sorted", "unsorted", "duplicates", "int64"])
@pytest.mark.parametrize("n_eq", [4, 0])
def test_the_barrier_jacobian_is_scipys_bit_for_bit_by_puts_after_its_first(n_eq, stored):
    """The first matrix of a structure is SciPy's own; the next ones, of new values, come from
    puts and equal SciPy's in values, indices and index dtype; a new structure, even one with
    the same rows' lengths (the columns moved), is learnt anew."""
    rng = np.random.default_rng(5)
    assemble, scipys = barrier.BarrierJacobian(), _scipy_assembly(12, n_eq, 9)
    first_eq, first_ineq, s = _jacobians(rng, n_eq=n_eq)
    moved = sparse.csr_array(
        (first_ineq.data, (first_ineq.indices + 1) % 12, first_ineq.indptr), shape=first_ineq.shape
    )
    store = (lambda J: _stored_otherwise(J, stored)) if stored != "sorted" else (lambda J: J)
    for J_eq, J_ineq in ((store(first_eq), store(first_ineq)), (store(first_eq), store(moved))):
        for _ in range(3):
            J_eq.data, J_ineq.data = rng.normal(size=J_eq.nnz), rng.normal(size=J_ineq.nnz)
            s = 10.0 ** rng.uniform(-9, 2, s.size)
            ours = assemble(J_eq, J_ineq, s, 12, scipys)
            assert barrier._identical(ours, scipys(J_eq, J_ineq, s))
            assert assemble._places is not None


@pytest.mark.parametrize("first_values", ["random", "all ones"])
def test_a_structure_whose_puts_differ_from_scipys_assembly_stays_scipys(first_values):
    """An assembly that puts each slack first in its row (a SciPy that lays the matrix out
    otherwise) is not learnt, even from a first matrix whose entries are all equal (which
    cannot tell places apart): every matrix is that assembly's."""
    rng = np.random.default_rng(6)
    scipys = _scipy_assembly(12, 4, 9)

    def slack_first(J_eq, J_ineq, s):
        A = scipys(J_eq, J_ineq, s)
        indices, data = A.indices.copy(), A.data.copy()
        for row in range(4, 13):
            start, end = A.indptr[row], A.indptr[row + 1]
            indices[start:end] = np.roll(A.indices[start:end], 1)
            data[start:end] = np.roll(A.data[start:end], 1)
        return sparse.csr_array((data, indices, A.indptr.copy()), shape=A.shape)

    assemble = barrier.BarrierJacobian()
    J_eq, J_ineq, s = _jacobians(rng)
    if first_values == "all ones":
        J_eq.data[:], J_ineq.data[:], s[:] = 1.0, 1.0, 1.0
    for _ in range(3):
        ours = assemble(J_eq, J_ineq, s, 12, slack_first)
        assert barrier._identical(ours, slack_first(J_eq, J_ineq, s))
        J_eq.data, J_ineq.data = rng.normal(size=J_eq.nnz), rng.normal(size=J_ineq.nnz)
    assert assemble._places is None


def _box_cases():
    """Segments against a barrier subproblem's trust box (free variables, slacks bounded below
    at -0.995) and harder boxes: directions with zeros, at a bound, NaN, ties at zero."""
    rng = np.random.default_rng(7)
    n = 40
    lb = np.r_[np.full(8, -np.inf), np.full(n - 8, -0.995)]
    ub = np.full(n, np.inf)
    cases = {}
    for k in range(40):
        scale = 10.0 ** rng.uniform(-3, 1)
        cases[f"random {k}"] = (rng.normal(size=n) * 0.1, rng.normal(size=n) * scale, lb, ub)
    z, d = rng.normal(size=n) * 0.1, rng.normal(size=n)
    two_sided = (-np.abs(rng.normal(size=n)) - 0.2, np.abs(rng.normal(size=n)) + 0.2)
    cases["two-sided box"] = (z, d, *two_sided)
    cases["start outside"] = (z + 3.0, d, *two_sided)
    cases["missing the box"] = (np.full(n, 2.0), np.abs(d), -np.ones(n), np.ones(n))
    still = d.copy()
    still[::5] = 0.0
    cases["some directions zero"] = (z, still, lb, ub)
    cases["zero direction outside"] = (np.where(still == 0.0, -2.0, z), still, lb, ub)
    cases["zero direction"] = (z, np.zeros(n), lb, ub)
    at_bound = z.copy()
    at_bound[9] = lb[9]
    cases["starting at a bound"] = (at_bound, d, lb, ub)
    cases["ending at a bound"] = (z, np.where(np.arange(n) == 9, lb - z, d), lb, ub)
    signed = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    cases["zeros of both signs"] = (np.zeros(n), signed, np.full(n, -0.0), np.zeros(n))
    cases["not a number"] = (np.where(np.arange(n) == 3, np.nan, z), d, lb, ub)
    cases["no finite bound"] = (z, d, np.full(n, -np.inf), ub)
    touch = np.full(n, -np.inf)
    touch[0] = z[0] + 0.5 * d[0]
    cases["touching the box"] = (z, d, touch, np.where(np.isinf(touch), np.inf, touch))
    return cases


BOX_CASES = _box_cases()


@pytest.mark.parametrize("entire_line", [False, True])
@pytest.mark.parametrize("case", sorted(BOX_CASES))
def test_the_box_intersection_is_scipys_bit_for_bit(case, entire_line):
    z, d, lb, ub = BOX_CASES[case]
    ours = boxes.box_intersections(z, d, lb, ub, entire_line)
    theirs = trust_constr.scipy_box_intersections(z, d, lb, ub, entire_line)
    assert [type(x) for x in ours] == [type(x) for x in theirs]
    assert [np.float64(x).tobytes() for x in ours[:2]] == [np.float64(x).tobytes() for x in theirs[:2]]
    assert ours[2] is theirs[2]


@pytest.mark.parametrize(
    "lb, ub",
    [(-1.0, np.inf), (np.full(3, -1.0), np.full(4, np.inf))],
    ids=["scalar bounds", "lengths that differ"],
)
def test_a_box_of_another_shape_is_scipys_to_judge(lb, ub):
    """SciPy's masks raise on bounds that are not the step's shape; so does the fast path."""
    z, d = np.zeros(4), np.array([1.0, -2.0, 0.5, 3.0])
    with pytest.raises(IndexError):
        trust_constr.scipy_box_intersections(z, d, lb, ub)
    with pytest.raises(IndexError):
        boxes.box_intersections(z, d, lb, ub)
