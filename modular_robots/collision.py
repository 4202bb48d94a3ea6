"""Distances between a robot's collision primitives and sphere obstacles, with python-fcl.

Robot primitives are FCL capsules (links) and spheres (ports, payload); obstacles are FCL
spheres. Distances are signed: negative when the shapes overlap (penetration depth).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import fcl
import numpy as np
import pinocchio as pin

from .robot import RobotModel

__all__ = ["SphereObstacle", "CollisionModel", "Distances", "PATH_CLEARANCE"]

#: Clearance a joint-space path must keep from every obstacle to count as clear [m] (step C's
#: initial guess).
PATH_CLEARANCE = 0.02
#: Below this distance between two sphere centres [m], python-fcl 0.7's signed distance query
#: does not return (measured: 1e-4 m hangs, 1e-3 m answers), so the distance is computed here.
CONCENTRIC = 1e-3


@dataclass(frozen=True)
class SphereObstacle:
    """A sphere obstacle: ``center`` in the base frame [m], ``radius`` [m]."""

    center: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class Distances:
    """Signed distances ``(n_primitives, n_obstacles)`` and the witness points on the robot and
    on the obstacle, each ``(n_primitives, n_obstacles, 3)``, in the base frame."""

    distance: np.ndarray
    robot_points: np.ndarray
    obstacle_points: np.ndarray

    @property
    def minimum(self) -> float:
        return float(self.distance.min()) if self.distance.size else float("inf")


class CollisionModel:
    """FCL shapes of one robot's primitives and of the obstacles around it.

    ``primitives`` selects which of the robot's primitives take part (indices into
    ``robot.primitives``; default all of them).
    """

    def __init__(self, robot: RobotModel, obstacles: Sequence[SphereObstacle],
                 primitives: Sequence[int] | None = None):
        self.robot = robot
        self.obstacles = tuple(obstacles)
        self.primitive_indices = tuple(range(len(robot.primitives)) if primitives is None else primitives)
        self._primitives = [robot.primitives[i] for i in self.primitive_indices]
        self._frame_ids = [int(robot.model.getFrameId(p.frame)) for p in self._primitives]
        self._robot_objects = [
            fcl.CollisionObject(fcl.Capsule(p.radius, p.length) if p.length > 0 else fcl.Sphere(p.radius))
            for p in self._primitives
        ]
        self._prim_radii = np.array([p.radius for p in self._primitives], dtype=float)
        self._prim_lengths = np.array([p.length for p in self._primitives], dtype=float)
        self._centers = np.array([o.center for o in self.obstacles], dtype=float).reshape(-1, 3)
        self._radii = np.array([o.radius for o in self.obstacles], dtype=float)
        self._obstacle_objects = [
            fcl.CollisionObject(fcl.Sphere(o.radius), fcl.Transform(np.asarray(o.center, dtype=float)))
            for o in self.obstacles
        ]

    def _axes(self, q: np.ndarray, kinematics_done: bool = False):
        return self.robot.primitive_axes(None if kinematics_done else q, self.primitive_indices)

    def _place_one(self, i: int, rot, mid) -> None:
        self._robot_objects[i].setTransform(fcl.Transform(rot[i], mid[i]))

    def distances(self, q: np.ndarray) -> Distances:
        """Signed distance of every (primitive, obstacle) pair at configuration ``q``."""
        rot, a, b = self._axes(q)
        mid = 0.5 * (a + b)
        for i in range(len(self._robot_objects)):
            self._place_one(i, rot, mid)
        shape = (len(self._robot_objects), len(self._obstacle_objects))
        dist = np.empty(shape)
        on_robot = np.empty(shape + (3,))
        on_obstacle = np.empty(shape + (3,))
        to_mid = np.linalg.norm(self._centers[None, :, :] - mid[:, None, :], axis=2)
        for i in range(len(self._robot_objects)):
            for j in range(len(self._obstacle_objects)):
                dist[i, j], on_robot[i, j], on_obstacle[i, j] = self._pair_distance(i, j, mid[i], to_mid[i, j])
        return Distances(dist, on_robot, on_obstacle)

    def _pair_distance(self, i: int, j: int, center: np.ndarray,
                       apart: float) -> tuple[float, np.ndarray, np.ndarray]:
        """Signed distance and witness points of placed primitive ``i`` (centred at ``center``,
        ``apart`` [m] from the obstacle's centre) and obstacle ``j``: FCL's, except for nearly
        concentric spheres (see :data:`CONCENTRIC`)."""
        if apart >= CONCENTRIC or self._prim_lengths[i] > 0.0:
            return _distance(self._robot_objects[i], self._obstacle_objects[j])
        u = (center - self._centers[j]) / apart if apart > 0.0 else np.array([0.0, 0.0, 1.0])
        return (apart - self._prim_radii[i] - self._radii[j], center - self._prim_radii[i] * u,
                self._centers[j] + self._radii[j] * u)

    def closest(self, q: np.ndarray, derivatives: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """For each obstacle, the signed distance [m] to the closest primitive, ``(n_obstacles,)``,
        and (if asked) its exact gradient with respect to ``q``, ``(n_obstacles, nv)``.

        Bounds from the primitives' axes (vectorised) discard the primitives that cannot be the
        closest; FCL measures the others. The gradient of the distance between a convex primitive
        and a sphere of centre ``c`` is ``n . dp/dq``: ``n`` is the unit direction from ``c`` to
        the obstacle's witness point, ``p`` the robot's witness point moving with its frame
        (Pinocchio frame Jacobian).
        """
        q = np.asarray(q, dtype=float)
        model, data = self.robot.model, self.robot.data
        if derivatives:
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
        rot, a, b = self._axes(q, kinematics_done=derivatives)
        placed = np.zeros(len(self._robot_objects), dtype=bool)
        centers, radii = self._centers, self._radii
        mid = 0.5 * (a + b)
        to_mid = np.linalg.norm(centers[None, :, :] - mid[:, None, :], axis=2)  # (P, O)
        pad = self._prim_radii[:, None] + radii[None, :]
        upper = (to_mid - pad).min(axis=0)
        lower = to_mid - 0.5 * self._prim_lengths[:, None] - pad
        n_obs = len(self.obstacles)
        dist = np.empty(n_obs)
        grad = np.zeros((n_obs, self.robot.nv)) if derivatives else None
        for j in range(n_obs):
            best = (np.inf, -1, None, None)
            for i in np.flatnonzero(lower[:, j] <= upper[j] + 1e-12):
                if not placed[i]:
                    self._place_one(i, rot, mid)
                    placed[i] = True
                d, on_robot, on_obstacle = self._pair_distance(i, j, mid[i], to_mid[i, j])
                if d < best[0]:
                    best = (d, i, on_robot, on_obstacle)
            dist[j], i, on_robot, on_obstacle = best
            if derivatives:
                fid = self._frame_ids[i]
                jac = pin.getFrameJacobian(model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
                normal = on_obstacle - centers[j]
                normal /= math.sqrt(normal @ normal)
                lever = on_robot - data.oMf[fid].translation
                moment = (lever[1] * normal[2] - lever[2] * normal[1], lever[2] * normal[0] - lever[0] * normal[2],
                          lever[0] * normal[1] - lever[1] * normal[0])  # lever x normal
                grad[j] = normal @ jac[:3] + np.asarray(moment) @ jac[3:]
        return dist, grad

    def min_distance(self, q: np.ndarray) -> float:
        """Smallest signed distance between the robot and any obstacle [m] (inf: no obstacle)."""
        return self.distances(q).minimum

    def path_clear(self, path: np.ndarray, clearance: float = PATH_CLEARANCE, samples: int = 24) -> bool:
        """True if the joint-space polyline ``path`` ``(K, nv)``, sampled ``samples`` times per
        segment, keeps ``clearance`` [m] from every obstacle (stops at the first sample that does not)."""
        path = np.asarray(path, dtype=float)
        if not self.obstacles:
            return True
        for a, b in zip(path[:-1], path[1:]):
            for s in np.linspace(0.0, 1.0, samples + 1):
                if self.closest(a + s * (b - a))[0].min() < clearance:
                    return False
        return True

    def in_collision(self, q: np.ndarray) -> bool:
        """True if any primitive touches or overlaps any obstacle."""
        return self.min_distance(q) <= 0.0


def _distance(a: fcl.CollisionObject, b: fcl.CollisionObject) -> tuple[float, np.ndarray, np.ndarray]:
    request = fcl.DistanceRequest(enable_nearest_points=True)
    result = fcl.DistanceResult()
    d = fcl.distance(a, b, request, result)
    if d < 0.0:  # overlapping: FCL's unsigned query says -1; ask for the penetration depth
        request = fcl.DistanceRequest(enable_nearest_points=True, enable_signed_distance=True)
        result = fcl.DistanceResult()
        d = fcl.distance(a, b, request, result)
    return d, np.asarray(result.nearest_points[0]), np.asarray(result.nearest_points[1])
