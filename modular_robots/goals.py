"""The goals of a task of several moves: after the start, the tool passes through or stops at
tolerated poses, stands still, or returns to an earlier configuration, in order.

* ``at``: the tool passes within the tolerance of a pose, moving or not;
* ``reach``: the tool arrives within the tolerance of a pose and comes to rest there;
* ``pause``: the robot stands still for ``duration`` seconds where the goal before left it (which
  is then at rest);
* ``return``: the robot comes back to the configuration it had at the start or at an earlier
  goal (``to``), at rest.

A task's motion ends at rest at its last goal, whatever its kind (a move that has not stopped has
not ended). Each move between two goals is a phase of step C's problem, with its own free
duration (:class:`~modular_robots.ocp.ShootingProblem`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from .orientation import Orientation

__all__ = ["Goal", "GOAL_KINDS", "START", "Stop", "stops_of", "tool_path_gap"]

#: The kinds of goal, as a scenario names them.
GOAL_KINDS = ("at", "reach", "pause", "return")
#: The ``to`` of a return to the start.
START = "start"


@dataclass(frozen=True)
class Goal:
    """One goal: its ``kind`` (:data:`GOAL_KINDS`), its ``id`` (what a return names), the tool
    ``position`` [m, base frame] with its ``tolerance`` [m] (None: step B's IK tolerance) and
    ``orientation`` (None: free) for ``at`` and ``reach``, the ``duration`` [s] of a ``pause``,
    and the ``to`` of a ``return`` (:data:`START` or an earlier goal's ``id``)."""

    kind: str
    id: str
    position: tuple[float, float, float] | None = None
    orientation: Orientation | None = None
    tolerance: float | None = None
    duration: float = 0.0
    to: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in GOAL_KINDS:
            raise ValueError(f"unknown goal kind {self.kind!r}; expected one of {', '.join(GOAL_KINDS)}")
        if (self.position is None) == (self.kind in ("at", "reach")):
            needs = "needs" if self.position is None else "has no"
            raise ValueError(f"goal {self.id!r}: an {self.kind} goal {needs} position")

    @property
    def moves(self) -> bool:
        """Whether the robot moves to this goal (every kind but a pause)."""
        return self.kind != "pause"


@dataclass(frozen=True)
class Stop:
    """Where one move ends: the goal's index in the task's goals, whether the robot is at rest
    there, the configuration index it must equal (a return: 0 the start, ``k`` the ``k``-th stop),
    and how long it then stands still [s] (the pauses that follow)."""

    goal: int
    rest: bool
    returns_to: int | None
    hold: float


def stops_of(goals: tuple[Goal, ...]) -> tuple[float, tuple[Stop, ...]]:
    """How long the robot stands still at the start [s] (pauses before the first move) and the
    moves' ends of ``goals``, in order: one per goal that moves, the last at rest (the motion ends
    at rest), each pause folded into the hold of the stop before it (which is then at rest)."""
    start_hold = 0.0
    stops: list[Stop] = []
    index_of = {START: 0}
    for i, goal in enumerate(goals):
        if goal.kind == "pause":
            if stops:
                last = stops[-1]
                stops[-1] = Stop(last.goal, True, last.returns_to, last.hold + goal.duration)
            else:
                start_hold += goal.duration
            continue
        returns_to = None if goal.to is None else index_of[goal.to]
        stops.append(Stop(i, goal.kind != "at", returns_to, 0.0))
        index_of[goal.id] = len(stops)
    if stops and not stops[-1].rest:
        last = stops[-1]
        stops[-1] = Stop(last.goal, True, last.returns_to, last.hold)
    return start_hold, tuple(stops)


def tool_path_gap(
    start: tuple[float, float, float], start_tolerance: float, goals: tuple[Goal, ...], tolerance: float
) -> float:
    """The least distance [m] the tool travels from ``start`` through ``goals`` in order: each
    move at least the distance between the nominal positions of its ends less both position
    tolerances (``tolerance`` for a goal that gives none), a return ending where the goal it names
    was. Valid for every motion that meets the goals, whatever the robot."""
    places: list[tuple[tuple[float, ...], float]] = [(start, start_tolerance)]
    index_of = {START: 0}
    for goal in goals:
        if goal.kind == "pause":
            continue
        if goal.kind == "return":
            places.append(places[index_of[str(goal.to)]])
        else:
            assert goal.position is not None  # an at or reach goal
            places.append((goal.position, tolerance if goal.tolerance is None else goal.tolerance))
        index_of[goal.id] = len(places) - 1
    return math.fsum(max(math.dist(a, b) - s - t, 0.0) for (a, s), (b, t) in itertools.pairwise(places))
