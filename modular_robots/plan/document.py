"""``result.json``, the results document (SPEC §7, ``docs/formats.md``): the one module that knows
its keys, to write it and to read it back.

The writer's functions turn values (:class:`~modular_robots.plan.candidate.CandidateResult`,
:class:`~modular_robots.plan.verification.Verification`, ...) into the document's JSON objects,
in the documented key order; :class:`~modular_robots.recorder.RunRecorder` decides when the
document is written. :func:`read_document` reads a document back as
:class:`~modular_robots.plan.records.ResultDocument`, checking every value's type and range: a
folder is data a user may edit, and what is read from it ends up in a web page.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..composition import Composition
from ..costs import Design, design_of
from ..exceptions import InputError, shorten
from ..obstacles import obstacle_to_json
from .boundary import BoundaryPair
from .candidate import CandidateResult, CandidateStatus
from .fields import Node
from .records import (
    ApproachRecord,
    CandidateRecord,
    DrawnTask,
    LimitsUsed,
    ResultDocument,
    SettingsRecord,
    TaskRecord,
    Totals,
    VerificationRecord,
    WinnerFiles,
    WinnerRecord,
)
from .tracking import Tracking
from .trajectory import Trajectory
from .verification import Verification

if TYPE_CHECKING:
    from ..collision import Approach
    from ..goals import Goal
    from ..scenario import Scenario, Task

__all__ = [
    "RESULT",
    "STATUSES",
    "settings_json",
    "task_json",
    "candidate_json",
    "result_design",
    "candidate_summary_json",
    "winner_json",
    "status_counts",
    "stage_counts",
    "single_composition_counts",
    "result_json",
    "result_text",
    "read_document",
    "read_json",
    "named_winner_files",
    "winner_armature",
    "winner_plan_files",
    "drawn_task",
]

RESULT = "result.json"
#: ``running`` until the run ends; then ``done``, ``infeasible`` (no composition passes step B),
#: ``failed`` (no candidate verified, or an error), or ``interrupted``.
STATUSES = ("running", "done", "infeasible", "failed", "interrupted")


# -- writing --------------------------------------------------------------------------------------
def settings_json(scenario: Scenario, **extra: Any) -> dict:
    """The ``settings`` block: the optimizer and pruning settings, cost and payload, then
    ``extra`` (``jobs`` and ``engine``, or ``rule``)."""
    return {
        "optimizer": asdict(scenario.optimizer),
        "pruning": asdict(scenario.pruning),
        "cost": str(scenario.task.cost),
        "payload": scenario.task.payload,
        **extra,
    }


def task_json(task: Task) -> dict:
    """The ``task`` block, as the scenario gave it."""
    return {
        "payload": task.payload,
        "start": list(task.start),
        "goal": list(task.goal),
        "obstacles": [obstacle_to_json(o) for o in task.collision_obstacles],
        "cost": str(task.cost),
        "start_orientation": task.start_orientation.to_json() if task.start_orientation else None,
        "goal_orientation": task.goal_orientation.to_json() if task.goal_orientation else None,
        "start_tolerance": task.start_tolerance,
        "goal_tolerance": task.goal_tolerance,
        "max_time": task.max_time,
        **({"goals": [goal_json(g) for g in task.goals]} if task.goals else {}),
    }


def goal_json(goal: Goal) -> dict:
    """One of a task's ``goals``, as the scenario gives it (:mod:`~modular_robots.goals`)."""
    out: dict = {"kind": goal.kind, "id": goal.id}
    if goal.position is not None:
        out["position"] = list(goal.position)
        out["orientation"] = goal.orientation.to_json() if goal.orientation else None
        out["tolerance"] = goal.tolerance
    if goal.kind == "pause":
        out["duration"] = goal.duration
    if goal.kind == "return":
        out["to"] = goal.to
    return out


def _finite(value: float | None) -> float | None:
    return float(value) if value is not None and np.isfinite(value) else None


def verification_json(v: Verification) -> dict:
    out = {k: (None if isinstance(x, float) and not np.isfinite(x) else x) for k, x in asdict(v).items()}
    out["passed"] = v.passed
    return out


def candidate_json(r: CandidateResult, design: Design | None = None) -> dict:
    """One entry of ``candidates`` (non-finite numbers as ``null``), with its composition's
    ``design`` (mass, joints, modules, price: what the costs of the design read) when given."""
    return {
        "composition": r.composition or r.name,
        "design": asdict(design) if design is not None else None,
        "candidate": r.name,
        "boundary_pair": str(r.boundary_pair),
        "dof": r.dof,
        "q_start": list(r.q_start),
        "q_goal": list(r.q_goal),
        "status": str(r.status),
        "reason": r.reason,
        "iterations": r.iterations,
        "seconds": round(r.seconds, 4),
        "cost": _finite(r.cost),
        "tf": _finite(r.tf),
        "constraint_violation": _finite(r.constraint_violation),
        "pruned_at_iteration": r.pruned_at_iteration,
        "cost_bound": _finite(r.cost_bound),
        "substeps": r.substeps,
        "verification": verification_json(r.verification) if r.verification else None,
        "cost_history": [_finite(c) for c in r.cost_history],
        "violation_history": [_finite(c) for c in r.violation_history],
        "refinement_history": list(r.refinement_history),
        **({"stop_times": list(r.stop_times)} if r.stop_times else {}),
    }


def result_design(result: CandidateResult, scenario: Scenario) -> Design:
    """The :class:`~modular_robots.costs.Design` of ``result``'s composition."""
    modules = Composition.from_name(result.composition or result.name, scenario.catalog).modules
    return design_of(modules, scenario.catalog)


def _design(r: CandidateResult, scenario: Scenario) -> Design | None:
    try:
        return result_design(r, scenario)
    except (InputError, ValueError):  # a name the catalogue does not know (an optimize run's own)
        return None


def candidate_summary_json(r: CandidateResult) -> dict:
    """The short form of an entry of ``candidates`` (what fits where nothing else does)."""
    return {"candidate": r.name, "status": str(r.status)}


def winner_json(
    result: CandidateResult, files: WinnerFiles, tracking: Tracking | None, approach: Approach | None = None
) -> dict:
    """The ``winner`` block of an optimal ``result``: its figures, checks, drives and ``files``."""
    trajectory = result.trajectory
    return {
        "composition": result.composition or result.name,
        "candidate": result.name,
        "boundary_pair": str(result.boundary_pair),
        "dof": result.dof,
        "cost": result.cost,
        "tf": result.tf,
        "iterations": result.iterations,
        "seconds": round(result.seconds, 4),
        "substeps": result.substeps,
        "verification": verification_json(result.verification) if result.verification else None,
        "limits_used": _limits_used(trajectory, result.verification) if trajectory is not None else None,
        "tracking": {k: float(v) for k, v in asdict(tracking).items()} if tracking is not None else None,
        "closest_approach": (
            {
                "clearance": approach.clearance,
                "t": approach.t,
                "primitive": approach.primitive,
                "obstacle": approach.obstacle,
            }
            if approach is not None
            else None
        ),
        "drive": result.drive,
        "files": files.by_kind(),
    }


def _limits_used(trajectory: Trajectory, verification: Verification | None) -> dict:
    """Per joint, the largest share of its effort and velocity limit the plan uses: at its rows
    and, where verification measured it, on its dense grid between them."""

    def share(values, limit, dense):
        rows = np.max(np.abs(values), axis=0) / np.where(limit > 0, limit, np.inf)
        return [float(v) for v in (np.maximum(rows, dense) if len(dense) == len(rows) else rows)]

    effort, velocity = (verification.effort_share, verification.velocity_share) if verification else ((), ())
    return {
        "effort": share(trajectory.tau, trajectory.effort_limit, effort),
        "velocity": share(trajectory.qd, trajectory.velocity_limit, velocity),
    }


def status_counts(results: Iterable[CandidateResult]) -> dict[str, int]:
    """Candidates per status, for ``counts``; ``stopped``: not started, or closed before they
    ended (while a run goes on, and after an interruption or an error)."""
    statuses = [r.status for r in results]
    return {str(s): statuses.count(s) for s in CandidateStatus}


def stage_counts(optimized: int, candidates: int) -> dict[str, int]:
    """``counts`` of step C: compositions ``optimized`` and their ``candidates``."""
    return {"optimized": optimized, "candidates": candidates}


def single_composition_counts(candidates: int) -> dict[str, int]:
    """``counts`` of an ``optimize`` run: one composition, feasible, its ``candidates``."""
    return {"enumerated": 1, "feasible": 1, **stage_counts(1, candidates)}


def result_json(
    scenario: Scenario,
    *,
    status: str,
    message: str,
    settings: dict,
    counts: dict,
    seconds: Mapping[str, float],
    results: Sequence[CandidateResult],
    winner: dict | None,
    wall_seconds: float,
    short: bool = False,
    search: dict | None = None,
) -> dict:
    """The whole document; ``partial`` is true while the run goes on and for an interrupted one.
    ``short``: the candidates in their short form (:func:`candidate_summary_json`). ``search``: a
    best-first search's block (its progress and certificate), written when given."""
    document = {
        "scenario": scenario.name,
        "scenario_file": str(scenario.path) if scenario.path else None,
        "status": status,
        "partial": status in ("running", "interrupted"),
        "message": message,
        "settings": settings,
        "task": task_json(scenario.task),
        "counts": counts,
        "seconds": {k: round(v, 4) for k, v in seconds.items()},
        "candidates": [
            candidate_summary_json(r) if short else candidate_json(r, _design(r, scenario)) for r in results
        ],
        "winner": winner,
        "totals": {
            "optimizer_iterations": int(sum(r.iterations for r in results)),
            "wall_seconds": round(wall_seconds, 3),
        },
    }
    if search is not None:
        document["search"] = search
    return document


def result_text(document: dict, allow_nan: bool = False) -> str:
    """The document as the file holds it."""
    return json.dumps(document, indent=1, allow_nan=allow_nan) + "\n"


# -- reading --------------------------------------------------------------------------------------
def read_json(folder: str | Path) -> Any:
    """The JSON of ``folder``'s ``result.json``, unchecked.

    Raises
    ------
    InputError
        If the folder has no ``result.json``, or it is unreadable or not JSON.
    """
    path = Path(folder) / RESULT
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{folder}: no {RESULT}; expected the results folder of a run") from None
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise InputError(f"{path}: expected the JSON a run writes ({shorten(exc, 120, quote=False)})") from None


def read_document(folder: str | Path, require_winner: bool = False, obstacles: bool = True) -> ResultDocument:
    """``folder``'s ``result.json``, checked; with ``require_winner``, one that has a winner.
    Without ``obstacles``, the task's obstacles are not read (its ``obstacles`` is empty): what
    needs only the robot and its plan (``export``, ``--ros2``) does not depend on the meshes the
    run read being where they were.

    Raises
    ------
    InputError
        Naming the file, the value's path and what was expected: no or unreadable
        ``result.json``, no winner (with the run's status) when one is required, a value of the
        wrong type or out of range, or a winner file that is not a plain name in the folder.
    """
    data = read_json(folder)
    source = str(Path(folder) / RESULT)
    if require_winner and not (isinstance(data, dict) and isinstance(data.get("winner"), dict)):
        status = data.get("status") if isinstance(data, dict) else None
        raise InputError(f"{source}: no winner to read (the run's status is {status!r})")
    return _document(Node(data, source), obstacles)


def _document(n: Node, obstacles: bool = True) -> ResultDocument:
    return ResultDocument(
        source=n.source,
        scenario=n["scenario"].string(),
        scenario_file=n["scenario_file"].optional(Node.string),
        status=n["status"].string(STATUSES),
        partial=n["partial"].boolean(),
        message=n["message"].string(),
        settings=_settings(n["settings"]),
        task=_task(n["task"], obstacles),
        counts=n["counts"].counts(),
        seconds={k: n["seconds"][k].number(0.0) for k in n["seconds"].obj()},
        candidates=tuple(_candidate(c) for c in n["candidates"].items()),
        winner=n["winner"].optional(_winner),
        totals=Totals(n["totals"]["optimizer_iterations"].integer(), n["totals"]["wall_seconds"].number(0.0)),
    )


def _settings(n: Node) -> SettingsRecord:
    known = ("optimizer", "pruning", "cost", "payload")
    optimizer = n["optimizer"]
    return SettingsRecord(
        cost=n["cost"].string(),
        payload=n["payload"].number(0.0),
        clearance_margin=optimizer["clearance_margin"].number(0.0),
        optimizer=optimizer.obj(),
        pruning=n["pruning"].obj(),
        extra={k: v for k, v in n.obj().items() if k not in known},
    )


def _task(n: Node, obstacles: bool = True) -> TaskRecord:
    shapes = n["obstacles"].items()
    return TaskRecord(
        payload=n["payload"].number(0.0),
        start=n["start"].numbers(size=3),
        goal=n["goal"].numbers(size=3),
        obstacles=tuple(o.obstacle() for o in shapes) if obstacles else (),
        cost=n["cost"].string(),
        waypoints=_waypoints(n),
    )


def _waypoints(task: Node) -> tuple[tuple[float, ...], ...]:
    """The positions of a task's goals on the way (``goals``; none for one move): each that has
    one, but the last goal's when the motion ends there (not when it ends with a return)."""
    if not task.has("goals"):
        return ()
    goals = task["goals"].items()
    positions = [g["position"].numbers(size=3) for g in goals if g.has("position")]
    moving = [g for g in goals if g["kind"].string() != "pause"]
    ends_at_pose = bool(moving) and moving[-1].has("position")
    return tuple(positions[:-1] if ends_at_pose else positions)


def _design_record(n: Node) -> Design:
    return Design(
        mass=n["mass"].number(0.0),
        joints=n["joints"].integer(),
        modules=n["modules"].integer(),
        price=_nullable(n["price"], 0.0),
    )


def _nullable(n: Node, minimum: float = -math.inf) -> float | None:
    return n.optional(lambda m: m.number(minimum))


def _verification(n: Node) -> VerificationRecord:
    return VerificationRecord(
        terminal_error=_nullable(n["terminal_error"], 0.0),
        terminal_speed=_nullable(n["terminal_speed"], 0.0),
        max_defect=_nullable(n["max_defect"], 0.0),
        min_clearance=_nullable(n["min_clearance"]),
        position_excess=_nullable(n["position_excess"], 0.0),
        velocity_ratio=_nullable(n["velocity_ratio"], 0.0),
        torque_ratio=_nullable(n["torque_ratio"], 0.0),
        grid_points=n["grid_points"].integer(),
        substeps=n["substeps"].integer(),
        velocity_share=n["velocity_share"].numbers(0.0),
        effort_share=n["effort_share"].numbers(0.0),
        orientation_excess=n["orientation_excess"].number(0.0) if n.has("orientation_excess") else 0.0,
        passed=n["passed"].boolean(),
        duration_excess=n["duration_excess"].number(0.0) if n.has("duration_excess") else 0.0,
        goal_excess=n["goal_excess"].number(0.0) if n.has("goal_excess") else 0.0,
    )


def _candidate(n: Node) -> CandidateRecord:
    name, status = n["candidate"].string(), CandidateStatus(n["status"].string(tuple(CandidateStatus)))
    if set(n.obj()) == {"candidate", "status"}:
        return CandidateRecord(name, status)
    return CandidateRecord(
        candidate=name,
        status=status,
        composition=n["composition"].string(),
        design=n["design"].optional(_design_record) if n.has("design") else None,
        boundary_pair=BoundaryPair(n["boundary_pair"].string(tuple(BoundaryPair))),
        dof=n["dof"].integer(),
        q_start=n["q_start"].numbers(),
        q_goal=n["q_goal"].numbers(),
        reason=n["reason"].string(),
        iterations=n["iterations"].integer(),
        seconds=n["seconds"].number(0.0),
        cost=_nullable(n["cost"]),
        tf=_nullable(n["tf"], 0.0),
        constraint_violation=_nullable(n["constraint_violation"]),
        pruned_at_iteration=n["pruned_at_iteration"].optional(Node.integer),
        cost_bound=_nullable(n["cost_bound"]),
        substeps=n["substeps"].integer(),
        verification=n["verification"].optional(_verification),
        cost_history=tuple(_nullable(c) for c in n["cost_history"].items()),
        violation_history=tuple(_nullable(c) for c in n["violation_history"].items()),
        refinement_history=tuple(c.integer() for c in n["refinement_history"].items()),
    )


def _file(n: Node) -> str:
    name = n.value
    if not isinstance(name, str) or not name or "/" in name:
        raise InputError(f"{n.source}: {n.path}: expected a file of this folder, got {shorten(name)}")
    return name


def _files(n: Node) -> WinnerFiles:
    return WinnerFiles(**{f.name: n[f.name].optional(_file) for f in fields(WinnerFiles)})


def _winner(n: Node) -> WinnerRecord:
    approach, used, tracking = n["closest_approach"], n["limits_used"], n["tracking"]
    return WinnerRecord(
        composition=n["composition"].string(),
        candidate=n["candidate"].string(),
        boundary_pair=BoundaryPair(n["boundary_pair"].string(tuple(BoundaryPair))),
        dof=n["dof"].integer(1),
        cost=n["cost"].number(),
        tf=n["tf"].number(0.0, above=True),
        iterations=n["iterations"].integer(),
        seconds=n["seconds"].number(0.0),
        substeps=n["substeps"].integer(1),
        verification=n["verification"].optional(_verification),
        limits_used=used.optional(lambda m: LimitsUsed(m["effort"].numbers(0.0), m["velocity"].numbers(0.0))),
        tracking=tracking.optional(lambda m: Tracking(**{f.name: m[f.name].number(0.0) for f in fields(Tracking)})),
        closest_approach=approach.optional(
            lambda m: ApproachRecord(
                m["clearance"].number(), m["t"].number(0.0), m["primitive"].string(), m["obstacle"].integer()
            )
        ),
        drive=n["drive"].optional(Node.obj),
        files=_files(n["files"]),
    )


def named_winner_files(folder: str | Path) -> set[str]:
    """The names the winner of ``folder``'s ``result.json`` lists as its files, if that document is
    one of ours (a run's status and settings); none if it is missing, unreadable or not ours.
    Never raises: a run about to start must not be stopped by a previous run's damaged file."""
    try:
        document = json.loads((Path(folder) / RESULT).read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):  # missing, unreadable, not JSON (or not UTF-8)
        return set()
    if not isinstance(document, dict) or document.get("status") not in STATUSES or "settings" not in document:
        return set()
    winner = document.get("winner")
    files = winner.get("files") if isinstance(winner, dict) else None
    return {n for n in files.values() if isinstance(n, str)} if isinstance(files, dict) else set()


def winner_armature(document: ResultDocument, nv: int) -> list[float] | None:
    """The armature [kg m^2 | kg] of each of the winner's ``nv`` joints (``None``: not recorded).

    Raises
    ------
    InputError
        If it is not ``nv`` numbers >= 0.
    """
    drive = document.winner.drive if document.winner is not None else None
    armature = drive.get("armature") if drive is not None else None
    if armature is None:
        return None
    if (
        not isinstance(armature, list)
        or len(armature) != nv
        or not all(isinstance(a, (int, float)) and not isinstance(a, bool) and 0.0 <= a < 1e9 for a in armature)
    ):
        raise InputError(
            f"{document.source}: winner.drive.armature: expected {nv} numbers >= 0 (one per joint), "
            f"got {shorten(armature)}"
        )
    return armature


def winner_plan_files(document: ResultDocument, folder: Path) -> tuple[Path, Path]:
    """The paths of the winner's URDF and trajectory in ``folder``.

    Raises
    ------
    InputError
        If the document has no winner, or either is not a file of the folder.
    """
    if document.winner is None:
        raise InputError(f"{document.source}: no winner to read (the run's status is {document.status!r})")
    files = document.winner.files
    for kind, name in (("urdf", files.urdf), ("trajectory", files.trajectory)):
        if name is None or not (folder / name).is_file():
            raise InputError(
                f"{document.source}: winner.files.{kind}: expected a file of this folder, got {shorten(name)}"
            )
    return folder / str(files.urdf), folder / str(files.trajectory)


def drawn_task(document: ResultDocument | Mapping[str, Any]) -> DrawnTask:
    """What a page draws of the task, from a document read or from its JSON as is, whose parts
    may be missing (no start or goal, no obstacles, a margin of 0)."""
    if isinstance(document, ResultDocument):
        read = document.task
        return DrawnTask(read.start, read.goal, read.obstacles, document.settings.clearance_margin, read.waypoints)
    n = Node(document, RESULT)
    task = n["task"] if n.has("task") else Node({}, RESULT, "task")
    settings = n["settings"] if n.has("settings") else Node({}, RESULT, "settings")
    optimizer = settings["optimizer"] if settings.has("optimizer") else Node({}, RESULT, "settings.optimizer")
    return DrawnTask(
        start=task["start"].optional(lambda m: m.numbers(size=3)),
        goal=task["goal"].optional(lambda m: m.numbers(size=3)),
        obstacles=tuple(o.obstacle() for o in task["obstacles"].items()) if task.has("obstacles") else (),
        clearance_margin=optimizer["clearance_margin"].number(0.0) if optimizer.has("clearance_margin") else 0.0,
        waypoints=_waypoints(task),
    )
