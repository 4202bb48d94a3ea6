"""The cost protocol: what a task minimises, for step C's solver and step D's pruning.

A cost is one file in this package (a class implementing :class:`Cost`) and one line in
:data:`~modular_robots.costs.COSTS`; the scenario's ``task.cost`` names it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from scipy import sparse

__all__ = [
    "Cost",
    "Problem",
    "Motion",
    "Bounds",
    "Evaluated",
    "Design",
    "continuation",
    "trapezoid_weights",
    "interval_gradient",
]

#: The scaled cost and, when asked, its gradient with respect to the scaled variables.
Evaluated = tuple[float, np.ndarray | None]


@dataclass(frozen=True)
class Design:
    """What a robot is made of, for the costs of its design (:mod:`~.design`): the modules' mass
    [kg] (no payload), the number of joints and of modules, and the sum of the modules' catalogue
    prices (None when a module has none)."""

    mass: float
    joints: int
    modules: int
    price: float | None = None


class Problem(Protocol):
    """What a cost reads of the shooting problem (:class:`~modular_robots.ocp.ShootingProblem`).

    Variables are scaled; a cost's value is in units of ``tf_guess`` seconds (its value in SI is
    the scaled value times ``tf_guess``). A motion through several goals has phases, each of
    ``phase_intervals`` intervals and its own duration (a single move is one phase); the robot
    also stands still for ``hold`` seconds in pauses.
    """

    intervals: int
    phase_intervals: int
    hold: float
    substeps: int
    n_variables: int
    tf_guess: float
    variable_scale: np.ndarray
    tau_scale: np.ndarray
    #: The robot's design (None for a robot read from a URDF alone).
    design: Design | None

    @property
    def interval_columns(self) -> np.ndarray:
        """``(N, p)``: the scaled variable of each of interval ``m``'s parameters ``(s_m, u_m,
        tf)`` (``tf`` its phase's duration), -1 where the parameter is fixed (the start state)."""
        ...


class Motion(Protocol):
    """The propagated motion: states ``(N, S + 1, 2 nv)`` (positions then velocities [rad | m,
    rad/s | m/s]) and torques ``(N, S + 1, nv)`` [N m | N] at the sub-step points of each interval
    and, when derivatives are asked, their sensitivities ``(N, S + 1, 2 nv, p)`` and ``(N, S + 1,
    nv, p)`` to the interval's parameters."""

    @property
    def states(self) -> np.ndarray: ...

    @property
    def state_sens(self) -> np.ndarray | None: ...

    @property
    def torques(self) -> np.ndarray: ...

    @property
    def torque_sens(self) -> np.ndarray | None: ...


class Bounds(Protocol):
    """What a cost's lower bound reads of the robot (:class:`~modular_robots.robot.RobotModel`)."""

    #: The robot's design (None for a robot read from a URDF alone).
    design: Design | None

    def travel_time_bound(self, q_a: np.ndarray, q_b: np.ndarray, velocity: np.ndarray | None = None) -> float: ...


@runtime_checkable
class Cost(Protocol):
    """A cost of a point-to-point motion, at rest at both ends.

    A cost may also have a ``continuation`` attribute: the smoother costs step C solves first
    (:func:`continuation`), e.g. the energy with a rounder absolute value."""

    @property
    def name(self) -> str:
        """The cost's name in a scenario's ``task.cost`` and in ``result.json``."""
        ...

    @property
    def bounded(self) -> bool:
        """False when :meth:`lower_bound` is 0 for every move: step D then needs no robot model to
        bound a candidate before its solve."""
        ...

    def lower_bound(self, robot: Bounds, q_start: np.ndarray, q_goal: np.ndarray, velocity_bound: np.ndarray) -> float:
        """A valid lower bound [SI] on the optimal cost of the move from ``q_start`` to ``q_goal``
        within the joint velocity bounds ``velocity_bound``, known before any solve: step D drops a
        candidate whose bound exceeds a verified cost. 0 where no better bound is known."""
        ...

    def evaluate(self, problem: Problem, tf: np.ndarray, motion: Motion, derivatives: bool) -> Evaluated:
        """The scaled cost of a motion whose interval ``m`` lasts ``tf[m] / phase_intervals``
        [s] (``tf`` ``(N,)``, each interval's phase's duration) and, if ``derivatives``, its
        gradient ``(n_variables,)`` with respect to the scaled variables."""
        ...

    def hessian(self, problem: Problem) -> Callable[[np.ndarray], sparse.csr_matrix] | None:
        """The exact Hessian of the scaled cost, as a function of the scaled variables, or None:
        the solver then approximates it (SR1)."""
        ...


def continuation(cost: Cost) -> tuple[Cost, ...]:
    """The smoother costs step C solves before ``cost``, smoothest first, each solve starting from
    the previous one's optimum: a cost's optional ``continuation`` attribute (none: ``()``)."""
    return tuple(getattr(cost, "continuation", ()))


def trapezoid_weights(problem: Problem) -> np.ndarray:
    """``(S + 1,)``: the trapezoid rule's weights of an interval's sub-step points, in normalised
    time (a point's ``dt`` is its phase's duration times its weight; they sum to ``1 /
    phase_intervals``)."""
    M, S = problem.phase_intervals, problem.substeps
    weights = np.full(S + 1, 1.0 / (M * S))
    weights[[0, -1]] *= 0.5
    return weights


def interval_gradient(problem: Problem, local: np.ndarray) -> np.ndarray:
    """The gradient ``(n_variables,)`` of a scaled cost [in ``tf_guess`` units] from its
    derivatives ``(N, p)`` [SI] with respect to each interval's parameters ``(s_m, u_m, tf)``."""
    grad = np.zeros(problem.n_variables)
    cols = problem.interval_columns
    mask = cols >= 0
    np.add.at(grad, cols[mask], local[mask])
    grad *= problem.variable_scale / problem.tf_guess
    return grad
