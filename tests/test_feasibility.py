"""Step B: each test fails and passes on hand-built cases; IK solutions are verified by FK."""

import dataclasses
import itertools
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from modular_robots import (
    CollisionModel,
    Composition,
    SphereObstacle,
    Task,
    cli,
    enumerate_compositions,
    load_scenario,
    robot_model,
)
from modular_robots.cli import main
from modular_robots.execution import ProcessEngine, SerialEngine
from modular_robots.feasibility import (
    TESTS,
    FeasibilitySummary,
    check_composition,
    check_compositions,
    filter_compositions,
    max_reach,
)
from modular_robots.ik import _lm_steps, ik_seeds, solve_position_ik, solve_position_ik_batch, solve_position_ik_many

from .helpers.paths import PAPER_5KG, PAPER_CATALOG, SMALL

G = 9.81


def _task(start, goal=None, payload=0.0, obstacles=()):
    return Task(payload=payload, start=tuple(start), goal=tuple(goal or start), obstacles=tuple(obstacles))


def _check(catalog, name, task):
    return check_composition(Composition.from_name(name, catalog), catalog, task)


# -- reach -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("B-J1-L2-E1", 0.25 + 0.75 + 0.2),  # straight up
        ("B-J2-L2-E2", 0.25 + 0.2 + 0.75 + 0.2 + 0.1),  # strokes extended
        ("B-J1-L1-E1", math.hypot(0.25, 0.75) + 0.2),  # L1 turns before it extends
        ("B-J1-L1-J1-L1-E1", 2 * math.hypot(0.25, 0.75) + 0.2),
    ],
)
def test_max_reach_by_hand(paper_catalog, name, expected):
    assert max_reach(Composition.from_name(name, paper_catalog), paper_catalog) == pytest.approx(expected, abs=1e-12)


def test_max_reach_is_an_upper_bound(paper_catalog):
    """No sampled configuration of any sampled composition goes beyond the bound."""
    rng = np.random.default_rng(3)
    for composition in itertools.islice(enumerate_compositions(paper_catalog), 0, None, 53):
        robot = robot_model(composition, paper_catalog, 0.0)
        bound = max_reach(composition, paper_catalog)
        reaches = [np.linalg.norm(robot.tool_position(rng.uniform(robot.lower, robot.upper))) for _ in range(40)]
        assert max(reaches) <= bound + 1e-12, composition.name


def test_arm_too_short(paper_catalog):
    verdict = _check(paper_catalog, "B-J1-L2-E1", _task((0.0, 0.0, 1.3)))
    assert verdict.failed_test == "reach"
    assert verdict.message == "reach: the start is 1.300 m from the base, the arm reaches at most 1.200 m"
    assert verdict.figures["reach_margin"] == pytest.approx(-0.1)


# -- workspace and inverse kinematics --------------------------------------------------------
def test_target_outside_joint_limits(paper_catalog):
    """B-J2-L2-E2 moves its tool along z from 1.2 m (strokes at 0) to 1.5 m: 1.1 m is within
    reach but below the prismatic lower limits, which the workspace box sees without IK."""
    verdict = _check(paper_catalog, "B-J2-L2-E2", _task((0.0, 0.0, 1.1)))
    assert verdict.failed_test == "workspace"
    assert verdict.message == (
        "workspace: the start is 0.1 m outside the box that holds every tool position within the joint "
        "limits (x [0.000, 0.000], y [0.000, 0.000], z [1.200, 1.500] m)"
    )
    assert verdict.figures["workspace_excess"] == pytest.approx(0.1, abs=1e-12)
    passed = _check(paper_catalog, "B-J2-L2-E2", _task((0.0, 0.0, 1.42)))
    assert passed.passed and sum(passed.q_start) == pytest.approx(0.22, abs=1e-4)


def test_target_inside_the_box_out_of_reach(paper_catalog):
    """B-J1-L1-E1 carries its tool on a circle of radius 0.95 m at 0.25 m: the circle's centre
    is inside its box and within reach of the base, and IK finds it 0.95 m away."""
    verdict = _check(paper_catalog, "B-J1-L1-E1", _task((0.0, 0.0, 0.25)))
    assert verdict.failed_test == "inverse kinematics"
    assert verdict.message == "inverse kinematics: no solution within joint limits at the start (closest 0.95 m)"
    assert verdict.figures["workspace_excess"] <= 1e-12


def test_ik_solutions_hold_the_target_within_limits(paper_catalog):
    scenario = load_scenario(PAPER_5KG)
    names = ["B-J1-L3-J1-L2-J1-L3-J1-L3-E1", "B-J1-L3-J1-L3-J2-L2-J1-L1-E1", "B-J1-L2-J1-L1-J1-L3-J1-L1-E1"]
    for name in names:
        verdict = check_composition(Composition.from_name(name, paper_catalog), paper_catalog, scenario.task)
        assert verdict.passed, verdict.message
        robot = robot_model(verdict.composition, paper_catalog, scenario.task.payload)
        for q, target in ((verdict.q_start, scenario.task.start), (verdict.q_goal, scenario.task.goal)):
            q = np.array(q)
            assert np.all(q >= robot.lower) and np.all(q <= robot.upper)
            assert np.linalg.norm(robot.tool_position(q) - target) <= 1e-4
        expected_bound = np.max(np.abs(np.subtract(verdict.q_goal, verdict.q_start)) / robot.velocity_limit)
        assert verdict.time_bound == pytest.approx(expected_bound)


def test_ik_converges_from_every_seed_on_a_reachable_target(paper_catalog):
    robot = robot_model(Composition.from_name("B-J1-L3-J1-L1-J1-L3-E1", paper_catalog), paper_catalog, 0.0)
    rng = np.random.default_rng(7)
    target = robot.tool_position(rng.uniform(robot.lower, robot.upper))
    results = [solve_position_ik(robot, target, q0) for q0 in ik_seeds(robot, 8)]
    assert sum(r.success() for r in results) >= 6
    for r in results:
        if r.success():
            assert np.linalg.norm(robot.tool_position(r.q) - target) == pytest.approx(r.error, abs=1e-12)


def test_ik_runs_in_lockstep_give_the_runs_of_their_own(paper_catalog):
    """Seeds that stop early, stall, or push joints against their limits, on robots of two, four
    and five joints (two robots of two and of five): each run of solve_position_ik_many, and of
    one solve_position_ik_batch over every robot and target, is bit for bit the run
    solve_position_ik makes from its seed alone."""
    scenario = load_scenario(PAPER_5KG)
    names = ("B-J1-L3-J1-L1-J1-L3-E1", "B-J1-L3-J1-L3-J2-L2-J1-L1-E1", "B-J1-L2-J1-L3-J2-L1-J1-L2-E1", "B-J2-L2-E2")
    problems = []
    for name in (*names, "B-J1-L2-E1"):
        robot = robot_model(Composition.from_name(name, paper_catalog), paper_catalog, 0.0)
        for target in (scenario.task.start, scenario.task.goal, (0.0, 0.0, 1.1)):
            problems.append((robot, np.array(target), ik_seeds(robot, 16)))
    batch = solve_position_ik_batch(problems)
    key = lambda run: (run.q.tobytes(), run.error, run.iterations)  # noqa: E731
    for (robot, target, seeds), together in zip(problems, batch):
        alone = [key(solve_position_ik(robot, target, q0)) for q0 in seeds]
        assert [key(run) for run in solve_position_ik_many(robot, target, seeds)] == alone
        assert [key(run) for run in together] == alone


def test_lm_step_matches_the_plain_normal_equations():
    rng = np.random.default_rng(0)
    for n in range(1, 7):
        jacobian, error = rng.normal(size=(3, n)), rng.normal(size=3)
        norm = float(np.linalg.norm(error))
        damping = 0.5 * norm * norm + 1e-4
        reference = np.linalg.solve(jacobian.T @ jacobian + damping * np.eye(n), jacobian.T @ error)
        np.testing.assert_allclose(
            _lm_steps(jacobian[None], error[None], np.array([norm]))[0], reference, rtol=1e-10, atol=1e-13
        )
    # many at once, one of them singular (no step), the others as each alone
    jacobians, errors = rng.normal(size=(9, 3, 4)), rng.normal(size=(9, 3))
    jacobians[4] = np.nan
    norms = np.linalg.norm(errors, axis=1)
    together = _lm_steps(jacobians, errors, norms)
    assert np.all(together[4] == 0.0)
    for k in (0, 3, 8):
        assert np.array_equal(together[k], _lm_steps(jacobians[k : k + 1], errors[k : k + 1], norms[k : k + 1])[0])


# -- collision -----------------------------------------------------------------------------------
def test_pose_forced_through_an_obstacle(paper_catalog):
    """B-J1-L2-E1 always stands straight up; L2 spans z in [0.25, 1] with radius 0.1."""
    blocking = SphereObstacle((0.35, 0.0, 0.6), 0.3)  # 0.35 - 0.1 - 0.3 = -0.05: overlaps L2
    verdict = _check(paper_catalog, "B-J1-L2-E1", _task((0.0, 0.0, 1.2), obstacles=[blocking]))
    assert verdict.failed_test == "collision"
    assert verdict.message == "collision: m2_L2_capsule 0.05 m inside task.obstacles[0] (start)"
    clear = SphereObstacle((0.45, 0.0, 0.6), 0.3)
    passed = _check(paper_catalog, "B-J1-L2-E1", _task((0.0, 0.0, 1.2), obstacles=[clear]))
    assert passed.passed and passed.figures["clearance"] == pytest.approx(0.05, abs=1e-9)


# -- static torque -------------------------------------------------------------------------------
def _threshold_case():
    """B-J1-L1-J1-L1-E1: joint 2's axis runs horizontally along the first L1, 0.25 m up; its
    pivot point is 0.75 + 0.25 m out from the base axis. The arm after it (L1 centre 0.375 m, E1
    0.75 m, payload 0.95 m from the axis) swings in the vertical plane across that axis. A target
    0.725 m high fixes |cos q2| = 0.5, so |tau2| = g sin(60 deg) (0.375 m_L1 + 0.75 m_E1 +
    0.95 m_payload), whatever q1 and q3."""
    sin = math.sin(math.radians(60))
    radius = math.hypot(1.0, 0.95 * sin)
    target = (radius, 0.0, 0.25 + 0.95 * 0.5)
    threshold = (100.0 / (G * sin) - 0.375 * 0.05 - 0.75 * 0.5) / 0.95
    return target, threshold


def test_payload_just_under_and_just_over_the_limit(paper_catalog):
    target, threshold = _threshold_case()
    assert threshold == pytest.approx(11.9756, abs=1e-4)
    under = _check(paper_catalog, "B-J1-L1-J1-L1-E1", _task(target, payload=threshold * 0.99))
    assert under.passed, under.message
    lever = 0.375 * 0.05 + 0.75 * 0.5
    # IK holds the target to 1e-4 m, which moves sin(q2) by up to ~6e-5 relative
    assert under.figures["torque_ratio"] == pytest.approx(
        (lever + 0.95 * 0.99 * threshold) / (lever + 0.95 * threshold), rel=2e-4
    )
    over = _check(paper_catalog, "B-J1-L1-J1-L1-E1", _task(target, payload=threshold * 1.01))
    assert over.failed_test == "static torque"
    assert over.message.startswith("static torque 10") and over.message.endswith(" N m > 100 N m (joint 2, start)")
    assert over.figures["torque_ratio"] == pytest.approx(
        (lever + 0.95 * 1.01 * threshold) / (lever + 0.95 * threshold), rel=2e-4
    )


def test_no_feasible_composition_gives_a_diagnosis(paper_catalog):
    """At 50 kg the compositions that hold 5 kg fail on torque; the summary says so."""
    scenario = load_scenario(PAPER_5KG)
    heavy = dataclasses.replace(scenario.task, payload=50.0)
    summary = FeasibilitySummary()
    for name in ("B-J1-L3-J1-L2-J1-L3-J1-L3-E1", "B-J1-L2-J1-L1-J1-L3-J1-L1-E1", "B-J1-L2-E1"):
        summary.add(check_composition(Composition.from_name(name, paper_catalog), paper_catalog, heavy))
    assert summary.removed == {"reach": 1, "workspace": 0, "inverse kinematics": 0, "static torque": 2, "collision": 0}
    lines = summary.diagnosis().splitlines()
    assert lines[0] == "no composition is feasible: the last 2 candidate(s) were removed by the static torque test"
    assert lines[1].startswith("best torque ratio found: ") and float(lines[1].split()[4]) > 1.0


def test_a_diagnosis_names_the_closest_workspace_miss(paper_catalog):
    """When the workspace test removes the last candidates, the diagnosis gives the nearest box."""
    summary = FeasibilitySummary()
    for name, z in (("B-J2-L2-E2", 1.1), ("B-J2-L2-E2", 0.9)):
        summary.add(_check(paper_catalog, name, _task((0.0, 0.0, z))))
    assert summary.diagnosis().splitlines() == [
        "no composition is feasible: the last 2 candidate(s) were removed by the workspace test",
        "smallest distance to a workspace box: 0.1 m (B-J2-L2-E2: workspace: the start is 0.1 m outside the box "
        "that holds every tool position within the joint limits (x [0.000, 0.000], y [0.000, 0.000], "
        "z [1.200, 1.500] m))",
    ]


def test_a_diagnosis_names_the_nearest_collision_and_reach_misses(paper_catalog):
    """The nearest miss of each test that removed compositions, the last test's first: the least
    penetration of an obstacle, then the largest (negative) reach margin."""
    summary = FeasibilitySummary()
    for x in (0.35, 0.38, 0.36):  # L2 (radius 0.1) 0.05, 0.02 and 0.04 m inside the sphere
        summary.add(
            _check(paper_catalog, "B-J1-L2-E1", _task((0.0, 0.0, 1.2), obstacles=[SphereObstacle((x, 0.0, 0.6), 0.3)]))
        )
    summary.add(_check(paper_catalog, "B-J1-L2-E1", _task((0.0, 0.0, 3.0))))
    assert summary.diagnosis().splitlines() == [
        "no composition is feasible: the last 3 candidate(s) were removed by the collision test",
        "largest clearance found: -0.02 m (B-J1-L2-E1: collision: m2_L2_capsule 0.02 m inside task.obstacles[0] (start))",
        "largest reach margin found: -1.8 m (B-J1-L2-E1: reach: the start is 3.000 m from the base, the arm reaches "
        "at most 1.200 m)",
    ]


# -- streaming and workers -------------------------------------------------------------------------
def test_a_summary_with_keep_holds_the_survivors_with_the_smallest_time_bounds():
    """A bounded summary (``filter`` on millions) counts like a full one and holds the ``keep``
    survivors with the smallest time bounds, the earlier of two equal bounds, in input order."""
    scenario = load_scenario(PAPER_5KG)
    sample = list(itertools.islice(enumerate_compositions(scenario.catalog, dof=5), 0, None, 8))
    verdicts = list(filter_compositions(scenario, sample, engine=SerialEngine()))
    verdicts += verdicts  # every bound twice: the first of each pair is kept
    full, bounded, empty = FeasibilitySummary(), FeasibilitySummary(keep=5), FeasibilitySummary(keep=0)
    for verdict in verdicts:
        for summary in (full, bounded, empty):
            summary.add(verdict)
    assert full.feasible == len(full.survivors) > 10
    assert bounded.counts() == full.counts() == empty.counts() and bounded.seconds == full.seconds
    passed = [i for i, verdict in enumerate(verdicts) if verdict.passed]
    best = sorted(sorted(passed, key=lambda i: verdicts[i].time_bound)[:5])  # a stable sort: input order on ties
    assert bounded.survivors == [verdicts[i] for i in best]
    assert empty.survivors == [] and empty.diagnosis() == ""


def test_same_verdicts_with_one_and_two_workers():
    scenario = load_scenario(PAPER_5KG)
    sample = list(itertools.islice(enumerate_compositions(scenario.catalog, dof=5), 0, None, 40))
    one = list(filter_compositions(scenario, sample, engine=SerialEngine()))
    two = list(filter_compositions(scenario, sample, engine=ProcessEngine(2)))
    assert [v.composition for v in one] == sample
    key = lambda v: (v.composition, v.failed_test, v.message, v.q_start, v.q_goal, v.time_bound)  # noqa: E731
    assert [key(v) for v in one] == [key(v) for v in two]
    assert any(v.passed for v in one) and any(not v.passed for v in one)


def test_compositions_checked_together_get_their_own_verdicts():
    """check_compositions runs the start IK of a whole chunk in lockstep (mixed DOF, some failing
    the reach test, some feasible): every verdict is the one check_composition gives alone."""
    scenario = load_scenario(PAPER_5KG)
    sample = list(itertools.islice(enumerate_compositions(scenario.catalog), 0, None, 97))
    together = check_compositions(sample, scenario.catalog, scenario.task)
    alone = [check_composition(c, scenario.catalog, scenario.task) for c in sample]
    key = lambda v: (v.to_json(), v.time_bound, v.clear_pair)  # noqa: E731
    assert [key(v) for v in together] == [key(v) for v in alone]
    assert {v.failed_test for v in together} >= {None, "reach", "inverse kinematics"}
    assert len({v.composition.dof for v in together}) > 1


def test_filter_cli_on_a_small_catalogue(tmp_path):
    """A 2-3 DOF version of the paper catalogue cannot reach the paper's targets: the command
    prints the table, then fails with the diagnosis."""
    (tmp_path / "catalogs").mkdir()
    (tmp_path / "catalogs" / "paper.yaml").write_text(PAPER_CATALOG.read_text().replace("dof: [2, 5]", "dof: [2, 3]"))
    (tmp_path / "s.yaml").write_text(PAPER_5KG.read_text())
    out = tmp_path / "feasible.json"
    result = CliRunner().invoke(main, ["filter", str(tmp_path / "s.yaml"), "--jobs", "1", "--out", str(out)])
    assert result.exit_code == 1
    rows = {line.split()[0]: line.split()[1:] for line in result.output.splitlines() if line.strip()}
    assert rows["reach"][:2] == ["84", "0"] and rows["collision"][:2] == ["0", "0"]
    assert "0 of 84 compositions are feasible" in result.output
    assert result.output.rstrip().endswith(
        "Error: no composition is feasible: the last 84 candidate(s) were removed by the reach test"
    )
    assert out.exists()


def test_cascade_order_is_rank_order():
    assert [t.rank for t in TESTS] == list(range(len(TESTS)))
    assert [t.name for t in TESTS] == ["reach", "workspace", "inverse kinematics", "static torque", "collision"]


def test_a_clear_pair_is_kept_when_the_fastest_pair_sweeps_through_an_obstacle(paper_catalog):
    """B-J1-L2-J1-L1-J1-L3-J1-L1-E1 on paper-5kg: the straight line of its fastest IK pair
    (2.153 s) sweeps a link through the sphere at (1.5, -1.3, 1.1); a pair 4 % slower is clear."""
    scenario = load_scenario(PAPER_5KG)
    verdict = _check(paper_catalog, "B-J1-L2-J1-L1-J1-L3-J1-L1-E1", scenario.task)
    assert verdict.passed and verdict.clear_pair is not None
    robot = robot_model(verdict.composition, paper_catalog, scenario.task.payload)
    collision = CollisionModel(robot, scenario.task.obstacles)

    def line_clearance(q_a, q_b):
        q_a, q_b = np.array(q_a), np.array(q_b)
        return min(collision.distances(q_a + s * (q_b - q_a)).minimum for s in np.linspace(0.0, 1.0, 401))

    assert verdict.time_bound == pytest.approx(2.153, abs=1e-3)
    assert line_clearance(verdict.q_start, verdict.q_goal) < -0.1
    assert robot.travel_time_bound(*map(np.array, verdict.clear_pair)) == pytest.approx(2.24, abs=0.01)
    assert line_clearance(*verdict.clear_pair) > 0.0
    blocked = _check(paper_catalog, "B-J1-L3-J1-L2-J1-L1-J1-L1-E2", scenario.task)  # no pair is clear
    assert blocked.passed and blocked.clear_pair is None


def test_filter_without_out_prints_the_same_survivors_holding_only_those_it_prints(tmp_path, monkeypatch):
    """Without ``--out``, ``filter`` holds only the survivors it prints (a stream of millions
    stays in bounded memory), and prints what it prints with ``--out``, which lists all of them."""
    monkeypatch.setattr(cli, "SURVIVOR_ROWS", 4)
    out = tmp_path / "feasible.json"
    bounded = CliRunner().invoke(main, ["filter", str(SMALL), "--jobs", "1"])
    full = CliRunner().invoke(main, ["filter", str(SMALL), "--jobs", "1", "--out", str(out)])
    assert bounded.exit_code == full.exit_code == 0
    table = lambda text: text[text.index("composition ") :].splitlines()  # noqa: E731
    assert table(full.output)[:-1] == table(bounded.output) and table(full.output)[-1] == f"wrote {out}"
    assert len(table(bounded.output)) == 1 + 4 + 1 and table(bounded.output)[-1] == "... and 2 more (see --out)"
    assert "6 of 516 compositions are feasible" in bounded.output
    survivors = json.loads(out.read_text())["survivors"]
    assert [s["composition"] for s in survivors[:4]] == [line.split()[0] for line in table(bounded.output)[1:5]]
    assert len(survivors) == 6
