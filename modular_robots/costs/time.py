"""Minimum time: the motion's duration ``tf`` [s], the paper's cost."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from .base import Bounds, Evaluated, Motion, Problem

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

    def evaluate(self, problem: Problem, tf: float, motion: Motion, derivatives: bool) -> Evaluated:
        grad = None
        if derivatives:
            grad = np.zeros(problem.n_variables)
            grad[0] = 1.0
        return tf / problem.tf_guess, grad

    def hessian(self, problem: Problem) -> Callable[[np.ndarray], sparse.csr_matrix]:
        """Zero: the scaled cost is the first variable."""
        from scipy import sparse  # at solve time: the scenario reader imports this module

        zero = sparse.csr_matrix((problem.n_variables, problem.n_variables))
        return lambda y: zero
