"""trust-constr's SQP loop with repeated second-order corrections (:mod:`modular_robots.ocp.sqp`):
with one correction it is SciPy's loop iterate for iterate; with the default it takes a path of
its own to the same optimum of a paper-5kg candidate, which passes the dense verification."""

from __future__ import annotations

import pytest

from modular_robots.ocp import sqp, trust_constr
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.ocp.verification import verify

from .test_canonical import paper_problem
from .test_trust_constr import history

LOOP = sqp.equality_constrained_sqp


@pytest.fixture(scope="module")
def problem():
    return paper_problem()


def with_corrections(monkeypatch, max_corrections: int) -> dict:
    """Make solver threads run :data:`LOOP` with ``max_corrections``; count its calls."""
    calls = {"loops": 0}

    def loop(*args, **kwargs):
        calls["loops"] += 1
        return LOOP(*args, **kwargs, max_corrections=max_corrections)

    monkeypatch.setattr(sqp, "equality_constrained_sqp", loop)
    return calls


def with_scipys_loop(monkeypatch) -> None:
    monkeypatch.setattr(trust_constr._interior_point, "equality_constrained_sqp", trust_constr.scipy_sqp_loop)


def test_with_one_correction_the_loop_is_scipys_iterate_for_iterate(monkeypatch, problem):
    calls = with_corrections(monkeypatch, 1)
    ours = history(problem)
    assert calls["loops"] >= 3 and ours[0] > 10  # one loop per barrier parameter: the copy ran
    with_scipys_loop(monkeypatch)
    assert history(problem) == ours


def test_repeated_corrections_reach_the_same_verified_optimum(monkeypatch, problem):
    ours = ShootingSolver(problem).solve()
    repeated = history(problem)
    with_corrections(monkeypatch, 1)
    assert history(problem) != repeated  # a correction past the first was taken on the way
    monkeypatch.undo()
    with_scipys_loop(monkeypatch)
    theirs = ShootingSolver(problem).solve()
    assert ours.converged and theirs.converged
    assert abs(ours.final.tf - theirs.final.tf) <= 1e-3 * theirs.final.tf
    assert verify(problem, ours.final.y).passed


def test_the_loop_is_installed_for_solver_threads():
    assert "SQP loop" in trust_constr.INSTALLED
    assert trust_constr._interior_point.equality_constrained_sqp is trust_constr.sqp_loop
    assert trust_constr.scipy_sqp_loop.__module__.startswith("scipy.")
    assert sqp.MAX_CORRECTIONS == 4 and sqp.CONTRACTION == 0.99  # IPOPT's max_soc and kappa_soc
