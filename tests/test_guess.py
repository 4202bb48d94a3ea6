"""Initial guesses: a goal held at the edge of the torque limit is reached by swinging past it.

Reference: a point-mass pendulum in a vertical plane, whose dynamics are written here by hand
(no Pinocchio): ``I qdd = tau + m g l cos q``, ``q`` the angle below the horizontal. Its goal
is held with 99.9 % of the torque limit and its start lies above the horizontal on the same side,
so the straight line passes poses (the horizontal) that need 1.11 times the limit to hold. Arriving
from above, the arm cannot brake at the goal; it has to overshoot to where holding is easier and
come back up, which is the guess :func:`~modular_robots.ocp.guess.swing_path` gives.
"""

from __future__ import annotations

import itertools

import numpy as np
import pinocchio as pin
import pytest
from scipy.integrate import solve_ivp

from modular_robots.ocp.candidate import Candidate
from modular_robots.ocp.guess import swing_path
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.report import write_winner_files
from modular_robots.robot import RobotModel
from modular_robots.scenario import OptimizerSettings

G0, MASS, ARM, I_OWN = 9.81, 1.0, 1.0, 1e-4
Q_START, Q_GOAL, HOLD_SHARE = -1.2, 0.45, 0.999
TAU_MAX = MASS * G0 * ARM * np.cos(Q_GOAL) / HOLD_SHARE


def pendulum(tau_max: float = TAU_MAX, joint=pin.JointModelRY) -> RobotModel:
    """Point mass ``MASS`` at ``ARM`` along the link's x; about y, positive angles lower it."""
    model = pin.Model()
    model.name = "pendulum"
    j = model.addJoint(
        0,
        joint(),
        pin.SE3.Identity(),
        "joint1",
        np.array([tau_max]),
        np.array([3.0]),
        np.array([-3.0]),
        np.array([3.0]),
    )
    model.appendBodyToJoint(j, pin.Inertia(MASS, np.array([ARM, 0.0, 0.0]), I_OWN * np.eye(3)), pin.SE3.Identity())
    model.addFrame(pin.Frame("tool0", j, 0, pin.SE3(np.eye(3), np.array([ARM, 0.0, 0.0])), pin.FrameType.OP_FRAME))
    return RobotModel(model, "tool0", name="pendulum")


def holding_torque(q: float) -> float:
    return MASS * G0 * ARM * abs(np.cos(q))


def test_the_straight_line_passes_poses_the_joint_cannot_hold():
    robot = pendulum()
    q = np.linspace(Q_START, Q_GOAL, 201)
    assert [abs(robot.gravity([x])[0]) for x in q] == pytest.approx([holding_torque(x) for x in q], rel=1e-9)
    assert holding_torque(Q_START) < TAU_MAX and holding_torque(Q_GOAL) == pytest.approx(HOLD_SHARE * TAU_MAX)
    assert max(holding_torque(x) for x in q) / TAU_MAX == pytest.approx(HOLD_SHARE / np.cos(Q_GOAL), rel=1e-4)


def test_the_swing_via_lies_past_the_goal_where_holding_is_easier():
    path = swing_path(pendulum(), None, np.array([[Q_START], [Q_GOAL]]))
    assert path.ravel() == pytest.approx([Q_START, Q_GOAL + 1.0, Q_GOAL])
    assert holding_torque(path[1, 0]) < 0.2 * holding_torque(Q_GOAL)


def test_a_loaded_start_is_left_through_a_via_next_to_it():
    path = swing_path(pendulum(), None, np.array([[Q_GOAL], [Q_START]]))
    assert path.ravel() == pytest.approx([Q_GOAL, Q_GOAL + 1.0, Q_START])


def test_a_goal_at_the_largest_holding_torque_swings_to_either_side():
    """At the horizontal the holding torque is at its maximum, so both sides are easier; the
    1 rad swings qualify on both and tie, so the via is 1 rad away (below the horizontal)."""
    robot = pendulum(tau_max=MASS * G0 * ARM / HOLD_SHARE)
    path = swing_path(robot, None, np.array([[-1.2], [0.0]]))
    assert abs(path[1, 0]) == pytest.approx(1.0)
    assert holding_torque(path[1, 0]) < 0.6 * holding_torque(0.0)


def test_no_swing_past_the_lowest_holding_torque_and_back_up():
    """From a goal 1.2 rad below the horizontal a 1 rad swing passes the vertical and climbs to
    a harder pose (2.2 rad); the 0.5 rad swing (1.7 rad) is the one taken."""
    robot = pendulum(tau_max=MASS * G0 * ARM * np.cos(1.2) / HOLD_SHARE)
    path = swing_path(robot, None, np.array([[-1.45], [1.2]]))
    assert path[1, 0] == pytest.approx(1.7)


def test_no_swing_where_the_loaded_joint_cannot_change_its_own_holding_torque():
    """A vertical prismatic joint carries the weight wherever it is."""
    robot = pendulum(joint=pin.JointModelPZ)
    assert abs(robot.gravity([0.0])[0]) == pytest.approx(MASS * G0)
    assert swing_path(robot, None, np.array([[-0.5], [0.5]])) is None


@pytest.mark.parametrize("transcription", ["forward", "inverse"])
def test_the_goal_held_at_the_torque_edge_is_reached_from_the_swing_guess(transcription):
    """From the straight line the solve fails; the candidate then solves from the swing guess,
    and the plan, re-integrated open loop with the hand-written dynamics, overshoots the goal,
    comes back and stops there within the torque limit."""
    # the goal is held at 99.9 % of the limit: plan at the full limits (no headroom)
    settings = OptimizerSettings(
        transcription=transcription, max_iterations=100, effort_margin=1.0, velocity_margin=1.0
    )
    problem = ShootingProblem(pendulum(), [Q_START], [Q_GOAL], settings=settings)
    straight = Candidate(problem, swing=False).solve()
    assert straight.status == "failed" and "iteration limit" in straight.reason

    result = Candidate(problem).solve()
    assert result.status == "optimal", result.reason
    assert "from a swing guess" in result.reason
    assert result.iterations > straight.iterations
    swung = problem.refined(result.substeps, result.waypoints)
    tf, _, controls = swung.unpack(result.y)
    intervals = swung.intervals
    # the result carries its own plan, sampled on the swing's problem: to tf, past the goal and back
    assert result.trajectory.t[-1] == pytest.approx(tf, rel=1e-12)
    # the rows chain from the start, so they end at the goal within the solver's continuity gaps
    assert result.trajectory.q[-1, 0] == pytest.approx(Q_GOAL, abs=1e-4)
    assert result.trajectory.q[:, 0].max() > Q_GOAL + 0.05
    inertia = MASS * ARM**2 + I_OWN
    if transcription == "forward":

        def torque(t, q, v):
            return controls[min(int(t / tf * intervals), intervals - 1), 0]
    else:  # u is the acceleration; the hand-written inverse dynamics give the torque

        def torque(t, q, v):
            qdd = controls[min(int(t / tf * intervals), intervals - 1), 0]
            return inertia * qdd - MASS * G0 * ARM * np.cos(q)

    def rhs(t, x):
        return [x[1], (torque(t, x[0], x[1]) + MASS * G0 * ARM * np.cos(x[0])) / inertia]

    grid = np.linspace(0.0, tf, intervals + 1)
    x, qs, taus = np.array([Q_START, 0.0]), [], []
    for a, b in itertools.pairwise(grid):
        piece = solve_ivp(rhs, (a, b), x, rtol=1e-10, atol=1e-10, dense_output=True)
        ts = np.linspace(a, b, 50, endpoint=False) + 1e-12
        qs.extend(piece.sol(ts)[0])
        taus.extend(torque(t, *piece.sol(t)) for t in ts)
        x = piece.y[:, -1]
    assert x[0] == pytest.approx(Q_GOAL, abs=1e-3) and abs(x[1]) < 1e-2
    assert max(qs) > Q_GOAL + 0.05
    assert max(abs(t) for t in taus) <= TAU_MAX * (1.0 + 1e-3)


def test_a_candidate_closed_during_its_swing_solve_records_the_swing_problem(tmp_path):
    """``y`` is scaled by the initial guess's ``tf``, so a result taken mid-swing must carry the
    swing's waypoints; a stopped result has no trajectory, and exporting one is refused."""
    problem = ShootingProblem(
        pendulum(),
        [Q_START],
        [Q_GOAL],
        settings=OptimizerSettings(max_iterations=100, effort_margin=1.0, velocity_margin=1.0),
    )
    candidate = Candidate(problem)
    swinging = 0
    for _ in candidate.iterate():
        swinging += len(candidate.problem.waypoints) == 3
        if swinging == 4:
            break
    candidate.close()
    result = candidate.result
    assert result.status == "stopped" and "from a swing guess" in result.reason
    assert result.waypoints.ravel() == pytest.approx([Q_START, Q_GOAL + 1.0, Q_GOAL])
    swung = problem.refined(result.substeps, result.waypoints)
    assert swung.unpack(result.y)[0] == pytest.approx(result.tf, rel=1e-12)
    assert problem.unpack(result.y)[0] != pytest.approx(result.tf, rel=1e-3)
    assert result.trajectory is None
    with pytest.raises(ValueError, match=r"^pendulum: a stopped result has no trajectory to write$"):
        write_winner_files(tmp_path, result)
