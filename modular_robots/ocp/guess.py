"""Joint-space paths that seed step C's initial guess (SPEC §5: the straight line).

The shooting problem walks one of these polylines with a trapezoidal velocity profile
(:meth:`~modular_robots.ocp.shooting.ShootingProblem.initial_guess`):

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

from ..collision import PATH_CLEARANCE, CollisionModel
from ..robot import RobotModel
from .transcription import positive_or_one

__all__ = ["detour_path", "swing_path", "path_times", "GUESS_TRIALS", "SWING", "LOADED"]

#: Random via configurations tried when the straight line hits an obstacle.
GUESS_TRIALS = 48

#: How far [rad] :func:`swing_path` tries moving the most loaded joint past the loaded end.
SWING = (1.0, 0.5)

#: Below this share of a joint's torque limit, holding an end still is easy and no swing is tried.
LOADED = 0.5


def path_times(robot: RobotModel, path: np.ndarray) -> np.ndarray:
    """Seconds each segment of the polyline ``path`` ``(K, nv)`` takes with its busiest joint at
    its velocity limit."""
    vmax = positive_or_one(robot.velocity_limit)
    return np.max(np.abs(np.diff(path, axis=0)) / vmax, axis=1)


def detour_path(
    robot: RobotModel,
    collision: CollisionModel | None,
    q_start: np.ndarray,
    q_goal: np.ndarray,
    trials: int = GUESS_TRIALS,
) -> np.ndarray:
    """The straight line ``(q_start, q_goal)`` if it clears the obstacles, else the fastest of
    ``trials`` seeded random one-via detours that does (the straight line if none does). Clear:
    by :data:`~modular_robots.collision.PATH_CLEARANCE`, or, where an end is nearer an obstacle
    than that, by half its clearance (a goal inside a machine, 6 mm from it: no path keeps 2 cm)."""
    straight = np.array([q_start, q_goal], dtype=float)
    if collision is None:
        return straight
    ends = min(collision.min_distance(straight[0]), collision.min_distance(straight[-1]))
    clearance = PATH_CLEARANCE if ends >= PATH_CLEARANCE else max(0.5 * ends, 0.0)
    if collision.path_clear(straight, clearance):
        return straight
    rng = np.random.default_rng(0)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, np.pi)
    best_time, best = np.inf, straight
    for _ in range(trials):
        path = np.array([q_start, rng.uniform(lo, hi), q_goal])
        duration = path_times(robot, path).sum()
        if duration < best_time and collision.path_clear(path, clearance):
            best_time, best = duration, path
    return best


def swing_path(
    robot: RobotModel,
    collision: CollisionModel | None,
    path: np.ndarray,
    swings: tuple[float, ...] = SWING,
    loaded: float = LOADED,
    samples: int = 12,
) -> np.ndarray | None:
    """``path`` with one more via next to whichever end needs the larger share of a joint's
    torque limit to hold still: that end with its most loaded joint moved by one of ``swings``
    [rad], either way, so that the arm arrives there from (or leaves it to) the side where
    holding is easier.

    A via qualifies when its worst joint needs a smaller share than at the end, no joint needs a
    larger share than at the end anywhere on the straight segment between them (``samples``
    points), it stays within the joint limits (a swing clipped to less than half its length
    does not count) and both segments next to it clear the obstacles. Of those, the one whose
    worst joint needs the smallest share wins (ties: the longer swing). On the way to a goal, such a via
    makes the last stretch climb against gravity, so the arm can brake with the torque it has.

    Returns None when no via qualifies, or when neither end needs ``loaded`` of a limit.
    """
    path = np.asarray(path, dtype=float)

    def share(q: np.ndarray) -> float:
        return float(np.max(robot.holding_ratios(q)))

    ends = [robot.holding_ratios(path[0]), robot.holding_ratios(path[-1])]
    at_goal = int(ends[1].max() >= ends[0].max())
    end, neighbour = (path[-1], path[-2]) if at_goal else (path[0], path[1])
    end_share = float(ends[at_goal].max())
    if end_share < loaded:
        return None
    joint = int(np.argmax(ends[at_goal]))
    t = np.linspace(0.0, 1.0, samples, endpoint=False)[:, None]
    best, best_share = None, np.inf
    for swing in swings:
        for direction in (1.0, -1.0):
            via = end.copy()
            via[joint] = np.clip(end[joint] + direction * swing, robot.lower[joint], robot.upper[joint])
            if abs(via[joint] - end[joint]) < 0.5 * swing:
                continue
            via_share = share(via)
            if via_share >= min(best_share, (1.0 - 1e-6) * end_share):
                continue
            if max(share(q) for q in via + t * (end - via)) > end_share:
                continue
            if collision is not None and not collision.path_clear(np.array([neighbour, via, end])):
                continue
            best, best_share = via, via_share
    if best is None:
        return None
    return np.vstack([path[:-1], best, path[-1:]]) if at_goal else np.vstack([path[:1], best, path[1:]])
