"""The solver's complementarity measure (:func:`modular_robots.ocp.solver.complementarity`): a
hand-worked case, and a solve of the rotor's trapezoid (closed-form optimum, ``test_shooting``)
whose final multipliers leave no inactive row with a multiplier of its size."""

from __future__ import annotations

import numpy as np
import pytest

from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.ocp.solver import ShootingSolver, complementarity
from modular_robots.scenario import OptimizerSettings

from .test_shooting import DQ_TRAP, I_ROTOR, TAU_ROTOR, V_TRAP, rotor

INF = np.inf


def test_the_largest_multiplier_times_gap_of_the_two_sided_rows():
    lower = np.array([0.0, 0.0, 0.0, -INF, 0.0, -INF])
    upper = np.array([1.0, 1.0, 0.0, INF, 1.0, 2.0])
    values = np.array([0.25, 1.0, 0.0, 5.0, 1.5, 1.5])
    multipliers = np.array([-2.0, 7.0, 9.0, 3.0, 4.0, 1.0])
    # 0.25 * 2 (nearer its lower bound); at a bound: 0; an equality and a free row: left out;
    # beyond its bound: 0; one-sided: 0.5 * 1
    assert complementarity(values, multipliers, lower, upper) == pytest.approx(0.5)
    assert complementarity(values[1:4], multipliers[1:4], lower[1:4], upper[1:4]) == 0.0


def test_a_converged_solve_reports_complementarity_near_its_barrier_parameter():
    settings = OptimizerSettings(nodes=9, substeps=2)
    problem = ShootingProblem(rotor(I_ROTOR, TAU_ROTOR, V_TRAP), [-0.5], [-0.5 + DQ_TRAP], settings=settings)
    outcome = ShootingSolver(problem).solve()
    assert outcome.status == "optimal"
    assert 0.0 < outcome.complementarity < 1e-4
    early = ShootingSolver(problem, max_iterations=3).solve()
    assert early.complementarity > 10 * outcome.complementarity
