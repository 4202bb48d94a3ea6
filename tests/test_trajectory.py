"""What a robot integrator receives: ``trajectory.csv`` under the acceleration contract, the
controller-rate export under the zero-order-hold contract, and closed-loop tracking.

Every check runs on an engine that did not produce the plan: MuJoCo, with its own URDF importer
and its own dynamics (inverse dynamics for the contract, forward integration for the
zero-order-hold contract, a computed-torque controller for tracking).
"""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest

from modular_robots import Candidate, OptimizerSettings, ShootingProblem, load_scenario, optimize_composition
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.ocp.trajectory import controller_rate, sample_trajectory
from modular_robots.report import export_controller_rate
from modular_robots.robot import RobotModel, robot_from_urdf

from .helpers.models import ARM_GOAL, ARM_START, planar_arm, ur5
from .helpers.mujoco_engine import mj_qadr, mujoco_model, urdf_movable_joints
from .helpers.paths import PAPER_5KG, SMALL

SMALL_NAME = "B-J1-L1-J1-L1-J1-L1-E2"
#: The paper-5kg winner of ``make run`` (from its clear boundary pair).
PAPER_WINNER = "B-J1-L2-J1-L1-J1-L2-J2-L1-E2+clear"


def _read(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float)


def _columns(header, table, groups):
    n = sum(1 for h in header if re.fullmatch(r"q\d+", h))
    out = {"t": table[:, 0], "tool": table[:, -3:]}
    for k, g in enumerate(groups):
        out[g] = table[:, 1 + k * n : 1 + (k + 1) * n]
    return n, out


@pytest.fixture(scope="module")
def small_results(tmp_path_factory):
    """``optimize`` on one composition of the small scenario: its results folder."""
    out = tmp_path_factory.mktemp("small-optimize")
    run = optimize_composition(load_scenario(SMALL), SMALL_NAME, out)
    assert run.winner.status == "optimal", run.winner.reason
    return out, run


def _mujoco(urdf_text: str, armature=None):
    mujoco, m = mujoco_model(urdf_text, np.array([0.0, 0.0, -9.81]))
    if armature is not None:
        _, dadr, _ = mj_qadr(mujoco, m, urdf_text)
        m.dof_armature[dadr] = armature
    return mujoco, m


def test_trajectory_csv_follows_the_acceleration_contract_in_mujoco(small_results):
    """Row by row: positions and velocities follow from the previous row under its constant
    acceleration (to rounding), ``tau`` is MuJoCo's inverse dynamics at the row and the tool
    columns MuJoCo's ``tool0`` (the exported URDF, read by MuJoCo's own importer)."""
    out, _ = small_results
    header, table = _read(out / "trajectory.csv")
    n, c = _columns(header, table, ("q", "qd", "qdd", "tau"))
    assert header == ["t", *(f"{g}{i}" for g in ("q", "qd", "qdd", "tau") for i in range(1, n + 1)), "x", "y", "z"]
    t, q, qd, qdd, tau = c["t"], c["q"], c["qd"], c["qdd"], c["tau"]
    h = np.diff(t)[:, None]
    assert np.all(h > 0)
    np.testing.assert_allclose(q[1:], q[:-1] + qd[:-1] * h + 0.5 * qdd[:-1] * h * h, rtol=0, atol=1e-12)
    np.testing.assert_allclose(qd[1:], qd[:-1] + qdd[:-1] * h, rtol=0, atol=1e-12)
    # the inverse transcription's accelerations are its controls: constant over each interval
    intervals = load_scenario(SMALL).optimizer.nodes - 1
    assert len(np.unique(qdd[:-1], axis=0)) == intervals and np.all(qdd[-1] == 0)

    document = json.loads((out / "result.json").read_text())
    urdf = (out / "winner.urdf").read_text()
    mujoco, m = _mujoco(urdf, document["winner"]["drive"]["armature"])
    d = mujoco.MjData(m)
    qadr, dadr, ids = mj_qadr(mujoco, m, urdf)
    assert len(ids) == n
    tool = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "tool0")
    limit = m.jnt_actfrcrange[ids, 1]
    for k in range(len(t)):
        d.qpos[qadr], d.qvel[dadr], d.qacc[dadr] = q[k], qd[k], qdd[k]
        mujoco.mj_inverse(m, d)
        np.testing.assert_allclose(tau[k], d.qfrc_inverse[dadr], rtol=1e-6, atol=1e-9 * limit.max())
        np.testing.assert_allclose(c["tool"][k], d.xpos[tool], rtol=0, atol=1e-9)
    # the plan keeps the margins at its rows; the file reports the share it uses, between rows too
    used = document["winner"]["limits_used"]
    rows = np.max(np.abs(tau) / limit, axis=0)
    assert rows.max() <= 0.9 * (1 + 1e-6) and max(used["velocity"]) <= 0.95 * (1 + 1e-6)
    assert np.all(np.array(used["effort"]) >= rows - 1e-12)
    dense = _inverse_dynamics_between_rows(mujoco, m, d, qadr, dadr, t, q, qd, qdd)
    np.testing.assert_allclose(used["effort"], np.maximum(rows, np.max(np.abs(dense) / limit, axis=0)), rtol=1e-6)


def _inverse_dynamics_between_rows(mujoco, m, d, qadr, dadr, t, q, qd, qdd, points=8):
    """MuJoCo's inverse dynamics at ``points`` instants after each row up to the next, the motion
    between them following the acceleration contract; the last is the left-hand limit at the next
    row (where the acceleration jumps, the row carries the right-hand torque)."""
    out = []
    for k in range(len(t) - 1):
        for s in np.arange(1, points + 1) * (t[k + 1] - t[k]) / points:
            d.qpos[qadr] = q[k] + qd[k] * s + 0.5 * qdd[k] * s * s
            d.qvel[dadr], d.qacc[dadr] = qd[k] + qdd[k] * s, qdd[k]
            mujoco.mj_inverse(m, d)
            out.append(d.qfrc_inverse[dadr].copy())
    return np.array(out)


def test_the_verifications_shares_cover_every_row_of_the_plan(tmp_path):
    """``effort_share`` and ``velocity_share`` (per joint, the largest |value| / limit) bound the
    plan's own rows, the last one too: the robot holds the payload still at the goal there (its
    torque is gravity's alone), which the grid of the motion did not count (this composition's
    third joint: 0.0638 on the grid, 0.0763 holding at the goal)."""
    run = optimize_composition(load_scenario(SMALL), "B-J1-L3-J1-L3-E2", tmp_path)
    plan, v = run.winner.trajectory, run.winner.verification
    assert run.winner.status == "optimal", run.winner.reason
    rows_effort = np.max(np.abs(plan.tau) / plan.effort_limit, axis=0)
    rows_velocity = np.max(np.abs(plan.qd) / plan.velocity_limit, axis=0)
    assert np.all(np.asarray(v.effort_share) >= rows_effort * (1.0 - 1e-9)), (v.effort_share, rows_effort)
    assert np.all(np.asarray(v.velocity_share) >= rows_velocity * (1.0 - 1e-6)), (v.velocity_share, rows_velocity)
    held = np.abs(plan.tau[-1]) / plan.effort_limit  # the goal's gravity torque, at rest
    assert np.allclose(plan.qd[-1], 0.0, atol=1e-9) and np.all(np.asarray(v.effort_share) >= held)


def test_forward_transcription_rows_follow_the_contract():
    """The forward transcription's acceleration varies within an interval: its rows are dense
    (1 ms) and still follow the contract exactly, with ``tau`` the inverse dynamics at the row;
    and they stay on the plan: the velocities at the nodes are the planned ones."""
    robot = planar_arm()
    problem = ShootingProblem(robot, ARM_START, ARM_GOAL, settings=OptimizerSettings(nodes=6, transcription="forward"))
    outcome = ShootingSolver(problem).solve()
    assert outcome.status == "optimal", outcome.reason
    trajectory = sample_trajectory(problem, outcome.final.y)
    t, q, qd, qdd = trajectory.t, trajectory.q, trajectory.qd, trajectory.qdd
    h = np.diff(t)[:, None]
    assert h.max() <= 1e-3 + 1e-12
    tf = problem.unpack(outcome.final.y)[0]
    substeps = np.linspace(0.0, tf, problem.intervals * problem.substeps + 1)  # SPEC §7: a row at each
    assert np.abs(t[:, None] - substeps[None, :]).min(axis=0).max() < 1e-12
    np.testing.assert_allclose(q[1:], q[:-1] + qd[:-1] * h + 0.5 * qdd[:-1] * h * h, rtol=0, atol=1e-12)
    np.testing.assert_allclose(qd[1:], qd[:-1] + qdd[:-1] * h, rtol=0, atol=1e-12)
    for k in range(0, len(t), 50):
        np.testing.assert_allclose(trajectory.tau[k], robot.rnea(q[k], qd[k], qdd[k]), rtol=1e-12, atol=1e-12)
    tf, nodes, _ = problem.unpack(outcome.final.y)
    for m, node in enumerate(nodes):
        k = int(np.argmin(np.abs(t - m * tf / problem.intervals)))
        # velocities are the plan's exactly; positions within the RK4 plan's own error (the rows
        # integrate its torques exactly)
        np.testing.assert_allclose(qd[k], node[problem.nv :], atol=1e-9)
        np.testing.assert_allclose(q[k], node[: problem.nv], atol=1e-3)


def test_export_at_1khz_follows_the_zero_order_hold_contract_in_mujoco(small_results):
    """``export --rate 1000``: holding each row's torque until the next row, MuJoCo's forward
    dynamics land on the next row within 1e-3 rad (m) and 1e-2 rad/s (m/s) (SPEC §7), far
    tighter in fact; the JSON loads into the ROS JointTrajectory shape with the same numbers."""
    out, _ = small_results
    files = export_controller_rate(out, 1000.0)
    header, table = _read(files["csv"])
    n, c = _columns(header, table, ("q", "qd", "tau"))
    assert not any(h.startswith("qdd") for h in header)
    t, q, qd, tau = c["t"], c["q"], c["qd"], c["tau"]
    np.testing.assert_allclose(np.diff(t)[:-1], 1e-3, rtol=0, atol=1e-12)
    assert np.diff(t)[-1] <= 1e-3 + 1e-12

    document = json.loads((out / "result.json").read_text())
    assert t[-1] == pytest.approx(document["winner"]["tf"], abs=1e-9)
    urdf = (out / "winner.urdf").read_text()
    mujoco, m = _mujoco(urdf, document["winner"]["drive"]["armature"])
    qadr, dadr, _ = mj_qadr(mujoco, m, urdf)
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    d = mujoco.MjData(m)
    worst_q = worst_v = 0.0
    for k in range(len(t) - 1):
        m.opt.timestep = (t[k + 1] - t[k]) / 4
        d.qpos[qadr], d.qvel[dadr] = q[k], qd[k]
        d.qfrc_applied[:] = 0.0
        d.qfrc_applied[dadr] = tau[k]
        for _ in range(4):
            mujoco.mj_step(m, d)
        worst_q = max(worst_q, float(np.abs(d.qpos[qadr] - q[k + 1]).max()))
        worst_v = max(worst_v, float(np.abs(d.qvel[dadr] - qd[k + 1]).max()))
    assert worst_q <= 1e-3 and worst_v <= 1e-2
    assert worst_q <= 1e-6 and worst_v <= 1e-4  # what it actually achieves

    trajectory = json.loads(files["json"].read_text())
    assert trajectory["header"] == {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "base_link"}  # start on receipt
    catalog = load_scenario(SMALL).catalog
    modules = document["winner"]["composition"].split("-")
    assert (
        trajectory["joint_names"]
        == urdf_movable_joints(urdf)
        == [f"m{i}_{module}_joint" for i, module in enumerate(modules) if catalog.module(module).dof]
    )
    assert len(trajectory["points"]) == len(t)
    for k in (0, 1, len(t) // 2, len(t) - 1):
        point = trajectory["points"][k]
        assert set(point) == {"positions", "velocities", "accelerations", "effort", "time_from_start"}
        stamp = point["time_from_start"]
        assert isinstance(stamp["sec"], int) and isinstance(stamp["nanosec"], int) and 0 <= stamp["nanosec"] < 10**9
        assert stamp["sec"] + stamp["nanosec"] * 1e-9 == pytest.approx(t[k], abs=1e-9)
        np.testing.assert_allclose(point["positions"], q[k], rtol=1e-15)
        np.testing.assert_allclose(point["effort"], tau[k], rtol=1e-15)
        assert len(point["velocities"]) == len(point["accelerations"]) == n


def _mujoco_tracking(mujoco, m, qadr, dadr, reference, limit, omega=20.0):
    """Computed-torque tracking in MuJoCo: MuJoCo's inverse dynamics for the command, its RK4 for
    the plant, the command clipped to ``limit`` and held for each 1 kHz tick. Returns (tool error
    at tf [m], largest tool deviation [m], share of clipped ticks)."""
    tool = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "tool0")
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
    d = mujoco.MjData(m)
    t, q_ref, qd_ref = reference.t, reference.q, reference.qd
    acc = np.diff(qd_ref, axis=0) / np.diff(t)[:, None]
    d.qpos[qadr], d.qvel[dadr] = q_ref[0], qd_ref[0]
    clipped, deviation = 0, 0.0
    for k in range(len(t) - 1):
        q, qd = d.qpos[qadr].copy(), d.qvel[dadr].copy()
        d.qacc[:] = 0.0
        d.qacc[dadr] = acc[k] + omega**2 * (q_ref[k] - q) + 2 * omega * (qd_ref[k] - qd)
        mujoco.mj_inverse(m, d)
        command = d.qfrc_inverse[dadr].copy()
        held = np.clip(command, -limit, limit)
        clipped += bool(np.any(held != command))
        d.qfrc_applied[:] = 0.0
        d.qfrc_applied[dadr] = held
        m.opt.timestep = (t[k + 1] - t[k]) / 4
        for _ in range(4):
            mujoco.mj_step(m, d)
        mujoco.mj_kinematics(m, d)
        deviation = max(deviation, float(np.linalg.norm(d.xpos[tool] - reference.tool[k + 1])))
    return float(np.linalg.norm(d.xpos[tool] - reference.tool[-1])), deviation, clipped / (len(t) - 1)


def test_the_paper_winner_is_tracked_at_1khz_without_saturating_in_mujoco(tmp_path):
    """The ``make run`` winner, optimised with the default margins and exported, tracked at 1 kHz
    with torques clipped at the URDF's limits: the tool ends within 1 cm, never strays 2 cm, no
    tick saturates; the product's own tracking (Pinocchio) says the same."""
    run = optimize_composition(load_scenario(PAPER_5KG), PAPER_WINNER, tmp_path)
    document = json.loads((tmp_path / "result.json").read_text())
    armature = document["winner"]["drive"]["armature"]
    urdf = (tmp_path / "winner.urdf").read_text()
    robot = robot_from_urdf(urdf, armature)
    reference = controller_rate(run.winner.trajectory, robot, 1000.0)
    mujoco, m = _mujoco(urdf, armature)
    limit = np.asarray(robot.effort_limit)
    qadr, dadr, _ = mj_qadr(mujoco, m, urdf)
    error, deviation, clipped = _mujoco_tracking(mujoco, m, qadr, dadr, reference, limit)
    assert error <= 0.01 and deviation <= 0.02 and clipped == 0.0
    ours = document["winner"]["tracking"]
    assert ours["clipped_share"] == 0.0 and ours["tool_error"] <= 0.01 and ours["max_deviation"] <= 0.02
    assert abs(ours["max_deviation"] - deviation) <= 1e-3


def _ur5_urdf(payload: float) -> str:
    """The UR5's URDF without meshes (MuJoCo's importer would look for them), with the payload
    sphere of :func:`tests.helpers.models.ur5` as a fixed body at tool0."""
    import importlib.metadata

    path = next(
        f.locate()
        for f in importlib.metadata.files("example-robot-data")
        if str(f).endswith("ur_description/urdf/ur5_robot.urdf")
    )
    text = re.sub(r"<(visual|collision)>.*?</\1>", "", path.read_text(), flags=re.S)
    inertia = 0.4 * payload * 0.05**2
    body = (
        f'<link name="payload"><inertial><origin xyz="0 0 0"/><mass value="{payload}"/>'
        f'<inertia ixx="{inertia}" iyy="{inertia}" izz="{inertia}" ixy="0" ixz="0" iyz="0"/></inertial></link>'
        '<joint name="payload_fixed" type="fixed"><parent link="tool0"/><child link="payload"/>'
        '<origin xyz="0 0 0"/></joint>'
    )
    return text.replace("</robot>", body + "</robot>")


def test_a_ur5_plan_is_tracked_at_1khz_without_saturating_in_mujoco():
    """A robot the package did not build: the UR5 with 2 kg, planned with the default margins;
    tracked in MuJoCo (the mesh-free URDF plus the payload) it stays within 1 cm / 2 cm and never
    saturates."""
    robot: RobotModel = ur5(payload=2.0)
    q_start = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
    q_goal = np.array([1.2, -1.0, 1.0, -1.5, -1.2, 0.5])
    problem = ShootingProblem(robot, q_start, q_goal, settings=OptimizerSettings(nodes=6, substeps=4))
    result = Candidate(problem).solve()
    assert result.status == "optimal", result.reason
    mujoco, m = _mujoco(_ur5_urdf(2.0))
    assert m.nv == 6
    # MuJoCo's model is the package's: same inverse dynamics at a row of the plan
    d = mujoco.MjData(m)
    qadr = dadr = np.arange(6)  # six hinges in URDF order
    for k in range(0, len(result.trajectory.t), 5):
        d.qpos[qadr], d.qvel[dadr], d.qacc[dadr] = (
            result.trajectory.q[k],
            result.trajectory.qd[k],
            result.trajectory.qdd[k],
        )
        mujoco.mj_inverse(m, d)
        np.testing.assert_allclose(d.qfrc_inverse[dadr], result.trajectory.tau[k], rtol=1e-6, atol=1e-6)
    reference = controller_rate(result.trajectory, robot, 1000.0)
    error, deviation, clipped = _mujoco_tracking(mujoco, m, qadr, dadr, reference, robot.effort_limit)
    assert error <= 0.01 and deviation <= 0.02 and clipped == 0.0


def test_the_export_puts_a_plan_resting_a_few_ulps_past_a_limit_on_it():
    """A plan that rests on a prismatic joint's upper limit comes out of the optimiser a few ulps
    past it (1e-16 m); the controller-rate export puts such points on the limit (a controller
    may refuse a point beyond the URDF's limits) and leaves a real excursion as it is."""
    from modular_robots import Composition, load_catalog
    from modular_robots.robot import robot_model

    catalog = load_catalog(PAPER_5KG.parent / "catalogs" / "paper.yaml")
    robot = robot_model(Composition.from_name("B-J1-L1-J2-L1-E1", catalog), catalog)
    upper = robot.upper[1]
    assert robot.lower[1] == 0.0 and 0.0 < upper < 1.0  # the prismatic joint
    for past, kept in ((1e-16, False), (1e-6, True)):
        t = np.array([0.0, 0.5, 1.0])
        q = np.zeros((3, robot.nv))
        q[:, 0] = [0.0, 0.1, 0.2]
        q[1:, 1] = upper + past
        exported = controller_rate(controller_rate_input(t, q), robot, 10.0).q
        assert exported[:, 1].max() == (upper + past if kept else upper)
        np.testing.assert_allclose(exported[:, 0], np.linspace(0.0, 0.2, 11))  # the other joints as they were


def controller_rate_input(t: np.ndarray, q: np.ndarray):
    """A plan through the rows ``q`` at times ``t``, each segment at constant speed."""
    from modular_robots.plan.trajectory import Trajectory

    qd = np.vstack([np.diff(q, axis=0) / np.diff(t)[:, None], np.zeros((1, q.shape[1]))])
    zeros = np.zeros_like(q)
    return Trajectory(t, q, qd, zeros, zeros, np.zeros((len(t), 3)))


def test_the_held_torques_carry_a_robot_with_friction_from_row_to_row():
    """The zero-order-hold contract with Coulomb friction (an IMPROV arm, 1 kg): each exported
    torque, held over its step and integrated by SciPy's DOP853 through Pinocchio's forward
    dynamics, lands on the next row's velocity. A rest-to-rest plan whose third joint reverses;
    the inverse dynamics at a step's start (what the export held before) missed by a median of
    1e-3 rad/s at 100 Hz and 1e-5 at 1 kHz (4e-4 at worst), since friction changes within a step."""
    from scipy.integrate import solve_ivp

    from modular_robots import Composition, load_catalog
    from modular_robots.plan.trajectory import Trajectory
    from modular_robots.robot import robot_model

    catalog = load_catalog(SMALL.parents[2] / "scenarios" / "catalogs" / "improv-4dof.yaml")
    robot = robot_model(Composition.from_name("base-PB22-L2-PB23-L6-L3", catalog), catalog, payload=1.0)
    assert robot.has_friction
    nv, t = robot.nv, np.linspace(0.0, 1.0, 5)
    accelerations = np.array(
        [[1.0, -0.8, 0.6, 0.5], [1.0, -0.8, -1.2, 0.5], [-1.0, 0.8, -0.6, -0.5], [-1.0, 0.8, 1.2, -0.5]]
    )
    q, qd = np.zeros((5, nv)), np.zeros((5, nv))
    q[0] = [0.3, -0.4, 0.2, 0.1]
    for i, a in enumerate(accelerations):
        qd[i + 1], q[i + 1] = qd[i] + a * 0.25, q[i] + qd[i] * 0.25 + a * 0.25**2 / 2
    qdd = np.vstack([accelerations, np.zeros(nv)])
    plan = Trajectory(t, q, qd, qdd, robot.rnea(q, qd, qdd), np.zeros((5, 3)))
    for rate, median, worst in ((100.0, 1e-4, 1e-2), (1000.0, 1e-6, 1e-4)):
        held = controller_rate(plan, robot, rate)
        misses = []
        for i in range(len(held.t) - 1):
            tau = held.tau[i]
            run = solve_ivp(
                lambda _, x, tau=tau: np.concatenate([x[nv:], robot.aba(x[:nv], x[nv:], tau)]),
                (0.0, held.t[i + 1] - held.t[i]),
                np.concatenate([held.q[i], held.qd[i]]),
                method="DOP853",
                rtol=1e-10,
                atol=1e-12,
            )
            misses.append(np.abs(run.y[nv:, -1] - held.qd[i + 1]).max())
        assert np.median(misses) < median and max(misses) < worst, (rate, np.median(misses), max(misses))
