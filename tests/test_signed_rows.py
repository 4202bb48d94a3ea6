"""The inequality Jacobian as signed copies of the rows kept
(:mod:`modular_robots.ocp._scipy.signed_rows`): against the plain sparse products, on
trust-constr's canonical rows of a paper-5kg shooting problem and on rows built to mislead."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from modular_robots.ocp._scipy import projections as projections_module
from modular_robots.ocp._scipy.projections import BarrierKKT
from modular_robots.ocp._scipy.signed_rows import SignedRows

from .test_projections import assert_same_projections, barrier_jacobian, paper_barrier_jacobian


def signed_rows(J: sparse.csr_array) -> SignedRows:
    return SignedRows(J.indptr, J.indices, J.data, J.shape[1])


@pytest.fixture(scope="module")
def paper_rows():
    """The inequality block of a paper-5kg barrier Jacobian: ``[J; -J; I; -I]``."""
    A, ny = paper_barrier_jacobian()
    mi = A.shape[1] - ny
    j_in = sparse.csr_array(A[A.shape[0] - mi :][:, :ny])
    return j_in, ny


def test_the_canonical_rows_pair_up_and_multiply_as_the_whole_matrix(paper_rows):
    j_in, ny = paper_rows
    rows = signed_rows(j_in)
    assert rows.n_kept == j_in.shape[0] // 2  # every row of [J; -J; I; -I] has its negative
    kept = rows.kept(j_in.data)
    rng = np.random.default_rng(0)
    x, g, d = rng.standard_normal(ny), rng.standard_normal(j_in.shape[0]), rng.uniform(0, 1e4, j_in.shape[0])
    assert rows.expand(kept @ x).tobytes() == (j_in @ x).tobytes()  # bit for bit
    plain = j_in.T @ g
    assert np.linalg.norm(kept.T @ rows.gather(g) - plain) <= 1e-14 * np.linalg.norm(plain) * np.sqrt(len(g))
    normal = (j_in.T @ sparse.diags_array(d) @ j_in).toarray()
    ours = (kept.T @ sparse.diags_array(rows.gather_weights(d)) @ kept).toarray()
    assert np.allclose(ours, normal, rtol=1e-13, atol=1e-13 * np.abs(normal).max())


def test_rows_with_the_same_columns_pair_only_with_their_own_negative():
    """Two torque rows of one node share their columns; each pairs with its own negative, an
    equal row is kept twice, and a row that is nearly a negative is kept."""
    a, b = np.array([[1.0, 2.0, 0.0, 3.0]]), np.array([[4.0, -1.0, 0.0, 0.5]])
    J = sparse.csr_array(np.vstack([a, b, a, -b, -a, -a * (1 + 1e-15), -a]))
    rows = signed_rows(J)
    assert rows.source.tolist() == [0, 1, 2, 1, 2, 3, 0]  # later copies pair with the latest kept row
    assert rows.sign.tolist() == [1, 1, 1, -1, -1, 1, -1]
    for x in (np.array([0.3, -1.1, 2.0, 0.7]), np.zeros(4)):  # the zeros: +0.0 on every row, as SciPy's
        assert rows.expand(rows.kept(J.data) @ x).tobytes() == (J @ x).tobytes()


def test_rows_that_stop_being_copies_are_found_again():
    """A factorisation's values decide: where a copy no longer holds, the layout finds the rows
    again, and the projections stay those of the matrix given."""
    A, ny = paper_barrier_jacobian()
    projections_module._last_layout.layout = None
    first = BarrierKKT(A, ny)._rows
    changed = A.copy()
    mi = A.shape[1] - ny
    copy = A.shape[0] - mi + int(np.flatnonzero(first.sign < 0)[0])  # the first negated row, in A
    changed.data[changed.indptr[copy]] *= 1.5
    again = BarrierKKT(changed, ny)._rows
    assert again is not first and again.n_kept == first.n_kept + 1
    assert_same_projections(changed, ny)
    assert_same_projections(A, ny)  # rows found for the changed values serve the first ones too


def test_a_kept_row_that_changes_ends_its_pair():
    """The check compares each copy with its kept row as it is now: the same values reuse the pairs
    found, a kept row changed (not its copy) has them found again."""
    A, ny = paper_barrier_jacobian()
    projections_module._last_layout.layout = None
    first = BarrierKKT(A, ny)._rows
    assert BarrierKKT(A.copy(), ny)._rows is first
    me = A.shape[0] - (A.shape[1] - ny)
    copy = int(np.flatnonzero(first.sign < 0)[0])
    kept = me + int(np.flatnonzero((first.source == first.source[copy]) & (first.sign > 0))[0])
    changed = A.copy()
    changed.data[changed.indptr[kept]] *= 1.5
    assert BarrierKKT(changed, ny)._rows is not first
    assert_same_projections(changed, ny)


def test_a_matrix_of_copies_projects_like_the_dense_qr():
    """Random rows each given with its negative, slacks at both kinds of size."""
    rng = np.random.default_rng(4)
    ny, me = 30, 10
    j_eq = sparse.csr_array(sparse.random_array((me, ny), density=0.3, random_state=rng) + sparse.eye_array(me, ny))
    half = sparse.random_array((40, ny), density=0.2, random_state=rng).toarray()
    j_in = sparse.csr_array(np.vstack([half, -half, np.eye(ny), -np.eye(ny)]))
    s = 10.0 ** rng.uniform(-2.0, 3.0, j_in.shape[0])
    s[rng.choice(j_in.shape[0], 12, replace=False)] = 10.0 ** rng.uniform(-9.0, -2.0, 12)
    A = barrier_jacobian(j_eq, j_in, s)
    assert BarrierKKT(A, ny)._rows.paired
    assert_same_projections(A, ny)
