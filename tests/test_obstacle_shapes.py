"""Box, capsule and half-space obstacles: distances against independent computations (a dense grid
over both segments; the height of the link ends), gradients against finite differences, inside
the shapes too (both are closed forms, never FCL), their scenario and JSON forms, and a
time-optimal motion of the planar arm around each, checked with the independent distance."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from modular_robots.collision import CollisionModel
from modular_robots.composition import enumerate_compositions
from modular_robots.exceptions import ScenarioError
from modular_robots.obstacles import BoxObstacle, CapsuleObstacle, PlaneObstacle, obstacle_from_json, obstacle_to_json
from modular_robots.obstacles._geometry import rpy_matrix
from modular_robots.ocp.candidate import Candidate
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.robot import robot_model
from modular_robots.scenario import OptimizerSettings, load_scenario

from .helpers.browser import CHROMIUM, visit
from .helpers.models import ARM_GOAL, ARM_START, R_LINK, arm_points, planar_arm
from .helpers.paths import PAPER_5KG

CAPSULES = [
    CapsuleObstacle((1.3, 0.9, 0.0), 0.15, 0.6),  # a column standing in the arm's plane
    CapsuleObstacle((0.6, -1.1, 0.2), 0.1, 1.0, (0.3, 1.2, -0.4)),  # a tilted beam
    CapsuleObstacle((-0.9, 0.5, -0.05), 0.2, 0.8, (np.pi / 2, 0.0, 0.3)),  # lying across the plane
]
BOXES = [
    BoxObstacle((1.4, 0.6, 0.0), (0.4, 0.3, 0.5), (0.2, 0.1, 0.7)),  # a turned block in the arm's way
    BoxObstacle((-0.8, -0.9, 0.3), (1.2, 0.2, 0.5)),  # a fence panel whose lower edge the arm passes
]
PLANES = [
    PlaneObstacle((1.6, 0.0, 0.0), (-1.0, 0.0, 0.0)),  # a wall: everything beyond x = 1.6
    PlaneObstacle((0.0, 0.0, -0.06), (0.3, -0.2, 1.0)),  # a tilted floor just under the arm
]


def _grid_distance(a0, a1, b0, b1, samples: int = 801) -> float:
    """The distance between segments a0-a1 and b0-b1 by brute force over a grid of both."""
    s = np.linspace(0.0, 1.0, samples)[:, None]
    pa = a0 + s * (a1 - a0)
    pb = b0 + s * (b1 - b0)
    best = np.inf
    for chunk in np.array_split(pa, 8):
        best = min(best, float(np.sqrt(((chunk[:, None] - pb[None]) ** 2).sum(-1)).min()))
    return best


def _arm_capsule_clearance(q, capsule: CapsuleObstacle) -> float:
    base, elbow, tool = arm_points(q)
    axis = rpy_matrix(capsule.rpy)[:, 2]
    c = np.asarray(capsule.center)
    b0, b1 = c - 0.5 * capsule.length * axis, c + 0.5 * capsule.length * axis
    return min(_grid_distance(a, b, b0, b1) for a, b in ((base, elbow), (elbow, tool))) - R_LINK - capsule.radius


def _arm_box_clearance(q, box: BoxObstacle, samples: int = 20001) -> float:
    """Brute force: the smallest distance of points along the links to the box (outside, the
    distance to the clamped point; inside, minus the depth below the nearest face)."""
    rotation, center, half = rpy_matrix(box.rpy), np.asarray(box.center), 0.5 * np.asarray(box.size)
    s = np.linspace(0.0, 1.0, samples)[:, None]
    best = np.inf
    for a, b in itertools.pairwise(arm_points(q)):
        local = (a + s * (b - a) - center) @ rotation
        clamped = np.clip(local, -half, half)
        outside = np.linalg.norm(local - clamped, axis=1)
        depth = np.min(half - np.abs(local), axis=1)
        best = min(best, float(np.where(outside > 0.0, outside, -depth).min()))
    return best - R_LINK


def _arm_plane_clearance(q, plane: PlaneObstacle) -> float:
    n = np.asarray(plane.normal)
    return min(float((p - np.asarray(plane.point)) @ n) for p in arm_points(q)) - R_LINK


def _configurations(obstacle) -> np.ndarray:
    """Random configurations and, toward the obstacle, a fan that reaches into it."""
    towards = np.asarray(obstacle.bounding_sphere()[0])
    if isinstance(obstacle, PlaneObstacle):
        towards = -np.asarray(obstacle.normal)
    heading = float(np.arctan2(towards[1], towards[0]))
    fan = [(heading + a, b) for a in (-0.5, -0.2, 0.1, 0.4) for b in (-0.8, -0.3, 0.2, 0.7)]
    return np.vstack([np.random.default_rng(11).uniform(-2.8, 2.8, (8, 2)), fan])


@pytest.mark.parametrize("capsule", CAPSULES, ids=["column", "tilted-beam", "lying"])
def test_capsule_distance_matches_a_dense_grid_over_both_segments(capsule):
    model = CollisionModel(planar_arm(), [capsule])
    configurations = _configurations(capsule)
    distances = model.closest_many(configurations)[0][:, 0]
    expected = [_arm_capsule_clearance(q, capsule) for q in configurations]
    assert min(expected) < 0.0 < max(expected)  # both sides of contact
    # a grid over the segments can only overestimate their distance, by at most about a step
    assert np.all(distances <= np.asarray(expected) + 1e-12)
    np.testing.assert_allclose(distances, expected, atol=2e-5)


@pytest.mark.parametrize("box", BOXES, ids=["turned-block", "fence"])
def test_box_distance_matches_points_sampled_along_the_links(box):
    model = CollisionModel(planar_arm(), [box])
    configurations = _configurations(box)
    distances = model.closest_many(configurations)[0][:, 0]
    expected = np.array([_arm_box_clearance(q, box) for q in configurations])
    assert expected.min() < 0.0 < expected.max()  # both sides of contact
    assert np.all(distances <= expected + 1e-12)  # sampling can only overestimate, by about a step
    np.testing.assert_allclose(distances, expected, atol=6e-5)


@pytest.mark.parametrize("plane", PLANES, ids=["wall", "tilted-floor"])
def test_plane_distance_is_the_lowest_link_end_above_it(plane):
    model = CollisionModel(planar_arm(), [plane])
    configurations = _configurations(plane)
    distances = model.closest_many(configurations)[0][:, 0]
    expected = [_arm_plane_clearance(q, plane) for q in configurations]
    np.testing.assert_allclose(distances, expected, atol=1e-12)
    assert min(expected) < 0.0 < max(expected)


@pytest.mark.parametrize(
    "obstacle",
    CAPSULES + BOXES + PLANES,
    ids=["column", "tilted-beam", "lying", "turned-block", "fence", "wall", "floor"],
)
def test_gradient_matches_central_differences_inside_and_outside(obstacle):
    model = CollisionModel(planar_arm(), [obstacle])
    h, checked = 1e-6, 0
    for q in _configurations(obstacle):
        d, grad = model.closest(q, derivatives=True)
        fd = [(model.closest(q + e)[0][0] - model.closest(q - e)[0][0]) / (2 * h) for e in h * np.eye(2)]
        # skip the kinks, where the closest pair of points jumps
        if abs(fd[0] - (model.closest(q + h * np.eye(2)[0])[0][0] - d[0]) / h) > 1e-4:
            continue
        np.testing.assert_allclose(grad[0], fd, atol=1e-5)
        checked += 1
    assert checked >= 8


def test_the_scenario_reads_both_shapes_and_refuses_bad_ones(tmp_path):
    text = PAPER_5KG.read_text().replace("catalog: catalogs/", f"catalog: {PAPER_5KG.parent}/catalogs/")
    assert "  obstacles:" in text

    def scenario(obstacles: str):
        path = tmp_path / "s.yaml"
        body = "\n".join(line for line in text.splitlines() if not line.strip().startswith(("- sphere", "- {sphere")))
        path.write_text(body.replace("  obstacles:", "  obstacles:\n" + obstacles, 1))
        return path

    task = load_scenario(
        scenario(
            "    - capsule: {center: [1.5, -1.3, 1.1], radius: 0.3, length: 0.5, rpy: [0, 0.5, 0]}\n"
            "    - plane: {point: [0, 0, -0.5], normal: [0, 0, 2]}\n"
            "    - box: {center: [-1.2, 2.1, 0.8], size: [0.2, 0.4, 0.6], rpy: [0, 0, 0.5]}\n"
        )
    ).task
    assert task.obstacles == (
        CapsuleObstacle((1.5, -1.3, 1.1), 0.3, 0.5, (0.0, 0.5, 0.0)),
        PlaneObstacle((0.0, 0.0, -0.5), (0.0, 0.0, 1.0)),
        BoxObstacle((-1.2, 2.1, 0.8), (0.2, 0.4, 0.6), (0.0, 0.0, 0.5)),
    )
    for o in task.obstacles:
        assert obstacle_from_json(obstacle_to_json(o)) == o
    bad = {
        "    - plane: {point: [0, 0, -0.5], normal: [0, 0, 0]}\n": r"task\.obstacles\[0\]\.plane\.normal: expected a non-zero vector",
        "    - capsule: {center: [1.5, -1.3, 1.1], radius: 0.3, length: 0}\n": r"task\.obstacles\[0\]\.capsule\.length: expected a number > 0",
        "    - plane: {point: [0, 0, 0.5], normal: [0, 0, 1]}\n": r"task\.obstacles\[0\]\.plane: the obstacle contains the robot's base",
        "    - cone: {center: [1, 1, 1]}\n": r"task\.obstacles\[0\]\.cone: unknown key \(expected one of: box, capsule, cylinder, mesh, plane, sphere\)",
    }
    for obstacles, message in bad.items():
        with pytest.raises(ScenarioError, match=message):
            load_scenario(scenario(obstacles))


@pytest.mark.parametrize(
    "obstacle",
    [
        CapsuleObstacle((1.75, 0.0, 0.0), 0.12, 0.6),
        BoxObstacle((1.8, 0.0, 0.0), (0.25, 0.3, 0.4), (0.0, 0.0, 0.4)),
        PlaneObstacle((1.6, 0.0, 0.0), (-1.0, 0.0, 0.0)),
    ],
    ids=["column", "block", "wall"],
)
def test_the_time_optimal_motion_goes_round_each_shape(obstacle):
    """The stretched arm sweeps through x = 2 on its straight line: both shapes are in the way.
    The verified plan keeps clear at every millisecond by the independent distance."""
    line = [np.asarray(ARM_START) + s * (np.asarray(ARM_GOAL) - ARM_START) for s in np.linspace(0, 1, 101)]
    independent = {
        CapsuleObstacle: _arm_capsule_clearance,
        BoxObstacle: _arm_box_clearance,
        PlaneObstacle: _arm_plane_clearance,
    }[type(obstacle)]
    assert min(independent(q, obstacle) for q in line[40:61]) < -0.1
    problem = ShootingProblem(
        planar_arm(), ARM_START, ARM_GOAL, [obstacle], "time", OptimizerSettings(nodes=8, substeps=4)
    )
    result = Candidate(problem).solve()
    assert result.status == "optimal", result.reason
    assert result.verification.passed and result.verification.min_clearance >= 0.0
    times = np.arange(0.0, result.tf, 1e-3)
    qs = result.trajectory.at(times)[0]
    step = 1 if isinstance(obstacle, PlaneObstacle) else 10  # the grid distance is slow: every 10 ms
    assert min(independent(q, obstacle) for q in qs[::step]) >= -1e-6
    for a, b in itertools.pairwise(qs[::step][:3]):
        assert np.all(np.isfinite(a)) and np.all(np.isfinite(b))


def test_a_run_among_a_column_and_a_floor_verifies_and_its_page_draws_them(tmp_path):
    """The small scenario with a capsule column beside the path and a floor plane under the
    base: the winner verifies clear of both, ``result.json`` keeps the shapes, and the page
    draws them (no console error in headless Chromium, where .ci/run installs it)."""
    import json

    from modular_robots.pipeline import run_scenario

    from .helpers.paths import SMALL

    text = SMALL.read_text().replace("../../scenarios/", f"{SMALL.parents[2]}/scenarios/")
    text = text.replace(
        "    - sphere: {center: [0.3, 1.0, 1.6], radius: 0.2}",
        "    - capsule: {center: [0.25, 1.1, 1.4], radius: 0.1, length: 0.5, rpy: [0.3, 0, 0]}\n"
        "    - plane: {point: [0, 0, -0.3], normal: [0, 0, 1]}",
    )
    scenario_path = tmp_path / "shapes.yaml"
    scenario_path.write_text(text)
    out = tmp_path / "out"
    result = run_scenario(load_scenario(scenario_path), out, jobs=1)
    winner = result.winner
    assert winner is not None and winner.verification.passed and winner.verification.min_clearance >= 0.0
    document = json.loads((out / "result.json").read_text())
    assert [next(iter(o)) for o in document["task"]["obstacles"]] == ["capsule", "plane", "floor"]
    if CHROMIUM is not None:
        assert visit(out, tmp_path).errors == []


def test_the_nearest_pair_measured_best_first_is_the_smallest_of_all_pairs():
    """Step B measures pairs in the order of their lower bounds and stops at the first bound past
    the nearest distance found (:meth:`CollisionModel.nearest`): the same distance and pair as
    measuring every one, on IMPROV among every shape in the cell scenario."""
    scenario = load_scenario(PAPER_5KG.parent / "cell-table.yaml")
    obstacles = scenario.task.collision_obstacles + (
        CapsuleObstacle((0.0, 0.5, 0.4), 0.05, 0.3),
        PlaneObstacle((0.0, -0.6, 0.0), (0.0, 1.0, 0.0)),
    )
    rng = np.random.default_rng(8)
    for composition in list(enumerate_compositions(scenario.catalog))[:4]:
        robot = robot_model(composition, scenario.catalog, 1.0)
        collision = CollisionModel(robot, obstacles)
        for q in rng.uniform(robot.lower, robot.upper, (10, robot.nv)):
            every = collision.distances(q).distance
            distance, i, j = collision.nearest(q)
            assert distance == every.min() and every[i, j] == distance
