"""The phases of a motion through several goals (:mod:`~modular_robots.goals`), as step C's
shooting problem sees them.

The motion is cut into phases, one per move, each with the same number of shooting intervals and
its own free duration. Where one phase ends and the next begins (a *via* node) the node's state
is a variable, held by rows: the tool pose of an ``at`` or ``reach`` goal
(:func:`~modular_robots.ocp.ends.end_rows`), zero velocity where the goal is at rest, and, for a
return, the configuration equal to the one it returns to. A pause adds its duration to the
motion's: the robot stands still at a node that is at rest, which costs time and no work.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..costs import Cost, WeightedSum
from ..goals import stops_of
from ..ik import DEFAULT_TOLERANCE
from ..robot import RobotModel
from ..scenario import Task
from .ends import ToolEnd, free_ends_bound

__all__ = ["Via", "Route", "NO_ROUTE", "task_route", "route_cost_bound"]


@dataclass(frozen=True)
class Via:
    """A node between two phases: the tool pose it keeps (None: a return, held by its
    configuration), whether the robot is at ``rest`` there, the configuration it returns to (0:
    the start, ``k``: the ``k``-th via; None: none) and its first guess ``q`` [rad | m] (step B's)."""

    end: ToolEnd | None
    rest: bool
    returns_to: int | None
    q: tuple[float, ...]


@dataclass(frozen=True)
class Route:
    """The vias of a motion in order, how long the robot stands still [s] at the start, at each
    via and at the goal (``holds``, ``len(vias) + 2`` of them), and the configuration the goal
    returns to (None: none; the goal's fixed configuration is then that one)."""

    vias: tuple[Via, ...] = ()
    holds: tuple[float, ...] = (0.0, 0.0)
    goal_returns_to: int | None = None

    def __post_init__(self) -> None:
        if len(self.holds) != len(self.vias) + 2:
            raise ValueError(f"expected {len(self.vias) + 2} holds (start, vias, goal), got {len(self.holds)}")

    @property
    def phases(self) -> int:
        return len(self.vias) + 1

    @property
    def hold(self) -> float:
        """The time the robot stands still in all [s]."""
        return math.fsum(self.holds)


#: The route of a single move: no via, no pause.
NO_ROUTE = Route()


def task_route(task: Task, q_via: tuple[tuple[float, ...], ...]) -> Route:
    """The route of ``task``'s goals with step B's configurations ``q_via`` at its vias (one move:
    no via, no hold)."""
    if not task.goals:
        return Route()
    start_hold, stops = stops_of(task.goals)
    if len(q_via) != len(stops) - 1:
        raise ValueError(f"expected {len(stops) - 1} via configurations, got {len(q_via)}")
    vias = []
    for stop, q in zip(stops, q_via):
        goal = task.goals[stop.goal]
        end = None
        if goal.position is not None:
            end = ToolEnd(goal.position, goal.tolerance or DEFAULT_TOLERANCE, goal.orientation)
        vias.append(Via(end, stop.rest, stop.returns_to, tuple(map(float, q))))
    holds = (start_hold, *(s.hold for s in stops))
    return Route(tuple(vias), holds, stops[-1].returns_to)


def route_cost_bound(
    cost: Cost,
    robot: RobotModel,
    q_start: np.ndarray,
    q_goal: np.ndarray,
    velocity_bound: np.ndarray,
    free_ends: tuple[ToolEnd, ToolEnd] | None,
    route: Route,
) -> float:
    """A valid lower bound of ``cost`` [SI] before a solve, for the motion from ``q_start`` to
    ``q_goal`` (fixed, or free within ``free_ends``) along ``route``, within the joint velocity
    bounds ``velocity_bound``.

    For the time, the larger of two bounds on the moving time, plus the pauses: the cost's own
    (the joints' travel between fixed ends, or the tool's between free ones:
    :func:`~modular_robots.ocp.ends.free_ends_bound`), and the tool's path through the route's
    tolerated positions in order, each move at least the distance between them less both
    tolerances, at the tool's largest speed
    (:meth:`~modular_robots.robot.RobotModel.tool_speed_bound`). A weighted sum: its terms'
    bounds, weighted. Another cost: its own bound (the pauses add no work; the effort of holding
    is not counted, and the scenario reader refuses effort with pauses)."""
    if isinstance(cost, WeightedSum):
        return math.fsum(
            w * route_cost_bound(c, robot, q_start, q_goal, velocity_bound, free_ends, route) for c, w in cost.terms
        )
    own = (
        cost.lower_bound(robot, q_start, q_goal, velocity_bound)
        if free_ends is None
        else free_ends_bound(cost, robot, free_ends, velocity_bound)
    )
    if cost.name != "time" or not route.vias:
        return own + (route.hold if cost.name == "time" else 0.0)
    places: list[tuple[np.ndarray, float]] = []
    if free_ends is None:
        places.append((robot.tool_position(q_start), 0.0))
    else:
        places.append((np.asarray(free_ends[0].position, dtype=float), free_ends[0].tolerance))
    for via in route.vias:
        if via.returns_to is not None:
            places.append(places[via.returns_to])
        else:
            assert via.end is not None  # a via that is not a return keeps a pose
            places.append((np.asarray(via.end.position, dtype=float), via.end.tolerance))
    if route.goal_returns_to is not None:
        places.append(places[route.goal_returns_to])
    elif free_ends is None:
        places.append((robot.tool_position(q_goal), 0.0))
    else:
        places.append((np.asarray(free_ends[1].position, dtype=float), free_ends[1].tolerance))
    gaps = [max(float(np.linalg.norm(b - a)) - s - t, 0.0) for (a, s), (b, t) in itertools.pairwise(places)]
    speed = robot.tool_speed_bound(velocity_bound)
    path = math.fsum(gaps) / speed if speed > 0.0 and math.isfinite(speed) else 0.0
    return max(own, path) + route.hold
