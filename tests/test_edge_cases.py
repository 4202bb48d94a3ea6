"""Valid edge cases that once crashed (issue 46, family 10).

A prismatic-only catalogue whose one feasible robot, ``B-P1-L2-E0``, has a single joint and holds
the tool at the start and the goal exactly at that joint's limits. Pinocchio hands a one-column
matrix back as a vector, so the one joint's Jacobian came as ``(6,)`` and step B's IK (then step
C's clearance Jacobians) crashed writing it into a ``(6, 1)`` slot: "unexpected ValueError: could
not broadcast input array from shape (6,) into shape (6,1)".
"""

from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest

from modular_robots.composition import enumerate_compositions
from modular_robots.pipeline import run_scenario
from modular_robots.robot import robot_model
from modular_robots.scenario import load_scenario

from .helpers.paths import ROOT

PRISMATIC_LIMITS = ROOT / "tests" / "data" / "prismatic-limits.yaml"

WINNER = "B-P1-L2-E0"
#: P1's stroke [m]: the tool is at z = 0.6 + q, so the start (z = 0.6) and the goal (z = 1.1)
#: are exactly its lower and upper limits.
LOWER, UPPER = 0.0, 0.5
VELOCITY_LIMIT, EFFORT_LIMIT = 1.0, 100.0
#: What P1 lifts [kg]: its own moving side (1.0), the link L2 (0.5), the effector E0 (0.2) and
#: the payload (1.0).
MOVING_MASS = 2.7
GRAVITY = 9.81
IK_TOLERANCE = 1e-4  # [m], step B's


def _trajectory(path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {key: np.array([float(row[key]) for row in rows]) for key in rows[0]}


def test_a_one_joint_robot_has_a_one_column_tool_jacobian():
    scenario = load_scenario(PRISMATIC_LIMITS)
    composition = next(c for c in enumerate_compositions(scenario.catalog) if c.name == WINNER)
    robot = robot_model(composition, scenario.catalog, scenario.task.payload)
    assert robot.nv == 1
    np.testing.assert_allclose(robot.tool_jacobian(np.array([0.25])), [[0.0], [0.0], [1.0]], atol=1e-12)


@pytest.mark.parametrize("transcription", ["inverse", "forward"])
def test_prismatic_only_catalogue_with_start_and_goal_at_the_joint_limits(tmp_path, transcription):
    scenario = load_scenario(PRISMATIC_LIMITS)
    scenario = dataclasses.replace(
        scenario, optimizer=dataclasses.replace(scenario.optimizer, transcription=transcription)
    )
    result = run_scenario(scenario, tmp_path, jobs=1)
    assert (result.winner.name, result.winner.dof) == (WINNER, 1)

    document = json.loads((tmp_path / "result.json").read_text())
    assert document["status"] == "done", document["message"]
    counts = document["counts"]
    # Two-joint robots start at z >= 1.1 and P2's stroke ends at z = 0.9: only B-P1-L2-E0 is left.
    assert (counts["enumerated"], counts["feasible"], counts["optimal"]) == (6, 1, 1)
    winner = document["winner"]
    assert (winner["composition"], winner["dof"]) == (WINNER, 1)
    assert winner["verification"]["passed"]

    # Step B's boundary configurations: the joint's limits, within the IK tolerance and never beyond.
    (candidate,) = document["candidates"]
    (q_start,), (q_goal,) = candidate["q_start"], candidate["q_goal"]
    assert LOWER <= q_start <= LOWER + IK_TOLERANCE
    assert UPPER - IK_TOLERANCE <= q_goal <= UPPER

    plan = _trajectory(tmp_path / "trajectory.csv")
    t, q, qd, qdd, tau = plan["t"], plan["q1"], plan["qd1"], plan["qdd1"], plan["tau1"]
    tool = np.column_stack([plan["x"], plan["y"], plan["z"]])
    start, goal = np.array(document["task"]["start"]), np.array(document["task"]["goal"])
    # Kinematics: the tool slides on the z axis at 0.6 + q.
    np.testing.assert_allclose(tool[:, :2], 0.0, atol=1e-12)
    np.testing.assert_allclose(tool[:, 2], 0.6 + q, atol=1e-12)
    # From rest at the start to rest at the goal.
    assert np.linalg.norm(tool[0] - start) <= IK_TOLERANCE
    assert np.linalg.norm(tool[-1] - goal) <= IK_TOLERANCE
    assert qd[0] == 0.0 and abs(qd[-1]) <= 1e-9 and qdd[-1] == 0.0
    # Within the limits all the way, though both ends sit on them.
    assert np.all((q >= LOWER) & (q <= UPPER))
    assert np.all(np.abs(qd) <= VELOCITY_LIMIT) and np.all(np.abs(tau) <= EFFORT_LIMIT)
    # Dynamics: a vertical slide pushes m (g + qdd); at rest at the goal it holds m g.
    np.testing.assert_allclose(tau, MOVING_MASS * (GRAVITY + qdd), rtol=1e-9)
    assert tau[-1] == pytest.approx(MOVING_MASS * GRAVITY, rel=1e-9)
    # Time: no faster than the whole stroke at the planned velocity bound (the cost's lower bound).
    tf = t[-1]
    assert tf == pytest.approx(winner["tf"], rel=1e-12)
    assert (UPPER - LOWER - 2 * IK_TOLERANCE) / (scenario.optimizer.velocity_margin * VELOCITY_LIMIT) <= tf < 1.0
    # The obstacle beside the path: P1's port sphere passes it 0.064 m clear at the top.
    assert winner["closest_approach"]["clearance"] == pytest.approx(np.hypot(0.35, 0.1) - 0.2 - 0.1, abs=1e-6)
