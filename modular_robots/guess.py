"""Joint-space paths that seed step C's initial guess (SPEC §5: the straight line).

The shooting problem walks one of these polylines with a trapezoidal velocity profile
(:meth:`~modular_robots.shooting.ShootingProblem.initial_guess`):

* :func:`detour_path`, the default: the straight line from ``q_start`` to ``q_goal`` if it clears
  the obstacles, else the fastest clear detour through one seeded random via configuration (a
  guess through an obstacle lets the solver settle on a motion that jumps through it between two
  sub-steps; a clear guess starts on the right side).
* :func:`swing_path`, a second guess for a solve that failed: the same path with a via that
  reaches the goal (or leaves the start) from the side where its most loaded joint holds it
  more easily. Why: on paper-5kg, two compositions hold the payload at the goal with 99.86 % of
  a joint's torque limit, and no joint-space path gets there quasi-statically: the smallest
  worst static torque along any two-via path (SLSQP from eight starts) was 1.024 times the
  limit. So the arm must swing through, and arriving from above the goal, at a torque margin of
  0.14 %, it cannot brake. From the straight line both solves stopped at the iteration limit,
  infeasible, with ``tf`` drifting to 50-80 s; from a via 1 rad past the goal, both converged
  and verified at ``tf`` = 4.87 s in 141 and 163 iterations (0.6 rad: the same optimum), which
  took paper-5kg from 70 to 72 of its 75 step-B survivors converged. On the 87 paper-5kg
  candidates that converge anyway, 15 first guesses also pass poses the joints cannot
  hold (up to 1.69 times the limit), so this guess is a second try, not the first.
"""

from __future__ import annotations

import numpy as np

from .collision import CollisionModel
from .robot import RobotModel
from .transcription import positive_or_one

__all__ = ["detour_path", "swing_path", "path_times", "GUESS_TRIALS", "SWING"]

#: Random via configurations tried when the straight line hits an obstacle.
GUESS_TRIALS = 48

#: How far [rad] :func:`swing_path` moves the most loaded joint past the loaded end, and the
#: shorter swing tried when that one does not clear the obstacles.
SWING = (1.0, 0.5)


def path_times(robot: RobotModel, path: np.ndarray) -> np.ndarray:
    """Seconds each segment of the polyline ``path`` ``(K, nv)`` takes with its busiest joint at
    its velocity limit."""
    vmax = positive_or_one(robot.velocity_limit)
    return np.max(np.abs(np.diff(path, axis=0)) / vmax, axis=1)


def detour_path(robot: RobotModel, collision: CollisionModel | None, q_start: np.ndarray,
                q_goal: np.ndarray, trials: int = GUESS_TRIALS) -> np.ndarray:
    """The straight line ``(q_start, q_goal)`` if it clears the obstacles, else the fastest of
    ``trials`` seeded random one-via detours that does (the straight line if none does)."""
    straight = np.array([q_start, q_goal], dtype=float)
    if collision is None or collision.path_clear(straight):
        return straight
    rng = np.random.default_rng(0)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, np.pi)
    best_time, best = np.inf, straight
    for _ in range(trials):
        path = np.array([q_start, rng.uniform(lo, hi), q_goal])
        duration = path_times(robot, path).sum()
        if duration < best_time and collision.path_clear(path):
            best_time, best = duration, path
    return best


def swing_path(robot: RobotModel, collision: CollisionModel | None, path: np.ndarray,
               swings: tuple[float, ...] = SWING) -> np.ndarray | None:
    """``path`` with one more via next to whichever end needs the larger share of a joint's
    torque limit to hold still: that end with its most loaded joint moved ``swing`` [rad]
    towards where its static torque falls, so that the arm arrives there from (or leaves it to)
    the side of easier holding.

    Returns None when no swing applies: the loaded joint's static torque does not depend on its
    own position (a prismatic joint), or neither swing stays within the joint limits and clear of
    the obstacles.
    """
    path = np.asarray(path, dtype=float)
    ends = (path[0], path[-1])
    ratios = [np.abs(robot.gravity(q)) / positive_or_one(robot.effort_limit) for q in ends]
    at_goal = int(ratios[1].max() >= ratios[0].max())
    end = ends[at_goal]
    joint = int(np.argmax(ratios[at_goal]))
    torque = robot.gravity(end)[joint]
    slope = robot.gravity_derivative(end)[joint, joint]
    if abs(slope) < 1e-9 * max(1.0, abs(torque)):
        return None
    direction = -np.sign(torque * slope)
    for swing in swings:
        via = end.copy()
        via[joint] = np.clip(end[joint] + direction * swing, robot.lower[joint], robot.upper[joint])
        if abs(via[joint] - end[joint]) < 0.5 * swing:
            continue
        swung = np.vstack([path[:-1], via, path[-1:]]) if at_goal else np.vstack([path[:1], via, path[1:]])
        if collision is None or collision.path_clear(swung):
            return swung
    return None
