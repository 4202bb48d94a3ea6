"""The tool's orientation at an end (``task.start`` / ``task.goal`` with ``rpy`` or ``axis``):
the angle measured against an independent formula (the trace of the relative rotation, the dot
product of the axes), pose IK checked by forward kinematics computed apart from the IK's
Jacobians, the scenario keys and their errors, and step B on IMPROV."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from modular_robots.composition import Composition, enumerate_compositions
from modular_robots.exceptions import ScenarioError
from modular_robots.feasibility import check_compositions
from modular_robots.ik import ik_seeds
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.ocp.verification import verify
from modular_robots.orientation import Orientation
from modular_robots.pose_ik import solve_pose_ik
from modular_robots.robot import RobotModel, robot_model
from modular_robots.scenario import load_scenario

from .helpers.models import ur5
from .helpers.paths import ROOT

IMPROV_6DOF = ROOT / "scenarios" / "catalogs" / "improv-6dof.yaml"


def _pose(robot: RobotModel, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``tool0``'s position and rotation, by forward kinematics alone."""
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    pose = pin.updateFramePlacement(robot.model, data, robot.tool_frame_id)
    return pose.translation.copy(), pose.rotation.copy()


def _rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle of the rotation between ``a`` and ``b``, from the trace of ``a^T b``."""
    return math.acos(np.clip((np.trace(a.T @ b) - 1.0) / 2.0, -1.0, 1.0))


def _random_rotation(rng) -> np.ndarray:
    return pin.exp3(rng.normal(size=3) * rng.uniform(0.0, 1.0))


def test_the_angle_of_an_rpy_orientation_is_that_of_the_relative_rotation():
    rng = np.random.default_rng(3)
    for _ in range(50):
        rpy = tuple(rng.uniform(-math.pi, math.pi, 3))
        tool = _random_rotation(rng)
        orientation = Orientation(rpy=rpy)
        asked = pin.rpy.rpyToMatrix(*rpy)
        assert orientation.angle(tool) == pytest.approx(_rotation_angle(asked, tool), abs=1e-9)
        # the error is the turn, in the base frame, that brings the tool onto the asked rotation
        assert np.allclose(pin.exp3(orientation.error(tool)) @ tool, asked, atol=1e-9)


def test_the_angle_of_an_axis_orientation_is_that_between_the_z_axes_and_ignores_the_turn_about_it():
    rng = np.random.default_rng(4)
    for _ in range(50):
        axis = rng.normal(size=3)
        tool = _random_rotation(rng)
        orientation = Orientation(axis=tuple(axis))
        unit = axis / np.linalg.norm(axis)
        assert orientation.angle(tool) == pytest.approx(math.acos(np.clip(tool[:, 2] @ unit, -1, 1)), abs=1e-9)
        assert np.allclose(pin.exp3(orientation.error(tool)) @ tool[:, 2], unit, atol=1e-9)
        spun = tool @ pin.exp3(np.array([0.0, 0.0, rng.uniform(-3, 3)]))  # about the tool's own z
        assert orientation.angle(spun) == pytest.approx(orientation.angle(tool), abs=1e-9)
    opposite = Orientation(axis=(0.0, 0.0, -1.0))
    assert opposite.angle(np.eye(3)) == pytest.approx(math.pi)


@pytest.mark.parametrize("kind", ["rpy", "axis"])
def test_pose_ik_meets_a_reachable_pose_within_both_tolerances(kind):
    robot = ur5(0.0)
    rng = np.random.default_rng(11)
    met = 0
    for _ in range(6):
        position, rotation = _pose(robot, rng.uniform(robot.lower, robot.upper))
        if kind == "rpy":
            orientation = Orientation(rpy=tuple(pin.rpy.matrixToRpy(rotation)), tolerance=0.02)
        else:
            orientation = Orientation(axis=tuple(rotation[:, 2]), tolerance=0.02)
        results = solve_pose_ik(robot, position, orientation, ik_seeds(robot, 8), tolerance=1e-4)
        found = [r for r in results if r.success(1e-4)]
        met += bool(found)
        for r in found:
            reached, turned = _pose(robot, r.q)
            assert np.linalg.norm(reached - position) <= 1e-4
            assert r.angle == pytest.approx(orientation.angle(turned), abs=1e-9)
            if kind == "rpy":
                assert _rotation_angle(turned, rotation) <= 0.02
            else:
                assert math.acos(np.clip(turned[:, 2] @ rotation[:, 2], -1, 1)) <= 0.02
            assert np.all(r.q >= robot.lower) and np.all(r.q <= robot.upper)
    assert met == 6  # a six-joint arm meets every pose it can hold, from eight seeds


def test_an_unreachable_orientation_is_reported_with_its_closest_angle():
    # a UR5 cannot point its tool up at a point beneath its shoulder, in reach of the wrist only
    robot = ur5(0.0)
    position, _ = _pose(robot, np.zeros(robot.nq))
    results = solve_pose_ik(robot, position + [0, 0, -0.9], Orientation(axis=(0, 0, 1)), ik_seeds(robot, 4))
    assert not any(r.success() for r in results)
    assert all(r.angle > 0.0 and math.isfinite(r.angle) for r in results)


def _scenario(tmp_path, goal: str, start: str = "[0.35, 0.35, 0.30]"):
    text = f"""
name: oriented
catalog: {IMPROV_6DOF}
task:
  payload: 1.0
  start: {start}
  goal: {goal}
  cost: time
"""
    path = tmp_path / "oriented.yaml"
    path.write_text(text)
    return path


def test_the_scenario_reads_rpy_axis_and_tolerances(tmp_path):
    task = load_scenario(
        _scenario(
            tmp_path,
            "{position: [0.45, -0.2, 0.12], axis: [0, 0, -2], angle_tolerance: 0.05, position_tolerance: 0.002}",
            "{position: [0.35, 0.35, 0.3], rpy: [3.14159, 0, 0.5]}",
        )
    ).task
    assert task.goal == (0.45, -0.2, 0.12) and task.goal_tolerance == 0.002
    assert task.goal_orientation == Orientation(axis=(0.0, 0.0, -1.0), tolerance=0.05)
    assert task.start_orientation is not None and task.start_orientation.rpy == (3.14159, 0.0, 0.5)
    assert task.start_orientation.tolerance == 0.01 and task.start_tolerance is None
    plain = load_scenario(_scenario(tmp_path, "[0.45, -0.2, 0.12]")).task
    assert plain.goal_orientation is None and plain.goal_tolerance is None


@pytest.mark.parametrize(
    "goal, expected",
    [
        ("{position: [0.45, -0.2, 0.12], rpy: [0, 0, 0], axis: [0, 0, 1]}", r"task\.goal\.axis: give rpy .* not both"),
        ("{position: [0.45, -0.2, 0.12], rpy: [0, .nan, 0]}", r"task\.goal\.rpy: item 1: expected a finite number"),
        ("{position: [0.45, -0.2, 0.12], rpy: [0, .inf, 0]}", r"task\.goal\.rpy: item 1: expected a finite number"),
        ("{position: [0.45, -0.2, 0.12], axis: [0, 0, 0]}", r"task\.goal\.axis: expected a direction"),
        ("{position: [0.45, -0.2, 0.12], axis: [0, 0, 1], angle_tolerance: 0}", r"task\.goal\.angle_tolerance: .*> 0"),
        (
            "{position: [0.45, -0.2, 0.12], axis: [0, 0, 1], angle_tolerance: -0.1}",
            r"task\.goal\.angle_tolerance: .*> 0",
        ),
        ("{position: [0.45, -0.2, 0.12], angle_tolerance: 0.1}", r"task\.goal\.angle_tolerance: .* add rpy or axis"),
        ("{position: [0.45, -0.2, 0.12], position_tolerance: 0}", r"task\.goal\.position_tolerance: .*> 0"),
        ("{position: [0.45, -0.2, 0.12], quaternion: [1, 0, 0, 0]}", r"task\.goal\.quaternion: unknown key .*axis"),
        ("{rpy: [0, 0, 0]}", r"task\.goal\.position: missing required key"),
    ],
)
def test_bad_orientations_are_refused_naming_the_key(tmp_path, goal, expected):
    with pytest.raises(ScenarioError, match=r"oriented\.yaml:\d+: " + expected):
        load_scenario(_scenario(tmp_path, goal))


def test_step_b_keeps_the_goal_orientation_and_says_which_test_removed_the_others(tmp_path):
    scenario = load_scenario(
        _scenario(tmp_path, "{position: [0.45, -0.2, 0.12], axis: [0, 0, -1], angle_tolerance: 0.05}")
    )
    catalog, task = scenario.catalog, replace(scenario.task, self_collision=False)
    verdicts = check_compositions(list(enumerate_compositions(catalog)), catalog, task)
    passed = [v for v in verdicts if v.passed]
    assert passed and len(passed) < len(verdicts)
    for v in passed:
        robot = robot_model(v.composition, catalog, task.payload)
        position, rotation = _pose(robot, np.asarray(v.q_goal))
        assert np.linalg.norm(position - task.goal) <= 1e-4
        assert math.acos(np.clip(-rotation[2, 2], -1, 1)) <= 0.05  # tool z within 0.05 rad of straight down
    removed = [v for v in verdicts if v.failed_test == "inverse kinematics"]
    assert removed and all("rad from the orientation axis [0.0, 0.0, -1.0]" in v.message for v in removed)
    assert all("no solution within joint limits and the orientation's tolerance at the" in v.message for v in removed)
    # without the orientation, more compositions hold the goal
    free = check_compositions([v.composition for v in removed], catalog, replace(task, goal_orientation=None))
    assert sum(v.passed for v in free) > 0
    assert Composition.from_name(passed[0].composition.name, catalog) == passed[0].composition


def test_verification_measures_the_orientation_at_both_ends_of_the_plan():
    """Step C keeps the ends at step B's configurations; verification measures the tool there
    against the task's orientations and fails a plan whose end is turned beyond the tolerance."""
    robot = ur5(0.0)
    rng = np.random.default_rng(5)
    q_start, q_goal = rng.uniform(-1.0, 1.0, (2, robot.nq))
    (_, start_rotation), (_, goal_rotation) = _pose(robot, q_start), _pose(robot, q_goal)
    met = (
        Orientation(axis=tuple(start_rotation[:, 2]), tolerance=0.01),
        Orientation(rpy=tuple(pin.rpy.matrixToRpy(goal_rotation))),
    )
    problem = ShootingProblem(robot, q_start, q_goal, self_collision=False, orientations=met)
    assert verify(problem, problem.initial_guess()).orientation_excess == 0.0
    turned = pin.rpy.matrixToRpy(goal_rotation @ pin.exp3(np.array([0.0, 0.3, 0.0])))
    missed = (met[0], Orientation(rpy=tuple(turned), tolerance=0.1))
    v = verify(replace_orientations(problem, missed), problem.initial_guess())
    assert v.orientation_excess == pytest.approx(0.3 - 0.1, abs=1e-9) and not v.passed


def replace_orientations(problem: ShootingProblem, orientations) -> ShootingProblem:
    return ShootingProblem(
        problem.robot, problem.q_start, problem.q_goal, self_collision=False, orientations=orientations
    )
