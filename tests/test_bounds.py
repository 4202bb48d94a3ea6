"""The bounds of the best-first search (``modular_robots/bounds.py`` and the relaxed step B) against
independent figures: the tool speeds of random motions from Pinocchio's Jacobians, the optima of
the committed scenario suite, and step B's own verdicts.

A bound above a real figure would let the search exclude a composition that could win, so each
test here looks for a counterexample where one is most likely: velocities at the corners of their
limits, in configurations drawn over the whole joint range.
"""

from __future__ import annotations

import json
import random

import numpy as np
import pinocchio as pin
import pytest

from modular_robots import Composition, load_scenario
from modular_robots.bounds import catalog_bound, joint_levers, tool_speed_limit
from modular_robots.composition import enumerate_compositions
from modular_robots.feasibility import FeasibilitySettings, check_compositions
from modular_robots.ik import DEFAULT_TOLERANCE
from modular_robots.robot import robot_model
from modular_robots.scenario import load_catalog

from .helpers.paths import PAPER_CATALOG, ROOT, SMALL, SUITE_RESULTS, SUITE_SCENARIOS

IMPROV = ROOT / "scenarios" / "catalogs" / "improv-science2019.yaml"


def _sample(catalog, count: int, seed: int) -> list[Composition]:
    compositions = list(enumerate_compositions(catalog))
    return random.Random(seed).sample(compositions, min(count, len(compositions)))


def _largest_tool_speed(robot, rng: np.random.Generator, draws: int) -> float:
    """The largest tool speed [m/s] found over random configurations within the limits, each with
    the joint velocities at the corner of their limits that is fastest there (the tool's
    velocity is linear in them: a corner of the box is the largest)."""
    model, data = robot.model, robot.data
    lower, upper = robot.lower, robot.upper
    largest = 0.0
    for _ in range(draws):
        q = rng.uniform(np.where(np.isfinite(lower), lower, -np.pi), np.where(np.isfinite(upper), upper, np.pi))
        jacobian = pin.computeFrameJacobian(model, data, q, robot.tool_frame_id, pin.LOCAL_WORLD_ALIGNED)[:3]
        columns = jacobian * robot.velocity_limit
        for _ in range(16):  # corners: signs drawn, then improved one joint at a time
            signs = rng.choice([-1.0, 1.0], size=len(q))
            for _ in range(2):
                for j in range(len(q)):
                    signs[j] = 1.0 if np.dot(columns @ signs - columns[:, j] * signs[j], columns[:, j]) >= 0 else -1.0
            largest = max(largest, float(np.linalg.norm(columns @ signs)))
    return largest


@pytest.mark.parametrize(("path", "seed"), [(PAPER_CATALOG, 0), (IMPROV, 2)])
def test_no_motion_within_the_limits_moves_the_tool_faster_than_the_bound(path, seed):
    catalog = load_catalog(path)
    rng = np.random.default_rng(seed)
    for composition in _sample(catalog, 12, seed):
        robot = robot_model(composition, catalog, 1.0)
        bound = tool_speed_limit(composition, catalog)
        found = _largest_tool_speed(robot, rng, 40)
        assert found <= bound * (1 + 1e-12), (composition.name, found, bound)
        assert found >= 0.2 * bound, (composition.name, found, bound)  # a bound, not a blanket


def test_the_levers_of_a_general_assembly_are_the_robot_models():
    """For general catalogues the catalogue's levers give the robot model's own bound (its joint
    placements), computed apart from it."""
    catalog = load_catalog(IMPROV)
    for composition in _sample(catalog, 20, 3):
        robot = robot_model(composition, catalog, 1.0)
        assert tool_speed_limit(composition, catalog) == pytest.approx(robot.tool_speed_bound(), rel=1e-12)
        assert [lever.velocity for lever in joint_levers(composition, catalog)] == pytest.approx(robot.velocity_limit)


def _suite_optima():
    for path in sorted(SUITE_RESULTS.glob("suite*.json")):
        for entry in json.loads(path.read_text())["bounds"]:
            if entry["cost"] is not None:
                yield entry


def test_the_catalogue_bound_never_exceeds_an_optimum_of_the_suite():
    scenarios: dict = {}
    checked = 0
    for entry in _suite_optima():
        scenario = scenarios.setdefault(entry["scenario"], load_scenario(SUITE_SCENARIOS / f"{entry['scenario']}.yaml"))
        composition = Composition.from_name(entry["composition"], scenario.catalog)
        bound = catalog_bound(composition, scenario.catalog, scenario.task, DEFAULT_TOLERANCE)
        assert bound.name == "tool speed" and 0.0 < bound.value <= entry["cost"], (entry["candidate"], bound)
        checked += 1
    assert checked >= 100


def test_the_relaxed_step_b_passes_what_step_b_passes_and_bounds_its_pair():
    """The relaxed cascade (no collision test, IK from every seed) keeps every composition the
    full one keeps, and its fastest pair is no slower than the one step B keeps: its time bound
    is a lower bound of step B's."""
    scenario = load_scenario(SMALL)
    compositions = list(enumerate_compositions(scenario.catalog))
    full = check_compositions(compositions, scenario.catalog, scenario.task)
    relaxed = check_compositions(compositions, scenario.catalog, scenario.task, FeasibilitySettings().relaxed())
    passed = 0
    for whole, loose in zip(full, relaxed):
        assert loose.failed_test != "collision"
        if whole.passed:
            passed += 1
            assert loose.passed, whole.composition.name
            assert loose.time_bound <= whole.time_bound + 1e-9, whole.composition.name
            if whole.clear_pair is not None:
                robot = robot_model(whole.composition, scenario.catalog, scenario.task.payload)
                assert loose.time_bound <= robot.travel_time_bound(*map(np.array, whole.clear_pair)) + 1e-9
        elif loose.passed:
            assert whole.failed_test in ("collision", "inverse kinematics", "static torque")
    assert passed == 6
