"""Minimum effort: the integral of the squared torques, each relative to its joint's limit."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from .base import Bounds, Evaluated, Motion, Problem, interval_gradient, trapezoid_weights

__all__ = ["Effort"]


class Effort:
    """``integral of sum_i (tau_i / tau_max,i)^2 dt`` [s], by the trapezoid rule over every
    interval's sub-steps. No bound is known before a solve (0): pruning's gate then keeps every
    candidate to its end. Its
    Hessian is approximated (SR1)."""

    name: ClassVar[str] = "effort"
    unit: ClassVar[str] = "s"
    bounded: ClassVar[bool] = False

    def lower_bound(self, robot: Bounds, q_start: np.ndarray, q_goal: np.ndarray, velocity_bound: np.ndarray) -> float:
        return 0.0

    def evaluate(self, problem: Problem, tf: np.ndarray, motion: Motion, derivatives: bool) -> Evaluated:
        weights = trapezoid_weights(problem)
        ratio = motion.torques / problem.tau_scale
        per_interval = np.einsum("j,mjk->m", weights, ratio**2)
        cost = float(tf @ per_interval) / problem.tf_guess
        if not derivatives:
            return cost, None
        assert motion.torque_sens is not None, "the motion was propagated without sensitivities"
        local = 2.0 * tf[:, None] * np.einsum("j,mjk,mjkp->mp", weights, ratio / problem.tau_scale, motion.torque_sens)
        local[:, -1] += per_interval
        return cost, interval_gradient(problem, local)

    def hessian(self, problem: Problem) -> None:
        return None
