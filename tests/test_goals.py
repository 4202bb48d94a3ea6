"""Tasks of several goals (:mod:`modular_robots.goals`): the scenario format, step B's chain of
configurations, step C's problem over phases, and the solved motion checked independently.

References used here:

* central finite differences of the phased problem's constraints and cost (its exact Jacobian
  and gradient must agree with them, the phases' duration columns and the route's rows among
  them);
* the sampled plan read at the goals' instants with Pinocchio's forward kinematics, not the
  solver's rows: the tool within each goal's tolerance, at rest where the goal asks it, standing
  still for each pause, back at the configuration a return names, the goals in order;
* the single-move problem: a route without vias is the same problem, bit for bit.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from modular_robots.bounds import catalog_bound
from modular_robots.cobra import import_cobra
from modular_robots.composition import Composition
from modular_robots.exceptions import ScenarioError
from modular_robots.feasibility import check_composition
from modular_robots.goals import Goal, stops_of, tool_path_gap
from modular_robots.ocp.candidate import make_candidate
from modular_robots.ocp.ends import DEFAULT_TOLERANCE
from modular_robots.pipeline import candidate_specs, cost_bound
from modular_robots.plan.trajectory import controller_rate
from modular_robots.plan.verification import LIMIT_TOLERANCE
from modular_robots.scenario import load_scenario
from modular_robots.search import ik_bound

from .helpers.paths import ROOT
from .test_shooting import central_difference, row_relative_error

TWO_GOALS = ROOT / "scenarios" / "improv-two-goals.yaml"
PAUSE = ROOT / "scenarios" / "improv-pick-pause.yaml"
#: A composition of the IMPROV 4-joint catalogue that passes step B on both scenarios.
ROBOT = "base-PB21-L1-PB23-L4-L3"


def _scenario_text(goals: str, cost: str = "time") -> str:
    return f"""
name: goals
catalog: {ROOT / "scenarios" / "catalogs" / "improv-4dof.yaml"}
task:
  payload: 1.0
  start: [0.45, 0.25, 0.25]
  goals:
{goals}
  cost: {cost}
"""


def _load(tmp_path, goals: str, cost: str = "time"):
    path = tmp_path / "goals.yaml"
    path.write_text(_scenario_text(goals, cost))
    return load_scenario(path)


# --------------------------------------------------------------------------------------------
# the scenario format
# --------------------------------------------------------------------------------------------
def test_goals_are_read_in_order_and_the_task_ends_at_the_last_pose(tmp_path):
    scenario = _load(
        tmp_path,
        """    - at: {position: [0.1, 0.55, 0.45], position_tolerance: 0.02}
    - reach: [-0.25, 0.45, 0.35]
      id: place
    - pause: 0.4
    - return: start""",
    )
    task = scenario.task
    assert [g.kind for g in task.goals] == ["at", "reach", "pause", "return"]
    assert [g.id for g in task.goals] == ["1", "place", "3", "4"]
    assert task.goal == task.start  # a return to the start ends there
    assert [label for label, _ in task.targets] == ["start", "goal 1", "goal place"]
    hold, stops = stops_of(task.goals)
    assert hold == 0.0
    assert [(s.goal, s.rest, s.returns_to, s.hold) for s in stops] == [
        (0, False, None, 0.0),
        (1, True, None, 0.4),
        (3, True, 0, 0.0),
    ]


def test_the_last_goal_is_at_rest_and_pauses_add_up():
    goals = (
        Goal("pause", "1", duration=0.2),
        Goal("at", "2", (0.3, 0.0, 0.3)),
        Goal("pause", "3", duration=0.1),
        Goal("pause", "4", duration=0.3),
        Goal("at", "5", (0.0, 0.3, 0.3)),
    )
    hold, stops = stops_of(goals)
    assert hold == pytest.approx(0.2)
    assert stops[0].rest and stops[0].hold == pytest.approx(0.4)  # a pause stops the robot
    assert stops[1].rest  # the motion ends at rest


@pytest.mark.parametrize(
    "goals, key, words",
    [
        ("    - follow: [0.1, 0.5, 0.4]", "goals[0].follow", "expected exactly one of at, reach, pause, return"),
        ("    - reach: [0.1, 0.5, 0.4]\n    - return: 7", "goals[1].return", "no earlier goal with id '7'"),
        (
            "    - reach: [0.1, 0.5, 0.4]\n      id: a\n    - at: [0.2, 0.5, 0.4]\n      id: a",
            "goals[1].id",
            "used twice (goals[0] has it)",
        ),
        (
            "    - reach: [0.1, 0.5, 0.4]\n      id: start",
            "goals[0].id",
            "'start' names the start (as in return: start)",
        ),
        (
            "    - reach: [0.1, 0.5, 0.4]\n      id: 2\n    - at: [0.2, 0.5, 0.4]",
            "goals[1]: goal id '2'",
            "is used twice (goals[0] has it); it is this goal's default id, its place in the list",
        ),
        ("    - reach: [0.45, 0.25, 0.2502]", "goals[0].reach", "from the one before"),
        ("    - reach: [0.1, 0.5, 0.4]\n    - pause: 0", "goals[1].pause", "expected a number > 0"),
        ("    - pause: 0.3", "goals", "at least one goal that moves"),
        ("    - return: start", "goals[0].return", "the robot is at the start's configuration already"),
        ("    - reach: [0.1, 0.5, 0.4]\n    - pause: 1\n    - return: 1", "goals[2].return", "at goal '1'"),
        (
            "    - reach: [0.1, 0.5, 0.4]\n    - return: start\n    - pause: 1\n    - return: start",
            "goals[3].return",
            "at the start's configuration already; expected a goal to return to that it has left",
        ),
        ("    - reach: [0.1, 0.5, 0.4]\n      at: [0.2, 0.5, 0.4]", "goals[0]", "expected exactly one of"),
    ],
)
def test_bad_goals_are_refused_naming_the_key(tmp_path, goals, key, words):
    with pytest.raises(ScenarioError) as error:
        _load(tmp_path, goals)
    message = str(error.value)
    assert f"task.{key}" in message and words in message, message
    assert ":" in message.split("task.")[0]  # file:line before the key


def test_effort_with_a_pause_is_refused(tmp_path):
    with pytest.raises(ScenarioError, match=r"task\.cost: the effort of a task with a pause"):
        _load(tmp_path, "    - reach: [0.1, 0.5, 0.4]\n    - pause: 0.3", cost="effort")


def test_pauses_as_long_as_max_time_are_refused(tmp_path):
    text = _scenario_text("    - reach: [0.1, 0.5, 0.4]\n    - pause: 1.5\n    - return: start")
    path = tmp_path / "paused.yaml"
    path.write_text(text + "  max_time: 1.5\n")
    with pytest.raises(ScenarioError, match=r"task\.max_time: the pauses take 1\.5 s, at least max_time = 1\.5 s"):
        load_scenario(path)
    path.write_text(text + "  max_time: 4\n")
    assert load_scenario(path).task.max_time == 4.0


def test_goal_and_goals_together_are_refused(tmp_path):
    text = _scenario_text("    - reach: [0.1, 0.5, 0.4]").replace("  goals:", "  goal: [0.1, 0.5, 0.4]\n  goals:")
    path = tmp_path / "both.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=r"give goal \(one move\) or goals \(several\), not both"):
        load_scenario(path)


# --------------------------------------------------------------------------------------------
# step B and step C's problem
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pause_candidate():
    scenario = load_scenario(PAUSE)
    composition = Composition.from_name(ROBOT, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    assert verdict.passed, verdict.message
    spec = next(candidate_specs([verdict]))
    return scenario, verdict, spec, make_candidate(scenario, spec)


def test_step_b_chains_a_return_to_the_start_configuration(pause_candidate):
    _, verdict, spec, candidate = pause_candidate
    assert verdict.q_goal == verdict.q_start  # returning to the start is ending where it started
    assert len(verdict.q_via) == 1 and spec.q_via == verdict.q_via
    problem = candidate.problem
    assert problem.phases == 2 and problem.hold == pytest.approx(0.5)
    robot = problem.robot
    place = np.asarray(load_scenario(PAUSE).task.goals[0].position)
    assert np.linalg.norm(robot.tool_position(np.asarray(verdict.q_via[0])) - place) < 1e-3


@pytest.mark.parametrize(
    "goals",
    [
        "    - at: [-0.2, 0.55, 0.2]",  # the motion ends there: at rest
        "    - at: [-0.2, 0.55, 0.2]\n    - pause: 0.5\n    - reach: [0.3, 0.1, 0.45]",
        "    - at: [-0.2, 0.55, 0.2]\n    - reach: [0.3, 0.1, 0.45]\n    - return: 1",
    ],
    ids=["last", "paused", "returned-to"],
)
def test_an_at_goal_where_the_robot_stands_still_gets_the_static_torque_test(tmp_path, goals):
    """15 kg at the far pose takes 101 N m of joint 2, over its 75.5 N m (Pinocchio's gravity
    torque in the message), and less at the start: an ``at`` goal the robot stops at, pauses at
    or comes back to rest at is held like a ``reach``; one passed moving is not."""

    def verdict(text):
        path = tmp_path / "held.yaml"
        path.write_text(
            _scenario_text(text)
            .replace("payload: 1.0", "payload: 15.0")
            .replace("[0.45, 0.25, 0.25]", "[0.30, 0.0, 0.45]")
        )
        scenario = load_scenario(path)
        return check_composition(Composition.from_name(ROBOT, scenario.catalog), scenario.catalog, scenario.task)

    held = verdict(goals)
    assert not held.passed and held.message.startswith("static torque") and "joint 2" in held.message
    passed = verdict("    - at: [-0.2, 0.55, 0.2]\n    - reach: [0.3, 0.1, 0.45]")
    assert passed.passed, passed.message


@pytest.mark.parametrize("path", [TWO_GOALS, PAUSE], ids=["two-goals", "pause"])
def test_phased_jacobian_and_gradient_match_central_differences(path):
    scenario = load_scenario(path)
    composition = Composition.from_name(ROBOT, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    problem = make_candidate(scenario, next(candidate_specs([verdict]))).problem
    rng = np.random.default_rng(3)
    y = problem.initial_guess() + 0.02 * rng.standard_normal(problem.n_variables)
    evaluation = problem.evaluate(y)
    jac = evaluation.jacobian.toarray()
    fd = central_difference(problem.constraints, y)
    err = row_relative_error(jac, fd)
    assert err.max() < 1e-5, (int(np.argmax(err)), err.max())
    route_rows = problem.rows_of("route")
    assert len(route_rows) and np.abs(fd[route_rows]).max() > 0.1  # the check is not vacuous
    for column in problem.duration_columns:  # every phase's duration moves the motion
        assert np.abs(fd[:, column]).max() > 1e-2
    gradient = problem.cost_gradient(y)
    assert np.allclose(gradient, central_difference(problem.cost, y)[0], atol=1e-7)
    assert gradient[problem.duration_columns].min() > 0.0


# --------------------------------------------------------------------------------------------
# the solved motion, checked on the plan sampled at a controller's rate
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def solved_pause(pause_candidate):
    scenario, _, spec, candidate = pause_candidate
    return scenario, spec, candidate.solve()


def _tool(robot, q):
    return np.array([robot.tool_position(x) for x in np.atleast_2d(q)])


def test_step_bs_time_bound_of_a_cycle_is_its_way_out_and_its_pause_below_the_optimum(pause_candidate, solved_pause):
    """A cycle back to its start ends where it began: its time bound was the joint travel between
    two equal configurations, 0 s (``filter`` listed every survivor at 0.000). It is the way out
    at the velocity limits, by hand, plus the pause, and the solved optimum is above it."""
    _, verdict, _, candidate = pause_candidate
    result, robot = solved_pause[2], candidate.problem.robot
    out = np.abs(np.subtract(verdict.q_via[0], verdict.q_start)) / robot.velocity_limit
    assert verdict.time_bound == pytest.approx(out.max() + 0.5, rel=1e-12) and out.max() > 0.5
    assert result.status == "optimal" and verdict.time_bound < result.cost
    # the search's stage-1 bound keeps to the configurations step C keeps, the first and the last
    # (here the same): the pause alone
    scenario = pause_candidate[0]
    assert ik_bound(scenario, verdict) == pytest.approx(0.5 / (1.0 + LIMIT_TOLERANCE), rel=1e-12)


def test_a_pause_and_a_return_hold_on_the_sampled_plan(solved_pause):
    scenario, spec, result = solved_pause
    assert result.status == "optimal", result.reason
    assert result.verification is not None and result.verification.passed
    robot = make_candidate(scenario, spec).problem.robot
    step = 0.01
    plan = controller_rate(result.trajectory, robot, 1.0 / step)
    (arrive, back) = result.stop_times
    assert 0.0 < arrive < back == pytest.approx(plan.t[-1])
    assert plan.t[-1] == pytest.approx(result.tf) and result.tf == pytest.approx(result.cost)
    # at the place position, at rest, for the pause's 0.5 s
    during = (plan.t >= arrive - 1e-9) & (plan.t <= arrive + 0.5 + 1e-9)
    assert during.sum() >= 0.5 / step
    q_place = plan.at(np.array([arrive]))[0][0]
    assert np.ptp(plan.q[during], axis=0).max() < 1e-9 and np.abs(plan.qd[during]).max() < 1e-9
    place = np.asarray(scenario.task.goals[0].position)
    assert np.linalg.norm(_tool(robot, q_place)[0] - place) <= 1e-3 + 1e-6  # step B's IK tolerance
    # the drives hold the payload through the pause (Pinocchio's gravity torque, not the plan's rows)
    model, data = robot.model, robot.data
    holding = pin.computeGeneralizedGravity(model, data, q_place)
    assert np.all(np.abs(holding) <= 0.9 * robot.effort_limit + 1e-6)  # the plan's effort margin
    assert np.allclose(plan.tau[during][:-1], holding, atol=1e-6)  # (the last row's drives the move after)
    # the robot moved in between: the pause is not the whole story
    assert np.linalg.norm(_tool(robot, plan.q[0])[0] - place) > 0.5
    # back to the start configuration, at rest, after the pause
    assert np.abs(plan.q[-1] - plan.q[0]).max() < 1e-6 and np.abs(plan.qd[-1]).max() < 1e-9
    assert result.cost_bound <= result.cost and result.cost_bound == pytest.approx(cost_bound(scenario, spec))
    assert result.cost_bound >= 0.5  # the pause counts in the bound


def test_a_max_time_shorter_than_the_moves_alone_ends_as_infeasible(pause_candidate):
    """A ``max_time`` below what the moves solved alone take (the first point's durations then
    exceed their bounds, which are kept feasible) is a diagnosis, not an error."""
    scenario, _, spec, candidate = pause_candidate
    assert candidate.problem.cost_bound < 1.5  # past the bound's early refusal
    hurried = replace(scenario, task=replace(scenario.task, max_time=1.5))
    result = make_candidate(hurried, spec).solve()
    assert result.status == "failed" and result.reason.startswith("infeasible"), result.reason


def test_an_at_goal_is_passed_moving_and_in_order():
    scenario = load_scenario(TWO_GOALS)
    composition = Composition.from_name(ROBOT, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    spec = next(candidate_specs([verdict]))
    candidate = make_candidate(scenario, spec)
    result = candidate.solve()
    assert result.status == "optimal" and result.verification.passed, result.reason
    robot = candidate.problem.robot
    (through, end) = result.stop_times
    q, qd, _ = result.trajectory.at(np.array([through]))
    waypoint, goal = scenario.task.goals
    assert np.linalg.norm(_tool(robot, q)[0] - np.asarray(waypoint.position)) <= waypoint.tolerance + 1e-6
    assert np.abs(qd).max() > 0.1  # passed moving: an at goal does not stop the robot
    assert end == pytest.approx(result.tf)
    assert np.linalg.norm(_tool(robot, result.trajectory.q[-1])[0] - np.asarray(goal.position)) < 1e-3 + 1e-6
    # the tool is nearer the waypoint at its instant than anywhere in the second move
    later = result.trajectory.t > through + 0.05
    dist = np.linalg.norm(_tool(robot, result.trajectory.q[later]) - np.asarray(waypoint.position), axis=1)
    assert dist.min() > np.linalg.norm(_tool(robot, q)[0] - np.asarray(waypoint.position))
    # the tool frame is Pinocchio's tool0 (the check above does not lean on the solver's rows)
    model, data = robot.model, robot.data
    pin.framesForwardKinematics(model, data, q[0])
    assert np.allclose(data.oMf[robot.tool_frame_id].translation, _tool(robot, q)[0])
    assert math.isfinite(result.cost_bound) and result.cost_bound < result.cost


def test_the_tool_path_through_the_goals_by_hand():
    goals = (
        Goal("reach", "a", (1.0, 0.0, 0.0), tolerance=0.1),
        Goal("pause", "p", duration=0.5),
        Goal("at", "b", (1.0, 2.0, 0.0)),
        Goal("return", "back", to="a"),
        Goal("return", "home", to="start"),
    )
    # 1 - 0.1, then 2 - 0.1 - 0.01 (b has no tolerance: 0.01), back the same, then home 1 - 0.1
    expected = 0.9 + 1.89 + 1.89 + 0.9
    assert tool_path_gap((0.0, 0.0, 0.0), 0.0, goals, 0.01) == pytest.approx(expected, rel=1e-15)


def test_the_catalogue_bound_through_the_goals_is_below_every_solved_optimum(tmp_path):
    """The catalogue bound of a task of several goals (the tool's path through them at its largest
    speed from catalogue numbers, plus the pauses) never exceeds a solved, verified optimum: the
    winners the goals benchmark recorded (CoBRA's PTP_3 and PTP_pause imported, the two scenarios)
    and one solved here; it is sharper than the start-to-goal bound where the motion comes back."""
    rows = json.loads((ROOT / "benchmarks" / "results" / "goals.json").read_text())["rows"]
    checked = 0
    for row in rows:
        if row["winner"] is None:
            continue
        if row["task"].startswith("PTP"):
            path = tmp_path / f"{row['task']}-{row['catalog']}.yaml"
            catalog = ROOT / "scenarios" / "catalogs" / f"{row['catalog']}.yaml"
            import_cobra(ROOT / "scenarios" / "cobra" / "tasks" / f"{row['task']}.json", catalog, path).write(path)
        else:
            path = ROOT / "scenarios" / f"{row['task']}.yaml"
        scenario = load_scenario(path)
        composition = Composition.from_name(row["winner"].split("+")[0], scenario.catalog)
        bound = catalog_bound(composition, scenario.catalog, scenario.task, DEFAULT_TOLERANCE)
        assert bound.name == "tool speed" and 0.0 < bound.value <= row["cycle_s"], (row["task"], bound)
        one_move = catalog_bound(composition, scenario.catalog, replace(scenario.task, goals=()), DEFAULT_TOLERANCE)
        goals = scenario.task.goals
        if sum(g.moves for g in goals) > 1 or any(g.duration for g in goals):  # a longer path, or pauses
            assert bound.value > one_move.value
        else:  # one move: the same bound, less verification's 1e-5 m at the goal
            assert bound.value == pytest.approx(one_move.value, rel=1e-3)
        checked += 1
    assert checked >= 4
    scenario = load_scenario(TWO_GOALS)
    composition = Composition.from_name(ROBOT, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    result = make_candidate(scenario, next(candidate_specs([verdict]))).solve()
    assert result.status == "optimal"
    assert catalog_bound(composition, scenario.catalog, scenario.task, DEFAULT_TOLERANCE).value <= result.cost


def test_free_ends_with_goals_unpack_and_solve_within_the_tolerances():
    """Free ends (``optimizer.free_ends``) with a goal on the way: the end columns come back as
    the first and last nodes, the motion passes its waypoint and ends within the goal's
    tolerance, and freeing the ends is no slower than the fixed ends (a wider feasible set)."""
    scenario = load_scenario(TWO_GOALS)
    composition = Composition.from_name(ROBOT, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    spec = next(candidate_specs([verdict]))
    results = {}
    for free in (False, True):
        freed = replace(scenario, optimizer=replace(scenario.optimizer, free_ends=free))
        candidate = make_candidate(freed, spec)
        problem = candidate.problem
        y = problem.initial_guess()
        _, nodes, _ = problem.unpack(y)
        assert nodes.shape == (problem.intervals + 1, 2 * problem.nv)
        assert np.allclose(problem.pack(problem.durations(y), nodes, problem.unpack(y)[2]), y)
        results[free] = (problem, candidate.solve())
    problem, result = results[True]
    assert result.status == "optimal" and result.verification.passed, result.reason
    robot = problem.robot
    waypoint, goal = scenario.task.goals
    q_through = result.trajectory.at(np.array([result.stop_times[0]]))[0]
    assert np.linalg.norm(_tool(robot, q_through)[0] - np.asarray(waypoint.position)) <= waypoint.tolerance + 1e-6
    for q, asked, tolerance in (
        (result.trajectory.q[0], scenario.task.start, scenario.task.start_tolerance),
        (result.trajectory.q[-1], goal.position, goal.tolerance),
    ):
        limit = DEFAULT_TOLERANCE if tolerance is None else tolerance
        assert np.linalg.norm(_tool(robot, q)[0] - np.asarray(asked)) <= limit * (1 + 1e-6)
    assert result.cost <= results[False][1].cost * (1 + 1e-3)


def test_free_ends_where_the_robot_pauses_are_held_within_the_effort_bounds(tmp_path):
    """With free ends, a pause at the start or at the goal holds a configuration step B never
    tested: gravity-torque rows keep it within the plan's effort bounds (exact Jacobian against
    central differences), and the plan's ends meet them (Pinocchio's gravity torque)."""
    scenario = _load(tmp_path, "    - pause: 0.3\n    - reach: [-0.25, 0.45, 0.35]\n    - pause: 0.4")
    scenario = replace(scenario, optimizer=replace(scenario.optimizer, free_ends=True))
    composition = Composition.from_name(ROBOT, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    candidate = make_candidate(scenario, next(candidate_specs([verdict])))
    problem = candidate.problem
    assert problem.route.holds == (0.3, 0.4) and len(problem.rows_of("route")) == 2 * problem.nv
    y = problem.initial_guess() + 0.02 * np.random.default_rng(5).standard_normal(problem.n_variables)
    rows = problem.rows_of("route")
    fd = central_difference(problem.constraints, y)[rows]
    assert np.abs(fd).max() > 0.1 and row_relative_error(problem.evaluate(y).jacobian.toarray()[rows], fd).max() < 1e-5
    result = candidate.solve()
    assert result.status == "optimal" and result.verification.passed, result.reason
    assert result.tf == pytest.approx(result.cost) and result.cost >= result.cost_bound >= 0.7  # the pauses count
    robot = problem.robot
    for q in (result.trajectory.q[0], result.trajectory.q[-1]):
        holding = pin.computeGeneralizedGravity(robot.model, robot.data, q)
        assert np.all(np.abs(holding) <= problem.effort_bound * (1 + 1e-6))
    # one move between two pauses: its stop is listed, where the last pause starts (at rest)
    (stop,) = result.stop_times
    assert stop == pytest.approx(result.trajectory.t[-1] - 0.4, abs=1e-12) and stop > 0.3
    assert np.abs(result.trajectory.at(np.array([stop, stop + 0.2]))[1]).max() < 1e-9


def test_one_reach_goal_is_the_single_move_bit_for_bit(tmp_path):
    """``goals: [reach: G]`` is ``goal: G``: the same problem, evaluated to the same bits."""
    listed = _load(tmp_path, "    - reach: [-0.25, 0.45, 0.35]")
    single = load_scenario(ROOT / "scenarios" / "improv-pick.yaml")
    task = single.task.__class__(**{**single.task.__dict__, "obstacles": (), "goals": ()})
    composition = Composition.from_name(ROBOT, listed.catalog)
    verdict = check_composition(composition, listed.catalog, listed.task)
    spec = next(candidate_specs([verdict]))
    one = make_candidate(listed, spec).problem
    other = make_candidate(listed.__class__(**{**listed.__dict__, "task": task}), spec).problem
    y = one.initial_guess() + 0.01 * np.random.default_rng(5).standard_normal(one.n_variables)
    a, b = one.evaluate(y), other.evaluate(y)
    assert one.phases == other.phases == 1 and one.n_variables == other.n_variables
    assert np.array_equal(a.constraints, b.constraints) and a.cost == b.cost
    assert np.array_equal(a.jacobian.toarray(), b.jacobian.toarray())


def test_the_moves_solved_first_are_yielded_at_the_motions_bound_and_can_be_stopped():
    """Step D sees the moves' first solves as iterates whose cost is the whole motion's lower
    bound (never a move's own cost), and a candidate stopped among them ends cleanly."""
    scenario = load_scenario(TWO_GOALS)
    composition = Composition.from_name(ROBOT, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    candidate = make_candidate(scenario, next(candidate_specs([verdict])))
    bound = candidate.problem.cost_bound
    iterates = candidate.iterate()
    first = [next(iterates) for _ in range(3)]
    assert [it.iteration for it in first] == [1, 2, 3]
    assert all(it.cost == bound == it.cost_bound and it.warm_up for it in first) and bound > 0.0
    candidate.close()
    result = candidate.result
    assert result is not None and result.status == "stopped" and result.stop_times == ()
    assert "while solving its moves one at a time" in result.reason
    # no cost of the motion yet, and the motion's ends and bound (not the first move's)
    assert math.isnan(result.cost) and math.isnan(result.tf) and result.cost_bound == bound
    assert result.q_start == verdict.q_start and result.q_goal == verdict.q_goal
