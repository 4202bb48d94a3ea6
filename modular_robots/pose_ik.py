"""Inverse kinematics of a tool pose: position and orientation within tolerances, within joint limits.

Levenberg-Marquardt on the stacked residual ``(p* - p, w e_R)``: ``e_R`` is the rotation vector
that turns the tool onto the asked orientation (:meth:`~modular_robots.orientation.Orientation.error`),
shrunk by half the angle tolerance (a dead zone: any orientation well inside the tolerance is as
good as the asked one, so the position is not traded for an exact angle), ``w`` =
:data:`ROTATION_WEIGHT`. Its Jacobian is Pinocchio's frame Jacobian in base-frame axes, the
angular rows projected normal to the tool's z axis for an ``axis`` orientation (the turn about it
is free). As in :mod:`modular_robots.ik`, joints at a limit that the step would push further out
are frozen for that step, and a run stops when its error stalls.

Tasks that give no orientation use :func:`~modular_robots.ik.solve_position_ik_batch`, whose
lockstep arithmetic this module does not try to match: the runs of one robot are stacked, the
robots are solved one after the other.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from .ik import DEFAULT_TOLERANCE, IKResult
from .orientation import Orientation
from .robot import RobotModel

__all__ = ["PoseProblem", "ROTATION_WEIGHT", "solve_pose_ik", "solve_pose_ik_batch"]

#: How much a radian of orientation error weighs against a metre of position error [m/rad] in
#: the residual (only the path of the iteration depends on it, not what counts as success).
ROTATION_WEIGHT = 0.1

PoseProblem = tuple[RobotModel, np.ndarray, Orientation, np.ndarray]
"""A robot, a tool position [m], an orientation and start configurations ``(S, nq)``."""


def solve_pose_ik(
    robot: RobotModel,
    position: np.ndarray,
    orientation: Orientation,
    seeds: np.ndarray,
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 100,
    stall_iterations: int = 6,
    stall_ratio: float = 0.995,
) -> list[IKResult]:
    """The tool of ``robot`` to ``position`` [m] with ``orientation``, from every row of
    ``seeds`` ``(S, nq)``: one result per row, its ``error`` the position error [m] and its
    ``angle`` the orientation error [rad] of the best configuration the run met (the one with the
    smallest residual). A result succeeds when the position is within ``tolerance`` [m] and the
    angle within the orientation's tolerance."""
    model, data, frame = robot.model, robot.data, robot.tool_frame_id
    low, high = model.lowerPositionLimit, model.upperPositionLimit
    q = np.clip(np.asarray(seeds, dtype=float).reshape(-1, model.nq), low, high)
    count = len(q)
    target = np.asarray(position, dtype=float)
    tolerance_angle = orientation.tolerance
    aim = 0.5 * tolerance_angle
    best_q, best = q.copy(), np.full(count, math.inf)
    best_error, best_angle = np.full(count, math.inf), np.full(count, math.inf)
    since_best = np.zeros(count, dtype=int)
    iterations = np.full(count, max_iterations)
    running = np.arange(count)
    for iteration in range(1, max_iterations + 1):
        jacobians = np.empty((len(running), 6, model.nv))
        residuals = np.empty((len(running), 6))
        errors, angles = np.empty(len(running)), np.empty(len(running))
        for row, run in enumerate(running):
            jacobian = pin.computeFrameJacobian(model, data, q[run], frame, pin.LOCAL_WORLD_ALIGNED).reshape(6, -1)
            pose = data.oMf[frame]
            turn = orientation.error(pose.rotation)
            angles[row] = float(np.linalg.norm(turn))
            shrink = max(0.0, 1.0 - aim / angles[row]) if angles[row] > 0.0 else 0.0
            residuals[row, :3] = target - pose.translation
            residuals[row, 3:] = ROTATION_WEIGHT * shrink * turn
            errors[row] = float(np.linalg.norm(residuals[row, :3]))
            angular = jacobian[3:]
            if orientation.free_about_z():
                z = pose.rotation[:, 2]
                angular = angular - np.outer(z, z @ angular)
            jacobians[row, :3], jacobians[row, 3:] = jacobian[:3], ROTATION_WEIGHT * angular
        norms = np.linalg.norm(residuals, axis=1)
        improved = norms < best[running] * stall_ratio
        since_best[running] = np.where(improved, 0, since_best[running] + 1)
        better = norms < best[running]
        runs = running[better]
        best[runs], best_q[runs] = norms[better], q[runs]
        best_error[runs], best_angle[runs] = errors[better], angles[better]
        reached = (errors <= tolerance) & (angles <= tolerance_angle)
        stop = reached | (since_best[running] >= stall_iterations)
        iterations[running[stop]] = iteration
        keep = ~stop
        if not keep.any():
            break
        running, jacobians, residuals, norms = running[keep], jacobians[keep], residuals[keep], norms[keep]
        q[running] = _step(q[running], low, high, jacobians, residuals, norms)
    return [
        IKResult(
            best_q[run].copy(), float(best_error[run]), int(iterations[run]), float(best_angle[run]), tolerance_angle
        )
        for run in range(count)
    ]


def _step(
    q: np.ndarray, low: np.ndarray, high: np.ndarray, jacobians: np.ndarray, residuals: np.ndarray, norms: np.ndarray
) -> np.ndarray:
    """The next configurations ``(K, nq)``: the damped least-squares step ``J^T (J J^T + w I)^-1 e``
    (``w = |e|^2 / 2 + 1e-4``, as :func:`~modular_robots.ik._lm_steps`) of each run, taken again
    without the joints it would push beyond a limit, then clipped into the limits."""
    damping = (0.5 * norms**2 + 1e-4)[:, None, None] * np.eye(6)
    step = np.zeros_like(q)
    free = np.ones_like(q, dtype=bool)
    for _ in range(2):
        masked = jacobians * free[:, None, :]
        dual = np.linalg.solve(masked @ masked.mT + damping, residuals[:, :, None])
        step = (masked.mT @ dual)[:, :, 0]
        blocked = ((q <= low) & (step < 0.0)) | ((q >= high) & (step > 0.0))
        if not blocked.any():
            break
        free &= ~blocked
    return np.minimum(np.maximum(q + step * free, low), high)


def solve_pose_ik_batch(
    problems: Sequence[PoseProblem],
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 100,
    stall_iterations: int = 6,
    stall_ratio: float = 0.995,
) -> list[list[IKResult]]:
    """:func:`solve_pose_ik` of each ``(robot, position, orientation, seeds)``."""
    return [
        solve_pose_ik(
            robot,
            position,
            orientation,
            seeds,
            tolerance=tolerance,
            max_iterations=max_iterations,
            stall_iterations=stall_iterations,
            stall_ratio=stall_ratio,
        )
        for robot, position, orientation, seeds in problems
    ]
