"""Sampling a shooting solution into a plan (:class:`~modular_robots.plan.trajectory.Trajectory`)
under the acceleration contract (SPEC §7, :mod:`modular_robots.plan.trajectory`).

* The inverse transcription's plan *is* such a motion (a parabola per interval), so its rows are
  the integration sub-steps and the contract holds to rounding.
* The forward transcription's acceleration changes continuously within an interval, so its rows
  are dense (at most :data:`FORWARD_ROW_STEP` apart, the sub-steps among them) and each ``qdd_i``
  is the plan's mean acceleration
  to the next row (its velocities re-integrated from each planned node under the interval's
  torque): the rows follow the plan's velocities exactly and its positions to about
  ``|jerk| h^3 / 12`` per row.

The plan's value type and its controller-rate resampling live in :mod:`modular_robots.plan`;
they are re-exported here.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from ..plan.trajectory import MAX_ROWS, Trajectory, controller_rate, joint_trajectory
from ..robot import RobotModel

__all__ = ["Trajectory", "sample_trajectory", "controller_rate", "joint_trajectory", "FORWARD_ROW_STEP", "MAX_ROWS"]

#: Largest time between two rows of a forward-transcription plan [s].
FORWARD_ROW_STEP = 1e-3


def sample_trajectory(problem, y: np.ndarray) -> Trajectory:
    """The plan of the solution ``y`` of ``problem`` (a
    :class:`~modular_robots.ocp.shooting.ShootingProblem`) as acceleration-contract rows, from
    ``t = 0`` to ``t = tf``.

    The rows are chained from the start state, each from the one before, so the contract holds to
    rounding even where the solver left a continuity gap at a node (at most its constraint
    tolerance); the chain ends at the goal within the sum of those gaps.
    """
    robot, tr = problem.robot, problem.transcription
    _, nodes, controls = problem.unpack(y)
    N, S, nv = problem.intervals, problem.substeps, problem.nv
    M, durations = problem.phase_intervals, problem.durations(y)
    h = durations / M
    phase_t = np.concatenate([[0.0], np.cumsum(durations)])
    node_t = np.concatenate([phase_t[k] + h[k] * np.arange(M) for k in range(problem.phases)] + [phase_t[-1:]])
    if tr.velocity_linear_in_time and problem.phases == 1:  # inverse: the controls are the accelerations
        t = np.linspace(0.0, durations[0], N * S + 1)
        qdd = np.vstack([np.repeat(controls, S, axis=0), np.zeros(nv)])
    elif tr.velocity_linear_in_time:
        t = np.concatenate([node_t[m] + h[m // M] * np.arange(S) / S for m in range(N)] + [node_t[-1:]])
        qdd = np.vstack([np.repeat(controls, S, axis=0), np.zeros(nv)])
    else:
        t, qd = _dense_velocities(robot, tr, nodes, controls, node_t, S)
        qdd = np.vstack([np.diff(qd, axis=0) / np.diff(t)[:, None], np.zeros(nv)])
    t, qdd = _with_holds(problem, t, qdd, phase_t)
    q, qd = _chain(t, nodes[0, :nv], nodes[0, nv:], qdd)
    tau = robot.rnea(q, qd, qdd)
    tool = np.array([robot.tool_position(x) for x in q])
    return Trajectory(
        t, q, qd, qdd, tau, tool, robot.velocity_limit, robot.effort_limit, problem.velocity_bound, problem.effort_bound
    )


def _with_holds(problem, t: np.ndarray, qdd: np.ndarray, phase_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows ``t``, ``qdd`` with the route's pauses: at the start, at each via and at the goal
    (all at rest), the robot stands still (``qdd = 0``) for the hold's seconds, and every later
    row is that much later."""
    holds = problem.route.holds
    if not any(holds):
        return t, qdd
    at = list(phase_t)
    nv = qdd.shape[1]
    for when, hold in sorted(zip(at, holds), reverse=True):  # latest first: earlier times stay put
        if hold <= 0.0:
            continue
        i = int(np.argmin(np.abs(t - when)))  # the row at the node
        t = np.concatenate([t[: i + 1], [t[i] + hold], t[i + 1 :] + hold])
        qdd = np.vstack([qdd[:i], np.zeros((1, nv)), qdd[i:]])
    return t, qdd


def _chain(t: np.ndarray, q0: np.ndarray, qd0: np.ndarray, qdd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities at ``t`` of the motion from ``(q0, qd0)`` whose acceleration is
    ``qdd[i]`` on ``[t_i, t_{i+1})``."""
    h = np.diff(t)[:, None]
    dq = np.zeros((len(t), len(q0)))
    dv = np.zeros_like(dq)
    dv[1:] = qdd[:-1] * h
    q, qd = np.empty_like(dq), np.empty_like(dq)
    q[0], qd[0] = q0, qd0
    for i in range(len(t) - 1):
        qd[i + 1] = qd[i] + dv[i + 1]
        q[i + 1] = q[i] + qd[i] * h[i] + 0.5 * qdd[i] * h[i] * h[i]
    return q, qd


def _dense_velocities(
    robot: RobotModel, tr, nodes: np.ndarray, controls: np.ndarray, node_t: np.ndarray, substeps: int
):
    """Row times at most :data:`FORWARD_ROW_STEP` apart, every node (at ``node_t`` [s]) and
    integration sub-step among them (SPEC §7), and the plan's velocities there: each interval
    re-integrated (DOP853) from its planned node under its control law."""
    nv = robot.nv
    times, velocities = [], []
    for m in range(len(controls)):
        h = node_t[m + 1] - node_t[m]
        k = substeps * max(1, math.ceil(h / (substeps * FORWARD_ROW_STEP) - 1e-9))
        local = np.linspace(0.0, h, k + 1)
        rhs = tr.plan_dynamics(robot, nodes[m : m + 1], controls[m : m + 1], np.zeros(1))
        sol = solve_ivp(rhs, (0.0, h), nodes[m], method="DOP853", rtol=1e-12, atol=1e-12, t_eval=local[:-1])
        times.append(node_t[m] + local[:-1])
        velocities.append(sol.y.T[:, nv:] if sol.success else np.full((k, nv), np.nan))
    t = np.concatenate([*times, node_t[-1:]])
    return t, np.vstack([*velocities, nodes[-1, nv:]])
