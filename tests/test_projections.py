"""trust-constr's projections computed from the barrier structure
(:mod:`modular_robots.ocp._scipy.projections`) against SciPy's own general sparse path and a dense QR,
on random matrices and on the barrier Jacobian of a real paper-5kg shooting problem, with slacks
from 1e-9 (a row at its bound near convergence) to 1e3 (a far bound)."""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg
from scipy import sparse
from scipy.optimize._trustregion_constr import equality_constrained_sqp
from scipy.optimize._trustregion_constr.projections import projections as scipy_projections

from modular_robots.composition import Composition
from modular_robots.feasibility import check_composition
from modular_robots.ocp._scipy import projections as projections_module
from modular_robots.ocp._scipy import trust_constr
from modular_robots.ocp._scipy.products import MatVec, rmatvec
from modular_robots.ocp._scipy.projections import SLACK_THRESHOLD, BarrierKKT, barrier_projections
from modular_robots.ocp.candidate import composition_problem
from modular_robots.scenario import load_scenario

from .helpers.paths import PAPER_5KG


@pytest.fixture(autouse=True, scope="module")
def installed():
    """The replacements in place, as a solver puts them before its first solve."""
    return trust_constr.install()


def barrier_jacobian(j_eq, j_ineq, slacks) -> sparse.csr_array:
    """``[[J_eq, 0], [J_ineq, diag(s)]]`` as trust-constr assembles it."""
    zeros = sparse.csr_array((j_eq.shape[0], len(slacks)))
    return sparse.csr_array(sparse.block_array([[j_eq, zeros], [j_ineq, sparse.diags_array(slacks)]]))


def slacks(rng, count: int, active: int) -> np.ndarray:
    """Slacks of an interior point iterate: ``active`` rows near their bound (1e-9 .. 1e-2,
    fewer than the variables, as in a nondegenerate problem), the others 1e-2 .. 1e3."""
    s = 10.0 ** rng.uniform(-2.0, 3.0, count)
    s[rng.choice(count, active, replace=False)] = 10.0 ** rng.uniform(-9.0, -2.0, active)
    return s


def random_case(seed: int, ny: int = 30, me: int = 12, mi: int = 90):
    rng = np.random.default_rng(seed)
    j_eq = sparse.random_array((me, ny), density=0.3, random_state=rng) + sparse.eye_array(me, ny)
    j_in = sparse.random_array((mi, ny), density=0.15, random_state=rng)
    return barrier_jacobian(sparse.csr_array(j_eq), sparse.csr_array(j_in), slacks(rng, mi, ny - me - 4)), ny


def paper_barrier_jacobian(nodes: int = 8):
    """A paper-5kg candidate's constraint Jacobian, as trust-constr's canonical form has it:
    continuity rows as equalities, every two-sided row and variable bound twice (``+`` and ``-``)."""
    scenario = load_scenario(PAPER_5KG)
    scenario = replace(scenario, optimizer=replace(scenario.optimizer, nodes=nodes))
    composition = Composition.from_name("B-J1-L3-J1-L2-J1-L3-J2-L2-E1", scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    problem = composition_problem(
        composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )
    jac = problem.evaluate(problem.initial_guess()).jacobian
    equal = problem.constraint_lower == problem.constraint_upper
    j_eq, j_rows = jac[np.flatnonzero(equal)], jac[np.flatnonzero(~equal)]
    eye = sparse.eye_array(problem.n_variables, format="csr")
    j_in = sparse.csr_array(sparse.vstack([j_rows, -j_rows, eye, -eye]))
    active = problem.n_variables - j_eq.shape[0] - 4
    return barrier_jacobian(j_eq, j_in, slacks(np.random.default_rng(7), j_in.shape[0], active)), problem.n_variables


@pytest.fixture(scope="module")
def paper_case():
    return paper_barrier_jacobian()


def assert_same_projections(A, ny, seed=0, tol=1e-9):
    """Ours equal the dense QR of ``A^T`` (``A^T = Q R``: ``Z = I - Q Q^T``, ``Y = Q R^-T``,
    ``LS = R^-1 Q^T``), and so does SciPy's path, less closely: on the paper case (condition number
    4e9) its unrefined multipliers ``LS`` are 2e-9 off, ours 3e-11."""
    m, n = A.shape
    q, r = scipy.linalg.qr(A.toarray().T, mode="economic")
    rng = np.random.default_rng(seed)
    x, y = rng.standard_normal(n), rng.standard_normal(m)
    qr = (
        x - q @ (q.T @ x),
        scipy.linalg.solve_triangular(r, q.T @ x),
        q @ scipy.linalg.solve_triangular(r, y, trans="T"),
    )
    ours, theirs = barrier_projections(A, ny), scipy_projections(A)
    for name, a, b, v, expected in zip(("Z", "LS", "Y"), ours, theirs, (x, x, y), qr):
        scale = np.linalg.norm(expected)
        assert np.linalg.norm(a @ v - expected) <= tol * scale, name
        assert np.linalg.norm(b @ v - expected) <= 10 * tol * scale, name  # the references agree


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_barrier_matrices_project_like_scipy(seed):
    A, ny = random_case(seed)
    assert_same_projections(A, ny, seed)


def test_paper_problem_projects_like_scipy(paper_case):
    A, ny = paper_case
    kkt = BarrierKKT(A, ny)
    small = int(np.sum(kkt.s < SLACK_THRESHOLD))
    assert 0 < small < len(kkt.s)  # both kinds of row are exercised
    assert kkt.size == ny + (A.shape[0] - len(kkt.s)) + small
    assert_same_projections(A, ny)


def test_a_matrix_without_the_barrier_structure_is_refused():
    A, ny = random_case(3)
    with pytest.raises(ValueError, match="slack columns are not one diagonal block under the equality rows"):
        BarrierKKT(A, ny - 1)  # a variable column taken for a slack one
    twice = sparse.csr_array(np.array([[1.0, 2.0, 0.0, 0.0], [1.0, 2.0, 0.0, 0.0]]))  # one row, twice
    j_in = sparse.csr_array(np.array([[0.0, 1.0, 1.0, 0.0], [0.0, 0.0, 1.0, 1.0]]))
    singular = barrier_jacobian(twice, j_in, np.array([1.0, 1e-3]))
    with pytest.raises(ValueError, match="singular"):
        BarrierKKT(singular, 4)


@pytest.mark.filterwarnings("ignore:Singular Jacobian matrix")  # SciPy's path, on its way to raising
def test_a_non_finite_matrix_is_refused_so_that_scipy_reports_it():
    """SciPy's path raises on a NaN Jacobian and trust-constr stops at once; ours must not hand
    trust-constr NaN projections instead (it would run to its iteration limit)."""
    A, ny = random_case(5)
    A.data[3] = np.nan
    with pytest.raises(ValueError, match="A has non-finite entries"):
        BarrierKKT(A, ny)
    seen = {}

    def in_solver_thread():
        trust_constr.mark_solver_thread(ny)
        try:
            trust_constr.projections(A)
        except ValueError as error:
            seen["error"] = str(error)

    thread = threading.Thread(target=in_solver_thread)
    thread.start()
    thread.join()
    assert seen["error"] == "array must not contain infs or NaNs"


def test_a_refinement_that_does_not_help_is_dropped():
    """Two inequality rows that are nearly each other's negative, both slacks at 1e-8: the reduced
    system is conditioned like 1/s^2 and refinement makes the residual grow. The solve returns the
    best of its iterates, never worse than the unrefined one."""
    rng = np.random.default_rng(0)
    ny, me = 8, 2
    j_eq = sparse.csr_array(sparse.random_array((me, ny), density=0.5, random_state=rng) + sparse.eye_array(me, ny))
    j_in = sparse.random_array((5, ny), density=0.4, random_state=rng).toarray()
    paired = sparse.csr_array(np.vstack([j_in, -j_in * (1 + 1e-9)]))
    A = barrier_jacobian(j_eq, paired, np.r_[np.full(5, 1e-8), np.random.default_rng(1).uniform(0.5, 2, 5) * 1e-8])
    kkt = BarrierKKT(A, ny)
    m, n = A.shape
    r, t = np.random.default_rng(3).standard_normal(n), np.zeros(m)

    def residual(z, w):
        return np.linalg.norm(r - z - A.T @ w) + np.linalg.norm(t - A @ z)

    unrefined = residual(*kkt._solve_once(r, t)[:2])
    assert residual(*kkt.solve(r, t)) <= unrefined


def test_trust_constr_gets_them_only_in_a_solver_thread():
    """In a solver's thread ``projections`` is the structured one where ``A`` has the structure,
    SciPy's elsewhere; outside, SciPy's for every matrix."""
    assert equality_constrained_sqp.projections is trust_constr.projections
    A, ny = random_case(4)
    plain = sparse.csr_array(np.random.default_rng(4).standard_normal((5, 9)))
    x = np.random.default_rng(5).standard_normal(A.shape[1])
    seen = {}

    def in_solver_thread():
        trust_constr.mark_solver_thread(ny)
        seen["structured"] = trust_constr.projections(A)[0] @ x
        seen["plain"] = trust_constr.projections(plain)[0] @ np.ones(9)

    thread = threading.Thread(target=in_solver_thread)
    thread.start()
    thread.join()
    reference = scipy_projections(A)[0] @ x
    assert np.allclose(seen["structured"], reference, rtol=0, atol=1e-10)
    assert np.allclose(seen["plain"], scipy_projections(plain)[0] @ np.ones(9), rtol=0, atol=1e-12)
    assert not trust_constr.in_solver_thread()


def split_entries(A: sparse.csr_array) -> sparse.csr_array:
    """``A`` with every entry stored as two halves (duplicates)."""
    half = 0.5 * A.data
    data = np.column_stack([half, A.data - half]).ravel()
    return sparse.csr_array((data, np.repeat(A.indices, 2), 2 * A.indptr), shape=A.shape)


def reversed_rows(A: sparse.csr_array) -> sparse.csr_array:
    """``A`` with the indices of every row stored in reverse order."""
    order = np.concatenate([np.arange(A.indptr[r + 1] - 1, A.indptr[r] - 1, -1) for r in range(A.shape[0])])
    reordered = sparse.csr_array((A.data[order], A.indices[order], A.indptr.copy()), shape=A.shape)
    reordered.has_sorted_indices = False
    return reordered


@pytest.mark.parametrize("stored", [split_entries, reversed_rows])
def test_duplicates_and_unsorted_rows_are_solved_as_the_matrix_they_sum_to(stored):
    A, ny = random_case(6)
    given = stored(A)
    arrays = [given.data.copy(), given.indices.copy(), given.indptr.copy()]
    rng = np.random.default_rng(7)
    r, t = rng.standard_normal(A.shape[1]), rng.standard_normal(A.shape[0])
    z, w = BarrierKKT(given, ny).solve(r, t)
    z_ref, w_ref = BarrierKKT(A, ny).solve(r, t)
    assert np.allclose(z, z_ref, rtol=0, atol=1e-10) and np.allclose(w, w_ref, rtol=0, atol=1e-10)
    assert all(np.array_equal(a, b) for a, b in zip(arrays, [given.data, given.indices, given.indptr], strict=True))


def test_one_structures_layout_serves_other_values_but_no_other_shape():
    A, ny = random_case(7)
    rng = np.random.default_rng(8)
    B = A.copy()
    B.data = B.data * rng.uniform(0.5, 2.0, B.nnz)
    r, t = rng.standard_normal(A.shape[1]), rng.standard_normal(A.shape[0])
    BarrierKKT(A, ny)
    reused = BarrierKKT(B, ny).solve(r, t)
    projections_module._last_layout.layout = None
    fresh = BarrierKKT(B, ny).solve(r, t)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(reused, fresh, strict=True))
    wider = sparse.csr_array((B.data, B.indices, B.indptr), shape=(B.shape[0], B.shape[1] + 1))
    with pytest.raises(ValueError, match="slack columns are not one diagonal block"):
        BarrierKKT(wider, ny)


@pytest.mark.parametrize("transpose", [False, True], ids=["M", "M.T"])
@pytest.mark.parametrize("layout", ["csr", "csc"])
def test_the_products_skip_only_scipys_checks(layout, transpose):
    """The solves' sparse products call SciPy's kernel directly: the product ``M @ x`` (and
    ``M.T @ x``, without building ``M.T``) is SciPy's bit for bit, on a barrier Jacobian in either
    format, on a strided vector too."""
    A, _ = random_case(9)
    matrix = A if layout == "csr" else A.tocsc()
    reference = matrix.T if transpose else matrix
    product = MatVec(matrix, transpose=transpose)
    # this SciPy has the kernel, and the vectors below fit it: the fast path is the one tested
    assert product.kernel is not None and (product.rows, product.columns) == reference.shape
    rng = np.random.default_rng(10)
    wide = rng.standard_normal(2 * reference.shape[1])
    for x in (wide[: reference.shape[1]], wide[::2]):
        assert product(x).tobytes() == reference.dot(x).tobytes()
        if transpose:
            assert rmatvec(matrix, x).tobytes() == reference.dot(x).tobytes()
    with pytest.raises(ValueError, match="dimension mismatch"):  # SciPy's own check, not a read past the end
        product(wide)
