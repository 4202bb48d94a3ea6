"""The floor (``task.floor``, z = 0 of the base frame by default): nothing a joint moves toward it
may cross it; the base, and what no joint moves toward it, stand on it. Checked against the
primitives' heights from Pinocchio's frames (not the collision model), on IMPROV, whose improv-pick
winner without a floor starts with a housing 1.8 cm below the floor."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from modular_robots.collision import CollisionModel
from modular_robots.composition import Composition
from modular_robots.exceptions import ScenarioError
from modular_robots.feasibility import check_composition
from modular_robots.obstacles import FloorObstacle
from modular_robots.pipeline import run_scenario
from modular_robots.robot import RobotModel, robot_model
from modular_robots.scenario import load_scenario

from .helpers.paths import ROOT

IMPROV_PICK = ROOT / "scenarios" / "improv-pick.yaml"
OLD_WINNER = "base-PB21-L2-PB21-L4-L3"  # improv-pick's winner with no floor


def _lowest_points(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """Each primitive's lowest z [m] (its axis's lower end less its radius), from the frames."""
    pin.framesForwardKinematics(robot.model, robot.data, q)
    out = []
    for p in robot.primitives:
        pose = robot.data.oMf[robot.model.getFrameId(p.frame)]
        ends = [pose.translation + pose.rotation[:, 2] * s for s in (p.offset, p.offset + p.length)]
        out.append(min(e[2] for e in ends) - p.radius)
    return np.array(out)


def _moved_toward_floor(robot: RobotModel) -> np.ndarray:
    """Which primitives some configuration raises or lowers (independently: 64 seeded samples)."""
    rng = np.random.default_rng(5)
    samples = np.array([_lowest_points(robot, q) for q in rng.uniform(robot.lower, robot.upper, (64, robot.nv))])
    return samples.max(axis=0) - samples.min(axis=0) > 1e-9


def test_the_old_winner_starts_below_the_floor_and_step_b_now_removes_it():
    scenario = load_scenario(IMPROV_PICK)
    composition = Composition.from_name(OLD_WINNER, scenario.catalog)
    no_floor = check_composition(composition, scenario.catalog, replace(scenario.task, floor=None))
    assert no_floor.passed
    robot = robot_model(composition, scenario.catalog, scenario.task.payload)
    heights = _lowest_points(robot, np.asarray(no_floor.q_start))
    moved = _moved_toward_floor(robot)
    assert heights[moved].min() == pytest.approx(-0.0181, abs=5e-4)
    with_floor = check_composition(composition, scenario.catalog, scenario.task)
    assert not with_floor.passed and "inside task.floor" in with_floor.message, with_floor.message


def test_what_no_joint_moves_toward_the_floor_stands_on_it():
    """IMPROV's first housings reach 2.8 cm below the mounting plane by design, fixed to the base;
    the collision model measures the floor only for the primitives some configuration moves."""
    scenario = load_scenario(IMPROV_PICK)
    robot = robot_model(Composition.from_name(OLD_WINNER, scenario.catalog), scenario.catalog, 0.0)
    moved = _moved_toward_floor(robot)
    heights = _lowest_points(robot, np.zeros(robot.nv))
    assert heights[~moved].min() < -0.02 and moved.any() and not moved.all()
    model = CollisionModel(robot, [FloorObstacle(0.0)])
    distances = model.distances(np.zeros(robot.nv)).distance[:, 0]
    assert np.all(np.isinf(distances[~moved]))
    np.testing.assert_allclose(distances[moved], heights[moved], atol=1e-12)


def test_the_improv_pick_winner_keeps_every_moving_part_above_the_floor_at_every_millisecond(tmp_path):
    scenario = load_scenario(IMPROV_PICK)
    result = run_scenario(scenario, tmp_path / "out", jobs=1)
    winner = result.winner
    assert winner is not None and winner.verification.passed and winner.composition != OLD_WINNER
    robot = robot_model(Composition.from_name(winner.composition, scenario.catalog), scenario.catalog, 1.0)
    moved = _moved_toward_floor(robot)
    times = np.arange(0.0, winner.tf, 1e-3)
    lowest = min(_lowest_points(robot, q)[moved].min() for q in winner.trajectory.at(times)[0])
    assert lowest >= -1e-6, lowest


def test_the_floor_key(tmp_path):
    text = IMPROV_PICK.read_text().replace("catalog: catalogs/", f"catalog: {IMPROV_PICK.parent}/catalogs/")

    def task(floor: str):
        path = tmp_path / "s.yaml"
        path.write_text(text.replace("task:\n", f"task:\n  floor: {floor}\n", 1))
        return load_scenario(path).task

    assert task("none").floor is None and task("none").collision_obstacles == task("none").obstacles
    assert task("-0.25").collision_obstacles[-1] == FloorObstacle(-0.25)
    with pytest.raises(ScenarioError, match=r"task\.floor: the start position .* is not above the floor at z = 2 m"):
        task("2")
    with pytest.raises(ScenarioError, match=r"task\.floor: expected a number"):
        task("low")
