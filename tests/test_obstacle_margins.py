"""An end near an obstacle: step B holds the start and the goal to no overlap only, so a goal can
lie closer to an obstacle than the clearance margin step C keeps at its sub-steps. The rows at the
sub-steps next to a goal at rest could not leave it by the margin: such an obstacle's rows keep
less (:func:`~modular_robots.ocp.shooting.end_margins`). Checked on the planar two-link arm, whose clearance has a closed form (no FCL), with a sphere 6 mm beyond the
tool at the start or at the goal."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from modular_robots.ocp.shooting import ShootingProblem, end_margins
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.ocp.verification import verify
from modular_robots.scenario import OptimizerSettings, SphereObstacle

from .helpers.models import ARM_GOAL, ARM_START, arm_clearance, arm_points, planar_arm

#: The sphere's distance from the arm at the goal [m]: below the default margin of 2 cm.
GAP = 0.006
RADIUS = 0.2


def sphere_beyond_the_tool(q, gap: float) -> SphereObstacle:
    """A sphere on the ray from the base through the tool at ``q``, ``gap`` from the arm
    (closed-form clearance)."""
    tool = arm_points(q)[2]
    ray = tool / np.linalg.norm(tool)

    def clearance(s: float) -> float:
        return arm_clearance(q, SphereObstacle(tuple(s * ray), RADIUS)) - gap

    s = brentq(clearance, float(np.linalg.norm(tool)), 5.0)
    return SphereObstacle(tuple(s * ray), RADIUS)


ENDS = {"start": ARM_START, "goal": ARM_GOAL}


@pytest.fixture(scope="module", params=list(ENDS))
def solved(request):
    near, other = ENDS[request.param], ENDS["goal" if request.param == "start" else "start"]
    obstacle = sphere_beyond_the_tool(near, GAP)
    problem = ShootingProblem(
        planar_arm(),
        ARM_START,
        ARM_GOAL,
        [obstacle],
        settings=OptimizerSettings(nodes=6, substeps=3, transcription="inverse"),
    )
    return obstacle, near, other, problem, ShootingSolver(problem).solve()


def test_the_margin_near_an_end_leaves_slack_there_and_is_continuous():
    margin = 0.02
    d = np.linspace(1e-4, 0.1, 100_001)
    kept = end_margins(margin, d)
    assert np.all(kept > 0.0) and np.all(kept <= d - np.minimum(0.5 * margin, 0.5 * d) + 1e-15)
    assert np.all(kept[d >= 1.5 * margin] == margin) and np.all(kept[d < 1.5 * margin] < margin)
    assert np.abs(np.diff(kept)).max() <= np.diff(d).max() * (1 + 1e-9)  # 1-Lipschitz: no jump


def test_an_obstacle_near_an_end_keeps_half_its_distance_there(solved):
    obstacle, near, other, problem, _ = solved
    margin = problem.settings.clearance_margin
    assert arm_clearance(near, obstacle) == pytest.approx(GAP, abs=1e-9)
    assert arm_clearance(other, obstacle) > 2 * margin
    assert problem.clearance_margins.tolist() == pytest.approx([0.5 * GAP], abs=1e-9)
    far = ShootingProblem(
        planar_arm(),
        ARM_START,
        ARM_GOAL,
        [sphere_beyond_the_tool(near, 2 * margin + 0.01)],
        settings=problem.settings,
    )
    assert far.clearance_margins.tolist() == [margin]


def test_a_plan_from_or_to_an_end_near_an_obstacle_verifies_and_keeps_its_rows(solved):
    """The solve converges and passes verification (dense re-integration); at every sub-step the
    closed-form clearance is at least the row's margin, up to the solver's tolerance. (With the
    full margin at every row, the start's own row cannot be met: that solve ends infeasible.)"""
    obstacle, _, _, problem, outcome = solved
    assert outcome.converged, outcome.reason
    y = outcome.final.y
    assert verify(problem, y).passed
    evaluation = problem.evaluate(y, derivatives=False)
    qs = evaluation.propagation.states[:, : problem.substeps, : problem.nv].reshape(-1, problem.nv)
    closed_form = np.array([arm_clearance(q, obstacle) for q in qs])
    assert closed_form.min() >= 0.5 * GAP - 1e-6
