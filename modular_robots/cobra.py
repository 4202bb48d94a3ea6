"""Import a CoBRA task (TUM's benchmark format, version 2022, as Timor writes it) as a scenario.

A CoBRA task places the robot's base at a pose in the world (``basePlacement``), lists goals in
the world frame and obstacles as boxes, cylinders, spheres and meshes. The scenario it becomes
is in the base frame: every pose is moved by the inverse of the base placement. What maps, and
how (``docs/formats.md``, "import-cobra"):

* CoBRA's start is free. The first goal (``at`` or ``reach``) becomes the scenario's start, the
  robot at rest there; the other goals follow in order: ``at``, ``reach``, ``pause``, and
  ``returnTo`` (to ``returnToGoal``, the start when absent, null or naming the first goal; a
  pause's ID stands for the goal the robot pauses at). An ``at`` goal that a ``returnTo`` names
  becomes a ``reach``: CoBRA compares the joint state there with the return's, velocity and
  acceleration included, and a return ends at rest.
* A tolerated pose's ``r_sph`` (``[0, r]``) is the position tolerance, ``Theta_R`` (``[0, a]``)
  the angle tolerance about the nominal orientation; ``x``, ``y``, ``z`` bounds symmetric about 0
  give the ball inside them (stricter than the box: a plan within it meets the task). Any other
  projection, a pose without a position projection, a pose given in another frame
  (``nominalParent``): refused, naming the goal.
* ``selfCollisionFree`` turns the self-collision check on, ``collisionFree`` keeps the obstacles
  (without it they are left out); the joint constraints are always kept (position, velocity and
  torque); there is no floor (the task's world is its obstacles).
* A mesh is copied beside the scenario; a mesh path outside the task's folder is refused.
* The cost: a CoBRA descriptor (``cyc``, ``mechEnergy``, ``mass``, ``numJ`` and weighted sums such
  as ``cyc_2,mass_0.1``) becomes the scenario's cost (time, energy, mass, joints); a name without
  a weight has Timor's default (``mass`` 0.05, ``numJ`` 0.1, the others 1).

The scenario's ``cobra`` block keeps what a solution document needs
(:mod:`~modular_robots.cobra_solution`): the task's ID and version, its time step, the base pose
and the goals' ids.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import yaml

from ._yamlio import MAX_FILE_BYTES
from .exceptions import ScenarioError, shorten
from .folder import atomic_path
from .urdf_assembly import rpy_from_matrix

__all__ = ["CobraImport", "import_cobra", "COBRA_COSTS", "COBRA_DEFAULT_WEIGHTS", "cobra_cost", "cobra_terms"]

#: CoBRA's cost abbreviations and the scenario's costs they are (Timor's ``CostFunctions``).
COBRA_COSTS = {"cyc": "time", "mechEnergy": "energy", "mass": "mass", "numJ": "joints"}
#: The weight of a cost named without one (Timor's ``default_weight``: ``mass`` is ``mass_0.05``).
COBRA_DEFAULT_WEIGHTS = {"cyc": 1.0, "mechEnergy": 1.0, "mass": 0.05, "numJ": 0.1}
#: CoBRA costs with no counterpart here, and why.
_UNSUPPORTED_COSTS = {
    "effort": "CoBRA's effort is the sum of |tau| over the samples, not the integral of squared relative torques",
    "linkMechEnergy": "the link-side energy (without rotor inertia and friction) is not a cost here",
    "qDist": "the joints' travel is not a cost here",
    "fulfillN": "every goal is always fulfilled here",
    "fulfillP": "every goal is always fulfilled here",
}
_GOAL_TYPES = {"at": "at", "reach": "reach", "pause": "pause", "returnto": "return"}
_ANGLE = "Theta_R"
_POSITION = ("r_sph", "x", "y", "z")
#: Earth's gravity along the world's z axis [m/s^2], the only gravity the robot models know.
GRAVITY = (0.0, 0.0, -9.81)


_T = TypeVar("_T")


@dataclass(frozen=True)
class CobraImport:
    """A converted task: the scenario's ``text`` and the mesh files to copy (``meshes``: the
    source path of each name the scenario gives, relative to its folder)."""

    text: str
    meshes: dict[str, Path]

    def write(self, path: str | Path, check: Callable[[Path], _T] | None = None) -> _T | None:
        """Write the scenario to ``path`` and its meshes beside it, and return ``check(path)``
        (e.g. :func:`~modular_robots.scenario.load_scenario`). If writing or ``check`` raises,
        what was written is taken back (a file it replaced gets its old content, a folder it made
        goes) before the error goes on: a refused import leaves the folder as it was. Each file is
        written beside its place and renamed onto it, so a process killed meanwhile leaves every
        file whole, the earlier import's or this one's."""
        path = Path(path)
        before: dict[Path, bytes | None] = {}
        made: set[Path] = set()

        def folder(of: Path) -> None:
            made.update(p for p in (of, *of.parents) if not p.exists())
            of.mkdir(parents=True, exist_ok=True)

        def put(target: Path, write: Callable[[Path], object]) -> None:
            before.setdefault(target, target.read_bytes() if target.is_file() else None)
            with atomic_path(target) as written:
                write(written)

        try:
            folder(path.parent)
            for name, source in self.meshes.items():
                target = path.parent / name
                folder(target.parent)
                put(target, functools.partial(shutil.copyfile, source))
            put(path, lambda target: target.write_text(self.text, encoding="utf-8"))
            return check(path) if check is not None else None
        except BaseException:
            for target, old in before.items():
                with contextlib.suppress(OSError):
                    if old is None:
                        target.unlink(missing_ok=True)
                    else:
                        with atomic_path(target) as written:
                            written.write_bytes(old)
            for made_folder in sorted(made, key=lambda p: len(p.parts), reverse=True):
                with contextlib.suppress(OSError):
                    made_folder.rmdir()
            raise


def cobra_terms(descriptor: str) -> list[tuple[str, float]]:
    """The terms of CoBRA's cost ``descriptor``, ``(abbreviation, weight)`` in order: comma-separated
    ``name`` or ``name_weight``, a name without a weight at Timor's default weight
    (:data:`COBRA_DEFAULT_WEIGHTS`); raises ScenarioError naming an unknown or unsupported cost."""
    terms = []
    for part in descriptor.split(","):
        name, _, weight = part.strip().partition("_")
        if name in _UNSUPPORTED_COSTS:
            raise ScenarioError(f"--cost: {shorten(name)} is not supported: {_UNSUPPORTED_COSTS[name]}")
        if name not in COBRA_COSTS:
            raise ScenarioError(
                f"--cost: unknown CoBRA cost {shorten(name)}; expected one of {', '.join(COBRA_COSTS)} "
                f"(weighted: name_weight, comma-separated, e.g. cyc_2,mass_0.1)"
            )
        try:
            value = float(weight) if weight else COBRA_DEFAULT_WEIGHTS[name]
        except ValueError:
            raise ScenarioError(f"--cost: the weight of {shorten(name)} is not a number: {shorten(weight)}") from None
        if not (math.isfinite(value) and value > 0.0):
            raise ScenarioError(f"--cost: the weight of {shorten(name)} must be a positive number, got {weight}")
        terms.append((name, value))
    return terms


def cobra_cost(descriptor: str) -> str:
    """The scenario's cost descriptor for CoBRA's ``descriptor`` (e.g. ``cyc_2,mass_0.1`` ->
    ``2*time + 0.1*mass``, ``cyc,numJ`` -> ``time + 0.1*joints``); raises ScenarioError naming an
    unknown or unsupported cost."""
    return " + ".join(
        COBRA_COSTS[name] if weight == 1.0 else f"{weight:g}*{COBRA_COSTS[name]}"
        for name, weight in cobra_terms(descriptor)
    )


def import_cobra(
    task_path: str | Path,
    catalog: str | Path,
    output: str | Path,
    cost: str = "cyc",
    payload: float = 0.0,
    max_time: float | None = None,
) -> CobraImport:
    """The scenario of the CoBRA task ``task_path`` for the catalogue ``catalog``, to be written at
    ``output`` (its paths are relative to that folder), minimising CoBRA's ``cost`` descriptor,
    with ``payload`` [kg] at the tool and the motion at most ``max_time`` [s] long (None: no
    limit). Raises :class:`~modular_robots.exceptions.ScenarioError` for what does not map,
    naming the file and the item."""
    task_path, output = Path(task_path), Path(output)
    where = str(task_path)
    costs = {COBRA_COSTS[name] for name, _ in cobra_terms(cost)}
    if max_time is None and costs == {"energy"} | (costs & {"mass", "joints"}):
        raise ScenarioError(
            f"cost {cost}: the mechanical energy without the cycle time has no minimum over the motion's duration "
            "(a slower move always needs less: the drives hold the payload without doing work); give the longest "
            "motion (--max-time SECONDS), or count the cycle time too (e.g. cyc_1,mechEnergy_0.01)"
        )
    if task_path.stat().st_size > MAX_FILE_BYTES:
        raise ScenarioError(f"{where}: larger than {MAX_FILE_BYTES} bytes")
    try:
        data = json.loads(task_path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ScenarioError(f"{where}: not a JSON document ({shorten(e, quote=False)})") from None
    _expect(isinstance(data, dict), where, "expected a JSON object (a CoBRA task)")
    header = _mapping(data, "header", where)
    time_step = _number(header.get("timeStepSize", 0.01), f"{where}: header.timeStepSize")
    _expect(time_step > 0.0, where, f"header.timeStepSize: expected a positive number of seconds, got {time_step}")
    gravity = header.get("gravity", list(GRAVITY))
    _expect(
        isinstance(gravity, list) and len(gravity) == 3 and np.allclose(gravity, GRAVITY, atol=1e-6),
        where,
        f"header.gravity: only {list(GRAVITY)} m/s^2 is supported, got {shorten(gravity)}",
    )
    constraints = data.get("constraints", [])
    _expect(isinstance(constraints, list), where, "constraints: expected a list")
    for k, constraint in enumerate(constraints):
        _expect(isinstance(constraint, dict), where, f"constraints[{k}]: expected an object, got {shorten(constraint)}")
    kinds = {str(c.get("type", "")).lower(): c for c in constraints if isinstance(c, dict)}
    for kind in kinds:
        _expect(
            kind
            in (
                "joint",
                "selfcollisionfree",
                "collisionfree",
                "allgoalsfulfilled",
                "allgoalsfulfilledinorder",
                "baseplacement",
                "alwaystrue",
                "validassembly",
            ),
            where,
            f"constraints: the constraint {shorten(kind)} is not supported (an end-effector speed limit, or goals for "
            "several robots)",
        )
    base = np.eye(4)
    if "baseplacement" in kinds:
        pose = _mapping(kinds["baseplacement"], "pose", f"{where}: constraints basePlacement")
        base = _matrix(pose.get("nominal"), f"{where}: constraints basePlacement.pose.nominal")
        _expect(
            np.allclose(base[:3, 2], (0.0, 0.0, 1.0), atol=1e-9),
            where,
            "constraints basePlacement: the base's z axis must point up (along the world's z, against gravity); "
            "a tilted base is not supported",
        )
    to_base = np.linalg.inv(base)
    goals = data.get("goals", [])
    least = "expected at least two: a CoBRA task's start is free, so the first goal is the start"
    _expect(isinstance(goals, list), where, f"goals: expected a list, got {type(goals).__name__}")
    _expect(len(goals) > 0, where, f"goals: none; {least}")
    scenario_goals, start, first_id = _goals(goals, to_base, where)  # (each goal's type checked first)
    _expect(len(goals) >= 2, where, f"goals: one; {least}, and one goal leaves no motion to optimise")
    if "allgoalsfulfilledinorder" in kinds:
        order = [str(i) for i in kinds["allgoalsfulfilledinorder"].get("order", [])]
        listed = [first_id, *(g.get("id") for g in scenario_goals)]
        positions = [listed.index(i) if i in listed else -1 for i in order]
        _expect(
            -1 not in positions and positions == sorted(positions),
            where,
            f"constraints allGoalsFulfilledInOrder: the order {order} is not the goals' order in the file {listed}",
        )
    obstacles, meshes = ([], {}) if "collisionfree" not in kinds else _obstacles(data, to_base, task_path, output)
    name = re.sub(r"[^A-Za-z0-9._-]", "_", str(header.get("taskName") or header.get("ID") or task_path.stem))[:100]
    task: dict[str, Any] = {
        "payload": payload,
        "start": start,
        "goals": scenario_goals,
        "obstacles": obstacles,
        "floor": "none",
        "self_collision": "selfcollisionfree" in kinds,
        "cost": cobra_cost(cost),
    }
    if max_time is not None:
        task["max_time"] = max_time
    document = {
        "name": name if re.match(r"[A-Za-z0-9]", name) else f"cobra_{name}",
        "description": f"CoBRA task {header.get('ID', task_path.stem)} (imported from {task_path.name})",
        "catalog": _relative(Path(catalog), output.parent),
        "task": task,
        "cobra": {
            "task": task_path.name,
            "id": str(header.get("ID", task_path.stem)),
            "version": str(header.get("version", "2022")),
            "time_step": time_step,
            "base_pose": base.tolist(),
            "start": first_id,
            "cost_function": cost,
        },
    }
    text = (
        f"# Imported from the CoBRA task {task_path.name} by `modular-robots import-cobra`: the goals, obstacles\n"
        "# and start in the robot's base frame (the task's basePlacement moved to the origin).\n"
    )
    return CobraImport(text + yaml.safe_dump(document, sort_keys=False, width=120, default_flow_style=None), meshes)


def _goals(goals: list, to_base: np.ndarray, where: str) -> tuple[list[dict], Any, str]:
    """The scenario's goals, its start and the id of the CoBRA goal the start stands for."""
    out: list[dict] = []
    first_id = ""
    start: Any = None
    seen: set[str] = set()
    where_paused: dict[str, str] = {}  # a pause's ID -> the goal it stands still at
    for i, goal in enumerate(goals):
        label = f"{where}: goals[{i}]"
        _expect(isinstance(goal, dict), label, "expected an object")
        gid = str(goal.get("ID", i + 1))
        _expect(gid not in seen, label, f"the goal ID {shorten(gid)} is used twice")
        _expect(
            not goal.get("constraints"),
            label,
            f"(ID {shorten(gid)}) constraints: a goal's own constraints are not supported",
        )
        kind = _GOAL_TYPES.get(str(goal.get("type", "")).lower())
        if kind is None:
            raise ScenarioError(
                f"{label} (ID {shorten(gid)}): the goal type {shorten(goal.get('type'))} is not supported; expected "
                "at, reach, pause or returnTo"
            )
        if i == 0:
            _expect(kind in ("at", "reach"), label, f"the first goal is the start: expected at or reach, got {kind}")
            start, first_id = _pose(goal, to_base, label), gid
        elif kind in ("at", "reach"):
            out.append({kind: _pose(goal, to_base, label), "id": gid})
        elif kind == "pause":
            duration = _number(goal.get("duration"), f"{label}: duration")
            _expect(duration > 0.0, label, f"duration: expected a positive number of seconds, got {duration}")
            out.append({"pause": duration, "id": gid})
            where_paused[gid] = next((str(g["id"]) for g in reversed(out) if "pause" not in g), first_id)
        else:
            named = goal.get("returnToGoal")
            back = first_id if named is None else str(named)
            _expect(back in seen, label, f"returnToGoal: no earlier goal with ID {shorten(back)}")
            back = where_paused.get(back, back)
            passed = next((g for g in out if g.get("id") == back and "at" in g), None)
            if passed is not None:  # CoBRA's returnTo compares the joint state, velocity included
                passed["reach"] = passed.pop("at")
                passed["id"] = passed.pop("id")
            out.append({"return": "start" if back == first_id else back, "id": gid})
        seen.add(gid)
    return out, start, first_id


def _pose(goal: dict, to_base: np.ndarray, label: str) -> dict:
    """A tolerated pose of the CoBRA goal as the scenario's pose mapping, in the base frame."""
    pose = _mapping(goal, "goalPose", label)
    _expect("nominalParent" not in pose, label, "goalPose.nominalParent: poses in other frames are not supported")
    nominal = to_base @ _matrix(pose.get("nominal"), f"{label}: goalPose.nominal")
    projections = pose.get("toleranceProjection", [])
    bounds = pose.get("tolerance", [])
    _expect(
        isinstance(projections, list) and isinstance(bounds, list) and len(projections) == len(bounds),
        label,
        "goalPose: expected as many tolerance bounds as toleranceProjection names",
    )
    radius, angle = math.inf, None
    for name, bound in zip(projections, bounds):
        low, high = _pair(bound, f"{label}: goalPose.tolerance of {name}")
        if name == "r_sph":
            _expect(low <= 0.0 < high, label, f"goalPose.tolerance of r_sph: expected [0, r] with r > 0, got {bound}")
            radius = min(radius, high)
        elif name in ("x", "y", "z"):
            _expect(
                low < 0.0 < high,
                label,
                f"goalPose.tolerance of {name}: expected bounds about the nominal position, got {bound}",
            )
            radius = min(radius, -low, high)
        elif name == _ANGLE:
            _expect(low <= 0.0 < high, label, f"goalPose.tolerance of Theta_R: expected [0, a] with a > 0, got {bound}")
            angle = min(high, math.pi)
        else:
            raise ScenarioError(
                f"{label}: goalPose.toleranceProjection {shorten(name)} is not supported; expected "
                f"{', '.join(_POSITION)} or {_ANGLE}"
            )
    _expect(
        math.isfinite(radius),
        label,
        "goalPose: no position tolerance (r_sph, x, y or z): a goal whose tool may be anywhere is not supported",
    )
    out: dict[str, Any] = {"position": _tidy(nominal[:3, 3]), "position_tolerance": min(radius, 0.1)}
    if angle is not None:
        out["rpy"] = _tidy(rpy_from_matrix(nominal[:3, :3]))
        out["angle_tolerance"] = angle
    return out


def _obstacles(data: dict, to_base: np.ndarray, task_path: Path, output: Path) -> tuple[list[dict], dict[str, Path]]:
    """The task's collision geometries as the scenario's obstacles, in the base frame, and the
    mesh files to copy beside the scenario."""
    where = str(task_path)
    obstacles: list[dict[str, Any]] = []
    meshes: dict[str, Path] = {}
    items = data.get("obstacles", [])
    _expect(isinstance(items, list), where, "obstacles: expected a list")
    home = task_path.parent.resolve().parent  # CoBRA keeps assets/ beside tasks/
    for i, obstacle in enumerate(items):
        label = f"{where}: obstacles[{i}]"
        _expect(isinstance(obstacle, dict), label, "expected an object")
        geometries = obstacle.get("collision")
        _expect(
            isinstance(geometries, list),
            label,
            f"collision: expected a list of geometries (an obstacle without it would be left out), got "
            f"{shorten(geometries)}",
        )
        for k, geometry in enumerate(geometries):
            part = f"{label}.collision[{k}]"
            _expect(isinstance(geometry, dict), part, "expected an object")
            pose = to_base @ _matrix(geometry.get("pose", np.eye(4).tolist()), f"{part}: pose")
            center, rpy = _tidy(pose[:3, 3]), _tidy(rpy_from_matrix(pose[:3, :3]))
            p = _mapping(geometry, "parameters", part)
            kind = geometry.get("type")
            if kind == "box":
                size = [_number(p.get(axis), f"{part}: parameters.{axis}") for axis in "xyz"]
                obstacles.append({"box": {"center": center, "size": size, "rpy": rpy}})
            elif kind == "cylinder":
                radius = _number(p.get("r"), f"{part}: parameters.r")
                length = _number(p.get("z"), f"{part}: parameters.z")
                obstacles.append({"cylinder": {"center": center, "radius": radius, "length": length, "rpy": rpy}})
            elif kind == "sphere":
                obstacles.append({"sphere": {"center": center, "radius": _number(p.get("r"), f"{part}: parameters.r")}})
            elif kind == "mesh":
                file = str(p.get("file", ""))
                found = [(folder / file).resolve() for folder in (task_path.parent, home)]
                source = next((f for f in found if f.is_file()), found[0])
                _expect(
                    source.is_relative_to(home) and source.is_file(),
                    part,
                    f"parameters.file: {shorten(file)} is not a file inside the task's folder or the one above it "
                    f"(looked in {task_path.parent.resolve()} and {home})",
                )
                if source.is_relative_to(output.parent.resolve()):  # already beside the scenario: used in place
                    name = source.relative_to(output.parent.resolve()).as_posix()
                else:
                    name = f"meshes/{re.sub(r'[^A-Za-z0-9._-]', '_', source.name)}"
                    meshes[name] = source
                scale = _scale(p.get("scale", 1.0), f"{part}: parameters.scale")
                obstacles.append({"mesh": {"file": name, "scale": scale, "position": center, "rpy": rpy}})
            else:
                raise ScenarioError(
                    f"{part}: the geometry type {shorten(kind)} is not supported; expected box, cylinder, sphere or "
                    "mesh"
                )
    return obstacles, meshes


def _scale(value: Any, where: str) -> float:
    """A mesh's scale: a number, or three equal ones (a scale per axis is not supported)."""
    if isinstance(value, list):
        _expect(len(value) == 3, where, f"expected a number or three, got {len(value)}")
        factors = [_number(v, where) for v in value]
        _expect(
            max(factors) - min(factors) <= 1e-12 * max(abs(f) for f in factors),
            where,
            f"a different scale per axis {factors} is not supported; expected one scale for all three",
        )
        return factors[0]
    return _number(value, where)


def _relative(path: Path, folder: Path) -> str:
    """``path`` relative to ``folder`` when it can be (the same drive), else absolute."""
    try:
        return Path(os.path.relpath(path.resolve(), folder.resolve())).as_posix()
    except ValueError:
        return str(path.resolve())


def _tidy(values) -> list[float]:
    """``values`` as plain floats, rounded to 1e-12 (no ``0.10000000000000009`` or ``-0.0`` from
    the change of frame)."""
    return [round(float(v), 12) + 0.0 for v in values]


def _expect(ok: bool, where: str, message: str) -> None:
    if not ok:
        raise ScenarioError(f"{where}: {message}")


def _mapping(data: dict, key: str, where: str) -> dict:
    value = data.get(key)
    _expect(isinstance(value, dict), where, f"{key}: expected an object")
    return value  # type: ignore[return-value]


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ScenarioError(f"{where}: expected a finite number, got {shorten(value)}")
    return float(value)


def _pair(value: Any, where: str) -> tuple[float, float]:
    if not (isinstance(value, list) and len(value) == 2):
        raise ScenarioError(f"{where}: expected [lower, upper], got {shorten(value)}")
    return _number(value[0], where), _number(value[1], where)


def _matrix(value: Any, where: str) -> np.ndarray:
    """A homogeneous 4x4 transform: finite, a rotation in its upper left (orthonormal, det 1), the
    last row 0 0 0 1."""
    try:
        m = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ScenarioError(f"{where}: expected a 4x4 matrix of numbers") from None
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ScenarioError(f"{where}: expected a 4x4 matrix of finite numbers, got shape {m.shape}")
    rotation = m[:3, :3]
    if not (np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-6) and np.allclose(m[3], (0, 0, 0, 1))):
        raise ScenarioError(f"{where}: expected a homogeneous transform (a rotation and a translation)")
    if np.linalg.det(rotation) < 0.0:
        raise ScenarioError(f"{where}: the rotation is a reflection (determinant -1)")
    return m
