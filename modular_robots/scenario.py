"""Scenario files: a task for a catalogue, with optimizer and pruning settings (SPEC §7)."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ._yamlio import Fields, load_yaml
from .catalog import Catalog, catalog_from_fields, load_catalog
from .costs import COSTS, DEFAULT_WITHIN, Objective, parse_objective
from .exceptions import InputError, ScenarioError, shorten
from .execution import CONNECT_TIMEOUT, ENGINES, ExecutionSettings, address_problem
from .goals import GOAL_KINDS, START, Goal
from .obstacles import FloorObstacle, Obstacle, SphereObstacle, obstacle_from_fields
from .orientation import DEFAULT_ANGLE_TOLERANCE, Orientation

__all__ = [
    "Obstacle",
    "SphereObstacle",
    "Task",
    "OptimizerSettings",
    "PruningSettings",
    "ExecutionSettings",
    "Scenario",
    "CobraOrigin",
    "load_scenario",
]

RULES = ("ratio", "paper", "none")
REFERENCES = ("trusted", "verified")
TRANSCRIPTIONS = ("forward", "inverse")
#: Step C's solvers by name (:data:`modular_robots.ocp.solvers.SOLVERS` holds them).
SOLVERS = ("trust-constr",)
#: A scenario's name is its results folder's default name: one safe path component.
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")
#: The shortest start-goal distance of a task [m]: closer, there is no motion to optimise.
MIN_TRAVEL = 1e-3
#: Largest shooting nodes and sub-steps: the solver's matrices are dense, so memory and time grow
#: with the square of the nodes (100 nodes of a 6-DOF arm are ~1200 variables).
MAX_NODES = 100
MAX_SUBSTEPS = 100
MAX_ITERATIONS = 100_000
#: The loosest optimality and constraint tolerances of step C: looser, the solver stops at once
#: with a plan that eats the margins and fails verification (which checks defects to 1e-3).
MAX_TOLERANCE = 1e-2
_LOOSE = "looser, the solver stops before the plan keeps its constraints and margins"
#: The highest floor [m]: a floor is the plane the robot stands on, near its base.
MAX_FLOOR = 10.0


@dataclass(frozen=True)
class Task:
    """Carry ``payload`` [kg] from tool position ``start`` to ``goal`` [m, base frame], at rest at
    both ends, clear of ``obstacles`` and above the ``floor`` (``z`` [m] in the base frame; None:
    no floor), minimising ``cost`` (an :class:`~modular_robots.costs.Objective`, or its descriptor:
    ``time``, ``effort``, a weighted sum such as ``time + 0.05*mass``, or a lexicographic order
    such as ``time then modules within 0.01``).

    At each end the tool may also be asked an orientation (``start_orientation``,
    ``goal_orientation``; None: free) and a position tolerance [m] (``start_tolerance``,
    ``goal_tolerance``; None: step B's IK tolerance).

    A task of several moves lists its ``goals`` (:mod:`~modular_robots.goals`) after the start;
    ``goal`` and its orientation and tolerance are then those of the last goal that moves (of the
    goal it returns to, for a return). Without ``goals``, the task is the one move from ``start``
    to ``goal``, at rest at both ends."""

    payload: float
    start: tuple[float, float, float]
    goal: tuple[float, float, float]
    obstacles: tuple[Obstacle, ...] = ()
    cost: Objective = field(default_factory=Objective)
    #: Keep the robot's modules that are not neighbours in the chain apart
    #: (:mod:`~modular_robots.self_collision`): in step B, step C and verification.
    self_collision: bool = True
    floor: float | None = 0.0
    start_orientation: Orientation | None = None
    goal_orientation: Orientation | None = None
    start_tolerance: float | None = None
    goal_tolerance: float | None = None
    #: The longest the move may take [s] (None: no limit). A task that minimises energy alone
    #: needs one: a slower move always needs less (the drives hold the payload without work).
    max_time: float | None = None
    goals: tuple[Goal, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "cost", parse_objective(self.cost))  # a descriptor string is welcome

    @property
    def route(self) -> tuple[Goal, ...]:
        """The task's goals after the start: ``goals``, or the one ``reach`` of ``goal``."""
        return self.goals or (Goal("reach", "1", self.goal, self.goal_orientation, self.goal_tolerance),)

    @property
    def targets(self) -> tuple[tuple[str, Goal], ...]:
        """Every tolerated pose the tool must meet, labelled for messages (``start``, ``goal``, or
        ``goal 2`` among several goals): the start as a ``reach`` goal, then each ``at`` and
        ``reach`` goal in order."""
        start = Goal("reach", START, self.start, self.start_orientation, self.start_tolerance)
        poses = [g for g in self.route if g.position is not None]
        if len(poses) == 1:
            return (("start", start), ("goal", poses[0]))
        return (("start", start), *((f"goal {g.id}", g) for g in poses))

    @property
    def collision_obstacles(self) -> tuple[Obstacle, ...]:
        """Everything the robot is kept clear of: the ``obstacles``, then the floor if there is one
        (:class:`~modular_robots.obstacles.FloorObstacle`)."""
        return self.obstacles + (() if self.floor is None else (FloorObstacle(self.floor),))


@dataclass(frozen=True)
class OptimizerSettings:
    """Step C settings: shooting nodes (intervals = nodes - 1), integration sub-steps per interval,
    trust-constr iteration limit and tolerances, the transcription, and the clearance [m] kept
    from obstacles at the sub-steps (so that the motion between two sub-steps, which is not
    checked by the solver, stays clear; verification checks it on a dense grid).

    ``effort_margin`` and ``velocity_margin`` (fractions in (0, 1]) are the share of each joint's
    effort and velocity limit the plan may use: the rest is headroom for a feedback controller
    that tracks it. Verification and the exported URDF keep the catalogue's full limits.
    """

    nodes: int = 8
    substeps: int = 4
    max_iterations: int = 300
    tolerance: float = 1e-6
    constraint_tolerance: float = 1e-6
    transcription: str = "inverse"
    clearance_margin: float = 0.02
    effort_margin: float = 0.9
    velocity_margin: float = 0.95
    #: The solver of step C, by name (:data:`SOLVERS`).
    solver: str = "trust-constr"
    #: Whether step C chooses the start and goal configurations itself, anywhere the tool is within
    #: the task's tolerances of the asked poses (step B's IK pair is the first guess), instead of
    #: keeping step B's.
    free_ends: bool = False


@dataclass(frozen=True)
class PruningSettings:
    """Step D settings (see :mod:`~modular_robots.pruning`): the ``rule`` (``ratio``, ``paper`` or
    ``none``); the ratio's ``threshold`` and ``start_iteration``; the ``reference`` it is taken
    against (``verified``: the best verified cost; ``trusted``: also nearly feasible live
    iterates); the ``gate`` (a candidate whose lower bound is below ``gate`` times the reference is
    judged on its bound only); the progress guard (a candidate is judged only when it was trusted
    ``window`` iterations ago too, and kept while the fall of its cost over the window, repeated
    ``lookahead`` times, would bring it within the threshold; ``window = 0`` turns it off); and
    ``patience`` (a candidate not trusted for that many iterations in a row is pruned once there
    is a reference; ``0`` turns it off). The defaults were chosen on replays of the seed-1
    scenario suite and confirmed on seed 2 (``docs/design-notes.md``).
    """

    rule: str = "ratio"
    threshold: float = 0.5
    start_iteration: int = 2
    window: int = 16
    lookahead: float = 2.0
    patience: int = 75
    #: What the ratio is taken against: ``trusted`` (the best trusted iterate or verified cost) or
    #: ``verified`` (the best verified cost only).
    reference: str = "verified"
    #: A candidate whose lower bound is below ``gate`` times the reference is judged on its bound
    #: only, never on its iterates (0: every candidate is judged on its iterates).
    gate: float = 0.7
    #: At most this many candidates iterate at once, admitted in the order of their lower bounds
    #: (0: all at once, the paper's lockstep).
    admission: int = 8


@dataclass(frozen=True)
class CobraOrigin:
    """Where a scenario came from, for its solution document: the CoBRA task's ``id`` and
    ``version``, its ``time_step`` [s], the robot's ``base_pose`` in the world (4x4), the ``start``
    goal (the CoBRA goal the scenario's start stands for) and the ``cost_function`` descriptor."""

    id: str
    version: str
    time_step: float
    base_pose: tuple[tuple[float, ...], ...]
    start: str
    cost_function: str


@dataclass(frozen=True)
class Scenario:
    name: str
    catalog: Catalog
    task: Task
    optimizer: OptimizerSettings = field(default_factory=OptimizerSettings)
    pruning: PruningSettings = field(default_factory=PruningSettings)
    path: Path | None = None
    #: Where steps B-D run (``execution: {engine, address, connect_timeout}``; the command line overrides it).
    execution: ExecutionSettings = field(default_factory=ExecutionSettings)
    #: The CoBRA task the scenario was imported from (None: not imported).
    cobra: CobraOrigin | None = None


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file; its ``catalog`` path is relative to the file.

    Raises
    ------
    ScenarioError
        Naming the file, line and key, and what was expected (catalogue errors propagate as
        :class:`~modular_robots.exceptions.CatalogError`).
    """
    return _scenario_from_fields(load_yaml(Path(path), ScenarioError))


def _not_a_cobra_task(top: Fields, expected: str = "a scenario") -> None:
    """Refuse a CoBRA task (JSON with a ``header`` and ``goals``) where a scenario or a catalogue
    is read, saying how to use it (its keys are not a scenario's)."""
    if top.has("header") and top.has("goals") and not top.has("task"):
        raise top.fail(
            None,
            f"expected {expected}, got a CoBRA task (JSON): solve it with `modular-robots run "
            f"{top.path} --catalog CATALOG`, or convert it with `modular-robots import-cobra {top.path} "
            "--catalog CATALOG -o SCENARIO.yaml`",
        )


def _scenario_from_fields(top: Fields) -> Scenario:
    top = top.reporting(ScenarioError)
    _not_a_cobra_task(top)
    path = top.path
    name = top.string("name")
    top.check(
        "name",
        NAME.fullmatch(name) is not None,
        f"expected a name of at most 100 letters, digits, '.', '_' or '-' that starts with a letter or digit "
        f"(it names the results folder), got {shorten(name)}",
    )
    top.string("description", default="")
    catalog_path = path.parent / top.string("catalog")
    if not catalog_path.exists():
        raise top.fail(
            "catalog",
            f"no catalogue file at {catalog_path} (looked in {catalog_path.parent.resolve()}: a relative path is "
            "taken from the scenario's folder)",
        )
    if not catalog_path.is_file():
        raise top.fail("catalog", f"{catalog_path} is not a regular file")
    if catalog_path.resolve() == path.resolve():
        raise top.fail("catalog", "the scenario names itself as its catalogue; expected a catalogue file")
    catalog = load_catalog(catalog_path)
    task = _read_task(top.mapping("task"))
    if "price" in task.cost.names:
        unpriced = [m.id for m in catalog.modules if m.price is None]
        if unpriced:
            raise top.mapping("task").fail(
                "cost",
                f"the price cost needs every module's price; catalogue {catalog_path.name} has none for "
                f"{', '.join(unpriced[:10])}{', ...' if len(unpriced) > 10 else ''} (add price: to each module)",
            )
    optimizer = _read_optimizer(top.mapping("optimizer", default=None))
    pruning = _read_pruning(top.mapping("pruning", default=None))
    execution = _read_execution(top.mapping("execution", default=None))
    cobra = _read_cobra(top.mapping("cobra", default=None), task)
    top.done()
    return Scenario(name, catalog, task, optimizer, pruning, path, execution, cobra)


def _read_cobra(f: Fields | None, task: Task) -> CobraOrigin | None:
    """``cobra``: where a scenario written by ``import-cobra`` came from
    (:class:`~modular_robots.cobra.CobraOrigin`), for its solution document."""
    if f is None:
        return None
    f.string("task", default="")
    origin = CobraOrigin(
        id=f.string("id"),
        version=str(f.raw("version", "2022")),
        time_step=f.number("time_step", exclusive_minimum=0.0, maximum=1.0),
        base_pose=_pose_rows(f),
        start=str(f.raw("start")),
        cost_function=f.string("cost_function", default="cyc"),
    )
    ids = {g.id for g in task.goals}
    f.check("start", origin.start not in ids, f"the start's goal id {shorten(origin.start)} is also a goal's")
    f.done()
    return origin


def _pose_rows(f: Fields) -> tuple[tuple[float, ...], ...]:
    """``cobra.base_pose``: a 4x4 homogeneous transform, by rows."""
    rows = f.raw("base_pose")
    ok = (
        isinstance(rows, list)
        and len(rows) == 4
        and all(isinstance(r, list) and len(r) == 4 for r in rows)
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for r in rows for v in r)
    )
    f.check("base_pose", ok, "expected a 4x4 matrix of finite numbers (rows)")
    return tuple(tuple(float(v) for v in r) for r in rows)


def _below(value: float, limit: float) -> str:
    """``value`` with the fewest significant digits (3 to 12) that still show it below ``limit``."""
    return next((text for digits in range(3, 13) if float(text := f"{value:.{digits}g}") < limit), f"{value!r}")


def _read_task(f: Fields) -> Task:
    payload = f.number("payload", minimum=0.0)
    start, start_orientation, start_tolerance = _read_end(f, "start")
    goals: tuple[Goal, ...] = ()
    if f.has("goals"):
        if f.has("goal"):
            raise f.fail("goal", "give goal (one move) or goals (several), not both")
        goals = _read_goals(f, start)
        final = _final_pose(goals)
        if final is None:  # back to the start
            goal, goal_orientation, goal_tolerance = start, start_orientation, start_tolerance
        else:
            assert final.position is not None  # an at or reach goal
            goal, goal_orientation, goal_tolerance = final.position, final.orientation, final.tolerance
        points = [("start", start)] + [(f"goal {g.id}", g.position) for g in goals if g.position is not None]
    else:
        goal, goal_orientation, goal_tolerance = _read_end(f, "goal")
        f.check(
            "goal",
            math.dist(start, goal) >= MIN_TRAVEL * (1.0 - 1e-9),  # 1 mm as decimals write it: 1.101 - 1.1 < 1e-3
            f"the goal is {_below(math.dist(start, goal) * 1000, MIN_TRAVEL * 1000)} mm from the start; expected at "
            f"least {MIN_TRAVEL * 1000:g} mm (a task moves the payload)",
        )
        points = [("start", start), ("goal", goal)]
    obstacles = []
    for item in f.mappings("obstacles", default=()):
        obstacle = obstacle_from_fields(item)
        if obstacle.contains((0.0, 0.0, 0.0)):
            raise item.fail(
                obstacle.kind,
                f"the obstacle contains the robot's base at the origin ({obstacle.describe()})",
            )
        for label, point in points:
            if obstacle.contains(point):
                raise item.fail(obstacle.kind, f"the obstacle contains the {label} position {list(point)}")
        obstacles.append(obstacle)
    floor = _read_floor(f, points)
    cost = _read_cost(f)
    max_time = f.number("max_time", default=None, exclusive_minimum=0.0, maximum=MAX_TIME)
    if max_time is None and _crawls(cost):
        raise f.fail(
            "cost",
            f"{cost} has no minimum over the move's duration: a slower move always costs less (the drives hold "
            "the payload without doing work), and step C would crawl toward an ever longer move; add "
            "task.max_time [s], or add the time to the sum (e.g. time + 0.01*energy)",
        )
    if max_time is None and cost.design_only:
        f.warn(
            "cost",
            f"{cost} counts the design alone: every plan of a robot costs the same, and its duration is "
            "whatever the solver stops at; add the time to the sum (e.g. mass + 0.01*time) or a "
            "task.max_time [s]",
        )
    paused = math.fsum(g.duration for g in goals)
    if max_time is not None and paused >= max_time:
        raise f.fail("max_time", f"the pauses take {paused:g} s, at least max_time = {max_time:g} s; expected more")
    if any(g.kind == "pause" for g in goals) and any(name == "effort" for name, _ in cost.terms):
        raise f.fail(
            "cost",
            "the effort of a task with a pause is not supported: holding the payload still costs effort that step C "
            "does not count; minimise the time or the energy (a pause does no work), or drop the pause",
        )
    self_collision = f.boolean("self_collision", default=True)
    f.done()
    return Task(
        payload,
        start,
        goal,
        tuple(obstacles),
        cost,
        self_collision,
        floor,
        start_orientation,
        goal_orientation,
        start_tolerance,
        goal_tolerance,
        max_time,
        goals,
    )


def _read_goals(f: Fields, start: tuple[float, float, float]) -> tuple[Goal, ...]:
    """``task.goals``: a list of one-key mappings, ``at`` or ``reach`` (a pose, as ``task.goal``),
    ``pause`` (a duration [s]) or ``return`` (``start`` or an earlier goal's id), each with an
    optional ``id`` (default: its position in the list, from 1)."""
    goals: list[Goal] = []
    previous: tuple[float, ...] = start
    poses: dict[str, tuple[float, ...]] = {START: start}
    at = START  # the goal whose configuration the robot is at
    items = list(f.mappings("goals"))
    f.check("goals", bool(items), "expected at least one goal")
    for number, item in enumerate(items, start=1):
        kinds = [k for k in GOAL_KINDS if item.has(k)]
        if len(kinds) != 1:
            unknown = [k for k in item.names() if k != "id"]
            raise item.fail(
                unknown[0] if len(unknown) == 1 else None,
                f"expected exactly one of {', '.join(GOAL_KINDS)} (and an optional id), got "
                f"{', '.join(map(shorten, unknown)) or 'none'}",
            )
        kind = kinds[0]
        named = item.has("id")
        id_ = str(item.raw("id", str(number)))
        item.check("id", id_ != START, f"{START!r} names the start (as in return: {START}); expected another id")
        clash = next((k for k, g in enumerate(goals) if g.id == id_), None)
        if clash is not None:
            raise item.fail(
                "id" if named else None,
                f"goal id {shorten(id_)} is used twice (goals[{clash}] has it)"
                + ("" if named else "; it is this goal's default id, its place in the list: give one of them an id"),
            )
        if kind == "pause":
            duration = item.number("pause", exclusive_minimum=0.0, maximum=MAX_TIME)
            goals.append(Goal("pause", id_, duration=duration))
        elif kind == "return":
            to = str(item.raw("return"))
            item.check(
                "return",
                to in poses,
                f"no earlier goal with id {shorten(to)} to return to; expected start or one of "
                f"{', '.join(k for k in poses if k != START) or 'none (no goal before it)'}",
            )
            item.check(  # (a pose that differs only in orientation, or another IK branch, is a move)
                "return",
                to != at,
                f"the robot is at {'the start' if to == START else f'goal {shorten(to)}'}'s configuration "
                "already; expected a goal to return to that it has left",
            )
            goals.append(Goal("return", id_, to=to))
            position = poses[to]
        else:
            position, orientation, tolerance = _read_end(item, kind)
            goals.append(Goal(kind, id_, position, orientation, tolerance))
        if kind != "pause":
            at = to if kind == "return" else id_  # whose configuration the robot is at after it
            item.check(
                kind,
                kind == "return" or math.dist(previous, position) >= MIN_TRAVEL * (1.0 - 1e-9),
                f"the goal is {_below(math.dist(previous, position) * 1000, MIN_TRAVEL * 1000)} mm from the one "
                f"before; expected at least {MIN_TRAVEL * 1000:g} mm (a move moves the payload)",
            )
            previous = poses[id_] = position
        item.done()
    f.check("goals", any(g.moves for g in goals), "expected at least one goal that moves (at, reach or return)")
    return tuple(goals)


def _final_pose(goals: tuple[Goal, ...]) -> Goal | None:
    """The pose goal where the motion ends: the last goal that moves, or the one it returns to
    (None: the start)."""
    by_id = {g.id: g for g in goals}
    last = [g for g in goals if g.moves][-1]
    while last.kind == "return":
        if last.to == START:
            return None
        last = by_id[str(last.to)]
    return last


#: The longest move a task may allow [s].
MAX_TIME = 3600.0


def _crawls(objective: Objective) -> bool:
    """Whether ``objective`` falls as the move lengthens, without end: the energy does (holding
    the payload does no work), unless the sum counts the time or the effort too (holding the
    payload costs effort, so an ever slower move costs ever more)."""
    names = [name for name, _ in objective.terms]
    return "energy" in names and not any(name in ("time", "effort") for name in names)


def _read_cost(f: Fields) -> Objective:
    """``task.cost``: a descriptor (:func:`~modular_robots.costs.parse_objective`), or a mapping of
    ``minimise`` (a cost's name, or costs and their weights), ``then`` (costs of the design that
    break ties, in order) and ``within`` (the tie band, a fraction of the best first cost)."""
    value = f.raw("cost", "time")
    if not isinstance(value, dict):
        f.check("cost", isinstance(value, str), "expected a cost's name, a descriptor or a mapping")
        try:
            return parse_objective(value)
        except ValueError as e:
            raise f.fail("cost", str(e)) from None
    c = f.mapping("cost")
    first = c.raw("minimise")
    if isinstance(first, dict):
        weights = c.mapping("minimise")
        for name in first:
            weights.check(str(name), name in COSTS, f"unknown cost; expected one of {', '.join(COSTS)}")
        terms = tuple((name, weights.number(name, exclusive_minimum=0.0)) for name in first)
        weights.done()
    else:
        name = c.string("minimise", choices=tuple(COSTS))
        terms = ((name, 1.0),)
    then = c.raw("then", [])
    c.check("then", isinstance(then, list) and all(isinstance(n, str) for n in then), "expected a list of cost names")
    for name in then:
        c.check("then", name in COSTS, f"unknown cost {shorten(name)}; expected one of {', '.join(COSTS)}")
    within = c.number("within", default=DEFAULT_WITHIN if then else 0.0, minimum=0.0, maximum=1.0)
    c.done()
    try:
        return Objective(terms, tuple(then), within)
    except ValueError as e:
        raise c.fail(
            "then" if "after the first" in str(e) else "within" if "within" in str(e) else None, str(e)
        ) from None


#: The loosest position tolerance of an end [m]: looser, the tool may end anywhere on a table.
MAX_POSITION_TOLERANCE = 0.1


def _read_end(f: Fields, key: str) -> tuple[tuple[float, float, float], Orientation | None, float | None]:
    """``task.start`` or ``task.goal``: a position ``[x, y, z]``, or a mapping of ``position``
    and optionally ``rpy`` or ``axis``, ``angle_tolerance`` [rad] and ``position_tolerance`` [m]."""
    if not isinstance(f.raw(key), dict):
        return f.vector(key, 3), None, None
    end = f.mapping(key)
    position = end.vector("position", 3)
    for optional in ("rpy", "axis"):  # known keys, for the message of an unknown one
        end.raw(optional, None)
    rpy = end.rpy() if end.has("rpy") else None
    axis = end.vector("axis", 3) if end.has("axis") else None
    if rpy is not None and axis is not None:
        raise end.fail("axis", "give rpy (the whole orientation) or axis (the tool's z axis), not both")
    tolerance = end.number("angle_tolerance", default=None, exclusive_minimum=0.0, maximum=math.pi)
    if tolerance is not None and rpy is None and axis is None:
        raise end.fail("angle_tolerance", "an angle tolerance needs an orientation: add rpy or axis")
    if axis is not None:
        end.check("axis", math.hypot(*axis) > 1e-9, f"expected a direction, got the zero vector {list(axis)}")
    position_tolerance = end.number(
        "position_tolerance", default=None, exclusive_minimum=0.0, maximum=MAX_POSITION_TOLERANCE
    )
    end.done()
    orientation = None
    if rpy is not None or axis is not None:
        orientation = Orientation(rpy, axis, DEFAULT_ANGLE_TOLERANCE if tolerance is None else tolerance)
    return position, orientation, position_tolerance


def _read_floor(f: Fields, points: Sequence[tuple[str, tuple[float, ...]]]) -> float | None:
    """``task.floor``: a height [m] (default 0, the base's mounting plane) or ``none``."""
    value = f.raw("floor", 0.0)
    if value is None or value == "none":
        return None
    height = f.number("floor", default=0.0, maximum=MAX_FLOOR)
    for label, point in points:
        f.check(
            "floor",
            point[2] > height,
            f"the {label} position {list(point)} is not above the floor at z = {height:g} m; expected a floor "
            f"below the task (or none)",
        )
    return height


_DENSE = "the solver's matrices are dense: memory and time grow with the square of the problem's size"


def _read_optimizer(f: Fields | None) -> OptimizerSettings:
    if f is None:
        return OptimizerSettings()
    d = OptimizerSettings()
    settings = OptimizerSettings(
        nodes=f.integer("nodes", default=d.nodes, minimum=3, maximum=MAX_NODES, why=_DENSE),
        substeps=f.integer("substeps", default=d.substeps, minimum=1, maximum=MAX_SUBSTEPS, why=_DENSE),
        max_iterations=f.integer("max_iterations", default=d.max_iterations, minimum=1, maximum=MAX_ITERATIONS),
        tolerance=f.number("tolerance", default=d.tolerance, exclusive_minimum=0.0, maximum=MAX_TOLERANCE, why=_LOOSE),
        constraint_tolerance=f.number(
            "constraint_tolerance",
            default=d.constraint_tolerance,
            exclusive_minimum=0.0,
            maximum=MAX_TOLERANCE,
            why=_LOOSE,
        ),
        transcription=f.string("transcription", default=d.transcription, choices=TRANSCRIPTIONS),
        clearance_margin=f.number("clearance_margin", default=d.clearance_margin, minimum=0.0, maximum=1.0),
        effort_margin=f.number("effort_margin", default=d.effort_margin, exclusive_minimum=0.0, maximum=1.0),
        velocity_margin=f.number("velocity_margin", default=d.velocity_margin, exclusive_minimum=0.0, maximum=1.0),
        solver=f.string("solver", default=d.solver, choices=SOLVERS),
        free_ends=f.boolean("free_ends", default=d.free_ends),
    )
    f.done()
    return settings


def _read_pruning(f: Fields | None) -> PruningSettings:
    if f is None:
        return PruningSettings()
    d = PruningSettings()
    settings = PruningSettings(
        rule=f.string("rule", default=d.rule, choices=RULES),
        threshold=f.number("threshold", default=d.threshold, exclusive_minimum=0.0),
        start_iteration=f.integer("start_iteration", default=d.start_iteration, minimum=1, maximum=MAX_ITERATIONS),
        window=f.integer("window", default=d.window, minimum=0, maximum=MAX_ITERATIONS),
        lookahead=f.number("lookahead", default=d.lookahead, minimum=0.0),
        patience=f.integer("patience", default=d.patience, minimum=0, maximum=MAX_ITERATIONS),
        reference=f.string("reference", default=d.reference, choices=REFERENCES),
        gate=f.number("gate", default=d.gate, minimum=0.0),
        admission=f.integer("admission", default=d.admission, minimum=0, maximum=1_000_000),
    )
    f.done()
    return settings


def _read_execution(f: Fields | None) -> ExecutionSettings:
    if f is None:
        return ExecutionSettings()
    engine = f.string("engine", default=ExecutionSettings.engine, choices=ENGINES)
    address = f.string("address", default=None)
    if address is not None and engine != "ray":
        raise f.fail("address", "only the ray engine connects to a cluster; set engine: ray, or remove the key")
    problem = None if address is None else address_problem(address)
    if problem:
        raise f.fail("address", problem)
    timeout = f.number("connect_timeout", default=CONNECT_TIMEOUT, exclusive_minimum=0.0, maximum=3600.0)
    f.done()
    return ExecutionSettings(engine, address, timeout)


def load_scenario_or_catalog(path: str | Path) -> tuple[Scenario | None, Catalog]:
    """For commands that take either: a scenario file (has ``task``) or a bare catalogue."""
    path = Path(path)
    top = load_yaml(path, InputError)
    _not_a_cobra_task(top, "a scenario or a catalogue")
    if top.has("task"):
        scenario = _scenario_from_fields(top)
        return scenario, scenario.catalog
    return None, catalog_from_fields(top)
