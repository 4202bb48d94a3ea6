"""Step C: the multiple-shooting problem, its solver and the candidate loop, checked against
physics that does not come from the package.

References used here:

* central finite differences of the package's own constraint and cost functions (the exact
  Jacobians and gradients must agree with them);
* closed-form time-optimal control of a 1-DOF rotor without gravity: bang-bang when only the
  torque limit binds, a trapezoidal velocity profile when the velocity limit binds too;
* the textbook closed-form dynamics of a planar two-link arm (no Pinocchio) and a closed-form
  capsule-sphere distance (no FCL), used to re-integrate solutions open loop from the start and
  measure their clearance on a dense grid;
* the UR5 of example-robot-data (a URDF the package did not generate) with a payload;
* the solver's documented generator semantics (iterate / close / iteration limit / failures).

Everything is seeded; no test is skipped.
"""

from __future__ import annotations

import csv
import json
import math
import threading
import time
import warnings
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from click.testing import CliRunner
from scipy.integrate import DOP853, solve_ivp

from modular_robots.cli import main
from modular_robots.composition import Composition
from modular_robots.exceptions import CompositionError
from modular_robots.feasibility import check_composition
from modular_robots.ocp import verification
from modular_robots.ocp._scipy import trust_constr
from modular_robots.ocp.candidate import Candidate, _crossing, composition_problem, make_candidate
from modular_robots.ocp.hessian import torque_hessians
from modular_robots.ocp.shooting import NonFiniteError, ShootingProblem
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.ocp.trajectory import sample_trajectory
from modular_robots.ocp.verification import Verification, verify
from modular_robots.pipeline import candidate_specs, optimize_composition
from modular_robots.robot import RobotModel
from modular_robots.scenario import OptimizerSettings, SphereObstacle, load_scenario

from .helpers.models import (
    ARM_GOAL,
    ARM_START,
    ARM_VEL,
    L_LINK,
    M_LINK,
    arm_clearance,
    arm_points,
    planar_arm,
    ur5,
)
from .helpers.paths import PAPER_5KG, ROOT
from .helpers.problems import without_floor

# A revolute + prismatic composition (J2 in the middle) and a revolute-only one, both feasible
# for the 5 kg paper task. The revolute-only one is chosen so that the forward transcription's
# RK4 propagation of the (perturbed) straight-line guess stays bounded: on several other
# revolute-only paper compositions it overflows (light distal joint, see the report).
MIXED = "B-J1-L3-J1-L2-J1-L3-J2-L2-E1"
REVOLUTE = "B-J1-L3-J1-L2-J1-L1-J1-L1-E1"
TRANSCRIPTIONS = ("forward", "inverse")


# --------------------------------------------------------------------------------------------
# models built by hand
# --------------------------------------------------------------------------------------------
def rotor(inertia: float, tau_max: float, v_max: float, arm: float = 0.5) -> RobotModel:
    """One revolute joint about z, rotational inertia ``inertia`` about the axis (mass on the
    axis), no gravity; ``tool0`` sits ``arm`` metres off the axis so the tool moves."""
    model = pin.Model()
    model.name = "rotor"
    joint = model.addJoint(
        0,
        pin.JointModelRZ(),
        pin.SE3.Identity(),
        "joint1",
        np.array([tau_max]),
        np.array([v_max]),
        np.array([-4.0]),
        np.array([4.0]),
    )
    model.appendBodyToJoint(joint, pin.Inertia(1.0, np.zeros(3), inertia * np.eye(3)), pin.SE3.Identity())
    model.addFrame(pin.Frame("tool0", joint, 0, pin.SE3(np.eye(3), np.array([arm, 0.0, 0.0])), pin.FrameType.OP_FRAME))
    model.gravity = pin.Motion.Zero()
    return RobotModel(model, "tool0", name="rotor")


def arm_mass_coriolis(q, v):
    """Textbook two-link dynamics (Spong): ``M(q)`` and the velocity product terms ``c(q, v)``."""
    lc, i_c = L_LINK / 2, M_LINK * L_LINK**2 / 12
    c2, s2 = math.cos(q[1]), math.sin(q[1])
    m11 = 2 * i_c + M_LINK * lc**2 + M_LINK * (L_LINK**2 + lc**2 + 2 * L_LINK * lc * c2)
    m12 = i_c + M_LINK * (lc**2 + L_LINK * lc * c2)
    m22 = i_c + M_LINK * lc**2
    h = M_LINK * L_LINK * lc * s2
    c = np.array([-h * (2 * v[0] * v[1] + v[1] ** 2), h * v[0] ** 2])
    return np.array([[m11, m12], [m12, m22]]), c


def replay_arm(problem: ShootingProblem, y: np.ndarray, points_per_interval: int = 200):
    """Apply the solution's torques to the closed-form arm dynamics open loop from the start
    state (never reset to the nodes) and return dense ``(q, v)`` samples and the final state.

    Forward transcription: the torque is the control, constant per interval. Inverse
    transcription: the torque is the closed-form inverse dynamics of the planned parabola."""
    tf, nodes, controls = problem.unpack(y)
    h = tf / problem.intervals
    x = problem.x_start.copy()
    qs, vs = [], []
    for node, u in zip(nodes[:-1], controls):

        def torque(s, node=node, u=u):
            if problem.transcription.controls_are_torques:
                return u
            q, v = node[:2] + node[2:] * s + 0.5 * u * s * s, node[2:] + u * s
            m, c = arm_mass_coriolis(q, v)
            return m @ u + c

        def rhs(s, state):
            m, c = arm_mass_coriolis(state[:2], state[2:])
            return np.concatenate([state[2:], np.linalg.solve(m, torque(s) - c)])

        grid = np.linspace(0.0, h, points_per_interval + 1)
        sol = solve_ivp(rhs, (0.0, h), x, method="DOP853", rtol=1e-11, atol=1e-11, t_eval=grid)
        assert sol.success
        qs.append(sol.y[:2].T)
        vs.append(sol.y[2:].T)
        x = sol.y[:, -1]
    return np.vstack(qs), np.vstack(vs), x


def improv_problem(transcription: str, nodes: int = 4, substeps: int = 3) -> ShootingProblem:
    """An IMPROV assembly (armature, viscous and smoothed Coulomb friction in the drives), without
    the floor: at its start its second housing is 1.8 cm below it."""
    scenario = without_floor(load_scenario(ROOT / "scenarios" / "improv-pick.yaml"))
    composition = Composition.from_name("base-PB21-L2-PB21-L4-L3", scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    assert verdict.passed, verdict.message
    settings = OptimizerSettings(nodes=nodes, substeps=substeps, transcription=transcription)
    return composition_problem(composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, settings)


# --------------------------------------------------------------------------------------------
# paper compositions
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def paper():
    """The 5 kg paper scenario and a cache of step B verdicts."""
    scenario = load_scenario(PAPER_5KG)
    verdicts = {}

    def problem(name, transcription, obstacles=True, cost="time", nodes=6, substeps=3):
        composition = Composition.from_name(name, scenario.catalog)
        if name not in verdicts:
            verdicts[name] = check_composition(composition, scenario.catalog, scenario.task)
            assert verdicts[name].passed, verdicts[name].message
        kept = {"obstacles": scenario.task.obstacles, "floor": scenario.task.floor} if obstacles else {}
        task = replace(scenario.task, cost=cost, **{"obstacles": (), "floor": None, **kept})
        settings = OptimizerSettings(nodes=nodes, substeps=substeps, transcription=transcription)
        verdict = verdicts[name]
        return composition_problem(composition, scenario.catalog, task, verdict.q_start, verdict.q_goal, settings)

    return problem


def perturbed_guess(problem: ShootingProblem, seed: int) -> np.ndarray:
    """The problem's initial guess moved by a seeded random step (scaled units). Torques are
    perturbed by 0.5 % of their limit only: larger torque noise on the paper arms' light distal
    joint makes the forward transcription's RK4 propagation blow up (finite differences of
    1e70-sized numbers check nothing)."""
    rng = np.random.default_rng(seed)
    step = 0.05 * rng.standard_normal(problem.n_variables)
    if problem.transcription.controls_are_torques:
        step[1 + (problem.intervals - 1) * problem.nx :] *= 0.1
    return problem.initial_guess() + step


def central_difference(f, y: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Central finite differences of the vector (or scalar) function ``f`` at ``y``: (m, n)."""
    columns = []
    for k in range(len(y)):
        e = np.zeros_like(y)
        e[k] = eps
        columns.append((np.atleast_1d(f(y + e)) - np.atleast_1d(f(y - e))) / (2 * eps))
    return np.column_stack(columns)


def row_relative_error(exact: np.ndarray, fd: np.ndarray) -> np.ndarray:
    """Per row: max |exact - fd| / max(1, max |fd|) (rows are scaled constraints, so an entry
    of 1 is a unit change of a scaled constraint per unit change of a scaled variable)."""
    return np.abs(exact - fd).max(axis=1) / np.maximum(1.0, np.abs(fd).max(axis=1))


# --------------------------------------------------------------------------------------------
# 1. exact derivatives
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("obstacles", [True, False], ids=["obstacles", "free"])
@pytest.mark.parametrize("transcription", TRANSCRIPTIONS)
@pytest.mark.parametrize("name", [MIXED, REVOLUTE])
def test_constraint_jacobian_matches_central_differences(paper, name, transcription, obstacles):
    problem = paper(name, transcription, obstacles)
    y = perturbed_guess(problem, seed=7)
    evaluation = problem.evaluate(y)
    assert np.all(np.isfinite(evaluation.constraints))
    assert np.abs(evaluation.propagation.states).max() < 1e5, "perturbed point left the bounded regime"
    if obstacles:
        # FCL's penetration depth is approximate and its gradient undefined inside: check the
        # derivatives where every sub-step point is clear.
        assert problem.collision is not None and evaluation.clearance.size
        assert evaluation.clearance.min() > 1e-3, evaluation.clearance.min()
    jac = evaluation.jacobian.toarray()
    fd = central_difference(problem.constraints, y)
    err = row_relative_error(jac, fd)
    worst = int(np.argmax(err))
    assert err.max() < 1e-5, (worst, err.max(), np.abs(jac[worst] - fd[worst]).max())
    # The check is not vacuous: the clearance rows and the tf column carry information.
    # clearance rows: the only ones bounded below only (a clearance >= 0 or a margin)
    clearance_rows = np.flatnonzero(np.isfinite(problem.constraint_lower) & np.isinf(problem.constraint_upper))
    # (and the checked pairs of the arm's own primitives that can come within the margin)
    self_rows = len(problem.self_collision_rows) * (problem.intervals * problem.substeps - 1)
    if obstacles:
        n_rows = len(problem.obstacles) * (problem.intervals * problem.substeps - 1) + self_rows
        assert len(clearance_rows) == n_rows
        # (an obstacle whose closest primitive sits on the first joint's axis has a constant
        # distance; the other one moves with the arm)
        assert np.count_nonzero(np.abs(fd[clearance_rows]).max(axis=1) > 1e-3) >= problem.intervals
    else:
        assert len(clearance_rows) == self_rows
    assert np.abs(fd[:, 0]).max() > 1e-2  # tf moves the motion


@pytest.mark.parametrize("name", [MIXED, REVOLUTE])
def test_exact_hessian_matches_differences_of_the_exact_jacobian(paper, name):
    """The Hessian given to trust-constr for every row but the clearance ones equals the central
    differences of ``J(y)^T lambda`` built from the exact Jacobian, for random multipliers."""
    problem = paper(name, "inverse", obstacles=True)
    y = perturbed_guess(problem, seed=5)
    rows = problem.rows_of("continuity", "path", "midpoint", "torque")
    clearance = problem.rows_of("clearance")
    assert len(rows) + len(clearance) == problem.n_constraints and len(clearance)
    multipliers = np.random.default_rng(3).standard_normal(len(rows))
    hessian = problem.exact_hessian(y, multipliers, rows).toarray()
    fd = central_difference(lambda z: problem.evaluate(z).jacobian[rows].T @ multipliers, y)
    scale = np.abs(fd).max()
    assert scale > 1.0  # the rows curve: torques in q, positions in (v, u, tf)
    assert np.abs(hessian - fd).max() < 1e-6 * scale, np.abs(hessian - fd).max() / scale
    assert np.abs(hessian - hessian.T).max() < 1e-12 * scale
    # The torque rows alone carry RNEA's curvature in the node configurations (not only in tf).
    torques = problem.rows_of("torque")
    curvature = problem.exact_hessian(y, np.ones(len(torques)), torques).toarray()
    assert np.abs(curvature[1 : 1 + problem.nv, 1 : 1 + problem.nv]).max() > 1e-3
    with pytest.raises(ValueError, match="the clearance rows have no exact Hessian"):
        problem.exact_hessian(y, np.ones(len(clearance)), clearance)


def test_torque_hessians_equal_the_chain_rule_through_the_whole_substep_jacobians():
    """The pull-back of RNEA's curvature, written with the sub-step Jacobians' scaled-identity
    blocks, equals the plain ``J^T A J`` with the Jacobians ``d(q_j, v_j) / d(q0, v0, u, tf)``
    built in full from the interval polynomials (``q_j = q0 + v0 s + u s^2 / 2``, ``s = tf f_j``)."""
    rng = np.random.default_rng(4)
    N, J, nv = 3, 4, 5
    fractions, tf, u = np.arange(J) / (2.0 * J), rng.uniform(1.0, 3.0, N), rng.normal(size=(N, nv))
    velocities = rng.normal(size=(N, J, nv))
    curvature = tuple(rng.normal(size=(N * J, nv, nv)) for _ in range(4))
    qq, vv, qv, qa = (c.reshape(N, J, nv, nv) for c in curvature)
    expected = np.zeros((N, 3 * nv + 1, 3 * nv + 1))
    eye = np.eye(nv)
    for m in range(N):
        for j, f in enumerate(fractions):
            s = tf[m] * f
            jq = np.hstack([eye, s * eye, 0.5 * s**2 * eye, (velocities[m, j] * f)[:, None]])
            jv = np.hstack([0 * eye, eye, s * eye, (u[m] * f)[:, None]])
            ja = np.hstack([0 * eye, 0 * eye, eye, np.zeros((nv, 1))])  # RNEA's acceleration is u
            cross = jq.T @ qv[m, j] @ jv + jq.T @ qa[m, j] @ ja
            expected[m] += jq.T @ qq[m, j] @ jq + jv.T @ vv[m, j] @ jv + cross + cross.T
    got = torque_hessians(fractions, tf, u, velocities, curvature)
    assert np.abs(got - expected).max() <= 1e-12 * np.abs(expected).max()


def test_exact_hessian_includes_the_drives_friction():
    """On an IMPROV assembly (armature, viscous and smoothed Coulomb friction in the motor torque)
    the exact Hessian still equals differences of the exact Jacobian, and the friction's
    curvature matters: without it the velocity block would differ."""
    problem = improv_problem("inverse", substeps=2)
    assert problem.robot.has_friction
    y = perturbed_guess(problem, seed=9)
    rows = problem.rows_of("continuity", "path", "midpoint", "torque")
    multipliers = np.random.default_rng(6).standard_normal(len(rows))
    hessian = problem.exact_hessian(y, multipliers, rows).toarray()
    fd = central_difference(lambda z: problem.evaluate(z).jacobian[rows].T @ multipliers, y, eps=1e-7)
    scale = np.abs(fd).max()
    assert np.abs(hessian - fd).max() < 1e-5 * scale, np.abs(hessian - fd).max() / scale
    v = problem.unpack(y)[1][1:-1, problem.nv :]
    assert np.abs(problem.robot.friction_second_derivative(v)).max() > 1.0  # within the tanh's bend


@pytest.mark.parametrize("transcription", TRANSCRIPTIONS)
def test_effort_cost_gradient_matches_central_differences(paper, transcription):
    problem = paper(MIXED, transcription, obstacles=True, cost="effort")
    y = perturbed_guess(problem, seed=11)
    gradient = problem.cost_gradient(y)
    fd = central_difference(problem.cost, y)[0]
    assert np.abs(fd).max() > 1e-3
    scale = max(1e-2, np.abs(fd).max())
    # node states and controls
    err = np.abs(gradient[1:] - fd[1:]).max() / scale
    assert err < 1e-5, (err, 1 + int(np.argmax(np.abs(gradient[1:] - fd[1:]))))
    # the final time: the cost is tf times the mean squared torque ratio
    assert gradient[0] == pytest.approx(fd[0], rel=1e-5, abs=1e-5 * scale), (
        f"d cost / d tf: exact {gradient[0]:.6g}, finite differences {fd[0]:.6g}"
    )
    # the effort gradient depends on the controls (and, for inverse, on the states)
    u0 = 1 + (problem.intervals - 1) * problem.nx
    assert np.abs(gradient[u0:]).max() > 1e-3
    if transcription == "inverse":
        assert np.abs(gradient[1:u0]).max() > 1e-3


def test_clearance_gradient_matches_finite_differences_on_the_arm():
    """The distance gradient the Jacobian is built from, against a closed-form distance."""
    robot = planar_arm()
    obstacle = SphereObstacle((1.3, 0.9, 0.0), 0.2)
    problem = ShootingProblem(
        robot,
        [-1.0, 0.5],
        [1.0, -0.5],
        [obstacle],
        settings=OptimizerSettings(nodes=4, substeps=2, transcription="inverse"),
    )
    rng = np.random.default_rng(3)
    checked = 0
    for q in rng.uniform(-2.5, 2.5, (10, 2)):
        if arm_clearance(q, obstacle) < 0.02:
            continue  # clear configurations only (FCL's penetration depth is approximate)
        dist, grad = problem.collision.closest(q, derivatives=True)
        assert dist[0] == pytest.approx(arm_clearance(q, obstacle), abs=1e-6)
        fd = [(arm_clearance(q + e, obstacle) - arm_clearance(q - e, obstacle)) / 2e-6 for e in 1e-6 * np.eye(2)]
        np.testing.assert_allclose(grad[0], fd, atol=1e-6)
        checked += 1
    assert checked >= 5


# --------------------------------------------------------------------------------------------
# 2. analytic time-optimal control of a rotor
# --------------------------------------------------------------------------------------------
I_ROTOR, TAU_ROTOR = 0.5, 2.0  # kg m^2, N m -> acceleration limit 4 rad/s^2
DQ_BANG = 1.5  # rad
T_BANG = 2.0 * math.sqrt(DQ_BANG * I_ROTOR / TAU_ROTOR)  # 1.2247 s, peak speed 2.45 rad/s
# With 7 equal intervals and a piecewise-constant torque the switch at tf/2 falls inside the
# middle interval. The best such profile is +tau for 3 intervals, 0 for the middle one, -tau for
# 3 (maximising the distance sum_k u_k (N - k - 1/2) h^2 subject to sum_k u_k = 0 is a linear
# programme): it covers 12 h^2 a = 12/49 tf^2 a instead of the continuous tf^2 a / 4, so its
# tf is sqrt(49/48) = 1.0104 times the continuous optimum. An even number of intervals puts the
# switch on a node and the continuous optimum is representable exactly.
T_BANG_7 = T_BANG * math.sqrt(49.0 / 48.0)
V_TRAP, DQ_TRAP = 1.0, 1.75  # rad/s, rad: accelerate 0.25 s, cruise 1.5 s, brake 0.25 s
T_TRAP = DQ_TRAP / V_TRAP + V_TRAP * I_ROTOR / TAU_ROTOR  # 2.0 s; switches at 0.25 s and 1.75 s

ROTOR_CASES = {
    # name: (velocity limit, distance, nodes, expected tf)
    "bang-bang": (10.0, DQ_BANG, 9, T_BANG),
    "bang-bang-7-intervals": (10.0, DQ_BANG, 8, T_BANG_7),
    "trapezoid": (V_TRAP, DQ_TRAP, 9, T_TRAP),
}


#: Plan at the full limits (no headroom), as the analytic optima assume.
FULL_LIMITS = {"effort_margin": 1.0, "velocity_margin": 1.0}


@pytest.mark.parametrize("transcription", ["inverse", "forward"])
@pytest.mark.parametrize(("effort_margin", "velocity_margin"), [(0.9, 0.95), (0.6, 0.8)])
def test_the_margins_give_the_optimum_of_the_reduced_limits(transcription, effort_margin, velocity_margin):
    """The trapezoid optimum within margins is the analytic one of a rotor whose limits are the
    margins times its own, ``dq / v + v I / tau``; the plan keeps those bounds, and verification
    (at the full limits) passes it with the headroom left."""
    settings = OptimizerSettings(
        nodes=9, substeps=2, transcription=transcription, effort_margin=effort_margin, velocity_margin=velocity_margin
    )
    problem = ShootingProblem(rotor(I_ROTOR, TAU_ROTOR, V_TRAP), [-0.5], [-0.5 + DQ_TRAP], settings=settings)
    outcome = ShootingSolver(problem).solve()
    assert outcome.status == "optimal", outcome.reason
    v, tau = velocity_margin * V_TRAP, effort_margin * TAU_ROTOR
    assert outcome.final.tf == pytest.approx(DQ_TRAP / v + v * I_ROTOR / tau, rel=0.01)
    trajectory = sample_trajectory(problem, outcome.final.y)
    assert np.abs(trajectory.qd).max() <= v * (1.0 + 1e-4)
    assert np.abs(trajectory.tau).max() == pytest.approx(tau, rel=0.02)
    check = verify(problem, outcome.final.y)
    assert check.passed and check.torque_ratio <= effort_margin * (1.0 + 1e-3)


@pytest.mark.parametrize("case", list(ROTOR_CASES))
def test_structured_hessian_reaches_the_analytic_minimum_time(case):
    """trust-constr with the exact Hessian of the torque and position rows ends at the same
    analytic optimum as with SR1 (gravity-free rotor, inverse transcription)."""
    v_max, dq, nodes, expected = ROTOR_CASES[case]
    settings = OptimizerSettings(nodes=nodes, substeps=2, transcription="inverse", **FULL_LIMITS)
    problem = ShootingProblem(rotor(I_ROTOR, TAU_ROTOR, v_max), [-0.5], [-0.5 + dq], settings=settings)
    outcome = ShootingSolver(problem, hessian="structured").solve()
    assert outcome.status == "optimal", outcome.reason
    assert outcome.final.tf == pytest.approx(expected, rel=0.01)
    assert verify(problem, outcome.final.y).passed
    with pytest.raises(ValueError, match=r"hessian must be one of \['sr1', 'structured'\], got 'bfgs'"):
        ShootingSolver(problem, hessian="bfgs")


@pytest.mark.parametrize("transcription", TRANSCRIPTIONS)
@pytest.mark.parametrize("case", list(ROTOR_CASES))
def test_rotor_reaches_the_analytic_minimum_time(case, transcription):
    v_max, dq, nodes, expected = ROTOR_CASES[case]
    robot = rotor(I_ROTOR, TAU_ROTOR, v_max)
    problem = ShootingProblem(
        robot,
        [-0.5],
        [-0.5 + dq],
        settings=OptimizerSettings(nodes=nodes, substeps=2, transcription=transcription, **FULL_LIMITS),
    )
    outcome = ShootingSolver(problem).solve()
    assert outcome.status == "optimal", outcome.reason
    tf = outcome.final.tf
    assert tf == pytest.approx(expected, rel=0.01)
    # nothing within the limits is faster than the analytic optimum, nor than the problem's
    # velocity bound (the whole stroke at the velocity limit)
    assert tf >= expected * (1.0 - 1e-4)
    assert problem.cost_bound == pytest.approx(dq / v_max, rel=1e-12)
    assert tf >= problem.cost_bound
    if case == "bang-bang-7-intervals":
        assert tf > 1.005 * T_BANG  # the piecewise-constant penalty is real
    check = verify(problem, outcome.final.y)
    assert check.passed, check
    # constant acceleration per interval: speed is linear between grid points, so the limits
    # hold to the solver's tolerance, far tighter than the package's 0.1 % allowance
    assert check.velocity_ratio <= 1.0 + 1e-5 and check.torque_ratio <= 1.0 + 1e-5
    assert check.terminal_error <= 1e-4  # 0.2 mrad at the 0.5 m arm
    trajectory = sample_trajectory(problem, outcome.final.y)
    assert np.abs(trajectory.qd).max() <= v_max * (1.0 + 1e-5)
    accelerating = trajectory.t < 0.5 * tf - 1e-9
    braking = trajectory.t > 0.5 * tf + 1e-9
    braking[-1] = False  # from tf on the rotor rests (the row at tf holds qdd = 0)
    if case == "bang-bang":
        # bang-bang: full torque forward, then full torque back; peak speed at tf / 2
        assert np.all(trajectory.tau[accelerating] > 0.97 * TAU_ROTOR)
        assert np.all(trajectory.tau[braking] < -0.97 * TAU_ROTOR)
        assert np.abs(trajectory.qd).max() == pytest.approx(TAU_ROTOR / I_ROTOR * expected / 2, rel=0.02)
    elif case == "trapezoid":
        # trapezoid: cruise at the velocity limit between the switch times
        t_switch = V_TRAP * I_ROTOR / TAU_ROTOR
        cruise = (trajectory.t > t_switch + 0.02 * tf) & (trajectory.t < tf - t_switch - 0.02 * tf)
        assert np.all(trajectory.qd[cruise, 0] > 0.98 * V_TRAP)
        assert np.all(np.abs(trajectory.tau[cruise, 0]) < 0.05 * TAU_ROTOR)


@pytest.mark.parametrize(
    ("v_max", "cost", "expected"), [(2.0, "time", 0.75), (np.inf, "time", 0.0), (2.0, "effort", 0.0)]
)
def test_cost_bound_counts_only_velocity_limited_joints_of_the_time_cost(v_max, cost, expected):
    """1.5 rad at 2 rad/s takes at least 0.75 s, at 0.95 of it (the default margin: the plan's own
    bound) 0.75 / 0.95 s; a joint without a velocity limit bounds nothing, and neither does the
    effort cost."""
    settings = OptimizerSettings(nodes=3, substeps=1)
    problem = ShootingProblem(rotor(I_ROTOR, TAU_ROTOR, v_max), [-0.5], [1.0], cost=cost, settings=settings)
    assert problem.cost_bound == pytest.approx(expected / settings.velocity_margin, rel=1e-15)


# --------------------------------------------------------------------------------------------
# 3. an obstacle across the straight line
# --------------------------------------------------------------------------------------------
# The straight-line motion sweeps the stretched arm through the sphere; the time-optimal motion
# folds the elbow to cut the inertia about joint 1 and passes inside it.
ARM_OBSTACLE = SphereObstacle((1.9, 0.0, 0.0), 0.2)


@pytest.mark.parametrize(
    ("transcription", "guess"), [("inverse", "straight"), ("forward", "straight"), ("inverse", "default")]
)
def test_obstacle_on_the_straight_line_is_avoided(transcription, guess):
    """``straight`` forces the straight-line guess through the sphere (``waypoints``);
    ``default`` lets the problem pick its own guess (a clear detour when the line collides)."""
    robot = planar_arm()
    # the straight line between the boundary configurations sweeps the arm through the sphere
    line = np.array([ARM_START, ARM_GOAL])
    samples = [line[0] + s * (line[1] - line[0]) for s in np.linspace(0, 1, 201)]
    assert min(arm_clearance(q, ARM_OBSTACLE) for q in samples) < -0.2
    problem = ShootingProblem(
        robot,
        ARM_START,
        ARM_GOAL,
        [ARM_OBSTACLE],
        "time",
        OptimizerSettings(nodes=8, substeps=4, transcription=transcription),
        waypoints=line if guess == "straight" else None,
    )
    assert min(problem.collision.min_distance(q) for q in samples) < -0.2
    if guess == "straight" and transcription == "inverse":
        # the inverse guess moves along the line (parabolas between nodes on it). The forward
        # guess's torques are clipped to the limits, so its propagated motion lags far behind
        # the line and only its (discontinuous) nodes lie on it.
        assert verify(problem, problem.initial_guess()).min_clearance < -0.2

    result = Candidate(problem).solve()
    assert result.status == "optimal", result.reason
    check = result.verification
    assert check.passed, check
    assert check.min_clearance >= 0.0
    # Open-loop replay with the closed-form dynamics and distance (no Pinocchio, no FCL).
    q, v, final = replay_arm(problem.refined(result.substeps, result.waypoints), result.y)
    assert min(arm_clearance(qk, ARM_OBSTACLE) for qk in q) >= 0.0
    assert np.linalg.norm(arm_points(final[:2])[2] - arm_points(ARM_GOAL)[2]) <= 0.01
    assert np.all(np.abs(v) <= ARM_VEL * (1.0 + 2e-3))


# --------------------------------------------------------------------------------------------
# 4. a robot the package did not build
# --------------------------------------------------------------------------------------------
def test_ur5_with_payload_solves_and_verifies():
    robot = ur5(payload=2.0)
    q_start = np.array([0.0, -1.57, 1.57, -1.57, -1.57, 0.0])
    q_goal = np.array([1.2, -1.0, 1.0, -1.5, -1.2, 0.5])
    problem = ShootingProblem(
        robot, q_start, q_goal, settings=OptimizerSettings(nodes=6, substeps=4, transcription="inverse")
    )
    # the payload is in the model: holding still at the start takes more torque with it
    assert np.abs(robot.gravity(q_start)).max() > np.abs(ur5(0.0).gravity(q_start)).max() + 1.0
    result = Candidate(problem).solve()
    assert result.status == "optimal", result.reason
    check = result.verification
    assert check.passed, check
    assert check.terminal_error <= 0.01
    assert check.position_excess <= 1e-6
    assert check.velocity_ratio <= 1.0 + 1e-3 and check.torque_ratio <= 1.0 + 1e-3
    # no motion within the velocity limits is faster than the slowest joint at full speed
    margin = problem.settings.velocity_margin
    assert result.cost_bound == pytest.approx(np.max(np.abs(q_goal - q_start) / (margin * robot.velocity_limit)))
    assert result.tf >= result.cost_bound


def test_midpoint_position_rows_are_the_parabola_midpoints(paper):
    """Second formulation: the rows that bound the positions inside each sub-step hold
    ``q_j + v_j h / 2 + a h^2 / 8`` of the inverse transcription's exact parabola."""
    problem = paper(MIXED, "inverse", substeps=4)
    y = perturbed_guess(problem, seed=3)
    tf, nodes, acc = problem.unpack(y)
    N, S, nv = problem.intervals, problem.substeps, problem.nv
    h = tf / (N * S)
    expected = np.empty((N, S, nv))
    for m in range(N):
        for j in range(S):
            t = (j + 0.5) * h
            expected[m, j] = nodes[m, :nv] + nodes[m, nv:] * t + 0.5 * acc[m] * t * t
    full = np.full(len(problem.row_scale), np.nan)
    full[problem._keep_row] = problem.constraints(y)
    rows = problem._rows["midpoint"]
    got = (full[rows.ravel()] * problem.row_scale[rows.ravel()]).reshape(N, S, nv)
    assert np.allclose(got, expected, rtol=0, atol=1e-12)
    # bounded like positions, and the prismatic joint's midpoints do move
    keep = np.cumsum(problem._keep_row) - 1
    lower = problem.constraint_lower[keep[rows]] * problem.row_scale[rows]
    assert np.allclose(lower, np.broadcast_to(problem.robot.lower, lower.shape))
    assert np.ptp(got[..., problem.robot.upper - problem.robot.lower < 1.0]) > 1e-3


def test_verification_defect_catches_a_broken_plan():
    """Against the optimum of the two-link arm, one control changed by 2 % after the solve: the
    re-integrated interval no longer ends on the plan's next node (for the inverse transcription
    each sub-step follows its parabola exactly, so the defect is the continuity gap; the forward
    transcription's RK4 error is caught in the refinement test below)."""
    robot = planar_arm()
    problem = ShootingProblem(
        robot, ARM_START, ARM_GOAL, settings=OptimizerSettings(nodes=6, substeps=4, transcription="inverse")
    )
    outcome = ShootingSolver(problem).solve()
    assert outcome.status == "optimal", outcome.reason
    good = verify(problem, outcome.final.y)
    assert good.max_defect < 1e-6 and good.terminal_ok, good  # (its torque may peak between sub-steps)
    y = outcome.final.y.copy()
    y[problem._u0 + 2 * problem.nv] *= 1.02  # interval 2, joint 1 acceleration
    bad = verify(problem, y)
    assert not bad.defect_ok and bad.max_defect > 10 * good.max_defect, bad


def substep_by_substep(problem: ShootingProblem, y: np.ndarray, points: int = 8):
    """A plain reference for :func:`verify`: each sub-step re-integrated on its own by SciPy's
    ``solve_ivp`` (DOP853, the same tolerances) from its planned state, the plan's torque law
    written out here, every grid point's clearance from FCL one configuration at a time (or its
    self-collision depth where the arm overlaps itself), and the last interval re-integrated whole.
    Returns the defect, the grid's ``(q, v, tau)`` and clearances, and the state at ``tf``."""
    robot, nv = problem.robot, problem.nv
    tf, nodes, controls = problem.unpack(y)
    N, S = problem.intervals, problem.substeps
    hs = tf / (N * S)
    inverse = problem.transcription.name == "inverse"

    def torque(m, s):
        node, u = nodes[m], controls[m]
        if not inverse:
            return u
        return robot.rnea(node[:nv] + node[nv:] * s + 0.5 * u * s * s, node[nv:] + u * s, u)

    def rhs(m):
        return lambda s, x: np.concatenate([x[nv:], robot.aba(x[:nv], x[nv:], torque(m, s))])

    planned = problem.transcription.propagate(robot, nodes[:-1], controls, tf, N, S, False).states
    defect, rows = 0.0, []
    for m in range(N):
        gap = 0.0
        for j in range(S):
            span = (j * hs, (j + 1) * hs)
            sol = solve_ivp(rhs(m), span, planned[m, j], method="DOP853", rtol=1e-10, atol=1e-10, dense_output=True)
            target = planned[m, j + 1] if j < S - 1 else nodes[m + 1]
            gap = gap + np.abs(sol.y[:, -1] - target) / problem.x_scale
            grid = np.linspace(j * hs, (j + 1) * hs, points + 1)[: -1 if j < S - 1 else None]
            rows += [(x, torque(m, s)) for x, s in zip(sol.sol(grid).T, grid)]
        defect = max(defect, gap.max())
    q = np.array([x[:nv] for x, _ in rows])
    v = np.array([x[nv:] for x, _ in rows])
    tau = np.array([t for _, t in rows])
    clearance = np.array([problem.collision.min_distance(qk) for qk in q]) if problem.collision else np.array([np.inf])
    if problem.self_collision is not None:
        own = np.array([problem.self_collision.min_distance(qk) for qk in q])
        if own.min() < 0.0:
            clearance = np.append(clearance, own.min())
    last = solve_ivp(rhs(N - 1), (0.0, S * hs), nodes[N - 1], method="DOP853", rtol=1e-10, atol=1e-10)
    return defect, q, v, tau, clearance, last.y[:, -1]


VERIFY_CASES = [
    (MIXED, "inverse", True, 3),
    (REVOLUTE, "forward", True, 3),
    (MIXED, "inverse", False, 1),
    ("IMPROV", "inverse", True, 3),
    ("IMPROV", "forward", True, 3),
]


@pytest.mark.parametrize(("name", "transcription", "obstacles", "substeps"), VERIFY_CASES)
def test_verification_integrates_all_substeps_as_each_on_its_own(paper, name, transcription, obstacles, substeps):
    """:func:`verify` integrates every sub-step at once (one adaptive step sequence, each
    sub-step's own error test); its figures equal those of a plain one-integration-per-sub-step
    reference. Off the optimum (a perturbed guess) the defects and clearances are far from zero,
    so agreement is not agreement at zero; the IMPROV assembly adds friction to both torque laws;
    one case has no obstacles and one sub-step per interval."""
    if name == "IMPROV":
        problem = improv_problem(transcription)
        assert problem.robot.has_friction
    else:
        problem = paper(name, transcription, obstacles=obstacles, substeps=substeps)
    y = perturbed_guess(problem, seed=4)
    got = verify(problem, y)
    defect, q, v, tau, clearance, final = substep_by_substep(problem, y, verification.grid_density(problem))
    robot = problem.robot
    assert defect > 1e-3 and got.max_defect == pytest.approx(defect, rel=1e-6)
    assert got.grid_points == len(q) >= verification.MIN_GRID_POINTS  # (8 a sub-step made 57 with one)
    assert got.min_clearance == pytest.approx(clearance.min(), abs=1e-9)
    span = robot.upper - robot.lower
    excess = max(0.0, float(np.max(np.maximum(robot.lower - q, q - robot.upper) / span)))
    assert got.position_excess == pytest.approx(excess, abs=1e-9)
    np.testing.assert_allclose(got.velocity_share, np.abs(v).max(axis=0) / robot.velocity_limit, rtol=1e-8)
    ends = y_nodes_at_rest(problem, y)  # the payload held still at the start and the goal
    holding = robot.rnea(ends, np.zeros_like(ends), np.zeros_like(ends))
    tau = np.vstack([tau, holding])
    np.testing.assert_allclose(got.effort_share, np.abs(tau).max(axis=0) / robot.effort_limit, rtol=1e-8)
    error = np.linalg.norm(robot.tool_position(final[: problem.nv]) - robot.tool_position(problem.q_goal))
    assert got.terminal_error == pytest.approx(error, rel=1e-6, abs=1e-9)
    assert got.terminal_speed == pytest.approx(np.abs(final[problem.nv :]).max(), rel=1e-6, abs=1e-9)


def y_nodes_at_rest(problem, y) -> np.ndarray:
    """The plan's first and last configurations ``(2, nv)``."""
    nodes = problem.unpack(y)[1]
    return nodes[[0, -1], : problem.nv]


def test_verification_one_substep_at_a_time_gives_the_same_figures(paper, monkeypatch):
    """The fallback for plans whose joint integration takes too many steps (each sub-step on its
    own) measures the same plan as the joint integration does."""
    problem = paper(MIXED, "inverse")
    y = perturbed_guess(problem, seed=4)
    joint = verify(problem, y)
    monkeypatch.setattr(verification, "JOINT_STEPS", 0)
    alone = verify(problem, y)
    for field in ("max_defect", "min_clearance", "terminal_error", "velocity_ratio", "torque_ratio"):
        assert getattr(alone, field) == pytest.approx(getattr(joint, field), rel=1e-7), field


def test_stacked_error_norm_is_the_worst_of_each_systems_own():
    """The joint integration's error norm is the largest of the DOP853 norms each sub-step would
    have alone (SciPy's own formula, applied block by block), so no sub-step's error hides in the
    others' (a norm over the whole stack would let one block's error grow with the others')."""
    rng = np.random.default_rng(3)
    blocks, n = 5, 4
    y0 = rng.standard_normal(blocks * n)
    stacked = verification._StackedDOP853(lambda t, x: -x, 1.0, y0, 2.0, blocks, rtol=1e-10, atol=1e-10)
    K = rng.standard_normal(stacked.K.shape)
    K[:, :n] *= 1e3  # one block much worse than the rest
    scale = 1e-10 + 1e-10 * np.abs(y0)
    got = stacked._estimate_error_norm(K, 0.01, scale)
    alone = [
        DOP853(lambda t, x: -x, 1.0, y0[b * n : (b + 1) * n], 2.0)._estimate_error_norm(
            K[:, b * n : (b + 1) * n], 0.01, scale[b * n : (b + 1) * n]
        )
        for b in range(blocks)
    ]
    assert got == pytest.approx(max(alone), rel=1e-12)
    whole = DOP853(lambda t, x: -x, 1.0, y0, 2.0)._estimate_error_norm(K, 0.01, scale)
    assert whole < 0.5 * got


@pytest.mark.parametrize("factor", [1e2, 1e4])
def test_verification_fails_a_plan_that_blows_up_without_raising(paper, factor):
    """Controls scaled far beyond any limit make the re-integration diverge (x 1e2) or the planned
    states overflow already (x 1e4): verification fails the plan at once, it neither raises nor
    follows the divergence down to steps of 1e-300 s."""
    problem = paper(MIXED, "forward")
    y = problem.initial_guess()
    y[-problem.nv :] *= factor
    with np.errstate(all="ignore"):
        check = verify(problem, y)
    assert not check.passed and check.grid_points == 0


# --------------------------------------------------------------------------------------------
# 5. the solver's generator semantics
# --------------------------------------------------------------------------------------------
def small_problem() -> ShootingProblem:
    return ShootingProblem(
        rotor(I_ROTOR, TAU_ROTOR, V_TRAP),
        [-0.5],
        [-0.5 + DQ_TRAP],
        settings=OptimizerSettings(nodes=9, substeps=2, transcription="forward"),
    )


def test_interleaved_solves_leave_the_warning_filters_as_they_were():
    """Two solvers advanced in turn (as the lockstep does) leave the process's warning filters as
    they were: a filter held for a whole solve was restored out of order, leaving an 'ignore
    everything' behind that silenced the caller's own warnings."""
    before = list(warnings.filters)
    first, second = ShootingSolver(small_problem(), max_iterations=5), ShootingSolver(small_problem(), max_iterations=5)
    a, b = first.iterate(), second.iterate()
    next(a)
    next(b)
    for _ in a:
        pass
    for _ in b:
        pass
    assert warnings.filters == before


def test_iterate_yields_increasing_iterations_then_sets_the_outcome():
    problem = small_problem()
    solver = ShootingSolver(problem)
    iterates = list(solver.iterate())
    assert len(iterates) >= 4
    numbers = [it.iteration for it in iterates]
    assert numbers == sorted(set(numbers)) and numbers[0] >= 1
    for it in iterates:
        assert it.tf == pytest.approx(problem.unpack(it.y)[0], rel=1e-12)
        assert it.cost == pytest.approx(it.tf, rel=1e-9)  # time cost, in seconds
    assert solver.outcome.status == "optimal"
    assert solver.outcome.iterations == numbers[-1]
    assert not solver._thread.is_alive()
    with pytest.raises(RuntimeError):
        next(solver.iterate())


def test_close_after_three_iterations_stops_the_solver():
    solver = ShootingSolver(small_problem())
    iterator = solver.iterate()
    seen = [next(iterator).iteration for _ in range(3)]
    assert seen == sorted(set(seen))
    solver.close()
    assert solver.outcome.status == "stopped"
    assert solver.outcome.iterations == seen[-1]
    assert not solver._thread.is_alive()
    iterator.close()


def test_close_before_starting():
    solver = ShootingSolver(small_problem())
    solver.close()
    assert solver.outcome.status == "stopped"
    assert solver._thread is None


class _SlowToExit(ShootingSolver):
    """The solver thread posts its outcome, then takes a while to end (as a thread may when the
    interpreter switches to the caller right after the post)."""

    def _finish(self, *args, **kwargs):
        super()._finish(*args, **kwargs)
        time.sleep(0.3)


class _DiesSilently(ShootingSolver):
    def _finish(self, *args, **kwargs):
        raise SystemExit  # ends the thread without an outcome and without a traceback


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
@pytest.mark.parametrize("solver_class", [_SlowToExit, _DiesSilently])
def test_iterate_returns_however_the_solver_thread_ends(solver_class):
    """A solve whose thread is still alive after posting its outcome (a hang seen in a
    95-candidate run), or that ends without one, returns instead of waiting for a message."""
    solver = solver_class(small_problem())
    done = threading.Thread(target=lambda: list(solver.iterate()), daemon=True)
    done.start()
    done.join(timeout=20.0)
    assert not done.is_alive(), "iterate() hangs"
    expected = "optimal" if solver_class is _SlowToExit else "failed"
    assert solver.outcome.status == expected
    assert not solver._thread.is_alive()


def test_solve_runs_in_the_calling_thread_with_the_iterates_of_iterate():
    """solve() has no thread to hand iterates over, and the same iterates as iterate(), bit for
    bit; the caller's thread is a solver's only while it solves, also when the solve fails."""
    problem = small_problem()
    threaded = ShootingSolver(problem)
    iterates = list(threaded.iterate())
    direct = ShootingSolver(problem)
    outcome = direct.solve()
    assert direct._thread is None and not trust_constr.in_solver_thread()
    assert (outcome.status, outcome.iterations) == (threaded.outcome.status, threaded.outcome.iterations)
    assert outcome.final.y.tobytes() == iterates[-1].y.tobytes() == threaded.outcome.final.y.tobytes()
    assert outcome.final == direct.last and outcome.seconds > 0.0
    assert direct.solve() is outcome and list(direct.iterate()) == []  # it ran once

    class Breaks(ShootingSolver):
        def _minimize(self):
            assert trust_constr.in_solver_thread()
            raise FloatingPointError("a model that cannot be evaluated")

    failed = Breaks(problem).solve()
    assert (failed.status, failed.reason) == ("failed", "FloatingPointError: a model that cannot be evaluated")
    assert not trust_constr.in_solver_thread()


class _Interrupted(ShootingSolver):
    """Ctrl-C in the fourth iteration's evaluation."""

    def _minimize(self):
        evaluate = self.problem.evaluate

        def interrupted(y, derivatives=True):
            if self.last is not None and self.last.iteration == 3:
                raise KeyboardInterrupt
            return evaluate(y, derivatives)

        self.problem.evaluate = interrupted
        try:
            return super()._minimize()
        finally:
            self.problem.evaluate = evaluate


class _FinishFails(ShootingSolver):
    def _finish(self, *args, **kwargs):
        raise ValueError("bookkeeping after trust-constr (test)")


class _ClosesItself(ShootingSolver):
    def _callback(self, intermediate_result):
        if intermediate_result.nit == 2:
            self.close()
        return super()._callback(intermediate_result)


def test_solve_ends_with_an_outcome_however_it_is_left():
    """Ctrl-C reaches the caller and leaves a stopped outcome with the last iterate (close()
    keeps it); a failure after trust-constr returns a failed outcome instead of raising; close()
    during a solve stops it at the next iteration. The caller's thread is unmarked each time."""
    interrupted = _Interrupted(small_problem())
    with pytest.raises(KeyboardInterrupt):
        interrupted.solve()
    assert (interrupted.outcome.status, interrupted.outcome.reason) == ("stopped", "interrupted (KeyboardInterrupt)")
    assert interrupted.outcome.iterations == 3 and interrupted.outcome.final.iteration == 3
    interrupted.close()
    assert interrupted.outcome.reason == "interrupted (KeyboardInterrupt)"
    assert not trust_constr.in_solver_thread()

    failed = _FinishFails(small_problem()).solve()
    assert (failed.status, failed.reason) == ("failed", "ValueError: bookkeeping after trust-constr (test)")
    assert failed.iterations > 3 and not trust_constr.in_solver_thread()

    closed = _ClosesItself(small_problem()).solve()
    assert (closed.status, closed.reason, closed.iterations) == ("stopped", "closed by the caller", 2)


def test_iteration_limit_fails_without_raising():
    outcome = ShootingSolver(small_problem(), max_iterations=2).solve()
    assert outcome.status == "failed"
    assert "iteration limit" in outcome.reason
    assert outcome.iterations == 2


@pytest.mark.parametrize("restart", [True, False])
def test_a_candidate_stopped_at_the_iteration_limit_restarts_once_from_where_it_stopped(restart):
    """A 9-iteration limit stops the rotor's solve early (it needs 10). The restart continues
    from the last iterate (iteration numbers and the cost run on), once: it ends at the limit
    again, within 1 % of the analytic optimum. (A restart drops SR1's curvature, so from a
    nearly converged point it first steps away: violation 1.4e-3 after 9 more iterations.)"""
    settings = OptimizerSettings(nodes=9, substeps=2, transcription="inverse", max_iterations=9, **FULL_LIMITS)
    problem = ShootingProblem(rotor(I_ROTOR, TAU_ROTOR, V_TRAP), [-0.5], [-0.5 + DQ_TRAP], settings=settings)
    first = ShootingSolver(problem).solve()
    assert first.limit_reached and first.iterations == 9
    result = Candidate(problem, restart=restart).solve()
    assert result.status == "failed" and "iteration limit" in result.reason
    if not restart:
        assert (result.iterations, len(result.cost_history)) == (9, 9) and "two solves" not in result.reason
        return
    assert (result.iterations, len(result.cost_history)) == (18, 18)
    assert result.reason.endswith("(in two solves, the second from where the first stopped)")  # 18 past a limit of 9
    assert result.cost_history[9] == pytest.approx(result.cost_history[8], rel=0.2)  # no restart from scratch
    assert result.tf == pytest.approx(T_TRAP, rel=1e-2)
    assert result.constraint_violation < 1e-2


def test_evaluation_error_fails_with_its_reason():
    problem = small_problem()
    evaluate = problem.evaluate
    calls = {"n": 0}

    def flaky(y, derivatives=True):
        calls["n"] += 1
        if calls["n"] > 5:
            raise NonFiniteError("the dynamics blew up (test)")
        return evaluate(y, derivatives)

    problem.evaluate = flaky
    solver = ShootingSolver(problem)
    outcome = solver.solve()
    assert outcome.status == "failed"
    assert "NonFiniteError" in outcome.reason and "blew up (test)" in outcome.reason
    calls["n"] = 0  # the same from the solver's thread, which then ends
    threaded = ShootingSolver(problem)
    list(threaded.iterate())
    assert threaded.outcome.reason == outcome.reason and not threaded._thread.is_alive()
    # a Candidate reports it the same way
    result = Candidate(problem).solve()
    assert result.status == "failed" and "blew up (test)" in result.reason


# --------------------------------------------------------------------------------------------
# 6. refinement of the RK4 sub-steps
# --------------------------------------------------------------------------------------------
def test_refinement_stops_when_a_clearance_deficit_does_not_shrink():
    """A sampling error shrinks with the sub-step; a link crossing an obstacle between two clear
    sub-steps stays as deep, and refining it again only costs time."""

    def checked(clearance):
        return Verification(0.0, 0.0, 0.0, clearance, 0.0, 1.0, 1.0, 100, 4)

    assert not _crossing(None, checked(-0.12))
    assert _crossing(checked(-0.12), checked(-0.1213))
    assert _crossing(checked(-0.16505), checked(-0.1649))
    assert not _crossing(checked(-0.01), checked(-0.003))
    assert not _crossing(checked(0.02), checked(-0.01))
    assert not _crossing(checked(-0.12), checked(0.01))


def test_the_clear_boundary_pair_verifies_where_the_fastest_pair_crosses_an_obstacle(tmp_path):
    """B-J1-L2-J1-L1-J1-L3-J1-L1-E1 on paper-5kg: from its fastest boundary pair the solver
    settles on a motion that holds the clearance at every sub-step while a link jumps through an
    obstacle between two of them (> 0.1 m deep on verification's dense grid). The same
    composition's second candidate starts from step B's clear pair, and its motion verifies."""
    scenario = load_scenario(PAPER_5KG)
    name = "B-J1-L2-J1-L1-J1-L3-J1-L1-E1"
    verdict = check_composition(Composition.from_name(name, scenario.catalog), scenario.catalog, scenario.task)
    specs = list(candidate_specs([verdict]))
    assert [(s.name, s.boundary_pair) for s in specs] == [(name, "fastest"), (f"{name}+clear", "clear")]
    fastest, clear = (make_candidate(scenario, s) for s in specs)
    np.testing.assert_array_equal(fastest.problem.q_start, verdict.q_start)
    np.testing.assert_array_equal(clear.problem.q_goal, verdict.clear_pair[1])

    crossing = ShootingSolver(fastest.problem).solve()
    assert crossing.status == "optimal", crossing.reason
    assert verify(fastest.problem, crossing.final.y).min_clearance < -0.1
    # the clear pair's candidate, through `optimize NAME+clear`
    cli = CliRunner().invoke(main, ["optimize", f"{name}+clear", "--scenario", str(PAPER_5KG), "--out", str(tmp_path)])
    assert cli.exit_code == 0, cli.output
    winner = json.loads((tmp_path / "result.json").read_text())["winner"]
    assert (winner["composition"], winner["candidate"], winner["boundary_pair"]) == (name, f"{name}+clear", "clear")
    assert winner["verification"]["passed"] and winner["verification"]["min_clearance"] >= 0.0
    with open(tmp_path / "trajectory.csv") as f:
        first = next(csv.DictReader(f))
    np.testing.assert_allclose(
        [float(first[f"q{i + 1}"]) for i in range(len(verdict.q_start))], verdict.clear_pair[0], atol=1e-9
    )


def test_a_crossing_refinement_cannot_remove_is_solved_again_from_the_first_guess():
    """B-J1-L3-J1-L2-J2-L3-J1-L1-E2 on paper-5kg: at 4 sub-steps the solver's motion crosses an
    obstacle between two clear sub-steps, and a warm refinement to 8 keeps the crossing. Solved
    again from the first guess at 8 sub-steps, the motion goes round: clear at 50 points of every
    row of its plan, measured with the collision model directly, not through verification. (No
    floor and no self-collision: this solve is the phenomenon; with the floor's rows, or the
    self-collision ones, the solver takes another path.)"""
    scenario = without_floor(load_scenario(PAPER_5KG))
    scenario = replace(scenario, task=replace(scenario.task, self_collision=False))
    name = "B-J1-L3-J1-L2-J2-L3-J1-L1-E2"
    verdict = check_composition(Composition.from_name(name, scenario.catalog), scenario.catalog, scenario.task)
    (spec,) = candidate_specs([verdict])
    candidate = make_candidate(scenario, spec)
    coarse = candidate.problem
    first = ShootingSolver(coarse).solve()
    assert first.status == "optimal" and verify(coarse, first.final.y).min_clearance < -0.02

    result = candidate.solve()
    assert result.status == "optimal", result.reason
    assert result.reason.endswith("(a link crossed an obstacle: solved again from the first guess at 8 sub-steps)")
    assert set(result.refinement_history) == {0, 1} and candidate.problem.substeps == 8
    plan = sample_trajectory(candidate.problem, candidate.last.y)
    # between rows the acceleration is constant (the contract): 50 points of each parabola
    s = np.linspace(0.0, 1.0, 50, endpoint=False)[:, None]
    dense = [
        q + qd * (s * dt) + 0.5 * qdd * (s * dt) ** 2
        for q, qd, qdd, dt in zip(plan.q[:-1], plan.qd[:-1], plan.qdd[:-1], np.diff(plan.t))
    ]
    clearance = min(coarse.collision.min_distance(q) for q in np.concatenate(dense + [plan.q[-1:]]))
    assert clearance >= 0.0


def test_a_composition_without_a_clear_pair_has_one_candidate():
    scenario = load_scenario(PAPER_5KG)
    name = "B-J1-L1-J1-L3-J1-L3-J1-L1-E1"
    composition = Composition.from_name(name, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    assert verdict.passed and verdict.clear_pair is None
    assert [s.name for s in candidate_specs([verdict])] == [name]
    with pytest.raises(
        CompositionError,
        match=r"^B-J1-L1-J1-L3-J1-L3-J1-L1-E1 has no clear boundary pair: the "
        r"straight line of its fastest pair already clears the obstacles, "
        r"or no pair's line does$",
    ):
        optimize_composition(scenario, f"{name}+clear")


def test_refinement_doubles_substeps_until_the_motion_verifies():
    """Forward transcription, one RK4 step per interval on the two-link arm: the coarse optimum
    exploits RK4's error (the true motion misses the goal / overspeeds), refinement fixes it."""
    robot = planar_arm()
    settings = OptimizerSettings(nodes=6, substeps=1, transcription="forward")
    coarse_problem = ShootingProblem(robot, ARM_START, ARM_GOAL, settings=settings)
    coarse = ShootingSolver(coarse_problem).solve()
    assert coarse.status == "optimal", coarse.reason
    assert not verify(coarse_problem, coarse.final.y).passed
    _, _, coarse_end = replay_arm(coarse_problem, coarse.final.y)
    assert np.linalg.norm(arm_points(coarse_end[:2])[2] - arm_points(ARM_GOAL)[2]) > 0.01

    result = Candidate(ShootingProblem(robot, ARM_START, ARM_GOAL, settings=settings), max_refinements=3).solve()
    assert result.status == "optimal", result.reason
    assert result.substeps > 1
    assert result.verification.passed and result.verification.substeps == result.substeps
    _, v, end = replay_arm(coarse_problem.refined(result.substeps, result.waypoints), result.y)
    assert np.linalg.norm(arm_points(end[:2])[2] - arm_points(ARM_GOAL)[2]) <= 0.01
    assert np.all(np.abs(v) <= ARM_VEL * (1.0 + 2e-3))


def test_a_failure_says_when_holding_the_payload_exceeds_the_plans_share():
    """B-J1-L2-J2-L1-J1-L3-J1-L1-E1 holds 5 kg at one of its ends with more than 0.9 of a joint's
    limit (step B's static torque figure, from its own torque check), so a failed plan's reason
    says so with that figure; B-J1-L3-J1-L2-J1-L1-J1-L1-E2 holds it well within the share."""
    from modular_robots.ocp.candidate import _held_beyond_share

    scenario = load_scenario(PAPER_5KG)
    for name, held in (("B-J1-L2-J2-L1-J1-L3-J1-L1-E1", True), ("B-J1-L3-J1-L2-J1-L1-J1-L1-E2", False)):
        composition = Composition.from_name(name, scenario.catalog)
        verdict = check_composition(composition, scenario.catalog, scenario.task)
        assert verdict.passed
        problem = composition_problem(
            composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
        )
        note = _held_beyond_share(problem)
        assert (verdict.figures["torque_ratio"] > 0.9) == held
        if held:
            assert note.startswith("; holding the payload at the ")
            assert f"takes {verdict.figures['torque_ratio']:.2f} of joint " in note
            assert note.endswith("more than the plan may use (effort_margin 0.9)")
        else:
            assert note == ""
