"""CoBRA tasks in (``import-cobra``) and solutions out (``cobra-solution.json``).

References used here:

* the CoBRA task files themselves (``scenarios/cobra/tasks``, from ``../shared/cobra``): the
  imported scenario's poses, moved back by the task's base placement, are the file's world poses;
* the goals and constraints of a solution checked as CoBRA's checker defines them (Timor's
  ``Goals`` and ``Constraints``), on the document's rows alone, with Pinocchio's kinematics of the
  winner's URDF placed at the document's ``basePose``: the tool's position within ``r_sph`` and
  its rotation within ``Theta_R`` of each goal's nominal world pose at its instant, the tool's
  spatial velocity within 1e-3 at a ``reach``, the rows constant and at rest over a ``pause``,
  ``q``, ``dq``, ``ddq`` within 1e-4 of the start's at a ``returnTo``, the goals in order, the
  joint limits at every row, the rows at most ``timeStepSize`` apart.
"""

from __future__ import annotations

import io
import json
import re
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yourdfpy
from click.testing import CliRunner

from modular_robots.cli import main
from modular_robots.cobra import cobra_cost, import_cobra
from modular_robots.cobra_solution import COBRA_SOLUTION, cobra_solution, sample_times
from modular_robots.composition import Composition
from modular_robots.exceptions import ScenarioError
from modular_robots.feasibility import check_composition
from modular_robots.ocp.candidate import make_candidate
from modular_robots.pipeline import candidate_specs
from modular_robots.robot import robot_from_urdf
from modular_robots.scenario import load_scenario

from .helpers.cobra_check import check_solution
from .helpers.paths import ROOT

TASKS = ROOT / "scenarios" / "cobra" / "tasks"
IMPROV_4DOF = ROOT / "scenarios" / "catalogs" / "improv-4dof.yaml"
IMPROV_6DOF = ROOT / "scenarios" / "catalogs" / "improv-6dof.yaml"
ROBOT = "base-PB21-L1-PB23-L4-L3"


def _world(scenario, position) -> np.ndarray:
    base = np.array(scenario.cobra.base_pose)
    return base[:3, :3] @ np.asarray(position) + base[:3, 3]


@pytest.mark.parametrize("name", ["PTP_1", "PTP_2", "PTP_3", "PTP_pause", "PTP_2_cycle"])
def test_the_samples_import_with_their_poses_in_the_base_frame(tmp_path, name):
    task = json.loads((TASKS / f"{name}.json").read_text())
    out = tmp_path / "scenario.yaml"
    import_cobra(TASKS / f"{name}.json", IMPROV_6DOF, out).write(out)
    scenario = load_scenario(out)
    goals = task["goals"]
    assert scenario.cobra.id == task["header"]["ID"] and scenario.cobra.start == goals[0]["ID"]
    assert [g.id for g in scenario.task.goals] == [g["ID"] for g in goals[1:]]
    nominal = np.array(goals[0]["goalPose"]["nominal"])
    assert np.allclose(_world(scenario, scenario.task.start), nominal[:3, 3], atol=1e-12)
    for goal, read in zip(goals[1:], scenario.task.goals):
        assert read.kind == {"reach": "reach", "at": "at", "pause": "pause", "returnTo": "return"}[goal["type"]]
        if read.position is not None:
            world = np.array(goal["goalPose"]["nominal"])
            assert np.allclose(_world(scenario, read.position), world[:3, 3], atol=1e-12)
            base = np.array(scenario.cobra.base_pose)[:3, :3]
            assert np.allclose(base @ read.orientation.rotation, world[:3, :3], atol=1e-9)
            assert read.tolerance == goal["goalPose"]["tolerance"][0][1]
            assert read.orientation.tolerance == goal["goalPose"]["tolerance"][1][1]
    meshes = [o for o in scenario.task.obstacles if o.kind == "mesh"]
    assert len(meshes) == len(task["obstacles"])  # every sample's obstacle is one collision mesh
    assert scenario.task.floor is None and scenario.task.self_collision


def test_a_base_placement_moves_every_pose(tmp_path):
    out = tmp_path / "ptp1.yaml"
    import_cobra(TASKS / "PTP_1.json", IMPROV_6DOF, out).write(out)
    scenario = load_scenario(out)
    assert scenario.task.start == (0.0, -1.0, 0.0)  # world (1, 1, 3), base at (1, 2, 3)
    assert scenario.task.goals[0].position == (1.0, 0.0, 0.0)
    assert scenario.task.goals[0].kind == "reach" and scenario.cobra.start == "1"


def _task(goals, obstacles=(), base=None, constraints=None) -> dict:
    return {
        "header": {"ID": "test/t", "version": "2022", "taskName": "t", "timeStepSize": 0.01, "gravity": [0, 0, -9.81]},
        "obstacles": list(obstacles),
        "constraints": constraints
        if constraints is not None
        else [
            {"type": "joint", "parts": ["q", "dq", "tau"]},
            {"type": "collisionFree"},
            {"type": "basePlacement", "pose": {"nominal": base if base is not None else np.eye(4).tolist()}},
        ],
        "goals": list(goals),
    }


def _pose(x, y, z, r=0.01):
    return {
        "nominal": [[1, 0, 0, x], [0, 1, 0, y], [0, 0, 1, z], [0, 0, 0, 1]],
        "toleranceProjection": ["r_sph"],
        "tolerance": [[0, r]],
    }


@pytest.mark.parametrize(
    "change, words",
    [
        (
            lambda t: t["goals"].append({"ID": "9", "type": "follow"}),
            "goals[2] (ID '9'): the goal type 'follow' is not supported",
        ),
        (
            lambda t: t["goals"].append({"ID": "9", "type": "returnTo", "returnToGoal": "7"}),
            "returnToGoal: no earlier goal with ID '7'",
        ),
        (
            lambda t: t["goals"][1]["goalPose"].update(toleranceProjection=["N_z"]),
            "toleranceProjection 'N_z' is not supported",
        ),
        (
            lambda t: t["goals"][1]["goalPose"].update(toleranceProjection=["Theta_R"], tolerance=[[0, 0.1]]),
            "no position tolerance",
        ),
        (lambda t: t["goals"][1]["goalPose"].update(nominalParent="frame"), "poses in other frames are not supported"),
        (lambda t: t["goals"].pop(), "goals: one; expected at least two"),
        (lambda t: t["goals"].clear(), "goals: none; expected at least two"),
        (lambda t: t.update(goals=[{"ID": "f", "type": "follow"}]), "goals[0] (ID 'f'): the goal type 'follow' is not"),
        (lambda t: t["header"].update(gravity=[0, 0, -3.7]), "header.gravity"),
        (
            lambda t: t["constraints"][2]["pose"].update(
                nominal=[[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]]
            ),
            "a tilted base",
        ),
        (
            lambda t: t["obstacles"].append(
                {
                    "collision": [
                        {
                            "type": "mesh",
                            "pose": np.eye(4).tolist(),
                            "parameters": {"file": "../../../etc/passwd", "scale": 1},
                        }
                    ]
                }
            ),
            "is not a file inside the task's folder",
        ),
        (lambda t: t["constraints"].append({"type": "endEffector"}), "the constraint 'endeffector' is not supported"),
        # silently dropped before: a goal's own constraints, a constraint that is a string, an
        # obstacle without its collision list; goals given as an object were 'goals: none'
        (
            lambda t: t["goals"][1].update(constraints=[{"type": "joint", "parts": ["q"]}]),
            "goals[1]: (ID '2') constraints: a goal's own constraints are not supported",
        ),
        (lambda t: t["constraints"].append("joint"), "constraints[3]: expected an object, got 'joint'"),
        (
            lambda t: t["obstacles"].append({"name": "o", "ID": "o", "visual": []}),
            "obstacles[0]: collision: expected a list of geometries",
        ),
        (lambda t: t.update(goals={"1": t["goals"][0]}), "goals: expected a list, got dict"),
    ],
)
def test_bad_tasks_are_refused_naming_the_item(tmp_path, change, words):
    task = _task(
        [
            {"ID": "1", "type": "reach", "goalPose": _pose(0.4, 0.2, 0.3)},
            {"ID": "2", "type": "reach", "goalPose": _pose(0.1, 0.4, 0.3)},
        ]
    )
    change(task)
    (tmp_path / "tasks").mkdir()
    path = tmp_path / "tasks" / "t.json"
    path.write_text(json.dumps(task))
    with pytest.raises(ScenarioError) as error:
        import_cobra(path, IMPROV_4DOF, tmp_path / "s.yaml")
    assert str(path) in str(error.value) and words in str(error.value), str(error.value)


def test_a_return_to_null_or_to_a_pause_goes_where_the_robot_stood(tmp_path):
    """``returnToGoal: null`` is the start; a pause's ID is the goal the robot paused at."""
    task = _task(
        [
            {"ID": "1", "type": "reach", "goalPose": _pose(0.4, 0.2, 0.3)},
            {"ID": "2", "type": "at", "goalPose": _pose(0.1, 0.4, 0.3)},
            {"ID": "wait", "type": "pause", "duration": 0.2},
            {"ID": "3", "type": "reach", "goalPose": _pose(-0.2, 0.4, 0.3)},
            {"ID": "4", "type": "returnTo", "returnToGoal": "wait"},
            {"ID": "5", "type": "returnTo", "returnToGoal": None},
        ]
    )
    (tmp_path / "tasks").mkdir()
    path = tmp_path / "tasks" / "t.json"
    path.write_text(json.dumps(task))
    out = tmp_path / "s.yaml"
    import_cobra(path, IMPROV_4DOF, out).write(out)
    goals = load_scenario(out).task.goals
    assert [(g.id, g.kind, g.to) for g in goals if g.kind == "return"] == [
        ("4", "return", "2"),
        ("5", "return", "start"),
    ]


def test_a_mesh_scale_of_three_equal_factors_is_one_and_unequal_ones_are_refused(tmp_path):
    (tmp_path / "tasks").mkdir()
    (tmp_path / "assets").mkdir()
    mesh = "QUASER_MV205_v3_compressed.stl"
    (tmp_path / "assets" / mesh).write_bytes((TASKS.parent / "assets" / mesh).read_bytes())
    task = json.loads((TASKS / "PTP_3.json").read_text())
    geometry = task["obstacles"][0]["collision"][0]
    geometry["parameters"].update(file=f"assets/{mesh}", scale=[0.001, 0.001, 0.001])
    path = tmp_path / "tasks" / "t.json"
    path.write_text(json.dumps(task))
    out = tmp_path / "s.yaml"
    import_cobra(path, IMPROV_6DOF, out).write(out)
    (obstacle,) = [o for o in load_scenario(out).task.obstacles if o.kind == "mesh"]
    assert obstacle.scale == 0.001
    geometry["parameters"]["scale"] = [0.001, 0.002, 0.001]
    path.write_text(json.dumps(task))
    with pytest.raises(ScenarioError, match=r"collision\[0\]: parameters.scale: a different scale per axis"):
        import_cobra(path, IMPROV_6DOF, out)


def test_cost_descriptors_map_and_typos_are_named():
    assert cobra_cost("cyc") == "time"
    assert cobra_cost("cyc_2,mass_0.1") == "2*time + 0.1*mass"
    assert cobra_cost("mechEnergy,numJ_0.5") == "energy + 0.5*joints"
    # a cost named without a weight has Timor's default weight (CostFunctions' default_weight)
    assert cobra_cost("cyc,mass") == "time + 0.05*mass"
    assert cobra_cost("numJ") == "0.1*joints"
    with pytest.raises(ScenarioError, match="unknown CoBRA cost 'cycc'"):
        cobra_cost("cycc")
    with pytest.raises(ScenarioError, match="'effort' is not supported: CoBRA's effort is the sum of"):
        cobra_cost("effort")
    with pytest.raises(ScenarioError, match="the weight of 'mass' must be a positive number"):
        cobra_cost("mass_-1")


def test_the_command_writes_a_scenario_that_runs_reads_back(tmp_path):
    out = tmp_path / "cell" / "pause.yaml"
    result = CliRunner().invoke(
        main, ["import-cobra", str(TASKS / "PTP_pause.json"), "--catalog", str(IMPROV_6DOF), "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "3 goals, 1 obstacles, 1 meshes" in result.output
    assert (out.parent / "meshes" / "QUASER_MV205_v3_compressed.stl").is_file()
    bad = CliRunner().invoke(
        main,
        ["import-cobra", str(TASKS / "PTP_1.json"), "--catalog", str(IMPROV_6DOF), "-o", str(out), "--cost", "cyk"],
    )
    assert bad.exit_code != 0 and "unknown CoBRA cost 'cyk'" in bad.output


def test_run_solves_a_cobra_task_directly(tmp_path):
    """``run TASK.json --catalog C``: the task imported into the results folder, solved, and the
    winner written back as a CoBRA solution that meets the task's goals on its rows."""
    task = _task(
        [
            {"ID": "a", "type": "reach", "goalPose": _pose(0.9, 0.5, 1.1)},
            {"ID": "b", "type": "reach", "goalPose": _pose(-0.5, 0.9, 0.9)},
        ]
    )
    path = tmp_path / "reach.json"
    path.write_text(json.dumps(task))
    catalog = ROOT / "scenarios" / "catalogs" / "paper-4dof.yaml"
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["run", str(path), "--catalog", str(catalog), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert (out / "cobra" / "reach.yaml").is_file()
    document = json.loads((out / "result.json").read_text())
    solution = json.loads((out / COBRA_SOLUTION).read_text())
    assert solution["taskID"] == "test/t" and set(solution["trajectory"]["goal2time"]) == {"a", "b"}
    figures = check_solution(task, solution, (out / document["winner"]["files"]["urdf"]).read_text(), None)
    assert max(figures["position_error"].values()) <= 0.01
    # a CoBRA task needs a catalogue, and a scenario has its own
    missing = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "x")])
    assert missing.exit_code != 0 and "--catalog" in missing.output and "CoBRA task" in missing.output
    scenario = CliRunner().invoke(main, ["run", str(out / "cobra" / "reach.yaml"), "--catalog", str(catalog)])
    assert scenario.exit_code != 0 and "a scenario names its own catalogue" in scenario.output
    # the commands that read a scenario (or a catalogue) say how to use a task (not "name: missing")
    for command in (["filter", str(path)], ["enumerate", str(path)], ["optimize", "--scenario", str(path), "B-J1"]):
        refused = CliRunner().invoke(
            main, [*command, "--out", str(tmp_path / "y")] if command[0] == "optimize" else command
        )
        assert refused.exit_code == 1, refused.output
        assert refused.output.splitlines()[-1] == (
            f"Error: {path}:1: (top level): expected a scenario{' or a catalogue' * (command[0] == 'enumerate')}, got a "
            f"CoBRA task (JSON): solve it with `modular-robots run {path} --catalog CATALOG`, or convert it with "
            f"`modular-robots import-cobra {path} --catalog CATALOG -o SCENARIO.yaml`"
        )


def test_sample_times_keep_every_event_and_the_step():
    t = sample_times([0.0, 0.0301, 0.5, 0.5000000001, 1.0], 0.01)
    assert t[0] == 0.0 and t[-1] == 1.0 and np.any(np.isclose(t, 0.0301, rtol=0, atol=1e-15))
    assert np.diff(t).max() <= 0.01 + 1e-12 and np.diff(t).min() > 1e-6
    # rows at most the step apart to the last ulp (a stretch a hair over 61 steps was cut into 61,
    # 0.010000000000000231 s apart), and an exact multiple of the step is not cut finer
    long = sample_times([0.0, 0.6100000000002, 2.5], 0.01)
    assert np.diff(long).max() <= 0.01 * (1 + 4e-16), np.diff(long).max()
    assert len(sample_times([0.0, 1.0], 0.01)) == 101


# --------------------------------------------------------------------------------------------
# a solution, checked as CoBRA's checker does
# --------------------------------------------------------------------------------------------
#: A CoBRA task of every goal kind for the 4-joint IMPROV catalogue (position tolerances only:
#: four joints cannot also hold an orientation), its base placed off the world's origin and
#: turned about z, so that every pose goes through the change of frame.
BASE = [[0.0, -1.0, 0.0, 2.0], [1.0, 0.0, 0.0, -1.0], [0.0, 0.0, 1.0, 0.5], [0.0, 0.0, 0.0, 1.0]]


def _world_pose(base_position):
    p = np.array(BASE) @ np.array([*base_position, 1.0])
    return _pose(*p[:3])


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cobra") / "tasks"
    folder.mkdir()
    goals = [
        {"ID": "pick", "type": "reach", "goalPose": _world_pose((0.45, 0.25, 0.25))},
        {"ID": "over", "type": "at", "goalPose": _world_pose((0.1, 0.55, 0.45))},
        {"ID": "place", "type": "reach", "goalPose": _world_pose((-0.25, 0.45, 0.35))},
        {"ID": "open", "type": "pause", "duration": 0.3},
        {"ID": "back", "type": "returnTo"},
    ]
    constraints = [
        {"type": "joint", "parts": ["q", "dq", "tau"]},
        {"type": "selfCollisionFree"},
        {"type": "allGoalsFulfilledInOrder", "order": ["pick", "over", "place", "back"]},
        {"type": "basePlacement", "pose": {"nominal": BASE}},
    ]
    task = _task(goals, constraints=constraints)
    path = folder / "cycle.json"
    path.write_text(json.dumps(task))
    out = folder.parent / "cycle.yaml"
    import_cobra(path, IMPROV_4DOF, out, payload=1.0).write(out)
    scenario = load_scenario(out)
    verdict = check_composition(Composition.from_name(ROBOT, scenario.catalog), scenario.catalog, scenario.task)
    assert verdict.passed, verdict.message
    result = make_candidate(scenario, next(candidate_specs([verdict]))).solve()
    assert result.status == "optimal" and result.verification.passed, result.reason
    robot = robot_from_urdf(result.urdf, result.drive["armature"])
    return task, scenario, result, cobra_solution(scenario, result, robot, 1.0)


def test_a_solution_meets_every_goal_and_constraint_at_its_rows(solved):
    task, _, result, document = solved
    assert document["taskID"] == "test/t" and document["costFunction"] == "cyc"
    assert document["notes"].endswith("; tau holds a payload of 1 kg at tool0 (CoBRA's task has none)")
    assert document["moduleOrder"] == ["1", "21", "4", "23", "6", "12"]  # Timor's ids of base PB21 L1 PB23 L4 L3
    assert document["moduleSet"] == "IMPROV"
    t = np.array(document["trajectory"]["t"])
    assert document["cost"] == pytest.approx(t[-1]) and t[-1] == pytest.approx(result.tf)
    figures = check_solution(task, document, result.urdf, result.drive["armature"])
    assert set(figures["reach_speed"]) == {"pick", "place"} and max(figures["position_error"].values()) <= 0.01
    times = document["trajectory"]["goal2time"]
    assert times["open"] == pytest.approx(times["place"] + 0.3)
    over = int(np.flatnonzero(np.isclose(t, times["over"]))[0])
    assert np.abs(np.array(document["trajectory"]["dq"][over])).max() > 0.05  # an at goal is passed moving


def test_a_plan_a_little_past_a_joint_limit_is_written_on_it(solved):
    """Between its nodes a plan may pass a joint limit by what verification allows (1e-3 of the
    range); CoBRA checks the limits exactly, so the solution's rows are put on them (the checker
    refused a PTP_2_cycle solution 2.24e-5 m past a prismatic joint's limit)."""
    task, scenario, result, _ = solved
    # joint 1's lower limit raised to 2e-5 rad above the lowest the plan takes it
    lowest = float(result.trajectory.q[:, 0].min())
    first = re.search(r'lower="([^"]+)"', result.urdf)
    assert first is not None and float(first.group(1)) < lowest - 1e-3
    urdf = result.urdf[: first.start(1)] + repr(lowest + 2e-5) + result.urdf[first.end(1) :]
    robot = robot_from_urdf(urdf, result.drive["armature"])
    assert robot.lower[0] == lowest + 2e-5
    document = cobra_solution(scenario, result, robot, 1.0)
    q = np.array(document["trajectory"]["q"])
    assert q[:, 0].min() == robot.lower[0]
    check_solution(task, document, urdf, result.drive["armature"])  # the limits, goals and tau = ID(rows)


def test_a_weighted_cost_is_scored_with_timors_default_weights(solved):
    """``cyc,mass,numJ`` is the cycle time plus 0.05 kg^-1 of the robot's mass plus 0.1 per joint
    (Timor's ``default_weight``), the mass summed from the URDF's links without the payload."""
    _, scenario, result, _ = solved
    robot = robot_from_urdf(result.urdf, result.drive["armature"])
    weighted = replace(scenario, cobra=replace(scenario.cobra, cost_function="cyc,mass,numJ"))
    scored = cobra_solution(weighted, result, robot, 1.0)
    links = yourdfpy.URDF.load(io.StringIO(result.urdf), build_scene_graph=False, load_meshes=False).robot.links
    mass = sum(link.inertial.mass for link in links if link.inertial is not None) - scenario.task.payload
    t_end = scored["trajectory"]["t"][-1]
    assert scored["cost"] == pytest.approx(t_end + 0.05 * mass + 0.1 * robot.nv, rel=1e-9)
    assert scored["costFunction"] == "cyc,mass,numJ" and mass > 1.0


def test_a_run_writes_the_solution_into_its_folder(solved, tmp_path):
    _, scenario, _, _ = solved
    result = CliRunner().invoke(
        main, ["optimize", ROBOT, "--scenario", str(scenario.path), "--out", str(tmp_path / "out")]
    )
    assert result.exit_code == 0, result.output
    document = json.loads((tmp_path / "out" / "result.json").read_text())
    assert document["winner"]["files"].get("cobra_solution") == COBRA_SOLUTION
    written = json.loads((tmp_path / "out" / COBRA_SOLUTION).read_text())
    assert set(written["trajectory"]["goal2time"]) == {"pick", "over", "place", "open", "back"}


def test_the_check_fails_a_solution_that_breaks_a_goal(solved):
    """The checker is not vacuous: a pause that drifts, a goal's instant moved off its pose."""
    task, _, result, document = solved
    times = document["trajectory"]["goal2time"]
    t = np.array(document["trajectory"]["t"])
    drifting = json.loads(json.dumps(document))
    inside = int(np.flatnonzero(np.isclose(t, times["open"]))[0]) - 1
    drifting["trajectory"]["q"][inside][0] += 1e-6
    with pytest.raises(AssertionError, match="q moves in the pause"):
        check_solution(task, drifting, result.urdf, result.drive["armature"])
    early = json.loads(json.dumps(document))
    early["trajectory"]["goal2time"]["place"] = float(t[int(np.flatnonzero(np.isclose(t, times["place"]))[0]) - 20])
    with pytest.raises(AssertionError, match="place"):
        check_solution(task, early, result.urdf, result.drive["armature"])


def test_a_return_to_an_at_goal_stops_there_and_meets_cobras_return(tmp_path):
    """CoBRA's returnTo compares the joint state with the named goal's, velocity included: an
    ``at`` goal a returnTo names becomes a ``reach``. Imported as an ``at``, the robot passed it at
    1.19 rad/s and the return ended at rest: the solution failed the check ('4', 'returnTo')."""
    (tmp_path / "tasks").mkdir()
    goals = [
        {"ID": "1", "type": "reach", "goalPose": _world_pose((0.45, 0.25, 0.25))},
        {"ID": "w", "type": "at", "goalPose": {**_world_pose((0.2, 0.25, 0.45)), "tolerance": [[0, 0.03]]}},
        {"ID": "2", "type": "reach", "goalPose": _world_pose((-0.25, 0.45, 0.35))},
        {"ID": "4", "type": "returnTo", "returnToGoal": "w"},
    ]
    constraints = [{"type": "joint", "parts": ["q", "dq", "tau"]}, {"type": "basePlacement", "pose": {"nominal": BASE}}]
    task = _task(goals, constraints=constraints)
    path = tmp_path / "tasks" / "back.json"
    path.write_text(json.dumps(task))
    out = tmp_path / "back.yaml"
    import_cobra(path, IMPROV_4DOF, out).write(out)
    scenario = load_scenario(out)
    assert [(g.id, g.kind) for g in scenario.task.goals] == [("w", "reach"), ("2", "reach"), ("4", "return")]
    composition = Composition.from_name("base-PB21-L1-PB21-L3", scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    assert verdict.passed, verdict.message
    result = make_candidate(scenario, next(candidate_specs([verdict]))).solve()
    assert result.verification is not None and result.verification.passed, (result.status, result.reason)
    robot = robot_from_urdf(result.urdf, result.drive["armature"])
    check_solution(task, cobra_solution(scenario, result, robot, 1.0), result.urdf, result.drive["armature"])


def test_a_refused_import_leaves_the_folder_as_it_was(tmp_path):
    """The reader refuses the written scenario (a max_time shorter than the task's pauses): nothing
    of it stays, neither in a new folder nor over an earlier import, whose scenario and mesh are
    kept; and the message says nothing was imported. Energy alone without a max_time is refused
    before anything is written, naming the option."""
    task = ["import-cobra", str(TASKS / "PTP_pause.json"), "--catalog", str(IMPROV_6DOF)]
    fresh = tmp_path / "new" / "cell" / "pause.yaml"
    short = ["--max-time", "0.001"]
    refused = CliRunner().invoke(main, [*task, "-o", str(fresh), *short])
    assert refused.exit_code == 1, refused.output
    assert f"{TASKS / 'PTP_pause.json'}: not imported, the scenario it gives is refused (" in refused.output
    assert "task.max_time: the pauses take 0.4 s" in refused.output
    assert not (tmp_path / "new").exists()
    kept = tmp_path / "kept" / "pause.yaml"
    assert CliRunner().invoke(main, [*task, "-o", str(kept)]).exit_code == 0
    files = {p: p.read_bytes() for p in kept.parent.rglob("*") if p.is_file()}
    refused = CliRunner().invoke(main, [*task, "-o", str(kept), *short])
    assert refused.exit_code == 1 and "task.max_time: the pauses take" in refused.output, refused.output
    assert {p: p.read_bytes() for p in kept.parent.rglob("*") if p.is_file()} == files
    energy = CliRunner().invoke(main, [*task, "-o", str(fresh), "--cost", "mechEnergy,mass"])
    assert energy.exit_code == 1 and "--max-time SECONDS" in energy.output, energy.output
    assert energy.output.startswith("Error: cost mechEnergy,mass: the mechanical energy without the cycle time")
    assert not (tmp_path / "new").exists()


def test_an_import_over_an_earlier_one_replaces_each_file_whole(tmp_path, monkeypatch):
    """Each file is written beside its place and renamed onto it: no write of the new import goes
    to a file's own path (so a kill -9 leaves each file old or new, never cut short), and the
    import ends as a fresh one."""
    task = TASKS / "PTP_pause.json"
    out = tmp_path / "cell" / "pause.yaml"
    import_cobra(task, IMPROV_6DOF, out, payload=1.0).write(out)
    earlier = {p: p.read_bytes() for p in out.parent.rglob("*") if p.is_file()}
    assert any(p.suffix == ".stl" for p in earlier)
    written = []

    def writing(target) -> None:
        written.append(Path(target))

    copyfile, write_text = shutil.copyfile, Path.write_text

    def copy_spy(source, target, *args, **kwargs):
        writing(target)
        return copyfile(source, target, *args, **kwargs)

    def write_spy(path, *args, **kwargs):
        writing(path)
        return write_text(path, *args, **kwargs)

    monkeypatch.setattr(shutil, "copyfile", copy_spy)
    monkeypatch.setattr(Path, "write_text", write_spy)
    import_cobra(task, IMPROV_6DOF, out).write(out)
    monkeypatch.undo()
    assert len(written) == len(earlier) and not set(written) & set(earlier)
    fresh = tmp_path / "fresh" / "pause.yaml"
    import_cobra(task, IMPROV_6DOF, fresh).write(fresh)
    now = {p.relative_to(out.parent): p.read_bytes() for p in out.parent.rglob("*") if p.is_file()}
    assert now == {p.relative_to(fresh.parent): p.read_bytes() for p in fresh.parent.rglob("*") if p.is_file()}
    assert now[Path("pause.yaml")] != earlier[out]  # the payload is gone: the scenario was replaced
