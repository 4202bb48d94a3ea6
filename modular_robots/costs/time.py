"""Minimum time: the motion's duration ``tf`` [s] (its pauses included), the paper's cost."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from .base import Bounds, Evaluated, Motion, Problem, interval_gradient

if TYPE_CHECKING:
    from scipy import sparse

__all__ = ["Time"]


class Time:
    """The duration of the motion [s]. Its bound: no motion within the velocity bounds is faster
    than its busiest joint moving at its bound all the way
    (:meth:`~modular_robots.robot.RobotModel.travel_time_bound`)."""

    name: ClassVar[str] = "time"
    unit: ClassVar[str] = "s"
    bounded: ClassVar[bool] = True

    def lower_bound(self, robot: Bounds, q_start: np.ndarray, q_goal: np.ndarray, velocity_bound: np.ndarray) -> float:
        return robot.travel_time_bound(q_start, q_goal, velocity_bound)

    def evaluate(self, problem: Problem, tf: np.ndarray, motion: Motion, derivatives: bool) -> Evaluated:
        M = problem.phase_intervals
        cost = (np.sum(tf) / M + problem.hold) / problem.tf_guess
        if not derivatives:
            return cost, None
        local = np.zeros(problem.interval_columns.shape)
        local[:, -1] = 1.0 / M
        return cost, interval_gradient(problem, local)

    def hessian(self, problem: Problem) -> Callable[[np.ndarray], sparse.csr_matrix]:
        """Zero: the scaled cost is linear in the variables."""
        from scipy import sparse  # at solve time: the scenario reader imports this module

        zero = sparse.csr_matrix((problem.n_variables, problem.n_variables))
        return lambda y: zero
