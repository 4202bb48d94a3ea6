"""``export RESULTS --ros2 OUT``: a ROS 2 package that plays the winner's plan. No ROS here, so the
files are checked against the definitions they must follow, as documented: the
``control_msgs/action/FollowJointTrajectory`` goal and ``trajectory_msgs`` messages (field names,
types, ranges), ``joint_trajectory_controller``'s and the controller manager's parameters (names,
types, allowed values and combinations), REP 144's package names, and the URDF read by two
parsers (urdfdom through Pinocchio, yourdfpy). The goal's points are checked against the plan
re-derived by hand from ``trajectory.csv``'s acceleration contract."""

from __future__ import annotations

import ast
import io
import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml
import yourdfpy
from click.testing import CliRunner

from modular_robots.cli import main
from modular_robots.pipeline import optimize_composition
from modular_robots.scenario import load_scenario

from .helpers.mujoco_engine import urdf_movable_joints
from .helpers.paths import SMALL

SMALL_NAME = "B-J1-L1-J1-L1-J1-L1-E2"  # a composition of the small scenario

INT32, UINT32 = (-(2**31), 2**31 - 1), (0, 2**32 - 1)
#: joint_trajectory_controller's documented combinations (Jazzy's userdoc and parameter file).
COMMAND_COMBINATIONS = [
    ["position"],
    ["position", "velocity"],
    ["position", "velocity", "acceleration"],
    ["velocity"],
    ["effort"],
    ["position", "effort"],
]
STATE_COMBINATIONS = [["position"], ["position", "velocity"], ["position", "velocity", "acceleration"]]
GOAL_FIELDS = {
    "trajectory",
    "multi_dof_trajectory",
    "path_tolerance",
    "component_path_tolerance",
    "goal_tolerance",
    "component_goal_tolerance",
    "goal_time_tolerance",
}


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ros2-results")
    run = optimize_composition(load_scenario(SMALL), SMALL_NAME, out)
    assert run.winner.status == "optimal", run.winner.reason
    return out


@pytest.fixture(scope="module")
def bundle(results, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ws") / "src" / "my-arm.v2"
    result = CliRunner().invoke(main, ["export", str(results), "--ros2", str(out), "--rate", "500"])
    assert result.exit_code == 0, result.output
    assert "my_arm_v2" in result.output
    return out


def _duration(value) -> float:
    assert set(value) == {"sec", "nanosec"}
    assert isinstance(value["sec"], int) and INT32[0] <= value["sec"] <= INT32[1]
    assert isinstance(value["nanosec"], int) and 0 <= value["nanosec"] < 10**9  # normalised
    return value["sec"] + value["nanosec"] * 1e-9


def _plan(results: Path):
    """``trajectory.csv``'s times and positions, the plan at any time from its contract (constant
    acceleration ``qdd_k`` from row k to row k + 1), written out here, and its largest
    acceleration [rad/s^2]."""
    lines = (results / "trajectory.csv").read_text().splitlines()
    header, rows = lines[0].split(","), np.array([[float(c) for c in line.split(",")] for line in lines[1:]])
    n = (len(header) - 4) // 4
    t, q, qd, qdd = rows[:, 0], rows[:, 1 : 1 + n], rows[:, 1 + n : 1 + 2 * n], rows[:, 1 + 2 * n : 1 + 3 * n]

    def at(time: float):
        k = min(max(int(np.searchsorted(t, time, side="right")) - 1, 0), len(t) - 2)
        dt = time - t[k]
        return q[k] + qd[k] * dt + 0.5 * qdd[k] * dt**2, qd[k] + qdd[k] * dt

    return t, q, at, float(np.abs(qdd).max())


def _movable(bundle: Path) -> list[str]:
    return urdf_movable_joints((bundle / "urdf" / "robot.urdf").read_text())


def test_the_package_is_named_as_rep_144_asks_and_installs_what_it_holds(bundle):
    package = ET.parse(bundle / "package.xml").getroot()
    assert package.get("format") == "3"
    name = package.findtext("name")
    assert name == "my_arm_v2" and re.fullmatch(r"[a-z][a-z0-9_]*", name) and "__" not in name
    assert package.findtext("buildtool_depend") == "ament_cmake"
    cmake = (bundle / "CMakeLists.txt").read_text()
    assert f"project({name}" in cmake
    installed = re.search(r"install\(DIRECTORY ([^)]*) DESTINATION", cmake)[1].split()
    assert sorted(installed) == sorted(p.name for p in bundle.iterdir() if p.is_dir())


def test_the_urdf_carries_a_ros2_control_system_for_every_joint_starting_at_the_plan(bundle, results):
    import pinocchio as pin

    text = (bundle / "urdf" / "robot.urdf").read_text()
    winner = (results / "winner.urdf").read_text()
    joints = _movable(bundle)
    assert joints == urdf_movable_joints(winner)
    model = pin.buildModelFromXML(text)  # urdfdom
    assert list(model.names)[1:] == joints
    urdf = yourdfpy.URDF.load(io.StringIO(text), load_meshes=False)
    assert urdf.validate() and list(urdf.actuated_joint_names) == joints
    _, q, _, _ = _plan(results)
    control = ET.fromstring(text).find("ros2_control")
    assert control.get("type") == "system" and control.findtext("hardware/plugin") == "mock_components/GenericSystem"
    assert [j.get("name") for j in control.findall("joint")] == joints
    for joint, q0 in zip(control.findall("joint"), q[0]):
        assert [c.get("name") for c in joint.findall("command_interface")] == ["position", "velocity", "effort"]
        assert [s.get("name") for s in joint.findall("state_interface")] == ["position", "velocity", "effort"]
        start = joint.find("state_interface[@name='position']/param[@name='initial_value']")
        assert float(start.text) == pytest.approx(q0, abs=1e-12)


def test_controllers_yaml_follows_the_controllers_parameter_definitions(bundle):
    config = yaml.safe_load((bundle / "config" / "controllers.yaml").read_text())
    manager = config["controller_manager"]["ros__parameters"]
    assert manager["update_rate"] == 500 and isinstance(manager["update_rate"], int)
    assert manager["joint_state_broadcaster"] == {"type": "joint_state_broadcaster/JointStateBroadcaster"}
    assert manager["joint_trajectory_controller"] == {"type": "joint_trajectory_controller/JointTrajectoryController"}
    jtc = config["joint_trajectory_controller"]["ros__parameters"]
    joints = _movable(bundle)
    assert jtc["joints"] == joints and len(set(joints)) == len(joints) > 0
    assert jtc["command_interfaces"] in COMMAND_COMBINATIONS
    assert jtc["state_interfaces"] in STATE_COMBINATIONS
    assert isinstance(jtc["allow_partial_joints_goal"], bool)
    constraints = jtc["constraints"]
    for key in ("stopped_velocity_tolerance", "goal_time"):
        assert isinstance(constraints[key], float) and constraints[key] >= 0.0
    per_joint = {k: v for k, v in constraints.items() if isinstance(v, dict)}
    assert set(per_joint) == set(joints)
    assert all(
        set(v) <= {"trajectory", "goal"} and all(isinstance(x, float) for x in v.values()) for v in per_joint.values()
    )
    # every interface the controller claims is one the hardware offers
    control = ET.fromstring((bundle / "urdf" / "robot.urdf").read_text()).find("ros2_control")
    for joint in control.findall("joint"):
        assert set(jtc["command_interfaces"]) <= {c.get("name") for c in joint.findall("command_interface")}
        assert set(jtc["state_interfaces"]) <= {s.get("name") for s in joint.findall("state_interface")}


def test_the_goal_is_a_follow_joint_trajectory_goal_of_the_plan(bundle, results):
    goal = yaml.safe_load((bundle / "config" / "goal.yaml").read_text())
    assert goal == json.loads((bundle / "config" / "goal.json").read_text())
    assert set(goal) <= GOAL_FIELDS
    joints = _movable(bundle)
    trajectory = goal["trajectory"]
    assert set(trajectory) == {"header", "joint_names", "points"}
    assert set(trajectory["header"]) == {"stamp", "frame_id"} and isinstance(trajectory["header"]["frame_id"], str)
    assert _duration(trajectory["header"]["stamp"]) == 0.0  # start on receipt
    assert trajectory["joint_names"] == joints
    t, q, at, largest_qdd = _plan(results)
    times = []
    for point in trajectory["points"]:
        assert set(point) == {"positions", "velocities", "accelerations", "effort", "time_from_start"}
        assert point["effort"] == []  # refused without an effort command interface
        for field in ("positions", "velocities", "accelerations"):
            assert len(point[field]) == len(joints) and all(isinstance(v, float) for v in point[field])
        times.append(_duration(point["time_from_start"]))
        position, velocity = at(times[-1])  # at the goal's time, rounded to the nanosecond:
        np.testing.assert_allclose(point["positions"], position, atol=1e-9)
        np.testing.assert_allclose(point["velocities"], velocity, atol=1e-9 + 0.5e-9 * largest_qdd)
    assert times[0] == 0.0 and np.all(np.diff(times) > 0) and times[-1] == pytest.approx(t[-1], abs=1e-9)
    assert np.diff(times)[:-1] == pytest.approx(0.01, abs=1e-9)  # the goal rate, 100 Hz
    np.testing.assert_allclose(trajectory["points"][-1]["positions"], q[-1], atol=1e-9)
    assert np.allclose(trajectory["points"][0]["velocities"], 0) and np.allclose(
        trajectory["points"][-1]["velocities"], 0
    )
    for key in ("path_tolerance", "goal_tolerance"):
        assert [tol["name"] for tol in goal[key]] == joints
        for tol in goal[key]:
            assert set(tol) == {"name", "position", "velocity", "acceleration"}
            assert all(isinstance(tol[k], float) and tol[k] >= 0.0 for k in ("position", "velocity", "acceleration"))
    assert _duration(goal["goal_time_tolerance"]) > 0.0


def test_the_launch_file_and_readme_play_this_package(bundle):
    launch = (bundle / "launch" / "play.launch.py").read_text()
    tree = ast.parse(launch)
    assert any(isinstance(n, ast.FunctionDef) and n.name == "generate_launch_description" for n in tree.body)
    strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)}
    assert "my_arm_v2" in strings
    for parts in (("urdf", "robot.urdf"), ("config", "controllers.yaml"), ("config", "view.rviz")):
        assert set(parts) <= strings and (bundle.joinpath(*parts)).is_file()
    assert {"joint_state_broadcaster", "joint_trajectory_controller", "ros2_control_node"} <= strings
    rviz = yaml.safe_load((bundle / "config" / "view.rviz").read_text())
    assert rviz["Visualization Manager"]["Global Options"]["Fixed Frame"] == "base_link"
    readme = (bundle / "README.md").read_text()
    commands = re.search(r"```sh\n(.*?)```", readme, re.S)[1].replace("\\\n", "").splitlines()
    assert len(commands) == 3
    assert commands[0].startswith("colcon build --packages-select my_arm_v2 ")
    assert commands[1] == "ros2 launch my_arm_v2 play.launch.py"
    assert "/joint_trajectory_controller/follow_joint_trajectory" in commands[2]
    assert "control_msgs/action/FollowJointTrajectory" in commands[2]
    assert "install/my_arm_v2/share/my_arm_v2/config/goal.yaml" in commands[2]


def test_a_bundle_is_never_written_over_its_inputs_or_someone_elses_files(results, bundle, tmp_path):
    before = {p: p.read_bytes() for p in results.iterdir() if p.is_file()}
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    for out in (results, results / "inside", foreign):
        result = CliRunner().invoke(main, ["export", str(results), "--ros2", str(out)])
        assert result.exit_code == 1, result.output
        assert result.output.startswith("Error: ") and str(out) in result.output
    assert {p: p.read_bytes() for p in results.iterdir() if p.is_file()} == before
    assert not (results / "inside").exists() and [p.name for p in foreign.iterdir()] == ["notes.txt"]
    fraction = CliRunner().invoke(main, ["export", str(results), "--ros2", str(tmp_path / "f"), "--rate", "333.3"])
    assert fraction.exit_code == 1 and fraction.output == (
        "Error: rate: expected a whole number of Hz (the controller manager's update_rate), got 333.3\n"
    )  # (it wrote update_rate 333 for a goal sampled at 333.3 Hz)
    assert not (tmp_path / "f").exists()
    again = CliRunner().invoke(main, ["export", str(results), "--ros2", str(bundle), "--rate", "500"])
    assert again.exit_code == 0, again.output  # a bundle of its own is replaced
