"""Minimum mechanical energy: the work the drives do, whichever way it flows (CoBRA's
``mechEnergy``)."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from .base import Bounds, Evaluated, Motion, Problem, interval_gradient, trapezoid_weights

__all__ = ["Energy", "POWER_SMOOTHING", "FIRST_SMOOTHING"]

#: The power [W] below which ``|P|`` is rounded off, ``sqrt(P^2 + d^2) - d``: the absolute value
#: has no derivative where the power changes sign (at rest, at every reversal), and the solver
#: needs one. The smoothed integrand is below ``|P|`` by at most this, so the reported energy is
#: below the exact one by at most ``d * tf`` [J].
POWER_SMOOTHING = 0.1
#: The smoothing [W] of the first solve, whose optimum starts the solve at
#: :data:`POWER_SMOOTHING` (a continuation): solved at once at 0.1 W, 2 of 4 improv-pick
#: candidates crawled to the iteration limit; from a 1 W optimum all 4 converged
#: (``docs/design-notes.md``).
FIRST_SMOOTHING = 1.0


class Energy:
    """``integral of |sum_i tau_i v_i| dt`` [J], the drives' torques ``tau`` (link side, rotor
    inertia and joint friction included) times the joint velocities, by the trapezoid rule over
    every interval's sub-steps; the power of all joints is summed before its absolute value is
    taken, as Timor's ``MechanicalEnergy`` (CoBRA) does. ``smoothing`` [W] rounds off ``|P|``
    (:data:`POWER_SMOOTHING`); step C solves at :data:`FIRST_SMOOTHING` first
    (:attr:`continuation`).

    No bound is used before a solve (0): the change of potential energy between the ends bounds
    the exact integral, but not its smoothed quadrature. Without a bound, pruning's gate keeps every
    candidate (a bound below ``gate`` times the best lets nothing but the bound prune it). Its
    Hessian is approximated (SR1)."""

    name: ClassVar[str] = "energy"
    unit: ClassVar[str] = "J"
    bounded: ClassVar[bool] = False

    def __init__(self, smoothing: float = POWER_SMOOTHING):
        self.smoothing = smoothing

    @property
    def continuation(self) -> tuple[Energy, ...]:
        """The smoother costs step C solves first, each from the previous one's optimum."""
        return () if self.smoothing >= FIRST_SMOOTHING else (Energy(FIRST_SMOOTHING),)

    def lower_bound(self, robot: Bounds, q_start: np.ndarray, q_goal: np.ndarray, velocity_bound: np.ndarray) -> float:
        return 0.0

    def evaluate(self, problem: Problem, tf: np.ndarray, motion: Motion, derivatives: bool) -> Evaluated:
        nv = motion.torques.shape[-1]
        weights = trapezoid_weights(problem)
        velocity = motion.states[..., nv:]
        power = np.einsum("mjk,mjk->mj", motion.torques, velocity)
        d = self.smoothing
        root = np.sqrt(power * power + d * d)
        per_interval = (root - d) @ weights
        cost = float(tf @ per_interval) / problem.tf_guess
        if not derivatives:
            return cost, None
        assert motion.torque_sens is not None and motion.state_sens is not None, "propagated without sensitivities"
        slope = power / root  # d|P|_smooth / dP
        d_power = np.einsum("mjk,mjkp->mjp", velocity, motion.torque_sens) + np.einsum(
            "mjk,mjkp->mjp", motion.torques, motion.state_sens[:, :, nv:]
        )
        local = tf[:, None] * np.einsum("j,mj,mjp->mp", weights, slope, d_power)
        local[:, -1] += per_interval
        return cost, interval_gradient(problem, local)

    def hessian(self, problem: Problem) -> None:
        return None
