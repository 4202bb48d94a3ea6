"""The stall test of trust-constr's barrier subproblems (:mod:`modular_robots.ocp._scipy.stall`):
its rule on sequences written by hand; the SQP loop ending a subproblem, or the solve, once a
problem small enough to follow by hand (a circle) is solved; on the paper-5kg candidate that
crawled, the same optimum in fewer iterations; and a real solve ended by a stall (trust-constr's
own ``barrier_tol`` read from its closure), which says so."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import OptimizeResult

from modular_robots.composition import Composition
from modular_robots.feasibility import check_composition
from modular_robots.ocp import solver as solver_module
from modular_robots.ocp._scipy import sqp, trust_constr
from modular_robots.ocp._scipy.stall import STALL_RADIUS, StallTest
from modular_robots.ocp.candidate import composition_problem
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.scenario import load_scenario

from .helpers.paths import PAPER_5KG


class Subproblem:
    """What the stall test reads of SciPy's ``BarrierSubproblem``, and a stopping test that never
    stops (so that only the stall test can end the loop)."""

    def __init__(self, barrier_parameter: float, barrier_tol: float, tolerance: float = 1e-3, xtol: float = 1e-6):
        self.barrier_parameter, self.tolerance, self.xtol = barrier_parameter, tolerance, xtol
        self.terminate = False
        self.calls = 0

        gtol = xtol

        def global_stop_criteria():  # trust-constr's: barrier_tol and gtol are its closure's names
            return barrier_tol, gtol

        self.global_stop_criteria = global_stop_criteria

    def stop_criteria(self, *_):
        self.calls += 1
        return self.calls > 500  # (a loop the stall test never ends fails the test, not hangs it)


def test_a_feasible_subproblem_stalls_when_its_barrier_function_stops_moving():
    test = StallTest(Subproblem(1e-3, 1e-6), iterations=3)
    # Falls of 0.1 an iteration, then none: over 3 iterations back the barrier function must stay
    # within 1e-6 * (1 + |f|) = 2.7e-6.
    seen = [test.stalled(f, 0.0, 1e-3) for f in (2.0, 1.9, 1.8, 1.7, 1.7, 1.7, 1.7 - 1e-7, 1.7 - 2e-7)]
    assert seen == [False, False, False, False, False, False, True, True]
    assert not test.stalled(1.7 - 2e-7, 0.0, STALL_RADIUS)  # still, but with a trust radius not tiny


def test_an_infeasible_moving_or_rising_subproblem_does_not_stall():
    infeasible = StallTest(Subproblem(1e-3, 1e-6, tolerance=1e-3), iterations=2)
    assert not any(infeasible.stalled(1.0, 2e-3, 0.0) for _ in range(10))
    # Feasible now, but not over the whole window: not yet a stall.
    once = StallTest(Subproblem(1e-3, 1e-6, tolerance=1e-3), iterations=2)
    assert [once.stalled(1.0, c, 0.0) for c in (2e-3, 0.0, 0.0, 0.0)] == [False, False, False, True]
    falling = StallTest(Subproblem(1e-3, 1e-6), iterations=2)
    # 3e-6 over two iterations is beyond 1e-6 * (1 + 1): never a stall.
    assert not any(falling.stalled(1.0 - 1.5e-6 * k, 0.0, 0.0) for k in range(10))
    rising = StallTest(Subproblem(1e-3, 1e-6), iterations=2)
    assert not any(rising.stalled(1.0 + 1.5e-6 * k, 0.0, 0.0) for k in range(10))
    assert not any(StallTest(Subproblem(1e-3, 1e-6), iterations=0).stalled(1.0, 0.0, 0.0) for _ in range(10))
    assert not any(StallTest(None).stalled(1.0, 0.0, 0.0) for _ in range(20))


def test_a_stall_ends_the_solve_only_below_the_barrier_tolerance_and_feasible_to_gtol():
    assert not StallTest(Subproblem(1e-3, 1e-6)).ends_solve(0.0)
    assert StallTest(Subproblem(1e-7, 1e-6)).ends_solve(0.0)
    assert not StallTest(Subproblem(1e-7, 1e-6)).ends_solve(2e-6)  # gtol is 1e-6 here
    no_closure = Subproblem(1e-7, 1e-6)
    no_closure.global_stop_criteria = lambda: None
    assert not StallTest(no_closure).ends_solve(0.0)


def circle_loop(subproblem: Subproblem, stall_iterations: int):
    """The loop on ``min x0 s.t. x0^2 + x1^2 = 1`` from ``(0, 1)`` with the Lagrangian's exact
    Hessian ``2 v I``, its stopping test never stopping: only a stall ends it."""

    def fun_and_constr(x):
        return x[0], np.array([x[0] ** 2 + x[1] ** 2 - 1.0])

    def grad_and_jac(x):
        return np.array([1.0, 0.0]), np.array([[2.0 * x[0], 2.0 * x[1]]])

    x0 = np.array([0.0, 1.0])
    g0, A0 = grad_and_jac(x0)
    state = OptimizeResult(status=None)
    x, state = sqp.equality_constrained_sqp(
        fun_and_constr, grad_and_jac, lambda x, v: 2.0 * v[0] * np.eye(2), x0, 0.0, g0, np.zeros(1), A0,
        subproblem.stop_criteria, state, 1.0, 1.0, "QRFactorization", stall_iterations=stall_iterations,
    )  # fmt: skip
    return x, state


def test_the_loop_ends_a_solved_subproblem_on_its_stall_and_the_solve_below_the_barrier_tolerance():
    subproblem = Subproblem(1e-3, 1e-6)
    x, state = circle_loop(subproblem, stall_iterations=5)
    assert np.allclose(x, [-1.0, 0.0], rtol=0, atol=1e-6)  # the minimum, where x0 stops falling
    assert 6 <= subproblem.calls < 60
    assert not subproblem.terminate and state.status is None  # the barrier parameter decreases next
    below = Subproblem(1e-7, 1e-6)
    x, state = circle_loop(below, stall_iterations=5)
    assert np.allclose(x, [-1.0, 0.0], rtol=0, atol=1e-6)
    assert below.terminate and state.status == 2  # SciPy's end by xtol: nothing left to decrease
    assert below.calls == subproblem.calls


@pytest.fixture(scope="module")
def crawling():
    """The paper-5kg candidate (as the peer benchmark solves it: no self-collision) whose barrier
    subproblems crawled: feasible, its cost still to 1e-9, the trust radius falling to xtol."""
    scenario = load_scenario(PAPER_5KG)
    scenario = replace(scenario, task=replace(scenario.task, self_collision=False))
    composition = Composition.from_name("B-J1-L2-J1-L1-J1-L2-J2-L1-E2", scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    return composition_problem(
        composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )


def test_the_stall_test_ends_a_crawl_at_the_same_optimum(monkeypatch, crawling):
    trust_constr.install()
    stalled = ShootingSolver(crawling).solve()
    loop = sqp.equality_constrained_sqp
    monkeypatch.setattr(sqp, "equality_constrained_sqp", lambda *a, **k: loop(*a, **k, stall_iterations=0))
    crawled = ShootingSolver(crawling).solve()
    assert stalled.converged and crawled.converged
    assert stalled.iterations <= crawled.iterations - 50  # its flat stretches took 40-45 iterations each
    # Within the solve's tolerances of the same optimum; no higher than the crawl's beyond them.
    assert stalled.final.tf <= crawled.final.tf * (1 + 1e-4)
    assert abs(stalled.final.tf - crawled.final.tf) <= 1e-3 * crawled.final.tf
    assert stalled.final.constraint_violation <= crawling.settings.constraint_tolerance


def test_a_solve_ended_by_a_stall_says_so(monkeypatch, crawling):
    """With trust-constr's ``barrier_tol`` above the first barrier parameter (``gtol`` unchanged),
    the crawling candidate's first stall, read against trust-constr's own closure, ends the solve:
    SciPy's status for an end by ``xtol``, feasible, with the stall test's reason."""
    trust_constr.install()
    results = []

    def minimize(*args, **kwargs):
        kwargs["options"] = {**kwargs["options"], "barrier_tol": 2e-3}
        results.append(real_minimize(*args, **kwargs))
        return results[-1]

    real_minimize = solver_module.minimize
    monkeypatch.setattr(solver_module, "minimize", minimize)
    ended = ShootingSolver(crawling).solve()
    assert results[-1].status == 2 and results[-1].barrier_parameter == 1e-3
    assert ended.converged and ended.reason.startswith("stalled: feasible")
    assert "barrier parameter 0.001" in ended.reason
    assert ended.final.constraint_violation <= crawling.settings.tolerance  # trust-constr's gtol
