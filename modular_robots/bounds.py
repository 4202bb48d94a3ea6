"""Lower bounds on a composition's optimal cost from catalogue numbers alone, before step B.

A best-first search (:mod:`~modular_robots.search`) checks compositions in the order of these
bounds and stops when the smallest bound left is not below the best verified cost, so every bound
here must be *valid*: never above the cost of any plan the pipeline can verify. Each is cheap
(no robot model, no IK: microseconds), so that it can be evaluated for millions of compositions.
Their proofs are in ``docs/design-notes.md`` ("Bounds before step B"); ``tests/test_bounds.py``
checks them against the tool speeds of random motions (Pinocchio's Jacobians) and against solved
optima.

``tool speed`` (the time cost): the tool must cover the distance between the tolerated start and
goal positions, and it cannot move faster than the sum, over the joints, of each joint's velocity
limit times an upper bound on the tool's distance from its axis (its *lever*, from the catalogue's
lengths by the triangle inequality; a prismatic joint moves the tool at its own speed). A cost
of the design (mass, joints, modules, price) is its own bound; a weighted sum's bound is the
weighted sum of its terms' (:func:`objective_bound`). The motion's other costs (effort) have no
bound here (0): a task minimising them alone is ordered by nothing and certified by nothing.
"""

from __future__ import annotations

import functools
import math
import typing
from dataclasses import dataclass

import numpy as np

from .assembly import AssemblyBlock
from .catalog import Catalog
from .composition import Composition
from .costs import COSTS, Design, DesignCost, Objective, design_of
from .feasibility import _piece_reach, _reach_along
from .goals import tool_path_gap
from .modules import Joint
from .plan.verification import GOAL_TOLERANCE, LIMIT_TOLERANCE, TERMINAL_TOLERANCE
from .scenario import Task
from .urdf_assembly import RX_PI, matrix

__all__ = [
    "Lever",
    "CatalogBound",
    "joint_levers",
    "tool_speed_limit",
    "block_speed_limits",
    "catalog_bound",
    "block_bounds",
    "objective_bound",
    "TOOL_SPEED",
    "IK_TRAVEL",
    "JOINT_TRAVEL",
    "DESIGN",
]

#: The bounds' names, as the certificate gives them: before step B (:func:`catalog_bound`), after
#: the relaxed step B (its IK solutions' joint travel) and after step B (a candidate's problem's).
TOOL_SPEED = "tool speed"
IK_TRAVEL = "joint travel of the IK solutions"
JOINT_TRAVEL = "joint travel"
#: The bound of an objective of the design's costs alone: their values.
DESIGN = "design"


@dataclass(frozen=True)
class Lever:
    """A joint as the tool's speed sees it: ``prismatic`` or revolute, its velocity limit
    [rad/s or m/s] and an upper bound on the tool's distance from its axis [m] (0 for a prismatic
    joint, which moves the tool at its own speed)."""

    prismatic: bool
    velocity: float
    distance: float

    @property
    def speed(self) -> float:
        """The largest tool speed this joint alone can give [m/s]."""
        return self.velocity if self.prismatic else self.velocity * self.distance


@dataclass(frozen=True)
class CatalogBound:
    """A bound's ``name`` and ``value`` [SI] (0 where the cost has none)."""

    name: str
    value: float


def joint_levers(composition: Composition, catalog: Catalog) -> tuple[Lever, ...]:
    """Every joint of ``composition`` from the base to the tool, with its velocity limit and its
    lever: the sum of the largest lengths of the rigid pieces between its axis and the tool (the
    reach test's pieces, :func:`~modular_robots.feasibility.max_reach`, after the axis)."""
    if catalog.general:
        return _general_levers(composition, catalog)
    return _simple_levers(composition, catalog)


def _simple_levers(composition: Composition, catalog: Catalog) -> tuple[Lever, ...]:
    """A revolute module turns about its inlet's axis: the lever is the reach of the chain after
    it, the whole reach less the pieces before that axis (each piece's length is bounded alone, so
    the pieces after the axis bound the distance from it to the tool)."""
    modules = composition.modules
    total, _, offset, strokes = _reach_along(catalog, modules)
    reach = total + _piece_reach(offset, strokes)
    levers = []
    for k, module_id in enumerate(modules):
        module = catalog.module(module_id)
        if module.joint == "fixed":
            continue
        assert module.limits is not None  # a movable module has limits
        if module.joint == "prismatic":
            levers.append(Lever(True, module.limits.velocity, 0.0))
        else:
            before = _reach_along(catalog, modules[: k + 1])[0]  # the pieces up to this axis
            levers.append(Lever(False, module.limits.velocity, max(reach - before, 0.0)))
    return tuple(levers)


def _general_levers(composition: Composition, catalog: Catalog) -> tuple[Lever, ...]:
    """The rigid piece between two consecutive joint origins (or the last one and the tool) has
    the length of the translation between them, whatever the first joint's angle (its origin is
    on its axis), plus the stroke of a prismatic joint at its start: a revolute joint's lever is
    the sum of the pieces after its origin (the robot model's
    :meth:`~modular_robots.robot.RobotModel.tool_speed_bound`, from catalogue numbers)."""
    frame, pieces, joints, stroke = _general_walk(catalog, composition.modules)
    if joints:
        pieces = (*pieces, _distance(frame, _ORIGIN) + stroke)
    after = np.cumsum(pieces[::-1])[::-1]  # the pieces from each joint's origin to the tool
    return tuple(
        Lever(joint.type == "prismatic", joint.velocity, 0.0 if joint.type == "prismatic" else float(rest))
        for joint, rest in zip(joints, after)
    )


@functools.lru_cache(maxsize=65536)  # assemblies share their chains but for the last modules
def _general_walk(
    catalog: Catalog, modules: tuple[str, ...]
) -> tuple[np.ndarray, tuple[float, ...], tuple[Joint, ...], float]:
    """After the chain ``modules``: the frame of its last outlet (composed with ``Rx(pi)``) in the
    frame of its last joint (the base's before any), the pieces between consecutive joint origins,
    the joints, and the stroke of the last joint if it is prismatic."""
    if not modules:
        return RX_PI, (), (), 0.0
    frame, pieces, joints, stroke = _general_walk(catalog, modules[:-1])
    inlet, steps, outlet = _module_frames(catalog, modules[-1])
    frame = frame @ inlet
    for joint, parent, child in steps:
        if joints:
            pieces = (*pieces, _distance(frame, parent[:, 3]) + stroke)
        joints = (*joints, joint)
        stroke = max(abs(joint.lower), abs(joint.upper)) if joint.type == "prismatic" else 0.0
        frame = child
    return frame @ outlet, pieces, joints, stroke


@functools.lru_cache(maxsize=1024)
def _module_frames(
    catalog: Catalog, module_id: str
) -> tuple[np.ndarray, tuple[tuple[Joint, np.ndarray, np.ndarray], ...], np.ndarray]:
    """A module's inlet body in its inlet's frame, its joints with their parent and child poses,
    and its outlet composed with ``Rx(pi)``, as matrices."""
    module = catalog.general_module(module_id)
    steps = tuple(
        (joint, matrix(joint.parent_pose), matrix(joint.child_pose))
        for _, joint in module.chain()[1:]
        if joint is not None
    )
    return np.linalg.inv(matrix(module.inlet.pose)), steps, matrix(module.outlet.pose) @ RX_PI


def tool_speed_limit(composition: Composition, catalog: Catalog) -> float:
    """An upper bound on the tool's speed [m/s] of ``composition`` within its velocity limits, in
    any configuration: the sum of :attr:`Lever.speed` (infinite if a joint has no finite limit)."""
    if catalog.general:
        frame, partial, revolute, stroke, prismatic = _general_speed(catalog, composition.modules)
        speed = partial + prismatic
        if revolute:  # Rx(pi) moves no origin: the tool's is the frame's own
            speed += revolute * (_distance(frame, _ORIGIN) + stroke)
    else:
        speed = sum(lever.speed for lever in joint_levers(composition, catalog))
    return float(speed) if math.isfinite(speed) else math.inf


@functools.lru_cache(maxsize=65536)
def _general_speed(catalog: Catalog, modules: tuple[str, ...]) -> tuple[np.ndarray, float, float, float, float]:
    """:func:`_general_walk` summed as it goes, for millions of assemblies: each piece counts
    once for every revolute joint before it, so the speed bound is the sum of each piece times the
    velocity limits of the revolute joints up to its start, plus the prismatic joints' limits.
    After the chain ``modules``: the last outlet's frame (as in :func:`_general_walk`), that sum
    over the pieces closed so far, the revolute joints' summed limits, the last joint's stroke,
    and the prismatic joints' summed limits."""
    if not modules:
        return RX_PI, 0.0, 0.0, 0.0, 0.0
    frame, partial, revolute, stroke, prismatic = _general_speed(catalog, modules[:-1])
    inlet, steps, outlet = _module_frames(catalog, modules[-1])
    frame = frame @ inlet
    for joint, parent, child in steps:
        if revolute or prismatic:
            partial += revolute * (_distance(frame, parent[:, 3]) + stroke)
        revolute, prismatic, stroke = _past(joint, revolute, prismatic)
        frame = child
    return frame @ outlet, partial, revolute, stroke, prismatic


def _past(joint: Joint, revolute: float, prismatic: float) -> tuple[float, float, float]:
    """The revolute and the prismatic joints' summed velocity limits once past ``joint``, and its
    stroke (0 for a revolute joint)."""
    if joint.type == "prismatic":
        return revolute, prismatic + joint.velocity, max(abs(joint.lower), abs(joint.upper))
    return revolute + joint.velocity, prismatic, 0.0


_ORIGIN = np.array([0.0, 0.0, 0.0, 1.0])


def block_speed_limits(catalog: Catalog, block: AssemblyBlock) -> np.ndarray | None:
    """:func:`tool_speed_limit` of every assembly of ``block`` at once, equal to the last bit:
    an array with an axis per gap (:attr:`~modular_robots.assembly.AssemblyBlock.shape`, the
    assemblies in the block's order when flattened). None where it does not apply: a catalogue of
    convention A, a gap not held in memory, a base, link or effector module with joints.

    The piece from a joint's origin to the next one's (or to the tool) depends only on the
    modules between them, so a gap's pieces are measured once per run, and the running sum of
    :func:`_general_speed` becomes an outer sum over the gaps, term by term in its order."""
    shape = block.shape
    if not catalog.general or shape is None or not _jointless(catalog, block):
        return None
    gaps = typing.cast("tuple[tuple[tuple[str, ...], ...], ...]", block.gaps)
    partial = np.zeros(())
    revolute = prismatic = stroke = 0.0
    before = block.base
    for gap, module in zip(gaps, block.joints, strict=False):
        steps = _module_frames(catalog, module)[1]
        if revolute or prismatic:
            pieces = _gap_pieces(catalog, before, gap, module)
            partial = partial[..., None] + revolute * (pieces + stroke)
        else:
            partial = np.repeat(partial[..., None], len(gap), axis=-1)
        for k, (joint, parent, _) in enumerate(steps):
            if k and (revolute or prismatic):
                partial = partial + revolute * (_distance(steps[k - 1][2], parent[:, 3]) + stroke)
            revolute, prismatic, stroke = _past(joint, revolute, prismatic)
        before = module
    speed = partial + prismatic
    if revolute:
        speed = speed[..., None] + revolute * (_gap_pieces(catalog, before, gaps[-1], block.effector) + stroke)
    else:
        speed = np.repeat(speed[..., None], len(gaps[-1]), axis=-1)
    return np.where(np.isfinite(speed), speed, math.inf)


def _jointless(catalog: Catalog, block: AssemblyBlock) -> bool:
    """Whether the block's base, effector and link modules have no joints."""
    links = _link_ids(catalog)
    return not (_module_frames(catalog, block.base)[1] or _module_frames(catalog, block.effector)[1]) and all(
        not _module_frames(catalog, m)[1] for m in links
    )


@functools.lru_cache(maxsize=64)
def _link_ids(catalog: Catalog) -> tuple[str, ...]:
    return tuple(m.id for m in catalog.modules if catalog.general_module(m.id).kind == "link")


@functools.lru_cache(maxsize=256)  # a pass meets few (module, gap, module) triples; each holds a float per run
def _gap_pieces(catalog: Catalog, before: str, gap: tuple[tuple[str, ...], ...], after: str) -> np.ndarray:
    """For each run of ``gap``: the distance from the last joint's origin of module ``before``
    to the first joint's origin of ``after`` (to its outlet, the tool, for an effector without
    joints), through the run, each frame composed as :func:`_general_speed` composes it."""
    start = _module_frames(catalog, before)
    assert start[1], "a joint module before every gap that moves the tool"
    origin = start[1][-1][2] @ start[2]
    inlet, steps, outlet = _module_frames(catalog, after)
    pieces = np.empty(len(gap))
    for i, run in enumerate(gap):
        frame = origin
        for module in run:
            m_inlet, _, m_outlet = _module_frames(catalog, module)
            frame = frame @ m_inlet @ m_outlet
        frame = frame @ inlet
        pieces[i] = _distance(frame, steps[0][1][:, 3]) if steps else _distance(frame @ outlet, _ORIGIN)
    return pieces


def _distance(frame: np.ndarray, point: np.ndarray) -> float:
    """The norm of ``frame @ point``'s position (``point`` homogeneous): what
    ``np.linalg.norm((frame @ pose)[:3, 3])`` gives for a pose whose last column is ``point``, at a
    third of its cost (the first pass bounds millions of assemblies)."""
    x, y, z, _ = (frame @ point).tolist()
    return math.sqrt(x * x + y * y + z * z)


def catalog_bound(composition: Composition, catalog: Catalog, task: Task, tolerance: float) -> CatalogBound:
    """The lower bound on ``composition``'s optimal cost for ``task`` before step B.

    For the time (:data:`TOOL_SPEED`) [s]: the distance between the start and the goal less
    both position tolerances (``task``'s, else step B's IK ``tolerance`` [m]) and verification's
    terminal tolerance, over :func:`tool_speed_limit` raised by verification's limit tolerance;
    for a task of several goals, the tool's path through them
    (:func:`~modular_robots.goals.tool_path_gap`) less verification's tolerances, at that speed,
    plus the pauses. For the task's objective, :func:`objective_bound` of that time (``none``
    when it is 0)."""
    objective = task.cost
    time = 0.0
    if objective.counts_time:
        speed = tool_speed_limit(composition, catalog) * (1.0 + LIMIT_TOLERANCE)
        gap, paused = _task_gap(task, tolerance)
        time = (max(gap, 0.0) / speed if 0.0 < speed < math.inf else 0.0) + paused
    value = objective_bound(
        objective, time, design_of(composition.modules, catalog) if objective.counts_design else None
    )
    if value <= 0.0:
        return CatalogBound("none", 0.0)
    return CatalogBound(TOOL_SPEED if time > 0.0 else DESIGN, value)


def block_bounds(block: AssemblyBlock, catalog: Catalog, task: Task, tolerance: float) -> np.ndarray | None:
    """:func:`catalog_bound`'s values for every assembly of ``block``, equal to the last bit, in
    the block's order (flattened). None where :func:`block_speed_limits` does not apply or the
    objective has a cost of the design (whose bound is computed per composition)."""
    objective = task.cost
    if objective.counts_design or not objective.counts_time:
        return None
    limits = block_speed_limits(catalog, block)
    if limits is None:
        return None
    speed = limits.ravel() * (1.0 + LIMIT_TOLERANCE)
    gap, paused = _task_gap(task, tolerance)
    moving = (speed > 0.0) & (speed < math.inf)
    time = np.where(moving, max(gap, 0.0) / np.where(moving, speed, 1.0), 0.0) + paused
    value = np.zeros_like(time)
    for name, weight in objective.terms:
        if name == "time":
            value = value + weight * time
    return np.where(value <= 0.0, 0.0, value)


def _task_gap(task: Task, tolerance: float) -> tuple[float, float]:
    """The distance [m] the tool must cover at least, and the pauses [s], for :func:`catalog_bound`."""
    if task.goals:
        gap = tool_path_gap(task.start, task.start_tolerance or tolerance, task.goals, tolerance)
        gap -= TERMINAL_TOLERANCE + GOAL_TOLERANCE * sum(g.moves for g in task.goals)
        return gap, math.fsum(g.duration for g in task.goals)
    gap = math.dist(task.start, task.goal) - (task.start_tolerance or tolerance) - (task.goal_tolerance or tolerance)
    return gap - TERMINAL_TOLERANCE, 0.0


def objective_bound(objective: Objective, time: float, design: Design | None) -> float:
    """A lower bound on the sum ``objective`` minimises, given a lower bound ``time`` [s] on the
    motion's duration and the robot's ``design`` (needed when the sum has a cost of the design):
    each term's weight times ``time`` for the time, times its value for a cost of the design, 0
    for another cost of the motion (none is known)."""
    total = 0.0
    for name, weight in objective.terms:
        if name == "time":
            total += weight * time
        elif isinstance(COSTS[name], DesignCost):
            total += weight * COSTS[name].value(design)  # type: ignore[attr-defined]
    return total
