"""Closed-loop check of a plan: can a torque-controlled robot follow it with feedback?

A computed-torque controller runs at a controller rate (1 kHz by default) on the exported robot:
at every tick it measures ``(q, qd)``, commands

``tau = ID(q, qd, a_ref + Kp (q_ref - q) + Kd (qd_ref - qd))``

with the plan's reference of :func:`~modular_robots.plan.trajectory.controller_rate` (``a_ref``
the mean acceleration to the next tick), clips it to the robot's effort limits (the URDF's) and
holds it until the next tick, while the robot's forward dynamics are integrated (RK4, four steps
per tick). Gains: ``Kp = omega^2``, ``Kd = 2 omega`` per joint, a critically damped error with
``omega`` = :data:`NATURAL_FREQUENCY`. The figures say how far the tool strays and how often the
drives saturate; a plan that uses the full effort limits saturates the controller as soon as it
corrects anything, which is what the scenario's ``effort_margin`` is for.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .trajectory import Trajectory, controller_rate

if TYPE_CHECKING:
    from ..robot import RobotModel

__all__ = ["Tracking", "track", "NATURAL_FREQUENCY", "RATE"]

#: The error dynamics' natural frequency [rad/s] (``Kp = 400 s^-2``, ``Kd = 40 s^-1``).
NATURAL_FREQUENCY = 20.0
#: Controller rate [Hz].
RATE = 1000.0


@dataclass(frozen=True)
class Tracking:
    """Figures of a tracked plan: ``tool_error`` [m] at ``tf`` (tracked vs planned tool position),
    ``max_deviation`` [m] the largest such distance over the motion, ``clipped_share`` the share of
    controller ticks where some joint's command was clipped to its effort limit,
    ``velocity_ratio`` the largest ``|qd| / limit`` of the tracked motion; ``rate`` [Hz] and
    ``natural_frequency`` [rad/s] the controller's."""

    tool_error: float
    max_deviation: float
    clipped_share: float
    velocity_ratio: float
    rate: float
    natural_frequency: float


def track(
    robot: RobotModel, trajectory: Trajectory, rate: float = RATE, natural_frequency: float = NATURAL_FREQUENCY
) -> Tracking:
    """Track ``trajectory`` on ``robot`` with the computed-torque controller of the module docstring."""
    reference = controller_rate(trajectory, robot, rate)
    kp, kd = natural_frequency**2, 2.0 * natural_frequency
    limit = robot.effort_limit
    vmax = np.where(robot.velocity_limit > 0, robot.velocity_limit, np.inf)
    nv = robot.nv
    q, qd = reference.q[0].copy(), reference.qd[0].copy()
    h = np.diff(reference.t)
    mean_acc = np.vstack([np.diff(reference.qd, axis=0) / h[:, None], np.zeros(nv)])
    clipped, deviation, velocity_ratio = 0, 0.0, 0.0

    def f(x, tau):
        return np.concatenate([x[nv:], robot.aba(x[:nv], x[nv:], tau)])

    for k in range(len(h)):
        command = mean_acc[k] + kp * (reference.q[k] - q) + kd * (reference.qd[k] - qd)
        tau = robot.rnea(q, qd, command)
        held = np.clip(tau, -limit, limit)
        clipped += bool(np.any(held != tau))
        x = np.concatenate([q, qd])
        step = h[k] / 4.0
        for _ in range(4):
            k1 = f(x, held)
            k2 = f(x + 0.5 * step * k1, held)
            k3 = f(x + 0.5 * step * k2, held)
            k4 = f(x + step * k3, held)
            x = x + step / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        q, qd = x[:nv], x[nv:]
        deviation = max(deviation, float(np.linalg.norm(robot.tool_position(q) - reference.tool[k + 1])))
        velocity_ratio = max(velocity_ratio, float(np.max(np.abs(qd) / vmax)))
    error = float(np.linalg.norm(robot.tool_position(q) - reference.tool[-1]))
    return Tracking(error, deviation, clipped / max(len(h), 1), velocity_ratio, rate, natural_frequency)
