"""Distances between a robot's collision primitives and sphere obstacles, with python-fcl.

Robot primitives are FCL capsules (links) and spheres (ports, payload); obstacles are FCL
spheres. Distances are signed: negative when the shapes overlap (penetration depth).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import fcl
import numpy as np

from .robot import RobotModel

__all__ = ["SphereObstacle", "CollisionModel", "Distances"]


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
    """FCL shapes of one robot's primitives and of the obstacles around it."""

    def __init__(self, robot: RobotModel, obstacles: Sequence[SphereObstacle]):
        self.robot = robot
        self.obstacles = tuple(obstacles)
        self._robot_objects = [
            fcl.CollisionObject(fcl.Capsule(p.radius, p.length) if p.length > 0 else fcl.Sphere(p.radius))
            for p in robot.primitives
        ]
        self._obstacle_objects = [
            fcl.CollisionObject(fcl.Sphere(o.radius), fcl.Transform(np.asarray(o.center, dtype=float)))
            for o in self.obstacles
        ]

    def _place(self, q: np.ndarray) -> None:
        for obj, pose in zip(self._robot_objects, self.robot.primitive_placements(q)):
            obj.setTransform(fcl.Transform(pose.rotation, pose.translation))

    def distances(self, q: np.ndarray) -> Distances:
        """Signed distance of every (primitive, obstacle) pair at configuration ``q``."""
        self._place(q)
        shape = (len(self._robot_objects), len(self._obstacle_objects))
        dist = np.empty(shape)
        on_robot = np.empty(shape + (3,))
        on_obstacle = np.empty(shape + (3,))
        for i, robot_obj in enumerate(self._robot_objects):
            for j, obstacle_obj in enumerate(self._obstacle_objects):
                dist[i, j], on_robot[i, j], on_obstacle[i, j] = _distance(robot_obj, obstacle_obj)
        return Distances(dist, on_robot, on_obstacle)

    def min_distance(self, q: np.ndarray) -> float:
        """Smallest signed distance between the robot and any obstacle [m] (inf: no obstacle)."""
        return self.distances(q).minimum

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
