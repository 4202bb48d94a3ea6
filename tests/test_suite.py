"""The safe pruning bound against every optimum of the scenario suite (``make bench`` writes
``benchmarks/results/suite*.json`` from brute-force runs of ``benchmarks/scenarios``).

The bound is recomputed here from the catalogue's numbers alone (each joint's velocity limit
times the scenario's margin, and the candidate's boundary configurations), independently of
:class:`~modular_robots.robot.RobotModel`, and must never exceed a verified optimum: a bound above
an optimum would let the bound rule drop a candidate that could win.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from modular_robots import Composition, load_scenario
from modular_robots.ocp.candidate import BoundaryPair, CandidateSpec, make_candidate
from modular_robots.pipeline import cost_bound

from .helpers.paths import SUITE_RESULTS, SUITE_SCENARIOS

FILES = sorted(SUITE_RESULTS.glob("suite*.json"))


def _entries():
    return [b for path in FILES for b in json.loads(path.read_text())["bounds"]]


def test_the_suite_results_are_committed():
    assert FILES, "benchmarks/results/suite*.json is missing: run `python -m benchmarks suite`"
    scenarios = {b["scenario"] for b in _entries()}
    assert len(scenarios) >= 8 and all((SUITE_SCENARIOS / f"{name}.yaml").is_file() for name in scenarios)


def test_the_bound_never_exceeds_an_optimum_on_the_suite():
    entries = _entries()
    optima = 0
    scenarios = {}
    for entry in entries:
        scenario = scenarios.setdefault(entry["scenario"], load_scenario(SUITE_SCENARIOS / f"{entry['scenario']}.yaml"))
        composition = Composition.from_name(entry["composition"], scenario.catalog)
        joints = [scenario.catalog.module(m) for m in composition.modules if scenario.catalog.module(m).dof]
        velocity = np.array([m.limits.velocity for m in joints]) * scenario.optimizer.velocity_margin
        travel = np.abs(np.subtract(entry["q_goal"], entry["q_start"]))
        bound = float(np.max(travel / velocity))
        assert entry["cost_bound"] == pytest.approx(bound, rel=1e-12), entry["candidate"]
        # the bound the run uses now (admission and pruning), from the package's own code
        spec = CandidateSpec(composition, tuple(entry["q_start"]), tuple(entry["q_goal"]), BoundaryPair.FASTEST)
        assert cost_bound(scenario, spec) == pytest.approx(bound, rel=1e-12), entry["candidate"]
        if entry["cost"] is not None:
            optima += 1
            assert bound <= entry["cost"], (entry["scenario"], entry["candidate"], bound, entry["cost"])
    assert optima >= 100  # the check covers the suite's optima, not a handful


def test_the_admission_bound_is_the_problem_bound():
    """``pipeline.cost_bound`` (admission, before a candidate is built) is the bound its shooting
    problem carries (pruning), for both boundary pairs of a few suite candidates."""
    entries = _entries()[:: max(1, len(_entries()) // 4)][:4]
    for entry in entries:
        scenario = load_scenario(SUITE_SCENARIOS / f"{entry['scenario']}.yaml")
        composition = Composition.from_name(entry["composition"], scenario.catalog)
        for pair in BoundaryPair:
            spec = CandidateSpec(composition, tuple(entry["q_start"]), tuple(entry["q_goal"]), pair)
            assert cost_bound(scenario, spec) == make_candidate(scenario, spec).problem.cost_bound > 0.0
