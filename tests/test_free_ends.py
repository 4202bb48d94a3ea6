"""Free ends (``optimizer.free_ends``): step C chooses the start and goal configurations within
the task's tolerated tool poses. The rows' Jacobian against central differences, the solved ends
against forward kinematics computed apart from the rows, and the bound against the optimum."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from modular_robots.composition import Composition
from modular_robots.exceptions import ScenarioError
from modular_robots.feasibility import check_composition
from modular_robots.obstacles import SphereObstacle
from modular_robots.ocp import solvers
from modular_robots.ocp.candidate import composition_problem, make_candidate
from modular_robots.ocp.ends import ToolEnd
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.ocp.verification import verify
from modular_robots.orientation import Orientation
from modular_robots.pipeline import candidate_specs
from modular_robots.plan.document import candidate_json
from modular_robots.scenario import load_scenario

from .helpers.models import ur5
from .helpers.paths import PAPER_5KG

WINNER = "B-J1-L2-J1-L1-J1-L2-J2-L1-E2"


def _tool(robot, q):
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    pose = pin.updateFramePlacement(robot.model, data, robot.tool_frame_id)
    return pose.translation.copy(), pose.rotation.copy()


def test_the_free_ends_rows_have_their_exact_jacobian():
    robot = ur5(1.0)
    rng = np.random.default_rng(2)
    q_start, q_goal = rng.uniform(-1.0, 1.0, (2, robot.nq))
    (p_start, r_start), (p_goal, r_goal) = _tool(robot, q_start), _tool(robot, q_goal)
    ends = (
        ToolEnd(tuple(p_start), 1e-3, Orientation(rpy=tuple(pin.rpy.matrixToRpy(r_start)), tolerance=0.05)),
        ToolEnd(tuple(p_goal), 1e-3, Orientation(axis=tuple(r_goal[:, 2]), tolerance=0.05)),
    )
    obstacle = SphereObstacle(tuple(0.5 * (p_start + p_goal) + [0.0, 0.0, 0.6]), 0.1)
    problem = ShootingProblem(robot, q_start, q_goal, [obstacle], self_collision=False, free_ends=ends)
    y = problem.initial_guess() + 0.01 * rng.normal(size=problem.n_variables)
    jacobian = problem.constraint_jacobian(y).toarray()
    numeric = np.empty_like(jacobian)
    for k in range(problem.n_variables):
        step = np.zeros(problem.n_variables)
        step[k] = 1e-6
        numeric[:, k] = (problem.constraints(y + step) - problem.constraints(y - step)) / 2e-6
    ends_rows = problem.rows_of("ends")
    assert len(ends_rows) == 3 + 1 + 3 + 1 + 1  # start pose, goal pose, the goal's clearance
    assert np.abs(jacobian - numeric).max() <= 1e-5 * max(1.0, np.abs(numeric).max())
    assert np.abs(jacobian[ends_rows] - numeric[ends_rows]).max() <= 1e-6


def test_freed_ends_of_the_paper_winner_stay_within_the_tolerance_and_are_no_slower():
    scenario = load_scenario(PAPER_5KG)
    composition = Composition.from_name(WINNER, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    assert verdict.clear_pair is not None
    solved = {}
    for free in (False, True):
        problem = composition_problem(
            composition,
            scenario.catalog,
            scenario.task,
            *verdict.clear_pair,
            replace(scenario.optimizer, free_ends=free),
        )
        outcome = ShootingSolver(problem).solve()
        assert outcome.status == "optimal" and outcome.final is not None
        assert verify(problem, outcome.final.y).passed
        solved[free] = (problem, outcome.final)
    problem, final = solved[True]
    nodes = problem.unpack(final.y)[1]
    for q, asked in ((nodes[0, : problem.nv], scenario.task.start), (nodes[-1, : problem.nv], scenario.task.goal)):
        assert np.linalg.norm(_tool(problem.robot, q)[0] - asked) <= 1e-4 * (1 + 1e-6)
        assert np.all(nodes[[0, -1], problem.nv :] == 0.0)  # at rest
    assert final.tf <= solved[False][1].tf + 1e-6
    assert 0.0 < problem.cost_bound <= final.tf  # the tool's distance over its largest speed
    assert not np.allclose(nodes[0, : problem.nv], verdict.clear_pair[0], atol=1e-3)  # the start moved


def test_the_tool_speed_bound_holds_on_sampled_motions():
    robot = ur5(0.0)
    bound = robot.tool_speed_bound()
    rng = np.random.default_rng(4)
    for q in rng.uniform(robot.lower, robot.upper, (500, robot.nv)):
        velocity = rng.choice([-1.0, 1.0], robot.nv) * robot.velocity_limit
        assert np.linalg.norm(robot.tool_jacobian(q) @ velocity) <= bound
    assert math.isfinite(bound)


def test_free_ends_is_an_optimizer_setting(tmp_path):
    text = PAPER_5KG.read_text().replace("catalog: catalogs/", f"catalog: {PAPER_5KG.parent}/catalogs/")
    path = tmp_path / "free.yaml"
    assert "\noptimizer:\n" in text
    path.write_text(text.replace("\noptimizer:\n", "\noptimizer:\n  free_ends: true\n", 1))
    assert load_scenario(path).optimizer.free_ends is True
    path.write_text(path.read_text().replace("free_ends: true", "free_ends: sometimes"))
    with pytest.raises(ScenarioError, match=r"optimizer\.free_ends: expected true or false"):
        load_scenario(path)


def test_a_failed_candidate_whose_last_iterate_left_tfs_bounds_is_recorded_without_a_duration(monkeypatch):
    """trust-constr's iterates may leave the variables' bounds: a failed improv-pick candidate
    with free ends ended on tf = -0.34 s, which result.json's reader refuses, so the run lost its
    folder at the end. A negative tf is no duration: the result has none (null in result.json)."""

    class LeavingBounds(ShootingSolver):
        def iterate(self):
            for iterate in super().iterate():
                yield replace(iterate, tf=-abs(iterate.tf))
            final = self.outcome.final
            self.outcome = replace(self.outcome, final=replace(final, tf=-abs(final.tf)))

    def leaving(problem, y0=None, *, jacobian="exact", iteration_offset=0):
        return LeavingBounds(problem, y0, jacobian=jacobian, iteration_offset=iteration_offset)

    monkeypatch.setitem(solvers.SOLVERS, "leaving", leaving)
    scenario = load_scenario(PAPER_5KG)
    composition = Composition.from_name(WINNER, scenario.catalog)
    spec = next(candidate_specs([check_composition(composition, scenario.catalog, scenario.task)]))
    chosen = replace(scenario, optimizer=replace(scenario.optimizer, solver="leaving", max_iterations=3))
    result = make_candidate(chosen, spec).solve()
    assert result.status != "optimal" and math.isnan(result.tf)
    assert candidate_json(result)["tf"] is None
