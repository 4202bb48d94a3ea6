"""The IPOPT peer of the benchmark (:mod:`benchmarks.casadi_peer`) solves the project's own NLP:
its symbolic dynamics equal Pinocchio's RNEA, and its constraint vector equals the project's, row
for row (issue: the peer is only a fair comparison if it is the same problem). The peer's exact
symbolic Hessian also checks the solver's second derivatives of RNEA.

Beside the code it checks, as it tests benchmark code, not the package alone; ``make test`` runs
it (``pytest tests benchmarks``)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

casadi = pytest.importorskip("casadi", reason="the peer needs the bench extra (make test installs it)")

from modular_robots import Composition, load_scenario  # noqa: E402
from modular_robots.feasibility import check_composition  # noqa: E402
from modular_robots.ocp.candidate import composition_problem  # noqa: E402
from modular_robots.robot import RobotModel, robot_model  # noqa: E402

from .casadi_peer import PeerNLP, SymbolicRobot  # noqa: E402

PAPER_5KG = Path(__file__).resolve().parents[1] / "scenarios" / "paper-5kg.yaml"

# revolute joints about x and z, prismatic along z, a clear pair through the obstacles
COMPOSITIONS = ("B-J1-L1-J2-L3-J1-L3-J1-L1-E2", "B-J1-L2-J1-L1-J1-L2-J2-L1-E2")


@pytest.fixture(scope="module")
def scenario():
    paper = load_scenario(PAPER_5KG)  # the paper's task: no self-collision, which the peer does not write
    return replace(paper, task=replace(paper.task, self_collision=False))


@pytest.mark.parametrize("name", COMPOSITIONS)
def test_symbolic_rnea_equals_pinocchio_with_armature(scenario, name):
    base = robot_model(Composition.from_name(name, scenario.catalog), scenario.catalog, 5.0)
    model = base.model.copy()
    model.armature[:] = np.linspace(0.1, 0.5, model.nv)  # a drive's reflected inertia on every joint
    robot = RobotModel(model, "tool0", base.primitives, name)
    symbolic = SymbolicRobot(robot)
    q, v, a = (casadi.SX.sym(k, robot.nv) for k in "qva")
    rnea = casadi.Function("rnea", [q, v, a], [symbolic.rnea(q, v, a)])
    rng = np.random.default_rng(7)
    for _ in range(5):
        qq = rng.uniform(robot.lower, robot.upper)
        vv, aa = rng.normal(scale=2.0, size=(2, robot.nv))
        expected = pin.rnea(model, model.createData(), qq, vv, aa)
        assert np.abs(np.asarray(rnea(qq, vv, aa)).ravel() - expected).max() <= 1e-9 * max(1.0, np.abs(expected).max())


@pytest.mark.parametrize("name", COMPOSITIONS)
def test_rnea_curvature_equals_the_symbolic_hessian(scenario, name):
    """The solver's second derivatives of RNEA (differences of Pinocchio's first derivatives)
    against CasADi's exact Hessian of the symbolic Newton-Euler, contracted with a weight."""
    from modular_robots.ocp.hessian import rnea_curvature

    robot = robot_model(Composition.from_name(name, scenario.catalog), scenario.catalog, 5.0)
    symbolic = SymbolicRobot(robot)
    q, v, a, w = (casadi.SX.sym(k, robot.nv) for k in "qvaw")
    x = casadi.vertcat(q, v, a)
    hessian = casadi.Function("h", [q, v, a, w], [casadi.hessian(casadi.dot(w, symbolic.rnea(q, v, a)), x)[0]])
    rng = np.random.default_rng(17)
    nv = robot.nv
    points = rng.uniform(robot.lower, robot.upper, size=(4, nv))
    velocities, accelerations, weights = rng.normal(scale=2.0, size=(3, 4, nv))
    qq, vv, qv, qa, grad_q, grad_v = rnea_curvature(robot, points, velocities, accelerations, weights)
    for k in range(4):
        exact = np.asarray(hessian(points[k], velocities[k], accelerations[k], weights[k]))
        scale = np.abs(exact).max()
        for block, rows, cols in ((qq, 0, 0), (vv, 1, 1), (qv, 0, 1), (qa, 0, 2)):
            reference = exact[rows * nv : (rows + 1) * nv, cols * nv : (cols + 1) * nv]
            assert np.abs(block[k] - reference).max() <= 1e-6 * scale, (rows, cols)
        assert np.abs(exact[2 * nv :, 2 * nv :]).max() == 0.0  # RNEA is linear in a
        dq, dv, _ = pin.computeRNEADerivatives(robot.model, robot.data, points[k], velocities[k], accelerations[k])
        assert np.allclose(grad_q[k], weights[k] @ dq) and np.allclose(grad_v[k], weights[k] @ dv)


@pytest.mark.parametrize("name", COMPOSITIONS)
def test_the_peer_nlp_has_the_projects_constraint_rows(scenario, name):
    composition = Composition.from_name(name, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    problem = composition_problem(
        composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )
    assert problem.collision is not None and problem.collision.obstacles == scenario.task.collision_obstacles
    nlp = PeerNLP.build(problem).functions()
    y0 = problem.initial_guess()
    rng = np.random.default_rng(11)
    for y in (y0, y0 + 0.05 * rng.normal(size=y0.shape)):  # the guess, and a point off it
        cost, constraints = nlp(y)
        assert float(cost) == pytest.approx(problem.cost(y), rel=1e-12)
        difference = np.abs(np.asarray(constraints).ravel() - problem.constraints(y))
        assert difference.max() <= 1e-9, int(difference.argmax())
