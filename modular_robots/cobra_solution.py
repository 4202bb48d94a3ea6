"""The winner of a run on an imported CoBRA task as a CoBRA solution document
(``cobra-solution.json``), in the shape Timor's ``SolutionTrajectory.to_json_data`` writes.

* The header fields at the top level (``taskID`` the task's ``ID``; ``version``, ``author``,
  ``email``, ``affiliation``, ``publication``, ``date``, ``computationTime``, ``processorName``,
  ``notes``, ``tags``), then the module assembly as Timor writes it (``moduleSet``,
  ``moduleOrder``: the modules' Timor ids where the catalogue was imported from a Timor database,
  else its own ids; a serial chain needs no ``moduleConnection``), ``basePose`` (the task's base
  placement, a list of one 4x4), ``cost`` and ``costFunction`` (the task's descriptor, its value
  computed as CoBRA defines it on the rows below), and ``trajectory``.
* ``trajectory``: ``t`` [s], ``q``, ``dq``, ``ddq`` (the plan's exact values, SPEC §7), ``tau``
  (the inverse dynamics at each row, rotor inertia and friction included, as CoBRA's checker
  computes them) and ``goal2time`` (each CoBRA goal's id and its instant: the start's goal at 0,
  a pause's at its end). The rows are at most the task's ``timeStepSize`` apart, every goal's
  instant among them, each move's rows evenly spaced; at every instant where the robot is at rest
  (the start, a ``reach``, a return, a pause, the end) ``dq`` and ``ddq`` are 0 and, over a pause,
  ``q`` is constant, as CoBRA's goals test them exactly. A position the plan takes past a joint
  limit between its nodes (verification allows 1e-3 of the joint's range; 2e-5 m on a prismatic
  joint of PTP_2_cycle) is put on the limit, as CoBRA checks the limits exactly; ``tau`` is that
  row's.
"""

from __future__ import annotations

import datetime
import itertools
import json
import math
import platform
import re
from pathlib import Path

import numpy as np

from .cobra import cobra_terms
from .folder import atomic_write
from .goals import stops_of
from .plan.candidate import CandidateResult
from .robot import RobotModel, robot_from_urdf
from .scenario import Scenario

__all__ = ["COBRA_SOLUTION", "cobra_solution", "write_cobra_solution", "sample_times"]

#: The solution document's name in a results folder.
COBRA_SOLUTION = "cobra-solution.json"
#: Two instants closer than this [s] are one row (CoBRA finds a goal's row with ``numpy.isclose``).
_SAME = 1e-6


def sample_times(events: list[float], step: float) -> np.ndarray:
    """Rows from the first event to the last, every event among them, each stretch between two
    events cut into equal steps of at most ``step`` [s]."""
    events = sorted(set(float(e) for e in events))
    merged = [events[0]]
    for e in events[1:]:
        if e - merged[-1] > _SAME:
            merged.append(e)
    rows = [np.array([merged[0]])]
    for a, b in itertools.pairwise(merged):
        count = max(1, math.ceil((b - a) / step))
        rows.append(np.linspace(a, b, count + 1)[1:])
    return np.concatenate(rows)


def _goal_times(scenario: Scenario, result: CandidateResult) -> tuple[dict[str, float], list[tuple[float, float]]]:
    """Each CoBRA goal's instant [s] and the windows ``(start, end)`` where the robot stands still
    (at the start and the end, at each stop at rest, over each pause)."""
    task, origin = scenario.task, scenario.cobra
    assert origin is not None and result.trajectory is not None
    end = float(result.trajectory.t[-1])
    start_hold, stops = stops_of(task.goals)
    arrivals = list(result.stop_times) or [end - stops[-1].hold]
    times = {origin.start: 0.0}
    still = [(0.0, start_hold), (end, end)]
    k, clock = -1, start_hold  # the stop reached last, and where its pauses have got to
    for goal in task.goals:
        if goal.kind == "pause":
            clock += goal.duration
            times[goal.id] = clock
            continue
        k += 1
        clock = arrivals[k]
        times[goal.id] = clock
        if stops[k].rest:
            still.append((clock, clock + stops[k].hold))
    return times, still


def cobra_solution(scenario: Scenario, result: CandidateResult, robot: RobotModel, seconds: float = -1.0) -> dict:
    """The solution document (module docstring) of ``result``, the winner of ``scenario`` (which
    came from a CoBRA task), ``robot`` its model with the drives; ``seconds`` the run's
    computation time."""
    origin = scenario.cobra
    if origin is None or result.trajectory is None:
        raise ValueError("a CoBRA solution needs a scenario imported from a CoBRA task and a verified plan")
    goal2time, still = _goal_times(scenario, result)
    t = sample_times(
        [0.0, float(result.trajectory.t[-1]), *goal2time.values(), *(e for w in still for e in w)], origin.time_step
    )
    q, dq, ddq = result.trajectory.at(t)
    for a, b in still:
        rows = (t >= a - _SAME) & (t <= b + _SAME)
        first = int(np.argmax(rows))
        q[rows] = q[first]
        dq[rows] = 0.0
        ddq[rows] = 0.0
    q = np.clip(q, robot.lower, robot.upper)
    tau = robot.rnea(q, dq, ddq)
    payload = scenario.task.payload
    modules = result.composition.split("-")
    catalog = scenario.catalog
    by_id = {m.id: m for m in catalog.modules}
    # import-timor notes each module's Timor id and the database it came from
    timor_ids = [re.search(r"Timor module ID (\S+),", getattr(by_id.get(m), "notes", "") or "") for m in modules]
    converted = (re.search(r"Converted from (\S+)/modules\.json", n) for n in catalog.notes)
    source = next((match for match in converted if match), None)
    design = _design(scenario, result)
    return {
        "cost": _cobra_cost(origin.cost_function, t, dq, tau, design),
        "costFunction": origin.cost_function,
        "taskID": origin.id,
        "version": "2023",
        "author": [""],
        "email": [""],
        "affiliation": [""],
        "publication": "",
        "date": datetime.date.today().strftime("%Y-%m-%d"),
        "computationTime": float(seconds),
        "processorName": platform.processor() or platform.machine(),
        "notes": f"modular-robots: {result.composition} ({len(modules)} modules, {robot.nv} joints)"
        + (f"; tau holds a payload of {payload:g} kg at tool0 (CoBRA's task has none)" if payload > 0 else ""),
        "tags": [""],
        "moduleSet": source.group(1).split("/")[-1] if source else catalog.name,
        "moduleOrder": [match.group(1) if match else m for m, match in zip(modules, timor_ids)],
        "basePose": [[list(row) for row in origin.base_pose]],
        "trajectory": {
            "t": t.tolist(),
            "q": q.tolist(),
            "dq": dq.tolist(),
            "ddq": ddq.tolist(),
            "tau": tau.tolist(),
            "goal2time": goal2time,
        },
    }


def _design(scenario: Scenario, result: CandidateResult) -> tuple[float, int]:
    """The robot's mass [kg, modules only] and joints."""
    from .composition import Composition
    from .costs import design_of

    modules = Composition.from_name(result.composition, scenario.catalog).modules
    design = design_of(modules, scenario.catalog)
    return design.mass, design.joints


def _cobra_cost(descriptor: str, t: np.ndarray, dq: np.ndarray, tau: np.ndarray, design: tuple[float, int]) -> float:
    """CoBRA's cost ``descriptor`` (Timor's ``CostFunctions``) of the rows: ``cyc`` the last
    ``t``; ``mechEnergy`` the sum over the rows but the last of ``|tau . dq| dt``; ``mass`` the
    robot's; ``numJ`` its joints; the terms weighted as :func:`~modular_robots.cobra.cobra_terms` reads them,
    summed."""
    values = {
        "cyc": float(t[-1]),
        "mechEnergy": float(np.sum(np.abs(np.einsum("ij,ij->i", tau[:-1], dq[:-1])) * np.diff(t))),
        "mass": design[0],
        "numJ": float(design[1]),
    }
    return math.fsum(weight * values[name] for name, weight in cobra_terms(descriptor))


def write_cobra_solution(folder: Path, scenario: Scenario, result: CandidateResult, seconds: float = -1.0) -> str:
    """Write :data:`COBRA_SOLUTION` of ``result`` into ``folder``; return its name."""
    assert result.urdf is not None and result.drive is not None  # a verified winner has them
    robot = robot_from_urdf(result.urdf, result.drive["armature"])
    document = cobra_solution(scenario, result, robot, seconds)
    atomic_write(Path(folder) / COBRA_SOLUTION, json.dumps(document) + "\n")
    return COBRA_SOLUTION
