"""The three extension points (obstacle shapes, costs, solvers) used as docs/extending.md says:
a member defined here, registered in its family's table, reaches the pipeline unchanged."""

from __future__ import annotations

from dataclasses import replace
from typing import ClassVar

import numpy as np
import pytest

from modular_robots import obstacles as obstacle_shapes
from modular_robots import scenario as scenario_module
from modular_robots.collision import CollisionModel
from modular_robots.composition import Composition
from modular_robots.costs import COSTS, Cost, Time
from modular_robots.exceptions import ScenarioError
from modular_robots.feasibility import check_composition
from modular_robots.obstacles import Obstacle, SphereObstacle, obstacle_from_json, obstacle_to_json
from modular_robots.ocp import solvers
from modular_robots.ocp.candidate import Candidate, make_candidate
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.pipeline import candidate_specs
from modular_robots.scenario import OptimizerSettings, load_scenario

from .helpers.models import ARM_GOAL, ARM_START, planar_arm
from .helpers.paths import PAPER_5KG


class Ball(SphereObstacle):
    """A second shape class with a sphere's geometry: the collision model batches obstacles by
    class, so a mix of classes must give what the same spheres give in one batch."""

    kind: ClassVar[str] = "ball"


def test_obstacles_of_two_shape_classes_measure_as_one_batch_of_spheres():
    robot = planar_arm()
    spec = [((1.3, 0.9, 0.0), 0.2), ((-0.4, 1.5, 0.1), 0.3), ((0.9, -1.2, 0.0), 0.25)]
    plain = CollisionModel(robot, [SphereObstacle(c, r) for c, r in spec])
    mixed = CollisionModel(robot, [SphereObstacle(*spec[0]), Ball(*spec[1]), SphereObstacle(*spec[2])])
    assert len(mixed._groups) == 2
    qs = np.random.default_rng(5).uniform(-2.5, 2.5, (40, 2))
    d_plain, g_plain = plain.closest_many(qs, derivatives=True)
    d_mixed, g_mixed = mixed.closest_many(qs, derivatives=True)
    assert np.isfinite(d_plain).all() and (d_plain < 0).any() and (d_plain > 0).any()  # both sides of contact
    np.testing.assert_array_equal(d_mixed, d_plain)
    np.testing.assert_array_equal(g_mixed, g_plain)
    path = np.array([ARM_START, ARM_GOAL])
    for clearance in (0.0, 0.05, 0.3):
        assert mixed.path_clear(path, clearance) == plain.path_clear(path, clearance)


class FclBall(SphereObstacle):
    """A shape as docs/extending.md allows one without a closed form: FCL measures it, apart and
    overlapping, and its normals are the convex shape's ``on_robot - on_obstacle``."""

    kind: ClassVar[str] = "fcl_ball"
    closed_form: ClassVar[bool] = False

    def signed_distance(self, mid, axis, length, radius):
        return None

    @classmethod
    def normals(cls, batch, on_robot, on_obstacle):
        return on_robot - on_obstacle


def test_a_shape_fcl_measures_gives_the_closed_forms_distances_and_gradients_inside_too():
    """FCL's distance is -1 on any overlap, with no witness points: passed on, the clearance was
    -1 m and its gradient NaN (a step C crash, 'array must not contain infs or NaNs'). Inside, the
    depth and contact of FCL's collision test give the sphere's closed form."""
    robot = planar_arm()
    spec = [((1.3, 0.9, 0.0), 0.2), ((-0.4, 1.5, 0.1), 0.3), ((0.9, -1.2, 0.0), 0.25)]
    exact = CollisionModel(robot, [SphereObstacle(c, r) for c, r in spec])
    fcl_model = CollisionModel(robot, [FclBall(c, r) for c, r in spec])
    qs = np.random.default_rng(5).uniform(-2.5, 2.5, (200, 2))
    d_exact, g_exact = exact.closest_many(qs, derivatives=True)
    d_fcl, g_fcl = fcl_model.closest_many(qs, derivatives=True)
    assert (d_exact < -0.01).sum() >= 5 and (d_exact > 0.01).sum() >= 5
    np.testing.assert_allclose(d_fcl, d_exact, rtol=0, atol=1e-9)
    np.testing.assert_allclose(g_fcl, g_exact, rtol=0, atol=1e-9)


def test_a_registered_shape_is_read_from_a_scenario_and_round_trips_through_json(tmp_path, monkeypatch):
    monkeypatch.setitem(obstacle_shapes.SHAPES, "ball", Ball)
    text = PAPER_5KG.read_text()
    catalog = (PAPER_5KG.parent / "catalogs" / "paper.yaml").resolve()
    text = text.replace("catalog: catalogs/paper.yaml", f"catalog: {catalog}")
    assert "obstacles:" in text
    scenario_path = tmp_path / "ball.yaml"
    scenario_path.write_text(text.replace("- sphere:", "- ball:", 1))
    task = load_scenario(scenario_path).task
    assert isinstance(task.obstacles[0], Ball) and isinstance(task.obstacles[0], Obstacle)
    assert [type(o) for o in task.obstacles[1:]] == [SphereObstacle] * (len(task.obstacles) - 1)
    for o in task.obstacles:
        assert obstacle_from_json(obstacle_to_json(o)) == o
    scenario_path.write_text(text.replace("- sphere:", "- cone:", 1))
    with pytest.raises(
        ScenarioError,
        match=r"task\.obstacles\[0\]\.cone: unknown key \(expected one of: ball, box, capsule, cylinder, mesh, plane, sphere\)",
    ):
        load_scenario(scenario_path)


def test_result_json_obstacles_are_validated_when_read():
    assert obstacle_from_json({"center": [0.5, 0.0, 0.4], "radius": 0.1}) == SphereObstacle((0.5, 0.0, 0.4), 0.1)
    with pytest.raises(ValueError, match=r"sphere\.radius: expected a finite number, got '<img"):
        obstacle_from_json({"sphere": {"center": [0.5, 0.0, 0.4], "radius": "<img src=x>"}})
    with pytest.raises(ValueError, match=r"expected a mapping of one shape key"):
        obstacle_from_json({"cone": {}})


class TwiceTime(Time):
    """Twice the duration: twice the cost, its gradient and its bound."""

    name: ClassVar[str] = "twice-time"

    def lower_bound(self, robot, q_start, q_goal, velocity_bound):
        return 2.0 * super().lower_bound(robot, q_start, q_goal, velocity_bound)

    def evaluate(self, problem, tf, motion, derivatives):
        cost, grad = super().evaluate(problem, tf, motion, derivatives)
        return 2.0 * cost, (None if grad is None else 2.0 * grad)


def test_a_cost_defined_outside_the_package_is_minimised_by_step_c():
    settings = OptimizerSettings(nodes=5, substeps=2)
    time = ShootingProblem(planar_arm(), ARM_START, ARM_GOAL, cost="time", settings=settings)
    twice = ShootingProblem(planar_arm(), ARM_START, ARM_GOAL, cost=TwiceTime(), settings=settings)
    assert isinstance(twice.objective, Cost) and twice.cost_name == "twice-time"
    assert twice.cost_bound == pytest.approx(2.0 * time.cost_bound) and time.cost_bound > 0
    y = time.initial_guess()
    assert twice.evaluate(y).cost == 2.0 * time.evaluate(y).cost
    np.testing.assert_array_equal(twice.evaluate(y).cost_gradient, 2.0 * time.evaluate(y).cost_gradient)
    # The solver minimises what the cost says: the outcome reports it, above its bound. (Scaled by
    # two, trust-constr takes another path and may end at another local optimum than for time.)
    outcome = ShootingSolver(twice).solve()
    assert outcome.converged and outcome.final.constraint_violation < 1e-6
    assert outcome.final.cost == pytest.approx(2.0 * outcome.final.tf, rel=1e-9)
    assert outcome.final.cost >= twice.cost_bound


def test_the_scenario_reader_and_the_solver_table_name_the_same_solvers():
    assert tuple(solvers.SOLVERS) == scenario_module.SOLVERS
    assert tuple(COSTS) == ("time", "effort", "energy", "mass", "joints", "modules", "price")
    assert isinstance(ShootingSolver(ShootingProblem(planar_arm(), ARM_START, ARM_GOAL)), solvers.Solver)
    with pytest.raises(solvers.UnknownSolverError, match=r"unknown solver 'nope'; expected one of \['trust-constr'\]"):
        solvers.make_solver("nope", ShootingProblem(planar_arm(), ARM_START, ARM_GOAL))


def test_the_scenarios_solver_setting_chooses_the_solver_of_every_candidate(monkeypatch):
    made = []

    def recording(problem, y0=None, *, jacobian="exact", iteration_offset=0):
        made.append(iteration_offset)
        return ShootingSolver(problem, y0, jacobian=jacobian, iteration_offset=iteration_offset)

    monkeypatch.setitem(solvers.SOLVERS, "recording", recording)
    scenario = load_scenario(PAPER_5KG)
    composition = Composition.from_name("B-J1-L2-J1-L1-J1-L2-J2-L1-E2", scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    spec = next(candidate_specs([verdict]))
    chosen = replace(scenario, optimizer=replace(scenario.optimizer, solver="recording", max_iterations=5))
    result = make_candidate(chosen, spec).solve()
    assert made and made[0] == 0 and result.iterations >= 5
    assert isinstance(make_candidate(scenario, spec), Candidate)
