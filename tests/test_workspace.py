"""The workspace box: it holds every tool position within the joint limits (sampled forward
kinematics on generated and foreign robots), it is exact on hand-derived cases, the
catalogue-number fast path equals the model's box, and its distance to a target bounds what IK
can reach."""

import dataclasses
import importlib.metadata
import itertools
import math

import numpy as np
import pinocchio as pin
import pytest

from modular_robots import Composition, enumerate_compositions, load_scenario, robot_model
from modular_robots.ik import ik_seeds, solve_position_ik_many
from modular_robots.robot import RobotModel
from modular_robots.workspace import WorkspaceBox, catalog_workspace_box, workspace_box

from .helpers.paths import PAPER_5KG

SCENARIOS = PAPER_5KG.parent


def _inside(box: WorkspaceBox, robot: RobotModel, samples: int, seed: int) -> float:
    """The largest distance [m] by which a sampled tool position leaves ``box`` (<= 0 inside)."""
    rng = np.random.default_rng(seed)
    lower, upper = np.array(box.lower), np.array(box.upper)
    worst = -math.inf
    for q in rng.uniform(robot.lower, robot.upper, size=(samples, robot.nq)):
        p = robot.tool_position(q)
        worst = max(worst, float(np.max(np.maximum(lower - p, p - upper))))
    return worst


def _foreign(name: str, tool: str) -> RobotModel:
    path = next(f.locate() for f in importlib.metadata.files("example-robot-data") if str(f).endswith(name))
    return RobotModel(pin.buildModelFromUrdf(str(path)), tool, (), name)


def test_box_by_hand(paper_catalog):
    """B-J1-L1-E1 carries its tool on a circle of radius 0.75 + 0.2 m at 0.25 m (L1 turns the
    chain horizontal); B-J2-L2-E2 moves it along z from 1.2 m to 1.5 m (strokes 0.2 m, 0.1 m)."""
    circle = catalog_workspace_box(Composition.from_name("B-J1-L1-E1", paper_catalog), paper_catalog)
    assert circle.lower == pytest.approx((-0.95, -0.95, 0.25), abs=1e-12)
    assert circle.upper == pytest.approx((0.95, 0.95, 0.25), abs=1e-12)
    line = catalog_workspace_box(Composition.from_name("B-J2-L2-E2", paper_catalog), paper_catalog)
    assert line.lower == pytest.approx((0.0, 0.0, 1.2), abs=1e-12)
    assert line.upper == pytest.approx((0.0, 0.0, 1.5), abs=1e-12)
    assert line.excess((0.0, 0.0, 1.1)) == pytest.approx(0.1, abs=1e-12)
    assert line.excess((0.3, 0.0, 1.9)) == pytest.approx(0.5, abs=1e-12)
    assert line.excess((0.0, 0.0, 1.3)) == 0.0


def test_paper_compositions_stay_inside(paper_catalog):
    """Every 41st composition of the paper catalogue, 60 random configurations each."""
    for composition in itertools.islice(enumerate_compositions(paper_catalog), 0, None, 41):
        robot = robot_model(composition, paper_catalog, 0.0)
        assert _inside(catalog_workspace_box(composition, paper_catalog), robot, 60, 1) <= 1e-12, composition.name


@pytest.mark.parametrize(
    ("urdf", "tool"),
    [
        ("ur_description/urdf/ur5_robot.urdf", "tool0"),
        ("panda_description/urdf/panda.urdf", "panda_leftfinger"),
    ],
)
def test_foreign_robots_stay_inside(urdf, tool):
    """URDFs the package did not generate: the UR5 (revolute joints about y and z, placements
    rotated) and the Panda up to a finger (seven revolute joints, then a prismatic one)."""
    robot = _foreign(urdf, tool)
    box = workspace_box(robot)
    assert _inside(box, robot, 3000, 2) <= 1e-12
    # a bound, and not a loose one: each face within 0.75 m of the farthest of 3000 sampled tool
    # positions (measured: UR5 0.17-0.21 m, Panda 0.34-0.60 m)
    rng = np.random.default_rng(3)
    tool_positions = np.array([robot.tool_position(rng.uniform(robot.lower, robot.upper)) for _ in range(3000)])
    assert np.all(tool_positions.min(axis=0) - np.asarray(box.lower) <= 0.75)
    assert np.all(np.asarray(box.upper) - tool_positions.max(axis=0) <= 0.75)


def test_unaligned_axes_and_unbounded_joints():
    """A revolute joint about a skew axis and a prismatic joint along another stay inside their
    box; a spherical joint, which the box does not bound, gives an unbounded box."""
    model = pin.Model()
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    shoulder = model.addJoint(0, pin.JointModelRevoluteUnaligned(axis), pin.SE3(np.eye(3), np.array([0, 0, 0.3])), "a")
    slide = pin.JointModelPrismaticUnaligned(np.array([0.6, 0.0, 0.8]))
    rotation = pin.rpy.rpyToMatrix(0.4, -0.2, 1.1)
    elbow = model.addJoint(
        shoulder,
        slide,
        pin.SE3(rotation, np.array([0.5, 0.1, 0.0])),
        "b",
        np.array([50.0]),
        np.array([1.0]),
        np.array([-0.1]),
        np.array([0.4]),
    )
    model.addFrame(pin.Frame("tool0", elbow, 0, pin.SE3(np.eye(3), np.array([0.2, -0.1, 0.3])), pin.FrameType.OP_FRAME))
    model.lowerPositionLimit[0], model.upperPositionLimit[0] = -math.pi, math.pi
    robot = RobotModel(model, "tool0", (), "skew")
    assert _inside(workspace_box(robot), robot, 3000, 3) <= 1e-12

    rail = pin.Model()  # the slide alone: its box is the segment it moves the tool along
    joint = rail.addJoint(
        0, slide, pin.SE3.Identity(), "b", np.array([50.0]), np.array([1.0]), np.array([-0.1]), np.array([0.4])
    )
    rail.addFrame(pin.Frame("tool0", joint, 0, pin.SE3(np.eye(3), np.array([0.2, -0.1, 0.3])), pin.FrameType.OP_FRAME))
    box = workspace_box(RobotModel(rail, "tool0", (), "rail"))
    assert box.lower == pytest.approx((0.2 - 0.06, -0.1, 0.3 - 0.08), abs=1e-12)
    assert box.upper == pytest.approx((0.2 + 0.24, -0.1, 0.3 + 0.32), abs=1e-12)

    ball = pin.Model()
    joint = ball.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    ball.addFrame(pin.Frame("tool0", joint, 0, pin.SE3(np.eye(3), np.array([0.0, 0.0, 1.0])), pin.FrameType.OP_FRAME))
    box = workspace_box(RobotModel(ball, "tool0", (), "ball"))
    assert box.lower == (-math.inf,) * 3 and box.upper == (math.inf,) * 3
    assert box.excess((10.0, 10.0, 10.0)) == 0.0

    rail.upperPositionLimit[0] = math.inf  # a stroke without a limit: unbounded, never NaN
    box = workspace_box(RobotModel(rail, "tool0", (), "rail"))
    assert box.lower == (-math.inf,) * 3 and box.upper == (math.inf,) * 3


@pytest.mark.parametrize("twisted", [False, True])
def test_catalogue_numbers_give_the_model_box(paper_catalog, twisted):
    """The fast path (catalogue numbers, shared chains of last modules) against the box of the
    Pinocchio model built from the generated URDF, on every 13th composition: of the paper
    catalogue, and of one whose every module, the base included, has other twists in and out
    (the URDF mounts the base at the origin without its twist in)."""
    catalog = paper_catalog
    if twisted:
        angles = itertools.cycle([0.3, -1.1, 0.7, 2.0, -0.4])
        modules = tuple(
            dataclasses.replace(m, twist_in=m.twist_in + next(angles), twist_out=m.twist_out + next(angles))
            for m in paper_catalog.modules
        )
        catalog = dataclasses.replace(paper_catalog, name="twisted", modules=modules)
        assert catalog.module("B").twist_in != 0.0
    for composition in itertools.islice(enumerate_compositions(catalog), 0, None, 13):
        fast = catalog_workspace_box(composition, catalog)
        robot = robot_model(composition, catalog, 0.0)
        model = workspace_box(robot)
        assert fast.lower == pytest.approx(model.lower, abs=1e-12), composition.name
        assert fast.upper == pytest.approx(model.upper, abs=1e-12), composition.name
        if twisted and composition.name.count("-") == 4:
            assert _inside(fast, robot, 40, 5) <= 1e-12, composition.name


def test_general_catalogue_stays_inside():
    """Modules of a general (Timor) catalogue: the box of the model built from the assembled URDF."""
    scenario = load_scenario(SCENARIOS / "improv-pick.yaml")
    for composition in itertools.islice(enumerate_compositions(scenario.catalog), 0, None, 97):
        robot = robot_model(composition, scenario.catalog, 0.0)
        assert _inside(workspace_box(robot), robot, 40, 4) <= 1e-12, composition.name


def test_excess_bounds_the_ik_error(paper_catalog):
    """For compositions whose box misses the paper's start, IK from 32 seeds never comes closer
    to it than the box's distance; it does come within 5 cm of it on some (the box is not
    hopelessly loose)."""
    start = np.array(load_scenario(PAPER_5KG).task.start)
    gaps = []
    for composition in itertools.islice(enumerate_compositions(paper_catalog), 5, None, 151):
        excess = catalog_workspace_box(composition, paper_catalog).excess(start)
        if excess <= 0.0:
            continue
        robot = robot_model(composition, paper_catalog, 0.0)
        closest = min(r.error for r in solve_position_ik_many(robot, start, ik_seeds(robot, 32)))
        assert closest >= excess - 1e-9, composition.name
        gaps.append(closest - excess)
    assert len(gaps) >= 8
    assert min(gaps) < 0.05
