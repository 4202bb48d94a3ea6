"""The first guess's detour round an obstacle when the goal itself lies nearer an obstacle than
the path clearance (a goal inside a machine): the detour keeps half the ends' clearance, and its
clearance is checked here in closed form (:func:`arm_clearance`, no FCL), densely."""

from __future__ import annotations

import itertools

import numpy as np

from modular_robots.collision import PATH_CLEARANCE, CollisionModel
from modular_robots.obstacles import SphereObstacle
from modular_robots.ocp.guess import detour_path

from .helpers.models import ARM_GOAL, ARM_START, R_LINK, arm_clearance, arm_points, planar_arm

BLOCK = SphereObstacle((1.5, 0.0, 0.0), 0.2)  # across the straight line (the arm stretched along x)
GAP = 0.006  # the goal's clearance from the sphere beside its tool


def _beside_goal() -> SphereObstacle:
    tool, elbow = arm_points(ARM_GOAL)[2], arm_points(ARM_GOAL)[1]
    along = (tool - elbow) / np.linalg.norm(tool - elbow)
    return SphereObstacle(tuple(tool + (R_LINK + 0.1 + GAP) * along), 0.1)


def _path_clearance(path: np.ndarray, obstacles) -> float:
    s = np.linspace(0.0, 1.0, 400)[:, None]
    qs = np.concatenate([a + s * (b - a) for a, b in itertools.pairwise(path)])
    return min(arm_clearance(q, o) for q in qs for o in obstacles)


def test_a_goal_nearer_an_obstacle_than_the_path_clearance_still_gets_a_clear_detour():
    obstacles = [BLOCK, _beside_goal()]
    assert (
        arm_clearance(ARM_GOAL, obstacles[1]) == np.float64(GAP)
        or abs(arm_clearance(ARM_GOAL, obstacles[1]) - GAP) < 1e-9
    )
    assert GAP < PATH_CLEARANCE
    straight = np.array([ARM_START, ARM_GOAL], dtype=float)
    assert _path_clearance(straight, obstacles) < 0.0  # the straight line runs through the block
    path = detour_path(planar_arm(), CollisionModel(planar_arm(), obstacles, cull=False), straight[0], straight[1])
    assert len(path) == 3
    assert _path_clearance(path, obstacles) >= 0.5 * GAP - 1e-6
