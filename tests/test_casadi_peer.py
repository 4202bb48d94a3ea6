"""The IPOPT peer of the benchmark solves the project's own NLP: its symbolic dynamics equal
Pinocchio's RNEA, and its constraint vector equals the project's, row for row (issue: the peer is
only a fair comparison if it is the same problem)."""

import numpy as np
import pinocchio as pin
import pytest

casadi = pytest.importorskip("casadi", reason="the peer needs the bench extra (make test installs it)")

from benchmarks.casadi_peer import PeerNLP, SymbolicRobot  # noqa: E402
from modular_robots import Composition, load_scenario  # noqa: E402
from modular_robots.feasibility import check_composition  # noqa: E402
from modular_robots.ocp.candidate import composition_problem  # noqa: E402
from modular_robots.robot import RobotModel, robot_model  # noqa: E402

from .conftest import PAPER_5KG  # noqa: E402

# revolute joints about x and z, prismatic along z, a clear pair through the obstacles
COMPOSITIONS = ("B-J1-L1-J2-L3-J1-L3-J1-L1-E2", "B-J1-L2-J1-L1-J1-L2-J2-L1-E2")


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(PAPER_5KG)


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
def test_the_peer_nlp_has_the_projects_constraint_rows(scenario, name):
    composition = Composition.from_name(name, scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    problem = composition_problem(
        composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )
    assert problem.collision is not None and len(problem.collision.obstacles) == len(scenario.task.obstacles)
    nlp = PeerNLP.build(problem).functions()
    y0 = problem.initial_guess()
    rng = np.random.default_rng(11)
    for y in (y0, y0 + 0.05 * rng.normal(size=y0.shape)):  # the guess, and a point off it
        cost, constraints = nlp(y)
        assert float(cost) == pytest.approx(problem.cost(y), rel=1e-12)
        difference = np.abs(np.asarray(constraints).ravel() - problem.constraints(y))
        assert difference.max() <= 1e-9, int(difference.argmax())
