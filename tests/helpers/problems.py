"""A real paper-5kg shooting problem, and a solve's history in one comparable value."""

from __future__ import annotations

import hashlib
from dataclasses import replace

import numpy as np

from modular_robots.composition import Composition
from modular_robots.feasibility import check_composition
from modular_robots.ocp.candidate import composition_problem
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.ocp.solver import ShootingSolver
from modular_robots.scenario import Scenario, load_scenario

from .paths import PAPER_5KG


def without_floor(scenario: Scenario) -> Scenario:
    """``scenario`` as written before the floor was a default (``floor: none``): for checks built
    around one problem's solve, which another constraint (even inactive) makes another solve."""
    return replace(scenario, task=replace(scenario.task, floor=None))


def paper_problem() -> ShootingProblem:
    """The shooting problem of ``B-J1-L3-J1-L2-J1-L1-J1-L1-E2`` on paper-5kg (no floor), from step
    B's pair."""
    scenario = without_floor(load_scenario(PAPER_5KG))
    composition = Composition.from_name("B-J1-L3-J1-L2-J1-L1-J1-L1-E2", scenario.catalog)
    verdict = check_composition(composition, scenario.catalog, scenario.task)
    return composition_problem(
        composition, scenario.catalog, scenario.task, verdict.q_start, verdict.q_goal, scenario.optimizer
    )


def history(problem) -> tuple[int, str]:
    """A solve of ``problem``: its iterations and a digest of every iterate and its optimality,
    equal for two solves only if they are iterate for iterate the same, bit for bit."""
    solver = ShootingSolver(problem)
    digest = hashlib.sha1()
    for iterate in solver.iterate():
        digest.update(iterate.y.tobytes())
        digest.update(np.float64(iterate.optimality).tobytes())
    return solver.outcome.iterations, digest.hexdigest()
