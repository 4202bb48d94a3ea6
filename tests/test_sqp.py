"""trust-constr's SQP loop with repeated second-order corrections (:mod:`modular_robots.ocp._scipy.sqp`):
with one correction it is SciPy's loop iterate for iterate; the corrections of one step, on a
problem small enough to follow by hand (a circle), land where the hand says and stop where the
rule says; and on a paper-5kg candidate the loop takes a path of its own to the same optimum,
which passes the dense verification."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from scipy.optimize._trustregion_constr import tr_interior_point

from modular_robots.ocp._scipy import sqp, trust_constr
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.ocp.verification import verify

from .helpers.problems import history, paper_problem

LOOP = sqp.equality_constrained_sqp


@pytest.fixture(autouse=True, scope="module")
def installed():
    """The replacements in place, as a solver puts them before its first solve."""
    return trust_constr.install()


@pytest.fixture(scope="module")
def problem():
    return paper_problem()


#: The loop's parameters at which it is SciPy's.
SCIPYS = {"max_corrections": 1, "stall_iterations": 0}


def with_settings(monkeypatch, **settings) -> dict:
    """Make solver threads run :data:`LOOP` with ``settings``; count its calls."""
    calls = {"loops": 0}

    def loop(*args, **kwargs):
        calls["loops"] += 1
        return LOOP(*args, **kwargs, **settings)

    monkeypatch.setattr(sqp, "equality_constrained_sqp", loop)
    return calls


def with_scipys_loop(monkeypatch) -> None:
    monkeypatch.setattr(tr_interior_point, "equality_constrained_sqp", trust_constr.scipy_sqp_loop)


def test_with_scipys_settings_the_loop_is_scipys_iterate_for_iterate(monkeypatch, problem):
    calls = with_settings(monkeypatch, **SCIPYS)
    ours = history(problem)
    assert calls["loops"] >= 3 and ours[0] > 10  # one loop per barrier parameter: the copy ran
    with_scipys_loop(monkeypatch)
    assert history(problem) == ours


def test_repeated_corrections_reach_the_same_verified_optimum(monkeypatch, problem):
    ours = ShootingSolver(problem).solve()
    repeated = history(problem)
    with_settings(monkeypatch, max_corrections=1)
    assert history(problem) != repeated  # a correction past the first was taken on the way
    monkeypatch.undo()
    with_scipys_loop(monkeypatch)
    theirs = ShootingSolver(problem).solve()
    assert ours.converged and theirs.converged
    assert abs(ours.final.tf - theirs.final.tf) <= 1e-3 * theirs.final.tf
    assert verify(problem, ours.final.y).passed


def test_the_loop_is_installed_for_solver_threads(installed):
    assert "SQP loop" in installed
    assert tr_interior_point.equality_constrained_sqp is trust_constr.sqp_loop
    assert trust_constr.scipy_sqp_loop.__module__.startswith("scipy.")
    assert sqp.MAX_CORRECTIONS == 4 and sqp.CONTRACTION == 0.99  # IPOPT's max_soc and kappa_soc


def one_iteration(radius: float, penalty: float, max_corrections: int):
    """One iteration of the loop on ``min x0 s.t. x0^2 + x1^2 = 1`` from ``(0, 1)`` with a zero
    Hessian: the step runs along the tangent to the trust radius, ``(-radius, 0)``, and each
    correction moves ``x1`` by ``-c / 2`` (the least-norm solution of the Jacobian ``(0, 2)`` at
    the start). Returns the points evaluated and the iterate after the iteration."""
    points, seen = [], {}

    def fun_and_constr(x):
        points.append(np.array(x))
        return x[0], np.array([x[0] ** 2 + x[1] ** 2 - 1.0])

    def grad_and_jac(x):
        return np.array([1.0, 0.0]), np.array([[2.0 * x[0], 2.0 * x[1]]])

    def stop_criteria(state, x, failed, *_):
        seen["calls"] = seen.get("calls", 0) + 1
        seen["x"], seen["failed"] = np.array(x), failed
        return seen["calls"] > 1

    x0 = np.array([0.0, 1.0])
    g0, A0 = grad_and_jac(x0)
    LOOP(
        fun_and_constr, grad_and_jac, lambda x, v: np.zeros((2, 2)), x0, 0.0, g0, np.zeros(1), A0,
        stop_criteria, None, penalty, radius, "QRFactorization", max_corrections=max_corrections,
    )  # fmt: skip
    return points, seen["x"], seen["failed"]


def test_a_second_correction_makes_a_refused_step_acceptable():
    """Merit ``x0 + 10 |c|``: the step to ``(-0.8, 1)`` (c = 0.64) and its first correction to
    ``(-0.8, 0.68)`` (c = 0.1024, merit 0.224) are refused; the second, to ``(-0.8, 0.6288)``
    (merit -0.446), is taken. SciPy's single correction refuses the step."""
    points, x, failed = one_iteration(0.8, 10.0, max_corrections=4)
    assert np.allclose(points, [[-0.8, 1.0], [-0.8, 0.68], [-0.8, 0.6288]], rtol=0, atol=1e-12)
    assert not failed and np.allclose(x, [-0.8, 0.6288], rtol=0, atol=1e-12)
    points, x, failed = one_iteration(0.8, 10.0, max_corrections=1)
    assert len(points) == 2 and failed and np.array_equal(x, [0.0, 1.0])


def test_corrections_stop_when_the_violation_stops_shrinking_or_at_the_cap():
    # At x0 = -1.5 no x1 meets the circle: c = 2.25, then 1.27, then 1.82 > 0.99 * 1.27: stop.
    points, _, failed = one_iteration(1.5, 10.0, max_corrections=4)
    assert failed and len(points) == 3
    # A penalty no correction can pay for: every one shrinks c, the cap ends them (1 + 4 points).
    points, _, failed = one_iteration(0.8, 1e6, max_corrections=4)
    assert failed and len(points) == 5
    assert np.all(np.diff([p[0] ** 2 + p[1] ** 2 - 1.0 for p in points]) < 0)


def test_outside_a_solver_thread_the_loop_is_scipys(monkeypatch):
    monkeypatch.setattr(trust_constr, "scipy_sqp_loop", lambda *args, **kwargs: "scipy's")
    monkeypatch.setattr(sqp, "equality_constrained_sqp", lambda *args, **kwargs: "ours")
    assert trust_constr.sqp_loop(1, 2, factorization_method=None) == "scipy's"
    seen = {}

    def in_solver_thread():
        trust_constr.mark_solver_thread(2)
        seen["loop"] = trust_constr.sqp_loop(1, 2, factorization_method=None)

    thread = threading.Thread(target=in_solver_thread)
    thread.start()
    thread.join()
    assert seen["loop"] == "ours"
