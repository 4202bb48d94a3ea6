"""Self-collision (``modular_robots.self_collision``) checked against physics that does not come
from it.

References used here:

* the distance of two capsules by dense point sampling of their axes (no closed form), with the
  axes placed by the robot's own frame placements (``RobotModel.primitive_segments``);
* central finite differences of the distances (the exact gradients must agree with them);
* a three-link arm built by hand, whose pairs and collisions follow from its drawing, and the
  paper catalogue with joints shortened to 0.1 m, so that a link can fold back onto the joint two
  modules before it;
* the re-integrated plan of a solve, sampled every millisecond.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from modular_robots.catalog import load_catalog
from modular_robots.composition import Composition
from modular_robots.feasibility import check_composition
from modular_robots.obstacles._geometry import segment_parameters
from modular_robots.ocp.candidate import Candidate, composition_problem
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.ocp.trajectory import sample_trajectory
from modular_robots.ocp.verification import verify
from modular_robots.robot import Primitive, RobotModel, robot_model
from modular_robots.scenario import OptimizerSettings, load_scenario
from modular_robots.self_collision import SelfCollisionModel, checked_pairs

from .helpers.paths import PAPER_5KG, PAPER_CATALOG

RADIUS = 0.05


def folding_arm(knuckle=0.3, last=0.5, axes="zzz", low=-3.0, high=3.0, payload=True) -> RobotModel:
    """Three links of 0.5 m, ``knuckle`` and ``last`` [m] along their frames' x, each turned by a
    joint at its start about ``axes``; capsules of radius 5 cm on the links (modules 1 to 3), a
    sphere of 5 cm at the base (module 0) and (if ``payload``) the payload's at the tip (module
    4). Rods of 1 kg."""
    model = pin.Model()
    model.name = "fold3"
    along_x = pin.utils.rotate("y", np.pi / 2)  # a primitive runs along its frame's z
    kinds = {"x": pin.JointModelRX, "y": pin.JointModelRY, "z": pin.JointModelRZ}
    parent, placement = 0, pin.SE3.Identity()
    primitives = [Primitive("base", "universe", RADIUS, 0.0, 0.0, 0)]
    for k, (length, axis) in enumerate(zip((0.5, knuckle, last), axes)):
        joint = model.addJoint(
            parent, kinds[axis](), placement, f"joint{k + 1}", np.array([10.0]), np.array([10.0]),
            np.array([low]), np.array([high]),
        )  # fmt: skip
        rod = np.diag([1e-4, length**2 / 12, length**2 / 12]) + 1e-4 * np.eye(3)
        model.appendBodyToJoint(joint, pin.Inertia(1.0, np.array([length / 2, 0.0, 0.0]), rod), pin.SE3.Identity())
        model.addFrame(pin.Frame(f"link{k + 1}", joint, 0, pin.SE3(along_x, np.zeros(3)), pin.FrameType.OP_FRAME))
        primitives.append(Primitive(f"link{k + 1}", f"link{k + 1}", RADIUS, length, 0.0, k + 1))
        parent, placement = joint, pin.SE3(np.eye(3), np.array([length, 0.0, 0.0]))
    model.addFrame(pin.Frame("tool0", parent, 0, placement, pin.FrameType.OP_FRAME))
    if payload:
        primitives.append(Primitive("payload", "tool0", RADIUS, 0.0, 0.0, 4))
    return RobotModel(model, "tool0", primitives, name="fold3")


def sampled_distance(robot: RobotModel, q: np.ndarray, i: int, j: int, points: int = 801) -> float:
    """Primitives ``i`` and ``j`` at ``q``: the smallest distance between ``points`` points along
    each axis, less both radii (within the spacing of the points of the exact distance)."""
    a, b = robot.primitive_segments(q)
    s = np.linspace(0.0, 1.0, points)[:, None]
    on_i, on_j = a[i] + s * (b[i] - a[i]), a[j] + s * (b[j] - a[j])
    gaps = np.linalg.norm(on_i[:, None] - on_j[None], axis=-1)
    return float(gaps.min()) - robot.primitives[i].radius - robot.primitives[j].radius


def names(robot: RobotModel, pairs) -> set[tuple[str, str]]:
    return {(robot.primitives[i].name, robot.primitives[j].name) for i, j in pairs}


@pytest.fixture(scope="module")
def short_joints(tmp_path_factory) -> Path:
    """The paper catalogue with every J1 joint 0.1 m long instead of 0.25 m."""
    old = "joint: revolute           # Rz(q) Tz(0.25)\n    length: 0.25"
    text = PAPER_CATALOG.read_text()
    assert text.count(old) == 1
    path = tmp_path_factory.mktemp("catalog") / "short.yaml"
    path.write_text(text.replace(old, old.replace("length: 0.25", "length: 0.1")))
    return path


# -- distances and gradients ---------------------------------------------------------------------
def test_distances_match_dense_point_sampling():
    """Capsule-capsule, capsule-sphere and sphere-sphere, apart and overlapping, in 3D."""
    robot = folding_arm(axes="zyz")
    model = SelfCollisionModel(robot)
    assert names(robot, model.pairs) >= {("link1", "link3"), ("base", "payload"), ("link1", "payload")}
    qs = np.random.default_rng(4).uniform(-3.0, 3.0, (12, 3))
    got = model.distances(qs)[0]
    reference = np.array([[sampled_distance(robot, q, i, j) for i, j in model.pairs] for q in qs])
    assert (reference < 0).any() and (reference > 0).any()
    # the sampled distance is at most half a spacing on each axis (0.625 mm) above the exact one
    assert np.all(got <= reference + 1e-12)
    assert np.abs(got - reference).max() < 7e-4


def test_gradients_match_central_differences():
    robot = folding_arm(axes="zyz")
    model = SelfCollisionModel(robot)
    h = 1e-6
    for q in np.random.default_rng(5).uniform(-3.0, 3.0, (10, 3)):
        _, grad = model.distances(q[None], derivatives=True)
        assert grad is not None
        steps = h * np.eye(3)
        fd = np.stack([(model.distances(q + e)[0][0] - model.distances(q - e)[0][0]) / (2 * h) for e in steps], axis=1)
        assert np.abs(grad[0] - fd).max() < 1e-6, (q, grad[0] - fd)
        assert np.abs(fd).max() > 0.1  # some pair moves


# -- which pairs ----------------------------------------------------------------------------------
def test_the_pair_rule_on_a_hand_built_arm():
    """Neighbours in the chain are left out, the others kept; with a 4 cm knuckle the first and
    last links overlap in every configuration (their axes are never more than 4 cm apart, their
    radii add to 10 cm), so they are left out too, while the payload, which can fold back onto
    the first link, is kept."""
    robot = folding_arm()
    kept = {("base", "link2"), ("base", "link3"), ("base", "payload")}
    kept |= {("link1", "link3"), ("link1", "payload"), ("link2", "payload")}
    assert names(robot, checked_pairs(robot)) == kept
    knuckle = folding_arm(knuckle=0.04)
    assert names(knuckle, checked_pairs(knuckle)) == kept - {("link1", "link3")}
    qs = np.random.default_rng(6).uniform(-3.0, 3.0, (200, 3))
    link1, link3 = 1, 3
    assert max(sampled_distance(knuckle, q, link1, link3, 101) for q in qs) < 0.0


def test_the_pair_rule_on_a_catalogue_composition(short_joints):
    catalog = load_catalog(short_joints)
    robot = robot_model(Composition.from_name("B-J1-L3-J1-L1-E1", catalog), catalog)
    modules = {p.name: p.module for p in robot.primitives}
    pairs = names(robot, checked_pairs(robot))
    assert all(abs(modules[a] - modules[b]) >= 2 for a, b in pairs)
    # L1 starts on the second joint's axis 0.1 m from L3's end, across it: the two capsules
    # (radius 0.1 m) overlap however the joint turns
    assert ("m2_L3_capsule", "m4_L1_capsule") not in pairs
    # L1 folds back onto the first joint
    assert ("m1_J1_port", "m4_L1_capsule") in pairs


# -- step B ----------------------------------------------------------------------------------------
def _folded_task(short_joints):
    """B-J1-L3-J1-L1-E1 of ``short_joints`` and a task whose start only a fold reaches (the
    tool 9 cm below the base, L1 folded back onto the first joint)."""
    catalog = load_catalog(short_joints)
    composition = Composition.from_name("B-J1-L3-J1-L1-E1", catalog)
    robot = robot_model(composition, catalog)
    start, goal = (robot.tool_position(np.array(q)) for q in ([0.0, 3.0, 0.0], [0.0, 1.0, 0.0]))
    task = replace(load_scenario(PAPER_5KG).task, payload=0.0, obstacles=(), floor=None)
    task = replace(task, start=tuple(map(float, start)), goal=tuple(map(float, goal)))
    return catalog, composition, task


def test_step_b_removes_a_composition_whose_pose_collides_with_itself(short_joints):
    catalog, composition, task = _folded_task(short_joints)
    assert task.self_collision  # the default
    verdict = check_composition(composition, catalog, task)
    assert verdict.failed_test == "collision"
    assert verdict.message.startswith("self-collision: m1_J1_port ") and verdict.message.endswith(
        "m inside m4_L1_capsule (start)"
    )
    assert verdict.figures["clearance"] < -0.03
    # without self-collision the same composition reaches the same start, folded
    off = check_composition(composition, catalog, replace(task, self_collision=False))
    assert off.passed and off.q_start is not None
    robot = robot_model(composition, catalog)
    assert SelfCollisionModel(robot).min_distance(np.array(off.q_start)) < 0.0


# -- step C and verification -----------------------------------------------------------------------
def dense_motion(problem: ShootingProblem, y: np.ndarray, step: float = 1e-3) -> np.ndarray:
    """The plan's configurations every ``step`` seconds: each row's parabola (constant
    acceleration from its row) evaluated in between."""
    plan = sample_trajectory(problem, y)
    out = [plan.q[-1:]]
    for k in range(len(plan.t) - 1):
        tau = np.arange(0.0, plan.t[k + 1] - plan.t[k], step)[:, None]
        out.append(plan.q[k] + plan.qd[k] * tau + 0.5 * plan.qdd[k] * tau**2)
    return np.vstack(out)


def test_an_optimised_motion_keeps_clear_of_itself():
    """A planar arm whose joint-space line from start to goal swings the last link through the
    first: with self-collision it goes round, clear on a 1 ms grid; without, it goes through.
    (No payload: folded back over the knuckle, it would touch the knuckle for every value of the
    second joint, and no way round would be left.)"""
    robot = folding_arm(knuckle=0.6, last=0.4, low=-1.0, high=5.0, payload=False)
    start, goal = np.array([0.0, 2.5, 1.6]), np.array([0.0, 2.5, 3.9])
    link1, link3 = 1, 3
    line = start + np.linspace(0.0, 1.0, 41)[:, None] * (goal - start)
    assert min(sampled_distance(robot, q, link1, link3, 101) for q in line) < -0.05
    settings = OptimizerSettings(nodes=6, substeps=3)
    plans = {}
    for on in (True, False):
        problem = ShootingProblem(robot, start, goal, (), "time", settings, self_collision=on)
        result = Candidate(problem).solve()
        assert result.status == "optimal", result.reason
        plans[on] = (problem, result)
    problem, result = plans[True]
    motion = dense_motion(problem, result.y)
    assert len(motion) > 400
    pairs = checked_pairs(robot)
    clearance = min(sampled_distance(robot, q, i, j, 201) for q in motion[::4] for i, j in pairs)
    assert 0.0 < clearance < 0.03  # the margin (0.02 m at the sub-steps) binds
    assert SelfCollisionModel(robot).distances(motion)[0].min() > 0.0
    # without: through the first link; the verification of a problem with self-collision fails it
    unchecked, through = plans[False]
    assert through.cost < result.cost
    assert min(sampled_distance(robot, q, link1, link3, 201) for q in dense_motion(unchecked, through.y)[::4]) < -0.05
    assert not verify(problem, through.y).clearance_ok
    assert verify(problem, result.y).passed


def test_self_collision_false_turns_it_off(short_joints, tmp_path):
    text = PAPER_5KG.read_text().replace("catalog: catalogs/paper.yaml", f"catalog: {PAPER_CATALOG}")
    assert "self_collision" not in text
    path = tmp_path / "off.yaml"
    path.write_text(text.replace("  cost: time\n", "  cost: time\n  self_collision: false\n"))
    assert load_scenario(PAPER_5KG).task.self_collision
    off = load_scenario(path)
    assert not off.task.self_collision
    catalog, composition, task = _folded_task(short_joints)
    assert check_composition(composition, catalog, replace(task, self_collision=off.task.self_collision)).passed
    # step C: no self-collision rows, and none of its distances in verification
    q_start, q_goal = [0.0, 1.0, 0.0], [0.0, 2.0, 0.5]
    rows = {}
    for on in (True, False):
        problem = composition_problem(composition, catalog, replace(task, self_collision=on), q_start, q_goal)
        assert (problem.self_collision is None) is not on
        rows[on] = len(problem.rows_of("clearance"))
    assert rows[False] == 0 < rows[True]


def test_the_closest_points_of_two_segments_match_dense_sampling_also_with_a_point_second():
    """``segment_parameters`` once set ``s = 0`` when the second segment was a point (a sphere
    after a capsule): the distance of the capsule's start, not its closest point."""
    rng = np.random.default_rng(21)
    samples = np.linspace(0.0, 1.0, 401)
    for case in range(300):
        p1, d1, p2, d2 = rng.normal(size=(4, 3))
        if case % 3 == 0:
            d2 = np.zeros(3)
        if case % 5 == 0:
            d1 = np.zeros(3)
        s, t = segment_parameters(p1, d1, p2, d2)
        found = np.linalg.norm(p1 + s * d1 - p2 - t * d2)
        first, second = p1 + samples[:, None] * d1, p2 + samples[:, None] * d2
        sampled = np.linalg.norm(first[:, None] - second[None], axis=2).min()
        assert found <= sampled + 1e-12 and found >= sampled - 1e-4 * (1 + np.linalg.norm(d1) + np.linalg.norm(d2))
