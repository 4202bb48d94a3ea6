"""The ends of a motion as constraints on the tool pose: with ``optimizer.free_ends``, step C
chooses the start and goal configurations itself, anywhere the tool is within the task's
tolerances of the asked pose (step B's IK pair is the first guess).

At each end, with ``p`` and ``R`` the position and rotation of ``tool0`` in the base frame:

* position: ``|p_i - p*_i| <= tol / sqrt(3)`` for each axis ``i`` (a box inside the ball of
  radius ``tol``, whose rows stay independent where ``p = p*``, unlike ``|p - p*|^2 <= tol^2``);
* ``rpy``: ``trace(R*^T R) >= 1 + 2 cos(tol)``, i.e. the angle of the rotation between them is at
  most ``tol``;
* ``axis``: ``z . a >= cos(tol)``, the angle between the tool's z axis and ``a`` at most ``tol``.

Each row's gradient is exact: Pinocchio's frame Jacobian (base-frame axes), its linear rows for
the position and its angular rows ``J_w`` for the orientation (``d trace(R*^T R) = sum_k
trace(R*^T [e_k]x R) J_w,k`` and ``d (z . a) = (z x a) . J_w``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..costs import Cost, DesignCost, WeightedSum
from ..ik import DEFAULT_TOLERANCE
from ..orientation import Orientation
from ..robot import RobotModel
from ..scenario import Task

__all__ = ["ToolEnd", "end_rows", "task_ends", "free_ends_bound"]

_SKEW = np.array([pin.skew(e) for e in np.eye(3)])


@dataclass(frozen=True)
class ToolEnd:
    """What one end asks of the tool: ``position`` [m, base frame] within ``tolerance`` [m], and
    the ``orientation`` (None: free)."""

    position: tuple[float, float, float]
    tolerance: float
    orientation: Orientation | None = None

    @property
    def size(self) -> int:
        """The number of constraint rows."""
        return 3 + (self.orientation is not None)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The rows' lower and upper bounds."""
        half = self.tolerance / math.sqrt(3.0)
        lower, upper = [-half] * 3, [half] * 3
        if self.orientation is not None:
            cosine = math.cos(self.orientation.tolerance)
            lower.append(1.0 + 2.0 * cosine if self.orientation.rpy is not None else cosine)
            upper.append(3.0 if self.orientation.rpy is not None else 1.0)
        return np.array(lower), np.array(upper)


def end_rows(robot: RobotModel, end: ToolEnd, q: np.ndarray, derivatives: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """The rows of ``end`` at configuration ``q`` ``(size,)`` and, if ``derivatives``, their
    Jacobian ``(size, nv)``."""
    model, data, frame = robot.model, robot.data, robot.tool_frame_id
    if derivatives:
        jacobian = pin.computeFrameJacobian(model, data, q, frame, pin.LOCAL_WORLD_ALIGNED).reshape(6, -1)
    else:
        pin.framesForwardKinematics(model, data, q)
    pose = data.oMf[frame]
    values = [pose.translation - np.asarray(end.position)]
    rows = [jacobian[:3]] if derivatives else []
    orientation = end.orientation
    if orientation is not None:
        rotation = pose.rotation
        if orientation.rpy is not None:
            asked = orientation.rotation
            assert asked is not None
            values.append(np.array([np.trace(asked.T @ rotation)]))
            gradient = np.einsum("ij,kjl,li->k", asked.T, _SKEW, rotation)
        else:
            axis = np.asarray(orientation.axis)
            values.append(np.array([rotation[:, 2] @ axis]))
            gradient = np.cross(rotation[:, 2], axis)
        if derivatives:
            rows.append((gradient @ jacobian[3:])[None])
    return np.concatenate(values), (np.vstack(rows) if derivatives else None)


def task_ends(task: Task) -> tuple[ToolEnd, ToolEnd]:
    """The start and goal ``task`` asks of the tool (its position tolerances, else step B's IK
    tolerance)."""
    return (
        ToolEnd(task.start, task.start_tolerance or DEFAULT_TOLERANCE, task.start_orientation),
        ToolEnd(task.goal, task.goal_tolerance or DEFAULT_TOLERANCE, task.goal_orientation),
    )


def free_ends_bound(cost: Cost, robot: RobotModel, ends: tuple[ToolEnd, ToolEnd], velocity_bound: np.ndarray) -> float:
    """A lower bound of ``cost`` with free ends: for the time, the distance the tool must travel
    between the two tolerated positions over the largest speed it can have
    (:meth:`~modular_robots.robot.RobotModel.tool_speed_bound` at ``velocity_bound``) [s]; for a
    cost of the design, its value; for a weighted sum, the sum of its terms' bounds; 0 for another
    cost (step B's configurations bound the joints' travel only when the ends are fixed)."""
    if isinstance(cost, WeightedSum):
        return sum(w * free_ends_bound(c, robot, ends, velocity_bound) for c, w in cost.terms)
    if isinstance(cost, DesignCost):
        return cost.value(robot.design)
    if cost.name != "time":
        return 0.0
    start, goal = ends
    gap = math.dist(start.position, goal.position) - start.tolerance - goal.tolerance
    speed = robot.tool_speed_bound(velocity_bound)
    return max(gap, 0.0) / speed if speed > 0.0 else 0.0
