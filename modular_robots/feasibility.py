"""Step B: which compositions can hold the start and the goal, cheapest test first.

The cascade, in rank order (measured costs per call in ``benchmarks/results/feasibility.json``):

0. ``reach`` — from catalogue numbers alone, before any model is built: the tool's distance
   from the base is at most the sum, over the rigid pieces between consecutive revolute axes,
   of each piece's largest length (prismatic strokes at their extremes). A revolute joint does
   not change the distance between points on its axis and points after it, so the bound is
   exact to the triangle inequality and can never drop a reachable target.
1. ``workspace`` — without IK: both targets within the IK tolerance of a box that holds every
   tool position within the joint limits (:mod:`modular_robots.workspace`), from catalogue
   numbers before any model is built (from the robot model for general catalogues). Also a
   bound that never drops a reachable target; on the paper's task it removes nine in ten of
   the compositions IK would reject, at a tenth of their IK cost.
2. ``inverse kinematics`` — position IK at the start and at the goal within joint limits, from
   several deterministic seeds (:mod:`modular_robots.ik`).
3. ``static torque`` — gravity torque with the payload within every joint's effort limit.
4. ``collision`` — every collision primitive clear of every obstacle (python-fcl) and, unless
   ``task.self_collision`` is false, of the primitives of modules that are not its neighbours
   (:mod:`~modular_robots.self_collision`, closed form).

Tests 3 and 4 run on *every* distinct IK solution: a composition passes a target as soon as
one of its solutions passes both. Torque runs before collision because it is about 200 times
cheaper. Among the passing solutions, the start and goal configurations that minimise the
velocity-limited lower bound on motion time are kept for step C.
"""

from __future__ import annotations

import functools
import heapq
import itertools
import math
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from .catalog import Catalog
from .collision import CollisionModel
from .composition import Composition, count_compositions, enumerate_compositions
from .exceptions import InputError, shorten
from .execution import Engine, make_engine
from .goals import START, stops_of
from .ik import DEFAULT_TOLERANCE, IKResult, distinct, ik_seeds, solve_position_ik_batch
from .obstacles import obstacle_label
from .orientation import Orientation
from .pose_ik import solve_pose_ik_batch
from .robot import RobotModel, robot_model
from .scenario import Scenario, Task
from .urdf_assembly import assembly_reach
from .workspace import WorkspaceBox, catalog_workspace_box, workspace_box

__all__ = [
    "FeasibilityTest",
    "FeasibilitySettings",
    "Verdict",
    "FeasibilitySummary",
    "TESTS",
    "max_reach",
    "check_composition",
    "check_compositions",
    "filter_compositions",
    "composition_space",
    "estimate_seconds",
    "MAX_COMPOSITIONS",
]


@dataclass(frozen=True)
class FeasibilityTest:
    """One test of the cascade: its ``name`` (as verdicts report it), its ``rank`` (the order it
    runs in, cheapest first), the ``figure`` its verdicts carry and what it checks."""

    name: str
    rank: int
    figure: str
    description: str


REACH = FeasibilityTest("reach", 0, "reach_margin [m]", "tool distance bound from catalogue numbers")
WORKSPACE = FeasibilityTest(
    "workspace", 1, "workspace_excess [m]", "start and goal inside a box around the tool's reachable positions"
)
INVERSE_KINEMATICS = FeasibilityTest(
    "inverse kinematics", 2, "ik_error [m]", "position IK at start and goal within joint limits"
)
STATIC_TORQUE = FeasibilityTest(
    "static torque", 3, "torque_ratio", "gravity torque with the payload within effort limits"
)
COLLISION = FeasibilityTest(
    "collision", 4, "clearance [m]", "every primitive clear of every obstacle and of the robot's other modules"
)

TESTS: tuple[FeasibilityTest, ...] = (REACH, WORKSPACE, INVERSE_KINEMATICS, STATIC_TORQUE, COLLISION)
"""The cascade's tests, in rank order (cheapest first)."""
TEST_NAMES: tuple[str, ...] = tuple(t.name for t in TESTS)


@dataclass(frozen=True)
class FeasibilitySettings:
    """IK seeds per target, success tolerance [m] and iteration cap per IK run.

    When a target is reached but no solution passes the torque and collision tests, the search
    is widened to ``seeds * escalation`` seeds before the composition is rejected: a borderline
    composition is then not lost to an unlucky set of IK solutions (measured in
    ``benchmarks/bench_feasibility.py`` against a 4x more thorough search).
    """

    seeds: int = 8
    escalation: int = 4
    tolerance: float = DEFAULT_TOLERANCE
    max_iterations: int = 100
    #: False: the *relaxed* cascade, without the collision test, its IK from all
    #: ``seeds * escalation`` seeds at once. It passes every composition the full cascade passes,
    #: and its ``time_bound`` (the fastest pair of its solutions that pass the torque test) is at
    #: most the full cascade's: a bound the best-first search uses before it measures collisions.
    collision: bool = True

    def relaxed(self) -> FeasibilitySettings:
        """These settings without the collision test (see :attr:`collision`)."""
        return replace(self, collision=False)


@dataclass(frozen=True)
class Verdict:
    """The outcome for one composition.

    ``failed_test`` is None when it passes; ``message`` says why it failed, with its figure,
    e.g. ``static torque 140 N m > 100 N m (joint 2, goal)``. ``figures`` holds the closest
    misses seen (``ik_error`` [m], ``torque_ratio``, ``clearance`` [m], ``reach_margin`` [m],
    ``workspace_excess`` [m]). For a passing composition, ``q_start``/``q_goal`` are the chosen
    boundary configurations and ``time_bound`` [s] their velocity-limited lower bound on motion
    time (for a task of several goals, through its poses, pauses included:
    :func:`_boundary_chain`); ``clear_pair`` is the fastest ``(q_start, q_goal)`` whose straight
    joint-space line keeps 0.02 m from every obstacle when the chosen pair's does not, else None
    (step C optimises from both, see :func:`_boundary_pair`).
    """

    composition: Composition
    failed_test: str | None
    message: str
    figures: dict[str, float] = field(default_factory=dict)
    seconds: dict[str, float] = field(default_factory=dict)
    q_start: tuple[float, ...] | None = None
    q_goal: tuple[float, ...] | None = None
    time_bound: float | None = None
    clear_pair: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    #: Among several goals, the configurations at the ends of the moves between the start and
    #: the last (step C's first guess there; :func:`_boundary_chain`).
    q_via: tuple[tuple[float, ...], ...] = ()

    @property
    def passed(self) -> bool:
        return self.failed_test is None

    def to_json(self) -> dict:
        out = {
            "composition": self.composition.name,
            "dof": self.composition.dof,
            "passed": self.passed,
            "failed_test": self.failed_test,
            "message": self.message,
            "figures": self.figures,
        }
        if self.passed:
            assert self.q_start is not None and self.q_goal is not None  # a passing verdict has them
            out.update(
                q_start=list(self.q_start),
                q_goal=list(self.q_goal),
                time_bound=self.time_bound,
                clear_pair=[list(q) for q in self.clear_pair] if self.clear_pair else None,
            )
            if self.q_via:
                out["q_via"] = [list(q) for q in self.q_via]
        return out


# -- test 0: reach ------------------------------------------------------------------------------
def _rx(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def max_reach(composition: Composition, catalog: Catalog) -> float:
    """Upper bound on the tool's distance from the base origin [m], from catalogue numbers."""
    if catalog.general:
        return assembly_reach(composition, catalog)
    total, _, offset, strokes = _reach_along(catalog, composition.modules)
    return total + _piece_reach(offset, strokes)


_Stroke = tuple[np.ndarray, float, float]


@functools.lru_cache(maxsize=16384)  # compositions share their chains but for the last modules
def _reach_along(
    catalog: Catalog, modules: tuple[str, ...]
) -> tuple[float, np.ndarray, np.ndarray, tuple[_Stroke, ...]]:
    """After the chain ``modules``: the bound on the distance covered by its rigid pieces that end
    at a revolute axis, and the open piece's rotation, offset and prismatic strokes (axis, lower,
    upper) since the last revolute axis."""
    if not modules:
        return 0.0, np.eye(3), np.zeros(3), ()
    total, rotation, offset, strokes = _reach_along(catalog, modules[:-1])
    module = catalog.module(modules[-1])
    rotation = rotation @ _rx(module.twist_in)
    if module.joint == "revolute":
        total += _piece_reach(offset, strokes)
        rotation, offset, strokes = np.eye(3), np.zeros(3), ()
    elif module.joint == "prismatic":
        limits = module.limits
        assert limits is not None  # a movable module has limits
        strokes = (*strokes, (rotation[:, 2].copy(), limits.lower, limits.upper))
    offset = offset + module.length * rotation[:, 2]
    return total, rotation @ _rx(module.twist_out), offset, strokes


def _piece_reach(offset: np.ndarray, strokes: tuple[_Stroke, ...]) -> float:
    """The largest length of a rigid piece with ``offset`` and prismatic ``strokes``: at a corner
    of the strokes."""
    corners = itertools.product(*[(lo * axis, hi * axis) for axis, lo, hi in strokes])
    return max(float(np.linalg.norm(offset + sum(c, np.zeros(3)))) for c in corners)


# -- tests 2 and 3: per configuration ---------------------------------------------------------
@dataclass(frozen=True)
class _Check:
    passed: bool
    figure: float
    message: str


def _torque_check(robot: RobotModel, q: np.ndarray, label: str) -> _Check:
    ratios = robot.holding_ratios(q)
    worst = int(np.argmax(ratios))
    torque = ratios * robot.effort_limit
    unit = "N" if robot.model.joints[worst + 1].shortname() == "JointModelPZ" else "N m"
    message = (
        f"static torque {torque[worst]:.4g} {unit} > {robot.effort_limit[worst]:.4g} {unit} "
        f"(joint {worst + 1}, {label})"
    )
    return _Check(bool(ratios[worst] <= 1.0), float(ratios[worst]), message)


def _collision_check(collision: CollisionModel, q: np.ndarray, label: str) -> _Check:
    """The obstacles' check, unless the robot's own (if on) fails worse: the figure of a
    configuration clear of itself is its obstacle clearance."""
    checks = [_Check(True, math.inf, "")]
    clearance, i, j = collision.nearest(q)
    if i >= 0:
        name = collision.robot.primitives[collision.primitive_indices[i]].name
        where = obstacle_label(collision.obstacles[j], collision.given_index[j])
        message = f"collision: {name} {-clearance:.3g} m inside {where} ({label})"
        checks.append(_Check(clearance > 0.0, clearance, message))
    if collision.self_collision is not None:
        own = collision.self_collision.closest(q)
        message = f"self-collision: {own.first} {-own.distance:.3g} m inside {own.second} ({label})"
        if own.distance <= 0.0:
            checks.append(_Check(False, own.distance, message))
    return min(checks, key=lambda check: check.figure)


# -- the cascade for one composition ---------------------------------------------------------
class _Clock:
    def __init__(self):
        self.seconds = {test: 0.0 for test in ("model",) + TEST_NAMES}

    def time(self, test: str, start: float) -> None:
        self.seconds[test] += time.perf_counter() - start


def check_composition(
    composition: Composition, catalog: Catalog, task: Task, settings: FeasibilitySettings = FeasibilitySettings()
) -> Verdict:
    """Run the cascade on one composition; never raises for an infeasible one."""
    return check_compositions([composition], catalog, task, settings)[0]


def check_compositions(
    compositions: Sequence[Composition],
    catalog: Catalog,
    task: Task,
    settings: FeasibilitySettings = FeasibilitySettings(),
) -> list[Verdict]:
    """:func:`check_composition` of each composition, a test at a time for all of them: the IK
    runs at a target of every composition still in the cascade run together
    (:func:`~modular_robots.ik.solve_position_ik_batch`).

    IK is most of step B's work, and an IK iteration costs less per seed the more seeds share it
    (about half as much with 64 seeds as with 8), while every result stays the one a
    composition's own IK gives: the verdicts are those of :func:`check_composition`, bit for bit.
    A shared IK's seconds are split among the compositions in proportion to their IK iterations.
    """
    ends = _ends(task, settings)
    cascades = [_Cascade(composition) for composition in compositions]
    for cascade in cascades:
        _reach_and_model(cascade, catalog, task, settings, ends)
    for label, end in ends.items():
        _at_target([c for c in cascades if c.verdict is None], label, end, settings)
    verdicts = []
    for cascade in cascades:
        if cascade.verdict is None:
            cascade.verdict = _feasible(cascade, task) if settings.collision else _relaxed(cascade, task)
        verdicts.append(cascade.verdict)
    return verdicts


@dataclass
class _Cascade:
    """One composition on its way through the cascade: its clock, the figures so far, its
    verdict once there is one and, once it passes the reach test, its robot model, collision
    model (built on first use: most compositions fail IK or torque before a collision is
    measured), IK seeds and the configurations that pass every test at each target so far."""

    composition: Composition
    clock: _Clock = field(default_factory=_Clock)
    figures: dict[str, float] = field(default_factory=dict)
    verdict: Verdict | None = None
    robot: RobotModel | None = None
    collision: Callable[[], CollisionModel] | None = None
    seeds: np.ndarray | None = None
    passing: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def fail(self, test: str, message: str) -> None:
        self.verdict = Verdict(self.composition, test, message, self.figures, self.clock.seconds)

    def built(self) -> _Built:
        """``robot``, ``collision`` and ``seeds``, which a cascade past the reach and workspace
        tests has (every cascade :func:`_at_target` and :func:`_feasible` see)."""
        assert self.robot is not None and self.collision is not None and self.seeds is not None
        return _Built(self.robot, self.collision, self.seeds)


class _End(NamedTuple):
    """What step B asks of the tool at one end: its ``position`` [m], the ``orientation`` (None:
    free), the position ``tolerance`` [m] of IK and the workspace test, and the ``slack`` [m] the
    task allows the reach test (its own position tolerance; 0 when it gives none), and whether the
    robot is at ``rest`` there (an ``at`` goal is passed moving: no static torque test)."""

    position: np.ndarray
    orientation: Orientation | None
    tolerance: float
    slack: float
    rest: bool = True


def _ends(task: Task, settings: FeasibilitySettings) -> dict[str, _End]:
    """The task's start and goals, by label (:attr:`~modular_robots.scenario.Task.targets`), with
    the task's tolerances or else the settings', at rest where the motion stops
    (:func:`~modular_robots.goals.stops_of`: an ``at`` goal is passed moving unless a pause
    follows it, it ends the motion, or a return comes back to its configuration to stop there)."""
    _, stops = stops_of(task.route)
    resting = {START} | {task.route[stop.goal].id for stop in stops if stop.rest}
    resting |= {str(goal.to) for goal in task.route if goal.kind == "return"}
    return {
        label: _End(
            np.asarray(goal.position, dtype=float),
            goal.orientation,
            goal.tolerance or settings.tolerance,
            goal.tolerance or 0.0,
            goal.id in resting,
        )
        for label, goal in task.targets
    }


class _Built(NamedTuple):
    robot: RobotModel
    collision: Callable[[], CollisionModel]
    seeds: np.ndarray


def _reach_and_model(
    cascade: _Cascade, catalog: Catalog, task: Task, settings: FeasibilitySettings, ends: dict[str, _End]
) -> None:
    """The reach test, then (if it passes) the workspace test and the robot model, and (if both
    tests pass) the collision model and the IK seeds of ``cascade``. The workspace box comes
    from catalogue numbers before the model is built when the catalogue allows it (most
    compositions then need no model), else from the model."""
    t0 = time.perf_counter()
    reach = max_reach(cascade.composition, catalog)
    far_label, far_end = max(ends.items(), key=lambda item: float(np.linalg.norm(item[1].position)) - item[1].slack)
    far = far_end.position
    cascade.figures["reach_margin"] = reach - float(np.linalg.norm(far)) + far_end.slack
    cascade.clock.time(REACH.name, t0)
    if cascade.figures["reach_margin"] < 0.0:
        cascade.fail(
            REACH.name,
            f"reach: the {far_label} is {np.linalg.norm(far):.3f} m from the base, "
            f"the arm reaches at most {reach:.3f} m",
        )
        return
    composition = cascade.composition
    if not catalog.general and not _inside_workspace(
        cascade, lambda: catalog_workspace_box(composition, catalog), ends
    ):
        return
    t0 = time.perf_counter()
    robot = cascade.robot = robot_model(cascade.composition, catalog, task.payload)
    cascade.clock.time("model", t0)
    if catalog.general and not _inside_workspace(cascade, lambda: workspace_box(robot), ends):
        return
    t0 = time.perf_counter()
    cascade.collision = functools.cache(
        lambda: CollisionModel(robot, task.collision_obstacles, self_collision=task.self_collision)
    )
    cascade.seeds = ik_seeds(robot, settings.seeds if settings.collision else settings.seeds * settings.escalation)
    cascade.clock.time("model", t0)


def _inside_workspace(cascade: _Cascade, box_of: Callable[[], WorkspaceBox], ends: dict[str, _End]) -> bool:
    """The workspace test: whether both targets lie within their position tolerance of the box
    ``box_of()`` (one farther out is beyond any IK run's reach); records the failure otherwise."""
    t0 = time.perf_counter()
    box = box_of()
    label, excess, slack = max(
        ((label, box.excess(end.position), end.tolerance) for label, end in ends.items()), key=lambda x: x[1] - x[2]
    )
    cascade.figures["workspace_excess"] = excess
    cascade.clock.time(WORKSPACE.name, t0)
    if excess <= slack:
        return True
    span = ", ".join(
        f"{axis} [{round(low, 3) + 0.0:.3f}, {round(high, 3) + 0.0:.3f}]"  # no -0.000 or 1e-16 of rounding
        for axis, low, high in zip("xyz", box.lower, box.upper)
    )
    cascade.fail(
        WORKSPACE.name,
        f"workspace: the {label} is {excess:.3g} m outside the box that holds every tool position "
        f"within the joint limits ({span} m)",
    )
    return False


def _at_target(cascades: list[_Cascade], label: str, end: _End, settings: FeasibilitySettings) -> None:
    """IK, static torque and collision at ``end`` for each of ``cascades``; one whose IK
    solutions all fail the other tests is searched again from more seeds before it fails."""
    outcomes = _solve(cascades, label, end, [c.built().seeds for c in cascades], settings)
    if settings.escalation > 1 and settings.collision:  # (relaxed: every seed was used at once)
        again = [i for i, outcome in enumerate(outcomes) if outcome.solutions and not outcome.kept]
        more = [
            ik_seeds(cascades[i].built().robot, settings.seeds * settings.escalation)[settings.seeds :] for i in again
        ]
        found = _solve([cascades[i] for i in again], label, end, more, settings, [outcomes[i] for i in again])
        for i, outcome in zip(again, found):
            outcomes[i] = outcome
    for cascade, outcome in zip(cascades, outcomes):
        _judge(cascade, label, outcome)


def _solve(
    cascades: list[_Cascade],
    label: str,
    end: _End,
    seeds: list[np.ndarray],
    settings: FeasibilitySettings,
    earlier: list[_TargetOutcome] | None = None,
) -> list[_TargetOutcome]:
    """IK of every cascade from its ``seeds``, together, then torque and collision on every
    distinct new solution (the ``earlier`` outcomes at the same target, if any, are extended)."""
    t0 = time.perf_counter()
    robots = [cascade.built().robot for cascade in cascades]
    if end.orientation is None:
        runs = solve_position_ik_batch(
            [(robot, end.position, start) for robot, start in zip(robots, seeds)],
            tolerance=end.tolerance,
            max_iterations=settings.max_iterations,
        )
    else:
        runs = solve_pose_ik_batch(
            [(robot, end.position, end.orientation, start) for robot, start in zip(robots, seeds)],
            tolerance=end.tolerance,
            max_iterations=settings.max_iterations,
        )
    _share(time.perf_counter() - t0, [cascade.clock for cascade in cascades], runs)
    befores: Sequence[_TargetOutcome | None] = earlier or [None] * len(cascades)
    return [
        _tests(cascade, label, found, end, before, settings.collision)
        for cascade, found, before in zip(cascades, runs, befores)
    ]


def _share(seconds: float, clocks: list[_Clock], runs: list[list[IKResult]]) -> None:
    """Split the ``seconds`` of a shared IK among ``clocks`` in proportion to their ``runs``' iterations."""
    work = [sum(run.iterations for run in found) for found in runs]
    total = max(sum(work), 1)
    for clock, iterations in zip(clocks, work):
        clock.seconds[INVERSE_KINEMATICS.name] += seconds * iterations / total


def _judge(cascade: _Cascade, label: str, outcome: _TargetOutcome) -> None:
    """The figures of ``outcome`` at the target ``label``, and the verdict if the composition fails there."""
    figures = cascade.figures
    figures["ik_error"] = max(figures.get("ik_error", 0.0), outcome.error)
    if outcome.orientation is not None:
        figures["ik_angle"] = max(figures.get("ik_angle", 0.0), outcome.angle)
    if not outcome.solutions:
        pose, within = "", "joint limits"
        if outcome.orientation is not None:
            pose = f", {outcome.angle:.3g} rad from the orientation {outcome.orientation.describe()}"
            within = "joint limits and the orientation's tolerance"
        cascade.fail(
            INVERSE_KINEMATICS.name,
            f"inverse kinematics: no solution within {within} at the {label} (closest {outcome.error:.3g} m{pose})",
        )
        return
    # the composition needs at least its best ratio at every target seen so far
    figures["torque_ratio"] = max(figures.get("torque_ratio", 0.0), outcome.best_ratio)
    if not outcome.kept:
        assert outcome.closest is not None  # every solution was rejected, the closest recorded
        tests_passed, figure, message = outcome.closest
        if tests_passed:
            figures["clearance"] = figure  # of the configuration nearest to clearing the obstacles
        cascade.fail((STATIC_TORQUE if tests_passed == 0 else COLLISION).name, message)
        return
    cascade.passing[label] = outcome.kept


def _feasible(cascade: _Cascade, task: Task) -> Verdict:
    """The verdict of a composition that passes every test at every target, with its boundary
    configurations."""
    built = cascade.built()
    robot, collision, figures = built.robot, built.collision(), cascade.figures
    if task.goals:
        chain, time_bound = _boundary_chain(robot, task, cascade.passing)
        (q_start, q_goal), clear = (chain[0], chain[-1]), None
    else:
        (q_start, q_goal), clear = _boundary_pair(robot, collision, cascade.passing["start"], cascade.passing["goal"])
        chain, time_bound = [q_start, q_goal], robot.travel_time_bound(q_start, q_goal)
    figures["torque_ratio"] = max(_torque_check(robot, q, "").figure for q in (q_start, q_goal))
    figures["clearance"] = min(collision.min_distance(q) for q in chain)
    return Verdict(
        cascade.composition,
        None,
        "feasible",
        figures,
        cascade.clock.seconds,
        tuple(map(float, q_start)),
        tuple(map(float, q_goal)),
        time_bound,
        (tuple(map(float, clear[0])), tuple(map(float, clear[1]))) if clear else None,
        tuple(tuple(map(float, q)) for q in chain[1:-1]),
    )


def _relaxed(cascade: _Cascade, task: Task) -> Verdict:
    """The verdict of a composition that passes the relaxed cascade: the fastest pair of its
    solutions (of the chain, among several goals), no clear pair (nothing was measured against
    the obstacles)."""
    robot = cascade.built().robot
    if task.goals:
        chain, time_bound = _boundary_chain(robot, task, cascade.passing)
        q_start, q_goal = chain[0], chain[-1]
    else:
        starts, goals = np.array(cascade.passing["start"]), np.array(cascade.passing["goal"])
        velocity = robot.velocity_limit
        limited = np.isfinite(velocity) & (velocity > 0)
        moves = np.abs(goals[None, :, limited] - starts[:, None, limited]) / velocity[limited]  # (start, goal, joint)
        times = np.max(moves, axis=2, initial=0.0)
        first = int(np.argmin(times))  # the first pair of least time, as min() over the pairs in order
        q_start, q_goal = starts[first // len(goals)], goals[first % len(goals)]
        chain, time_bound = [q_start, q_goal], robot.travel_time_bound(q_start, q_goal)
    return Verdict(
        cascade.composition,
        None,
        "feasible without the collision test",
        cascade.figures,
        cascade.clock.seconds,
        tuple(map(float, q_start)),
        tuple(map(float, q_goal)),
        time_bound,
        None,
        tuple(tuple(map(float, q)) for q in chain[1:-1]),
    )


def _boundary_chain(
    robot: RobotModel, task: Task, passing: dict[str, list[np.ndarray]]
) -> tuple[list[np.ndarray], float]:
    """The configurations of a task of several goals at its start and at the end of each move
    (:func:`~modular_robots.goals.stops_of`): among the passing solutions at each pose, the chain
    of least summed ``max_i |dq_i| / qdot_max,i`` over the moves between poses (dynamic
    programming), a return taking the configuration it returns to. Step C starts from it; the
    configurations of the goals between the start and the end are free there.

    With it, the time bound through the poses' kept solutions [s]: that least sum, plus the task's
    pauses (``filter``'s order of the survivors; step C frees the configurations between the
    first and the last, so the search bounds by those two alone). A return adds nothing to it (a
    move back is at least 0 s, and a return between two poses is bounded by the move between
    them, the bound being a norm's distance), so a cycle back to its start keeps its way out."""
    labels = [label for label, _ in task.targets]
    options = [np.asarray(passing[label]) for label in labels]
    # Least total time to each option of pose k, and the option of pose k - 1 it came from.
    best, back = np.zeros(len(options[0])), []
    for before, after in itertools.pairwise(options):
        legs = np.array([[robot.travel_time_bound(a, b) for b in after] for a in before])
        total = best[:, None] + legs
        back.append(np.argmin(total, axis=0))
        best = total.min(axis=0)
    pick = [int(np.argmin(best))]
    for came_from in reversed(back):
        pick.append(int(came_from[pick[-1]]))
    chosen = [options[k][i] for k, i in enumerate(reversed(pick))]
    _, stops = stops_of(task.goals)
    posed = [i for i, goal in enumerate(task.goals) if goal.position is not None]
    pose_of = {goal_index: k for k, goal_index in enumerate(posed)}
    chain = [chosen[0]]
    for stop in stops:
        chain.append(chain[stop.returns_to] if stop.returns_to is not None else chosen[1 + pose_of[stop.goal]])
    pauses = sum(goal.duration for goal in task.goals if goal.kind == "pause")
    return chain, float(best.min()) + pauses


@dataclass
class _TargetOutcome:
    solutions: list[np.ndarray]
    error: float
    kept: list[np.ndarray]
    best_ratio: float
    closest: tuple[int, float, str] | None  # (tests passed, figure, message) of the best reject
    angle: float = math.inf  # [rad] of the run nearest to an end that asks an orientation
    orientation: Orientation | None = None


def _tests(
    cascade: _Cascade,
    label: str,
    runs: list[IKResult],
    end: _End,
    earlier: _TargetOutcome | None,
    collision: bool = True,
) -> _TargetOutcome:
    """Torque and (if ``collision``) collision on every distinct new solution of the IK ``runs``
    (the ``earlier`` outcome at the same target, if any, is extended)."""
    built, clock = cascade.built(), cascade.clock
    robot = built.robot
    t0 = time.perf_counter()
    known = earlier.solutions if earlier else []
    solutions = distinct(itertools.chain(known, (r.q for r in runs if r.success(end.tolerance))))
    clock.time(INVERSE_KINEMATICS.name, t0)
    error = min([r.error for r in runs] + ([earlier.error] if earlier else []))
    outcome = earlier or _TargetOutcome([], error, [], math.inf, None)
    outcome.solutions, outcome.error = solutions, error
    if end.orientation is not None:  # the orientation error of the run nearest to the pose
        nearest = min(runs, key=lambda r: max(r.error / end.tolerance, r.angle / r.angle_tolerance))
        outcome.angle = min(outcome.angle, nearest.angle)
        outcome.orientation = end.orientation
    for q in solutions[len(known) :]:
        if end.rest:
            t0 = time.perf_counter()
            torque = _torque_check(robot, q, label)
            clock.time(STATIC_TORQUE.name, t0)
            outcome.best_ratio = min(outcome.best_ratio, torque.figure)
            if not torque.passed:
                outcome.closest = _closer(outcome.closest, (0, -torque.figure, torque.message))
                continue
        else:
            outcome.best_ratio = 0.0
        if collision:
            t0 = time.perf_counter()
            clear = _collision_check(built.collision(), q, label)
            clock.time(COLLISION.name, t0)
            if not clear.passed:
                outcome.closest = _closer(outcome.closest, (1, clear.figure, clear.message))
                continue
        outcome.kept.append(q)
    return outcome


def _closer(best, candidate):
    return candidate if best is None or candidate[:2] > best[:2] else best


def _boundary_pair(robot: RobotModel, collision: CollisionModel, starts, goals):
    """The (start, goal) pair minimising ``max_i |q_goal,i - q_start,i| / qdot_max,i``, and the
    fastest pair whose straight joint-space line keeps
    :data:`~modular_robots.collision.PATH_CLEARANCE` from the obstacles if that is another one
    (None otherwise).

    Step C optimises from both pairs, as two candidates (see
    :func:`~modular_robots.ocp.candidate.make_candidate` for why neither alone suffices). Joint
    limits of the paper catalogue do not allow wrapping through +-pi, so the shortest way within
    limits is the plain difference.
    """
    pairs = sorted(itertools.product(starts, goals), key=lambda pair: robot.travel_time_bound(*pair))
    clear = next((i for i, pair in enumerate(pairs) if collision.path_clear(np.array(pair))), None)
    return pairs[0], (pairs[clear] if clear else None)


# -- many compositions -------------------------------------------------------------------------
def _check_chunk(context, chunk: list[Composition]) -> list[Verdict]:
    catalog, task, settings = context
    return check_compositions(chunk, catalog, task, settings)


#: CPU seconds of step B per composition on the paper's catalogue (``benchmarks/bench_feasibility.py``
#: measures 1.2-1.7 ms on the 2.4 GHz development machine), for the estimate given before long work.
SECONDS_PER_COMPOSITION = 1.5e-3
#: Step A spaces larger than this are refused unless a larger ``max_compositions`` is given.
MAX_COMPOSITIONS = 1_000_000


def composition_space(
    catalog: Catalog, max_compositions: int = MAX_COMPOSITIONS, jobs: int = 1, limit: int | None = None
) -> int:
    """The number of compositions of step A, counted without listing them (only the first
    ``limit`` if given: a streamed prefix of the space).

    Raises
    ------
    InputError
        If there are more than ``max_compositions``, with the count and an estimate of step B's
        wall time on ``jobs`` cores, before any work starts.
    """
    total = sum(count_compositions(catalog).values())
    if limit is not None:
        total = min(total, limit)
    if total == 0:
        low, high = catalog.grammar.dof
        where = f"{catalog.source}: grammar.dof: " if catalog.source else ""
        raise InputError(
            f"{where}the catalogue {shorten(catalog.name)} allows no composition of {low} to {high} DOF with its "
            f"{len(catalog.modules)} modules; expected a grammar.dof its modules can make (or more modules, or "
            "connectors that meet)"
        )
    if total > max_compositions:
        low, high = catalog.grammar.dof
        raise InputError(
            f"the catalogue {shorten(catalog.name)} allows {total:,} compositions ({low} to {high} DOF)"
            f"{' in the prefix asked for' if limit is not None else ''}; step B would "
            f"take about {_duration(estimate_seconds(total, jobs))} on {jobs} core(s). Narrow its "
            f"grammar (grammar.dof) or raise the limit of {max_compositions:,} (--max-compositions)"
        )
    return total


def estimate_seconds(compositions: int, jobs: int) -> float:
    """Step B's expected wall time [s] for ``compositions`` on ``jobs`` cores."""
    return compositions * SECONDS_PER_COMPOSITION / max(jobs, 1)


def _duration(seconds: float) -> str:
    for unit, size in (("days", 86400.0), ("hours", 3600.0), ("minutes", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


def filter_compositions(
    scenario: Scenario,
    compositions: Iterable[Composition] | None = None,
    *,
    engine: Engine | None = None,
    settings: FeasibilitySettings = FeasibilitySettings(),
    max_compositions: int = MAX_COMPOSITIONS,
) -> Iterator[Verdict]:
    """Yield a :class:`Verdict` per composition (default: all of step A, refused above
    ``max_compositions``, see :func:`composition_space`), in input order.

    Streams: compositions are drawn lazily and at most a few chunks are in flight, on every
    core by default. Verdicts do not depend on the engine or its number of workers. A chunk of
    16 compositions runs its IK together (:func:`check_compositions`): 10 % less CPU than 8 on
    the paper catalogue, and a chunk still takes only tens of milliseconds.
    """
    engine = engine or make_engine()
    if compositions is None:
        composition_space(scenario.catalog, max_compositions, engine.jobs)
        compositions = enumerate_compositions(scenario.catalog)
    context = (scenario.catalog, scenario.task, settings)
    yield from engine.map_chunks(_check_chunk, context, compositions, chunksize=16)


#: Per test, the figure by which a removed composition's nearness to passing is judged, ``1`` if
#: smaller is nearer (``-1`` if larger is), and the diagnosis line's words for the nearest.
_NEAREST_MISS: dict[str, tuple[str, int, str]] = {
    REACH.name: ("reach_margin", -1, "largest reach margin found: {:.3g} m"),
    WORKSPACE.name: ("workspace_excess", 1, "smallest distance to a workspace box: {:.3g} m"),
    INVERSE_KINEMATICS.name: ("ik_error", 1, "smallest IK position error: {:.3g} m"),
    STATIC_TORQUE.name: ("torque_ratio", 1, "best torque ratio found: {:.2f} x the limit"),
    COLLISION.name: ("clearance", -1, "largest clearance found: {:.3g} m"),
}


@dataclass
class FeasibilitySummary:
    """Counts, CPU seconds per test and the closest misses of a stream of verdicts.

    Parameters
    ----------
    keep
        How many survivors to hold: all of them (``None``: what step C needs), or the ``keep``
        with the smallest time bounds, so that a stream of millions of verdicts is summarised in
        bounded memory (a survivor with its IK solutions holds about 1.6 kB; 40 % of the
        nine-joint chains of the paper's catalogue widened to 9 DOF survive).
    """

    keep: int | None = None
    checked: int = 0
    feasible: int = 0
    removed: dict[str, int] = field(default_factory=lambda: {t: 0 for t in TEST_NAMES})
    seconds: dict[str, float] = field(default_factory=lambda: {t: 0.0 for t in ("model",) + TEST_NAMES})
    #: Per test, the figure of the removed composition that came nearest to passing it and
    #: ``"name: message"`` of that composition (see ``_NEAREST_MISS``).
    nearest_misses: dict[str, tuple[float, str]] = field(default_factory=dict)
    _kept: list = field(default_factory=list, init=False, repr=False)

    @property
    def best_torque_ratio(self) -> float:
        """The smallest static torque ratio of a composition the static torque test removed."""
        return self.nearest_misses.get(STATIC_TORQUE.name, (math.inf, ""))[0]

    @property
    def survivors(self) -> list[Verdict]:
        """The survivors held (all of them unless ``keep`` is set), in input order."""
        if self.keep is None:
            return self._kept
        return [verdict for _, _, verdict in sorted(self._kept, key=lambda entry: -entry[1])]

    def add(self, verdict: Verdict) -> None:
        self.checked += 1
        for test, seconds in verdict.seconds.items():
            self.seconds[test] += seconds
        if verdict.failed_test is None:  # passed
            self.feasible += 1
            if self.keep is None:
                self._kept.append(verdict)
            elif self.keep > 0:
                # a max-heap on (time bound, input order): its root is the survivor to let go first
                assert verdict.time_bound is not None  # a passing verdict has one
                entry = (-verdict.time_bound, -self.feasible, verdict)
                (heapq.heappush if len(self._kept) < self.keep else heapq.heappushpop)(self._kept, entry)
            return
        test = verdict.failed_test
        self.removed[test] += 1
        key, sign, _ = _NEAREST_MISS[test]
        value = verdict.figures.get(key)
        nearest = self.nearest_misses.get(test)
        if value is not None and not math.isnan(value) and (nearest is None or sign * value < sign * nearest[0]):
            self.nearest_misses[test] = (value, f"{verdict.composition.name}: {verdict.message}")

    def counts(self) -> dict:
        """The step-B block of ``result.json``'s ``counts``."""
        return {
            "enumerated": self.checked,
            "removed": dict(self.removed),
            "remaining_after": self.remaining_after(),
            "feasible": self.feasible,
        }

    def remaining_after(self) -> dict[str, int]:
        left, out = self.checked, {}
        for test in TEST_NAMES:
            left -= self.removed[test]
            out[test] = left
        return out

    def diagnosis(self) -> str:
        """Why nothing passed: the test that removed the last candidates and the closest miss."""
        if self.feasible:
            return ""
        last = next((t for t in reversed(TEST_NAMES) if self.removed[t]), None)
        if last is None:
            return "no composition was checked"
        lines = [
            f"no composition is feasible: the last {self.removed[last]} candidate(s) were removed by the {last} test"
        ]
        for test in reversed(TEST_NAMES):  # the later a test, the nearer its removed came to passing
            if test in self.nearest_misses:
                value, miss = self.nearest_misses[test]
                lines.append(f"{_NEAREST_MISS[test][2].format(value)} ({miss})")
        return "\n".join(lines)
