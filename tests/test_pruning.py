"""Step D (lockstep pruning) and the whole pipeline (issue 5 item 6).

The rule and the manager are checked on scripted fake candidates, whose costs and constraint
violations are fixed lists, so every pruning decision is known in advance. The pipeline is
checked on ``tests/data/small.yaml`` (516 compositions, 6 feasible): each real run is made once
per module, in a module-scoped fixture, and shared by several tests.
"""

from __future__ import annotations

import csv
import itertools
import json
import multiprocessing
import re
import time
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
import pytest
from click.testing import CliRunner

from modular_robots import feasibility
from modular_robots.cli import main
from modular_robots.composition import Composition
from modular_robots.execution import InProcessExecutor, ProcessExecutor
from modular_robots.ocp.candidate import CandidateResult
from modular_robots.ocp.solver import Iterate
from modular_robots.pipeline import RunResult, run_scenario
from modular_robots.pruning import GUARD_VIOLATION, Progress, PruningManager, RoundCosts, reference_cost
from modular_robots.pruning import ratio_rule as _ratio_rule
from modular_robots.scenario import PruningSettings, load_scenario

from .helpers.paths import PAPER_SCENARIO, SMALL

SMALL_WINNER = "B-J1-L1-J1-L1-J1-L1-E2"
#: Its time [s] within the default margins (effort 0.9, velocity 0.95; 1.575 s at the full limits).
SMALL_TF = 1.658
SPEC_CANDIDATE_FIELDS = {
    "composition",
    "dof",
    "status",
    "iterations",
    "cost",
    "tf",
    "constraint_violation",
    "pruned_at_iteration",
    "cost_history",
}


# --------------------------------------------------------------------------------------------
# Scripted fake candidates (same interface as modular_robots.ocp.candidate.Candidate for executors)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Script:
    """A fake candidate: one iterate per entry of ``costs`` (violation from ``violations``, 0 by
    default); when the script runs out it ends with status ``end`` and cost ``final_cost``
    (default: the last iterate's cost). Iterates from index ``refine_from`` on belong to a
    re-solve with refined sub-steps (``refinement`` 1). ``bound`` is the problem's lower bound on
    the cost, carried by every iterate. The first ``warm_up`` iterates are a multi-goal
    candidate's moves solved alone (:attr:`~modular_robots.ocp.solver.Iterate.warm_up`)."""

    name: str
    costs: tuple[float, ...]
    violations: tuple[float, ...] | None = None
    end: str = "optimal"
    final_cost: float | None = None
    refine_from: int | None = None
    bound: float = 0.0
    warm_up: int = 0

    def violation(self, i: int) -> float:
        return 0.0 if self.violations is None else self.violations[i]


class FakeCandidate:
    """Yields the scripted iterates; ``log`` (a list, in-process only) records every step."""

    def __init__(self, script: Script, log: list | None = None):
        self.name = script.name
        self.script = script
        self.log = log
        self.result: CandidateResult | None = None
        self.last: Iterate | None = None
        self.history: list[float] = []
        self._generator = None

    def iterate(self):
        if self._generator is None:
            self._generator = self._run()
        return self._generator

    def _run(self):
        for i, cost in enumerate(self.script.costs):
            if self.log is not None:
                self.log.append(("step", self.name, i + 1))
            refining = self.script.refine_from is not None and i >= self.script.refine_from
            self.last = Iterate(
                i + 1,
                float(cost),
                self.script.violation(i),
                float(cost),
                np.array([cost, self.script.violation(i)]),
                refinement=int(refining),
                cost_bound=self.script.bound,
                warm_up=i < self.script.warm_up,
            )
            self.history.append(float(cost))
            yield self.last
        if self.log is not None:
            self.log.append(("end", self.name, len(self.script.costs)))
        self._finish(self.script.end, self.script.final_cost)

    def close(self):
        if self.log is not None:
            self.log.append(("close", self.name, self.last.iteration if self.last else 0))
        if self._generator is not None:
            self._generator.close()
        if self.result is None:
            self._finish("stopped", None)

    def _finish(self, status: str, cost: float | None):
        last = self.last
        if cost is None:
            cost = last.cost if last else float("nan")
        self.result = CandidateResult(
            name=self.name,
            dof=3,
            status=status,
            reason=f"scripted {status}",
            iterations=last.iteration if last else 0,
            cost=cost,
            tf=cost,
            constraint_violation=last.constraint_violation if last else float("nan"),
            cost_history=tuple(self.history),
            substeps=4,
            y=last.y if last else None,
        )


def fake_factory(context, spec: Script) -> FakeCandidate:
    """Module-level (picklable) factory; ``context`` is an event log or None."""
    return FakeCandidate(spec, context)


class RecordingExecutor:
    """Wraps an executor and logs its ``advance`` and ``stop`` calls into ``log``."""

    def __init__(self, inner, log: list):
        self.inner, self.log = inner, log

    def names(self):
        return self.inner.names()

    def advance(self, names):
        self.log.append(("advance", tuple(names)))
        return self.inner.advance(names)

    def stop(self, names):
        self.log.append(("stop", tuple(names)))
        return self.inner.stop(names)

    def shutdown(self):
        self.log.append(("shutdown",))
        self.inner.shutdown()


def ratio_rule(
    costs,
    violations,
    converged,
    iteration,
    threshold=0.5,
    start_iteration=2,
    guard_violation=GUARD_VIOLATION,
    earlier=None,
    lookahead=0.0,
    untrusted_for=None,
    patience=0,
    floors=None,
    reference="trusted",
    gate=0.0,
):
    """The rule on one round's figures, with the settings spelt out (0 turns a guard part off)."""
    view = RoundCosts(iteration, costs, violations, converged, earlier, untrusted_for or {}, floors or {})
    settings = PruningSettings(
        "ratio",
        threshold,
        start_iteration,
        window=0,
        lookahead=lookahead,
        patience=patience,
        reference=reference,
        gate=gate,
    )
    return set(_ratio_rule(view, settings, guard_violation))


#: The ratio rule without the guard's progress window, patience and bound gate, against the best
#: trusted cost (scripts are short; the defaults are tested on their own below).
BARE = {"window": 0, "lookahead": 0.0, "patience": 0, "reference": "trusted", "gate": 0.0, "admission": 0}


def make_executor(scripts, jobs=1, log=None):
    names = [s.name for s in scripts]
    if jobs == 1:
        return InProcessExecutor(fake_factory, log, list(scripts), names)
    return ProcessExecutor(fake_factory, None, list(scripts), names, jobs)


def run_fakes(scripts, rule="ratio", threshold=0.5, start_iteration=2, jobs=1, log=None, **guard):
    """Run ``scripts`` under the manager; return (results by name, list of Progress). The guard's
    progress window and patience are off unless given (the scripts are a few iterations long)."""
    guard = {**BARE, **guard}
    settings = PruningSettings(rule, threshold, start_iteration, **guard)
    manager = PruningManager(make_executor(scripts, jobs, log), settings)
    progress = list(manager.rounds())
    assert list(manager.results) == [s.name for s in scripts]  # the executor's order
    return manager.results, progress


def summary(results) -> list[tuple]:
    return [(r.name, r.status, r.pruned_at_iteration, r.iterations, r.cost, r.cost_history) for r in results.values()]


def expected_outcome(
    scripts,
    rule,
    threshold,
    start_iteration,
    guard=GUARD_VIOLATION,
    window=0,
    lookahead=0.0,
    patience=0,
    reference="trusted",
    gate=0.0,
) -> dict:
    """An independent re-statement of SPEC §6 with the documented guard, its progress window and
    its patience: name -> (status, iterations, pruned_at_iteration)."""
    by_name = {s.name: s for s in scripts}
    alive = [s.name for s in scripts]
    out, converged = {}, {}
    round_ = 0

    def trusted_cost(name, r):  # the cost of round r (1-based) if that iterate is trusted
        return by_name[name].costs[r - 1] if by_name[name].violation(r - 1) <= guard else None

    def untrusted_run(name, r):  # rounds in a row up to r whose iterate was not trusted
        k = 0
        while r - k >= 1 and trusted_cost(name, r - k) is None:
            k += 1
        return k

    while alive:
        round_ += 1
        for name in alive:
            s = by_name[name]
            if round_ > len(s.costs):  # this round's next() ends the generator
                out[name] = (s.end, len(s.costs), None)
                if s.end == "optimal":
                    converged[name] = s.final_cost if s.final_cost is not None else s.costs[-1]
        alive = [n for n in alive if n not in out]
        if rule == "ratio" and round_ >= start_iteration:

            def refining(n, round_=round_):
                return by_name[n].refine_from is not None and round_ > by_name[n].refine_from

            now = {
                n: (by_name[n].costs[round_ - 1], by_name[n].violation(round_ - 1)) for n in alive if not refining(n)
            }
            trusted = [c for c, v in now.values() if v <= guard and reference == "trusted"]
            trusted += list(converged.values())
            if trusted and min(trusted) > 0:
                ref = min(trusted)
                for n in alive:  # the cost bound, and a re-solve's previous optimum, bound the final cost
                    floor = by_name[n].bound
                    if refining(n):
                        floor = max(floor, by_name[n].costs[by_name[n].refine_from - 1])
                    if (floor - ref) / ref > threshold:
                        out[n] = ("pruned", round_, round_)
                for n, (c, v) in now.items():
                    if by_name[n].bound < gate * ref:  # a bound that could still win: judged on it only
                        continue
                    if v > guard:
                        if patience and untrusted_run(n, round_) >= patience:
                            out[n] = ("pruned", round_, round_)
                    elif (c - ref) / ref > threshold:
                        before = trusted_cost(n, round_ - window) if round_ - window >= 1 else None
                        # kept while the cost projected lookahead windows ahead is within the threshold
                        projected = None if before is None else c - lookahead * (before - c)
                        if window == 0 or (projected is not None and (projected - ref) / ref > threshold):
                            out[n] = ("pruned", round_, round_)
        if rule == "ratio" and converged:  # safe: a bound above the best verified cost never wins
            for n in alive:
                if by_name[n].bound > min(converged.values()):
                    out[n] = ("pruned", round_, round_)
        alive = [n for n in alive if n not in out]
    return out


def random_scripts(rng: np.random.Generator, count: int) -> list[Script]:
    scripts = []
    for k in range(count):
        length = int(rng.integers(1, 12))
        costs = tuple(float(c) for c in np.round(rng.uniform(0.5, 3.0, length), 2))
        violations = tuple(
            float(v) for v in rng.choice([0.0, GUARD_VIOLATION, 1e-2, 1.0], length, p=[0.5, 0.1, 0.2, 0.2])
        )
        end = str(rng.choice(["optimal", "optimal", "failed"]))
        final = None if rng.random() < 0.5 else float(np.round(rng.uniform(0.5, 3.0), 2))
        refine = int(rng.integers(1, length)) if length > 1 and rng.random() < 0.3 else None
        # a bound at most the script's trusted and final costs, as a real problem's (feasible costs
        # are above it, untrusted ones need not be)
        lowest = min(
            [c for c, v in zip(costs, violations) if v <= GUARD_VIOLATION] + [final if final is not None else costs[-1]]
        )
        bound = float(np.floor(rng.uniform(0.5, 1.0) * lowest * 100) / 100) if rng.random() < 0.3 else 0.0
        scripts.append(Script(f"c{k}", costs, violations, end, final, refine, bound))
    return scripts


# --------------------------------------------------------------------------------------------
# 1. The rule's arithmetic
# --------------------------------------------------------------------------------------------


def test_reference_cost_is_the_smallest_trusted_cost():
    costs = {"a": 1.0, "b": 2.0, "c": 3.0}
    assert reference_cost(costs, {"a": 0.0, "b": 0.0, "c": 0.0}, {}) == 1.0
    # an untrusted iterate is never the reference, however cheap
    assert reference_cost(costs, {"a": 0.5, "b": 0.0, "c": 0.0}, {}) == 2.0
    # the guard is inclusive: a violation equal to GUARD_VIOLATION is trusted
    assert reference_cost(costs, {"a": GUARD_VIOLATION, "b": 1.0, "c": 1.0}, {}) == 1.0
    assert reference_cost(costs, {"a": np.nextafter(GUARD_VIOLATION, 1.0), "b": 1.0, "c": 1.0}, {}) is None
    # converged costs count, even when no live candidate is trusted
    assert reference_cost(costs, {"a": 1.0, "b": 1.0, "c": 1.0}, {"z": 2.5}) == 2.5
    assert reference_cost(costs, {"a": 0.0, "b": 1.0, "c": 1.0}, {"z": 0.5}) == 0.5
    assert reference_cost({}, {}, {}) is None


@pytest.mark.parametrize("cost_b, pruned", [(3.0, False), (np.nextafter(3.0, 4.0), True), (2.9, False), (4.0, True)])
def test_ratio_rule_prunes_strictly_above_the_threshold(cost_b, pruned):
    # (3 - 2) / 2 == 0.5 exactly: not pruned; one ulp more: pruned
    chosen = ratio_rule({"a": 2.0, "b": cost_b}, {"a": 0.0, "b": 0.0}, {}, iteration=2)
    assert chosen == ({"b"} if pruned else set())


def test_ratio_rule_threshold_and_start_iteration():
    costs, violations = {"a": 1.0, "b": 1.3, "c": 10.0}, {"a": 0.0, "b": 0.0, "c": 0.0}
    assert ratio_rule(costs, violations, {}, iteration=1) == set()  # before start_iteration (2)
    assert ratio_rule(costs, violations, {}, iteration=2) == {"c"}
    assert ratio_rule(costs, violations, {}, iteration=2, threshold=0.2) == {"b", "c"}
    assert ratio_rule(costs, violations, {}, iteration=4, threshold=0.2, start_iteration=5) == set()
    assert ratio_rule(costs, violations, {}, iteration=5, threshold=0.2, start_iteration=5) == {"b", "c"}
    assert ratio_rule(costs, violations, {}, iteration=1, start_iteration=0) == {"c"}


def test_ratio_rule_guard():
    # the cheap iterate is infeasible: the reference is b's 2.0, so c (3.0) stays
    assert ratio_rule({"a": 1.0, "b": 2.0, "c": 3.0}, {"a": 0.1, "b": 0.0, "c": 0.0}, {}, 2) == set()
    # c is far too expensive but its own iterate is not trusted: not pruned
    assert ratio_rule({"a": 1.0, "c": 100.0}, {"a": 0.0, "c": 2 * GUARD_VIOLATION}, {}, 2) == set()
    assert ratio_rule({"a": 1.0, "c": 100.0}, {"a": 0.0, "c": GUARD_VIOLATION}, {}, 2) == {"c"}
    # nothing trusted: nobody is pruned
    assert ratio_rule({"a": 1.0, "c": 100.0}, {"a": 1.0, "c": 1.0}, {}, 2) == set()
    # a converged cost is a reference on its own
    assert ratio_rule({"c": 1.6}, {"c": 0.0}, {"z": 1.0}, 2) == {"c"}
    assert ratio_rule({"c": 1.5}, {"c": 0.0}, {"z": 1.0}, 2) == set()
    # a custom guard
    assert ratio_rule({"a": 1.0, "c": 2.0}, {"a": 0.05, "c": 0.0}, {}, 2, guard_violation=0.1) == {"c"}


def test_progress_guard_keeps_a_candidate_whose_cost_is_still_falling():
    costs, violations = {"a": 1.0, "b": 2.0}, {"a": 0.0, "b": 0.0}
    # b is 100 % worse than a (pruned above 1.5): over the window it fell from 2.25 to 2.0
    assert ratio_rule(costs, violations, {}, 5, earlier={"b": 2.25}, lookahead=2.0) == set()  # 2 - 0.5 = 1.5
    assert ratio_rule(costs, violations, {}, 5, earlier={"b": 2.25}, lookahead=1.0) == {"b"}  # 1.75
    assert ratio_rule(costs, violations, {}, 5, earlier={"b": 2.0}, lookahead=100.0) == {"b"}  # stalled
    assert ratio_rule(costs, violations, {}, 5, earlier={"b": 1.9}, lookahead=2.0) == {"b"}  # rising
    # not trusted a window ago: too new to judge
    assert ratio_rule(costs, violations, {}, 5, earlier={}, lookahead=2.0) == set()
    # the guard never prunes below the threshold
    assert ratio_rule({"a": 1.0, "b": 1.4}, violations, {}, 5, earlier={"b": 1.4}, lookahead=0.0) == set()


def test_patience_prunes_a_candidate_that_stays_untrusted():
    costs, violations = {"a": 1.0, "b": 0.5}, {"a": 0.0, "b": 1.0}
    assert ratio_rule(costs, violations, {}, 60, untrusted_for={"b": 50}, patience=50) == {"b"}
    assert ratio_rule(costs, violations, {}, 60, untrusted_for={"b": 49}, patience=50) == set()
    assert ratio_rule(costs, violations, {}, 60, untrusted_for={"b": 50}, patience=0) == set()
    # without a trusted reference nobody is pruned, however long
    assert ratio_rule(costs, {"a": 1.0, "b": 1.0}, {}, 60, untrusted_for={"a": 60, "b": 60}, patience=50) == set()
    assert ratio_rule(costs, {"a": 1.0, "b": 1.0}, {"z": 2.0}, 60, untrusted_for={"a": 60, "b": 60}, patience=50) == {
        "a",
        "b",
    }


def test_a_refining_candidate_is_judged_on_its_previous_optimum():
    costs, violations = {"a": 1.0}, {"a": 0.0}
    assert ratio_rule(costs, violations, {}, 5, floors={"r": 1.6}) == {"r"}
    assert ratio_rule(costs, violations, {}, 5, floors={"r": 1.5}) == set()
    # a floor is not a reference: alone it prunes nobody
    assert ratio_rule({}, {}, {}, 5, floors={"r": 1.0, "s": 9.0}) == set()


def test_manager_judges_a_re_solve_on_the_optimum_before_it():
    """r converges at 1.8 then re-solves (its iterates jump to 9): it is pruned on 1.8 once the
    reference is below 1.2 (round 4), never on its transients; s re-solves from 1.25 and is kept."""
    scripts = [
        Script("a", (1.3, 1.3, 1.25, 1.0, 1.0, 1.0)),
        Script("r", (1.8, 1.8, 9.0, 9.0, 9.0, 9.0), refine_from=2),
        Script("s", (1.25, 1.25, 9.0, 9.0, 9.0, 9.0), refine_from=2),
    ]
    results, _ = run_fakes(scripts)
    assert results["r"].status == "pruned" and results["r"].pruned_at_iteration == 4  # 1.8 > 1.5 * 1.0
    assert results["s"].status == "optimal"


def test_manager_prunes_on_the_cost_bound_before_the_candidate_is_trusted():
    """b's iterates are never trusted, but no plan of its problem is faster than 1.6 s: it is
    pruned in the first round with a reference (round 2, start_iteration), c (bound 1.5) is not."""
    scripts = [
        Script("a", (1.0,) * 5),
        Script("b", (0.5,) * 5, violations=(1.0,) * 5, bound=1.6),
        Script("c", (1.2,) * 5, bound=1.5),
    ]
    results, _ = run_fakes(scripts)
    assert (results["b"].status, results["b"].pruned_at_iteration) == ("pruned", 2)
    assert results["c"].status == "optimal"
    # a bound is not a reference: alone it prunes nobody
    results, _ = run_fakes(
        [
            Script("b", (0.5,) * 3, violations=(1.0,) * 3, bound=9.0),
            Script("d", (0.4,) * 3, violations=(1.0,) * 3, bound=1.0),
        ]
    )
    assert {r.status for r in results.values()} == {"optimal"}


def test_ratio_rule_without_a_positive_reference_prunes_nobody():
    assert ratio_rule({"a": 0.0, "b": 5.0}, {"a": 0.0, "b": 0.0}, {}, 3) == set()


# --------------------------------------------------------------------------------------------
# 1. The rule inside the manager, on scripted candidates
# --------------------------------------------------------------------------------------------


def test_pruned_at_the_first_round_above_the_threshold():
    scripts = [
        Script("a", (1.0,) * 6),
        # round 1 is before start_iteration; rounds 2-3 exactly at the threshold; round 4 above
        Script("b", (9.0, 1.5, 1.5, 1.75, 1.0, 1.0)),
    ]
    results, progress = run_fakes(scripts)
    a, b = results["a"], results["b"]
    assert (a.status, a.iterations, a.pruned_at_iteration) == ("optimal", 6, None)
    assert (b.status, b.pruned_at_iteration, b.iterations) == ("pruned", 4, 4)
    assert b.cost == 1.75 and b.cost_history == (9.0, 1.5, 1.5, 1.75)
    assert "pruned" in b.reason
    assert [p.pruned for p in progress] == [(), (), (), ("b",), (), (), ()]
    assert [p.alive for p in progress] == [2, 2, 2, 1, 1, 1, 0]
    assert [p.finished for p in progress][-1] == ("a",)
    assert progress[3] == Progress(4, 1, 1.0, ("b",), ())


@pytest.mark.parametrize("start_iteration", [1, 2, 3, 5])
def test_never_pruned_before_start_iteration(start_iteration):
    scripts = [Script("a", (1.0,) * 6), Script("b", (10.0,) * 6)]
    results, _ = run_fakes(scripts, start_iteration=start_iteration)
    assert results["b"].status == "pruned"
    assert results["b"].pruned_at_iteration == start_iteration == results["b"].iterations
    assert results["b"].cost_history == (10.0,) * start_iteration


def test_threshold_setting_is_used():
    scripts = [Script("a", (1.0,) * 4), Script("b", (1.3,) * 4), Script("c", (1.1,) * 4)]
    results, _ = run_fakes(scripts, threshold=0.2)
    assert [r.status for r in results.values()] == ["optimal", "pruned", "optimal"]
    results, _ = run_fakes(scripts, threshold=0.5)
    assert [r.status for r in results.values()] == ["optimal"] * 3


def test_rule_none_prunes_nobody():
    scripts = [Script("a", (1.0,) * 5), Script("b", (100.0,) * 3), Script("c", (50.0,) * 7, end="failed")]
    results, progress = run_fakes(scripts, rule="none")
    assert summary(results) == [
        ("a", "optimal", None, 5, 1.0, (1.0,) * 5),
        ("b", "optimal", None, 3, 100.0, (100.0,) * 3),
        ("c", "failed", None, 7, 50.0, (50.0,) * 7),
    ]
    assert all(p.pruned == () for p in progress)
    assert len(progress) == 8


def test_guard_reference_and_own_iterate_must_be_trusted():
    scripts = [
        # cheapest, but trusted only from round 4 on
        Script("a", (1.0,) * 8, (0.5, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0)),
        # twice a's cost; its own iterate is untrusted in round 4 -> pruned in round 5
        Script("b", (2.0,) * 8, (0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0)),
        # three times a's cost but never trusted -> never pruned
        Script("c", (3.0,) * 8, (1.0,) * 8),
        # trusted at exactly the guard -> pruned as soon as a is trusted
        Script("d", (1.6,) * 8, (GUARD_VIOLATION,) * 8),
    ]
    results, progress = run_fakes(scripts)
    assert results["a"].status == "optimal"
    assert (results["b"].status, results["b"].pruned_at_iteration) == ("pruned", 5)
    assert results["c"].status == "optimal" and results["c"].iterations == 8
    assert (results["d"].status, results["d"].pruned_at_iteration) == ("pruned", 4)
    # the best trusted cost: d's 1.6 while a is untrusted, then a's 1.0
    assert [p.best_cost for p in progress[:5]] == [1.6, 1.6, 1.6, 1.0, 1.0]


def test_no_trusted_iterate_means_no_pruning():
    scripts = [
        Script("a", (1.0,) * 5, (0.1,) * 5),
        Script("b", (10.0,) * 5, (0.2,) * 5),
        Script("c", (20.0,) * 5, (1.0,) * 5, end="failed"),
    ]
    results, progress = run_fakes(scripts)
    assert [r.status for r in results.values()] == ["optimal", "optimal", "failed"]
    assert [p.best_cost for p in progress[:5]] == [None] * 5


def test_a_converged_cost_stays_the_reference_after_it_finished():
    scripts = [
        # converges in round 3 with a verified cost of 1.0 (its last iterate said 1.1)
        Script("a", (1.2, 1.1), end="optimal", final_cost=1.0),
        # 1.4 is within 50 % of 1.0; 1.55 is not (but is within 50 % of a's last iterate, 1.1)
        Script("b", (1.4, 1.4, 1.4, 1.4, 1.55, 1.55, 1.55)),
        Script("c", (5.0, 5.0), (1.0, 1.0)),  # untrusted until it converges in round 3
    ]
    results, progress = run_fakes(scripts)
    assert (results["a"].status, results["a"].cost, results["a"].iterations) == ("optimal", 1.0, 2)
    assert (results["b"].status, results["b"].pruned_at_iteration) == ("pruned", 5)
    assert results["c"].status == "optimal"
    assert progress[2].finished == ("a", "c") and progress[2].best_cost == 1.0
    assert all(p.best_cost == 1.0 for p in progress[2:])
    # the best verified cost: none before round 3, then a's 1.0, never rising
    assert [p.best_optimal for p in progress[:2]] == [None, None]
    assert all(p.best_optimal == 1.0 for p in progress[2:])


def test_a_failed_candidate_is_no_reference():
    scripts = [
        Script("a", (1.2, 1.1), end="failed", final_cost=1.0),
        Script("b", (1.4, 1.4, 1.4, 1.4, 1.55, 1.55, 1.55)),
    ]
    results, progress = run_fakes(scripts)
    assert [r.status for r in results.values()] == ["failed", "optimal"]
    assert [p.best_cost for p in progress] == [1.2, 1.1, 1.4, 1.4, 1.55, 1.55, 1.55, 1.55]
    assert [p.best_optimal for p in progress] == [None] * 7 + [1.55]  # a failed: never a best cost


def test_a_converged_candidate_is_never_pruned():
    # b's generator ends (converged, cost 3.0) in round 3, when a's cost is 1.0: b stays optimal,
    # and its cost does not prune anything either
    scripts = [Script("a", (1.0,) * 4), Script("b", (1.0, 1.0), final_cost=3.0)]
    results, _ = run_fakes(scripts)
    assert [(r.status, r.cost) for r in results.values()] == [("optimal", 1.0), ("optimal", 3.0)]


def test_candidate_without_iterates():
    scripts = [Script("a", (), final_cost=2.0), Script("b", (), end="failed"), Script("c", (1.0, 2.0, 3.0))]
    results, progress = run_fakes(scripts)
    assert summary(results)[:2] == [
        ("a", "optimal", None, 0, 2.0, ()),
        ("b", "failed", None, 0, pytest.approx(np.nan, nan_ok=True), ()),
    ]
    assert results["c"].status == "optimal" and progress[0].finished == ("a", "b")


def test_the_defaults_keep_a_slow_winner_that_the_trusted_reference_prunes():
    """The suite's hard case in miniature: ``slow`` is trusted at three times its final cost for
    its first iterations while ``quick`` converges at once, and ends below it. Against the best
    trusted cost and without a gate it is pruned at once; under the defaults (the best verified
    cost as the reference, and the gate: its bound 1.2 s is below 0.7 x 2.0 s) it is kept and
    wins, while ``hopeless``, whose bound 1.5 s passes the gate, is pruned on its trusted cost once
    ``quick`` has verified, and ``beyond``, whose bound exceeds the verified cost, by its bound."""
    scripts = [
        Script("quick", (2.4, 2.1, 2.0), end="optimal", final_cost=2.0, bound=1.0),
        Script("slow", (6.0, 5.9, 5.6, 5.0, 4.0, 3.0, 2.2, 1.8), end="optimal", final_cost=1.8, bound=1.2),
        Script("hopeless", (5.0,) * 8, end="optimal", bound=1.5),
        Script("beyond", (9.0,) * 8, violations=(1.0,) * 8, end="optimal", bound=2.1),
    ]
    old, _ = run_fakes(scripts, "ratio", **BARE)
    assert old["slow"].status == "pruned"
    new, _ = run_fakes(scripts, "ratio", window=0, lookahead=0.0, patience=0, reference="verified", gate=0.7)
    assert new["slow"].status == "optimal" and new["slow"].cost == 1.8
    assert new["hopeless"].status == "pruned" and new["hopeless"].pruned_at_iteration == 4
    assert "ratio rule: trusted cost 5 is 2.50x the reference 2" in new["hopeless"].reason
    assert new["beyond"].status == "pruned" and new["beyond"].pruned_at_iteration == 4
    assert "by the bound: no plan of it costs less than 2.1, above the best verified cost 2" in new["beyond"].reason


def test_a_candidate_solving_its_moves_alone_is_no_reference_and_not_judged_on_them():
    """A multi-goal candidate's first iterates are its moves solved alone, reported at the whole
    motion's bound with the move's (tiny) violation. They once made the best trusted cost: on
    improv-pick-pause with ``reference: trusted``, 13 of 14 candidates were pruned against such a
    bound and a robot 22 % slower than the exhaustive winner won. Now only the bound of such a
    candidate counts; its warm-up neither is trusted nor counts towards patience."""
    moves = Script("moves", (0.9,) * 5 + (3.0, 2.5, 2.2, 2.1), end="optimal", final_cost=2.1, bound=0.9, warm_up=5)
    other = Script("other", (2.4, 2.3, 2.2, 2.2, 2.2, 2.2, 2.2, 2.2, 2.2), end="optimal", final_cost=2.2, bound=1.0)
    results, progress = run_fakes([moves, other], "ratio")
    assert results["other"].status == results["moves"].status == "optimal"
    assert [p.best_cost for p in progress[:5]] == [2.4, 2.3, 2.2, 2.2, 2.2]  # never the bound 0.9
    # the same scripts without the warm-up flag: "other" pruned against the bound 0.9
    unflagged, _ = run_fakes([replace(moves, warm_up=0), other], "ratio")
    assert unflagged["other"].status == "pruned" and "reference 0.9" in unflagged["other"].reason
    # patience counts only the whole motion's untrusted iterates
    slow = Script("slow", (0.9,) * 5 + (3.0,) * 3, (0.0,) * 5 + (1.0,) * 3, end="optimal", bound=0.9, warm_up=5)
    kept, _ = run_fakes([slow, other], "ratio", patience=4)
    assert kept["slow"].status == "optimal"
    # ... and its bound alone can still prune it, above the verified reference
    hopeless = Script("hopeless", (4.0,) * 6, end="optimal", bound=4.0, warm_up=6)
    quick = Script("quick", (2.0,), end="optimal", final_cost=2.0, bound=1.0)
    bounded, _ = run_fakes([quick, hopeless], "ratio", reference="verified")
    assert bounded["hopeless"].status == "pruned" and "costs less than 4" in bounded["hopeless"].reason


def test_admission_by_bound_drops_a_candidate_before_its_first_iteration():
    """With ``admission`` 1 the candidates iterate one at a time in the order of their bounds:
    ``a`` (bound 1.0) verifies at 1.5, ``b`` (1.2) runs next and verifies at 1.3, and ``c``
    (bound 2.0, above both) is dropped without a single iteration, saying why; all at once
    (admission 0), ``c`` would have run from the first round."""
    scripts = [
        Script("c", (3.0,) * 5, end="optimal", bound=2.0),
        Script("b", (2.0, 1.6, 1.3), end="optimal", bound=1.2),
        Script("a", (1.8, 1.5), end="optimal", bound=1.0),
    ]
    log = []
    settings = PruningSettings("ratio", **{**BARE, "admission": 1})
    bounds = {s.name: s.bound for s in scripts}
    manager = PruningManager(RecordingExecutor(make_executor(scripts, 1), log), settings, bounds=bounds)
    results = {r.name: r for r in manager.run()}
    advanced = [names for entry in log if entry[0] == "advance" for names in entry[1]]
    assert advanced == ["a"] * 3 + ["b"] * 4  # one at a time, by bound; each next() that ends it counts
    assert (results["a"].status, results["a"].cost, results["b"].status, results["b"].cost) == (
        "optimal",
        1.5,
        "optimal",
        1.3,
    )
    c = results["c"]
    assert (c.status, c.iterations, c.pruned_at_iteration) == ("pruned", 0, 0)
    assert c.reason == (
        "pruned at iteration 0 by the bound: no plan of it costs less than 2, above the best verified cost 1.3"
    )
    everyone, _ = run_fakes(scripts, "ratio", **BARE)
    assert everyone["c"].iterations > 0


def test_random_scripts_match_the_rule_statement():
    rng = np.random.default_rng(20240506)
    decided_by_bounds = 0
    for trial in range(240):
        scripts = random_scripts(rng, int(rng.integers(1, 7)))
        threshold = float(rng.choice([0.2, 0.5, 1.0]))
        start = int(rng.integers(1, 4))
        rule = "ratio" if trial % 5 else "none"
        guard = {
            "window": int(rng.choice([0, 1, 3])),
            "lookahead": float(rng.choice([0.0, 1.0, 4.0])),
            "patience": int(rng.choice([0, 2, 4])),
            "reference": str(rng.choice(["trusted", "verified"])),
            "gate": float(rng.choice([0.0, 0.7, 1.5])),
        }
        results, progress = run_fakes(scripts, rule, threshold, start, **guard)
        expected = expected_outcome(scripts, rule, threshold, start, **guard)
        got = {r.name: (r.status, r.iterations, r.pruned_at_iteration) for r in results.values()}
        assert got == expected, (trial, scripts, threshold, start, guard)
        for r in results.values():
            assert r.cost_history == by_name(scripts)[r.name].costs[: r.iterations]
        assert sum(len(p.pruned) for p in progress) == sum(r.status == "pruned" for r in results.values())
        unbounded = [replace(s, bound=0.0) for s in scripts]
        decided_by_bounds += expected_outcome(unbounded, rule, threshold, start, **guard) != expected
    assert decided_by_bounds >= 5, decided_by_bounds  # the draws exercise the cost bounds, not only the iterates


def by_name(scripts):
    return {s.name: s for s in scripts}


# --------------------------------------------------------------------------------------------
# 2. Lockstep order
# --------------------------------------------------------------------------------------------


def split_rounds(log):
    """The event log cut at every ``advance`` call: one list of events per round."""
    rounds = []
    for event in log:
        if event[0] == "advance":
            rounds.append([event])
        elif rounds:
            rounds[-1].append(event)
    return rounds


@pytest.mark.parametrize("rule", ["ratio", "none"])
def test_lockstep_every_live_candidate_advances_once_per_round(rule):
    scripts = [
        Script("a", (1.0,) * 7),
        Script("b", (1.2,) * 2),  # finishes in round 3
        Script("c", (1.1,) * 5, end="failed"),  # fails in round 6
        Script("d", (3.0,) * 9),  # pruned in round 2 under ratio
        Script("e", (1.4, 1.4, 1.4, 1.6, 1.6, 1.6)),  # pruned in round 4 under ratio
    ]
    log = []
    manager = PruningManager(RecordingExecutor(make_executor(scripts, 1, log), log), PruningSettings(rule, **BARE))
    for progress in manager.rounds():
        log.append(("progress", progress))
    rounds = split_rounds(log)
    alive = [s.name for s in scripts]
    ends = {"b": 3, "c": 6, "a": 8}
    prunes = {"d": 2, "e": 4} if rule == "ratio" else {}
    if rule == "none":
        ends.update(d=10, e=7)
    assert len(rounds) == max(ends.values())
    for number, events in enumerate(rounds, start=1):
        advance, progress = events[0], [e for e in events if e[0] == "progress"][-1]
        assert advance == ("advance", tuple(alive)), number
        assert progress[0] == "progress" and progress[1].round == number
        moves = [e for e in events if e[0] in ("step", "end")]
        # each live candidate exactly once, and all of them before any pruning decision
        assert sorted(e[1] for e in moves) == sorted(alive)
        first_stop = next((i for i, e in enumerate(events) if e[0] in ("stop", "close")), len(events))
        assert all(events.index(m) < first_stop for m in moves)
        assert all(e[2] == number for e in moves if e[0] == "step")
        finished = tuple(n for n in alive if ends.get(n) == number)
        pruned = tuple(sorted(n for n in alive if prunes.get(n) == number))
        assert progress[1].finished == finished and progress[1].pruned == pruned
        if pruned:
            assert ("stop", pruned) in events
            assert sorted(e[1] for e in events if e[0] == "close") == sorted(pruned)
        alive = [n for n in alive if n not in finished and n not in pruned]
        assert progress[1].alive == len(alive)
    assert alive == []
    assert log[-1] == ("shutdown",)
    results = manager.results
    for name, end in ends.items():
        assert results[name].iterations == end - 1 and results[name].status == by_name(scripts)[name].end
    for name, at in prunes.items():
        assert (results[name].status, results[name].pruned_at_iteration, results[name].iterations) == ("pruned", at, at)


def test_closing_the_rounds_early_stops_the_live_candidates():
    scripts = [Script("a", (1.0,) * 6), Script("b", (1.1,) * 2), Script("c", (1.2,) * 6)]
    log = []
    manager = PruningManager(RecordingExecutor(make_executor(scripts, 1, log), log), PruningSettings(**BARE))
    rounds = manager.rounds()
    for progress in rounds:
        if progress.round == 4:
            break
    rounds.close()
    assert ("stop", ("a", "c")) in log and log[-1] == ("shutdown",)
    assert {n: (r.status, r.iterations) for n, r in manager.results.items()} == {
        "a": ("stopped", 4),
        "b": ("optimal", 2),
        "c": ("stopped", 4),
    }


# --------------------------------------------------------------------------------------------
# 3. Worker-count independence on scripted candidates
# --------------------------------------------------------------------------------------------

SCRIPT_SETS = [
    [Script("a", (1.0,) * 6), Script("b", (9.0, 1.5, 1.5, 1.75, 1.0, 1.0))],
    [
        Script("a", (1.0,) * 8, (0.5, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0)),
        Script("b", (2.0,) * 8, (0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0)),
        Script("c", (3.0,) * 8, (1.0,) * 8),
        Script("d", (1.6,) * 8, (GUARD_VIOLATION,) * 8),
    ],
    [
        Script("a", (1.2, 1.1), final_cost=1.0),
        Script("b", (1.4, 1.4, 1.4, 1.4, 1.55, 1.55, 1.55)),
        Script("c", (5.0, 5.0), (1.0, 1.0)),
        Script("x", (), end="failed"),
        Script("y", (2.0,) * 3, end="failed"),
    ],
    random_scripts(np.random.default_rng(7), 7),
    random_scripts(np.random.default_rng(8), 5),
]


def _progress_tuples(progress):
    return [(p.round, p.alive, p.best_cost, p.pruned, tuple(sorted(p.finished))) for p in progress]


@pytest.mark.parametrize("rule", ["ratio", "none"])
def test_same_decisions_in_process_and_with_workers(rule):
    for scripts in SCRIPT_SETS:
        reference, reference_progress = run_fakes(scripts, rule, jobs=1)
        for jobs in (2, 3):
            results, progress = run_fakes(scripts, rule, jobs=jobs)
            assert summary(results) == summary(reference) or _nan_equal(summary(results), summary(reference))
            assert _progress_tuples(progress) == _progress_tuples(reference_progress)
    deadline = time.monotonic() + 5
    while multiprocessing.active_children() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert multiprocessing.active_children() == []


def _nan_equal(a, b):
    return repr(a) == repr(b)


def test_workers_advance_in_lockstep():
    scripts = SCRIPT_SETS[1] + [Script("e", (1.0,) * 3)]
    log = []
    manager = PruningManager(RecordingExecutor(make_executor(scripts, 2), log), PruningSettings(**BARE))
    alive = {s.name for s in scripts}
    for progress in manager.rounds():
        advances = [e for e in log if e[0] == "advance"]
        assert len(advances) == progress.round and set(advances[-1][1]) == alive
        alive -= set(progress.pruned) | set(progress.finished)
    assert {n: r.iterations for n, r in manager.results.items()} == {"a": 8, "b": 2, "c": 8, "d": 2, "e": 3}


# --------------------------------------------------------------------------------------------
# Failure paths: interruption mid-command, a failing factory, a dead worker
# --------------------------------------------------------------------------------------------


class _InterruptingConnection:
    """Stands for a worker pipe; the first ``recv`` after ``arm()`` raises KeyboardInterrupt
    before reading the reply, as a Ctrl-C while the parent waits for a worker does."""

    def __init__(self, conn):
        self.conn, self.armed = conn, False

    def send(self, obj):
        self.conn.send(obj)

    def recv(self):
        if self.armed:
            self.armed = False
            raise KeyboardInterrupt
        return self.conn.recv()

    def close(self):
        self.conn.close()


def test_ctrl_c_while_waiting_for_a_worker_leaves_candidate_results():
    scripts = [Script(n, (1.0,) * 20) for n in "abcd"]
    executor = make_executor(scripts, 2)
    executor._conns = [_InterruptingConnection(c) for c in executor._conns]
    manager = PruningManager(executor, PruningSettings(**BARE))
    with pytest.raises(KeyboardInterrupt):
        for progress in manager.rounds():
            if progress.round == 2:
                executor._conns[0].armed = True
    assert set(manager.results) == set("abcd")
    assert all(isinstance(r, CandidateResult) and r.status == "stopped" for r in manager.results.values())


class _InterruptedAfterSend(_InterruptingConnection):
    """The first ``send`` after ``arm()`` delivers the command and then raises KeyboardInterrupt,
    as a signal landing just after the bytes left does: the worker's reply is due but unread."""

    def send(self, obj):
        self.conn.send(obj)
        if self.armed:
            self.armed = False
            raise KeyboardInterrupt

    def recv(self):
        return self.conn.recv()


def test_ctrl_c_just_after_a_command_left_skips_its_reply_and_stops_every_job():
    # once in 80 signal tests under load, this instant ended the run failed, reading the
    # advance's reply as the stop's (docs/known-limits.md kept the race until it was fixed)
    scripts = [Script(n, (1.0,) * 20) for n in "abcd"]
    executor = make_executor(scripts, 2)
    executor._conns = [_InterruptedAfterSend(c) for c in executor._conns]
    manager = PruningManager(executor, PruningSettings(**BARE))
    with pytest.raises(KeyboardInterrupt):
        for progress in manager.rounds():
            if progress.round == 2:
                executor._conns[0].armed = True
    assert set(manager.results) == set("abcd")
    assert all(isinstance(r, CandidateResult) and r.status == "stopped" for r in manager.results.values())


def broken_factory(context, spec: Script):
    if spec.name == "bad":
        raise RuntimeError("cannot build bad")
    return FakeCandidate(spec)


def test_factory_error_propagates_in_process():
    scripts = [Script("a", (1.0,) * 3), Script("bad", (1.0,) * 3)]
    manager = PruningManager(InProcessExecutor(broken_factory, None, scripts, ["a", "bad"]), PruningSettings(**BARE))
    try:
        manager.run()
    except Exception as exc:
        assert isinstance(exc, RuntimeError), f"{type(exc).__name__}: {exc}"


def test_a_dead_worker_does_not_leave_the_others_running():
    scripts = [Script("a", (1.0,) * 3), Script("bad", (1.0,) * 3), Script("c", (1.0,) * 3)]
    names = [s.name for s in scripts]
    executor = ProcessExecutor(broken_factory, None, scripts, names, 2)
    try:
        # the factory's error reaches the parent as it is, as in process (test above)
        with pytest.raises(RuntimeError, match=r"^cannot build bad$"):
            PruningManager(executor, PruningSettings(**BARE)).run()
        for proc in executor._procs:
            proc.join(timeout=1)
        assert not any(proc.is_alive() for proc in executor._procs)
    finally:
        for proc in executor._procs:  # only the processes this test started
            if proc.is_alive():
                proc.terminate()
                proc.join(timeout=5)


# --------------------------------------------------------------------------------------------
# 3-5. The real small scenario
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_scenario():
    return load_scenario(SMALL)


@pytest.fixture(scope="module")
def small_run_1(small_scenario, tmp_path_factory) -> tuple[RunResult, object]:
    out = tmp_path_factory.mktemp("small-jobs1")
    return run_scenario(small_scenario, out, jobs=1), out


@pytest.fixture(scope="module")
def small_run_2(small_scenario, tmp_path_factory) -> tuple[RunResult, object]:
    out = tmp_path_factory.mktemp("small-jobs2")
    result = run_scenario(small_scenario, out, jobs=2)
    return result, out


@pytest.fixture(scope="module")
def small_cli_none(tmp_path_factory):
    """``modular-robots run small.yaml --rule none`` through click: (CliRunner result, result.json)."""
    out = tmp_path_factory.mktemp("small-none")
    result = CliRunner().invoke(main, ["run", str(SMALL), "--rule", "none", "--jobs", "2", "--out", str(out)])
    document = json.loads((out / "result.json").read_text()) if (out / "result.json").exists() else None
    return result, document, out


def _per_candidate(run: RunResult):
    return [(c.name, c.status, c.iterations, c.pruned_at_iteration, len(c.cost_history)) for c in run.candidates]


def test_small_same_outcome_with_one_and_two_workers(small_run_1, small_run_2):
    one, two = small_run_1[0], small_run_2[0]
    assert one.winner.name == two.winner.name == SMALL_WINNER
    assert _per_candidate(one) == _per_candidate(two)
    assert one.rounds == two.rounds and one.iterations == two.iterations
    for a, b in zip(one.candidates, two.candidates):
        assert a.cost == pytest.approx(b.cost, rel=1e-9, abs=1e-12)
        assert np.allclose(a.cost_history, b.cost_history, rtol=1e-9)
    assert one.winner.tf == pytest.approx(SMALL_TF, abs=2e-3)
    assert multiprocessing.active_children() == []


def test_small_result_json(small_run_1):
    run, out = small_run_1
    doc = json.loads((out / "result.json").read_text())
    assert doc["status"] == "done" and doc["partial"] is False
    assert doc["scenario"] == "small"
    assert doc["settings"]["pruning"] == {
        "rule": "ratio",
        "threshold": 0.5,
        "start_iteration": 2,
        "window": 16,
        "lookahead": 2.0,
        "patience": 75,
        "reference": "verified",
        "gate": 0.7,
        "admission": 8,
    }
    counts = doc["counts"]
    assert counts["enumerated"] == 516 and counts["feasible"] == 6 and counts["optimized"] == 6
    assert sum(counts["removed"].values()) == 516 - 6
    assert counts["remaining_after"]["collision"] == 6
    assert counts["pruned"] + counts["failed"] + counts["optimal"] == 6 and counts["stopped"] == 0
    assert counts["pruned"] == sum(c.status == "pruned" for c in run.candidates)
    assert {"feasibility", "optimization", "report"} <= set(doc["seconds"])

    candidates = doc["candidates"]
    assert len(candidates) == counts["candidates"] == 6 and len({c["composition"] for c in candidates}) == 6
    assert {c["candidate"] for c in candidates} == {c["composition"] for c in candidates}
    for c in candidates:
        assert set(c) >= SPEC_CANDIDATE_FIELDS, c["composition"]
        assert c["status"] in ("optimal", "pruned", "failed")
        assert 2 <= c["dof"] <= 4
        assert len(c["cost_history"]) == c["iterations"] > 0
        assert c["cost"] == c["cost_history"][-1] or c["status"] == "optimal"
        if c["status"] == "pruned":
            assert c["pruned_at_iteration"] == c["iterations"] >= 2
        else:
            assert c["pruned_at_iteration"] is None
    assert doc["totals"]["optimizer_iterations"] == sum(c["iterations"] for c in candidates) == run.iterations

    winner = doc["winner"]
    optimal = [c for c in candidates if c["status"] == "optimal"]
    assert winner["composition"] == min(optimal, key=lambda c: c["cost"])["composition"] == SMALL_WINNER
    # The cost is the solver's scaled objective times its unit, tf the durations summed: two roundings.
    assert winner["tf"] == pytest.approx(SMALL_TF, abs=2e-3) and winner["cost"] == pytest.approx(
        winner["tf"], rel=1e-12
    )
    verification = winner["verification"]
    assert verification["passed"] is True
    assert verification["terminal_error"] <= 0.01 and verification["min_clearance"] >= 0.0
    assert set(winner["files"].values()) == {
        "winner.urdf",
        "trajectory.csv",
        "joints.png",
        "pruning.png",
        "winner.html",
    }
    for name in winner["files"].values():
        assert (out / name).is_file()
    assert not list(out.glob(".*"))  # no temporary files left behind


def test_small_winner_urdf_loads_in_pinocchio_and_yourdfpy(small_run_1):
    yourdfpy = pytest.importorskip("yourdfpy")
    _, out = small_run_1
    path = out / "winner.urdf"
    model = pin.buildModelFromUrdf(str(path))
    assert model.nq == model.nv == 4
    assert model.existFrame("base_link") and model.existFrame("tool0")
    urdf = yourdfpy.URDF.load(str(path))
    if hasattr(urdf, "validate"):
        assert urdf.validate()
    assert urdf.base_link == "base_link" and "tool0" in urdf.link_map
    assert len(urdf.actuated_joint_names) == 4
    # the payload (1 kg) is in the model
    mass = sum(link.inertial.mass for link in urdf.robot.links if link.inertial is not None)
    assert sum(i.mass for i in model.inertias) == pytest.approx(mass)
    assert any(
        link.inertial is not None and link.inertial.mass == pytest.approx(1.0)
        for link in urdf.robot.links
        if link.name == "payload"
    )


def _read_csv(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float)


def test_small_trajectory_csv(small_run_1, small_scenario):
    yourdfpy = pytest.importorskip("yourdfpy")
    run, out = small_run_1
    header, table = _read_csv(out / "trajectory.csv")
    n = run.winner.dof
    assert header == ["t", *(f"{g}{i}" for g in ("q", "qd", "qdd", "tau") for i in range(1, n + 1)), "x", "y", "z"]
    t, q, qd, qdd, tau, tool = (table[:, 0], *(table[:, 1 + k * n : 1 + (k + 1) * n] for k in range(4)), table[:, -3:])
    intervals = small_scenario.optimizer.nodes - 1
    assert len(t) >= intervals * run.winner.substeps + 1
    assert t[0] == 0.0 and t[-1] == pytest.approx(run.winner.tf, abs=1e-8)
    assert np.all(np.diff(t) > 0)
    assert np.linalg.norm(tool[0] - small_scenario.task.start) <= 1e-3
    assert np.linalg.norm(tool[-1] - small_scenario.task.goal) <= 1e-3
    assert np.abs(qd[0]).max() <= 1e-6 and np.abs(qd[-1]).max() <= 1e-6

    model = pin.buildModelFromUrdf(str(out / "winner.urdf"))
    data = model.createData()
    vmax, effort = np.asarray(model.velocityLimit), np.asarray(model.effortLimit)
    # the plan keeps the default margins below the URDF's limits
    margins = small_scenario.optimizer
    assert np.all(np.abs(qd) <= margins.velocity_margin * vmax * (1 + 1e-3)), np.max(np.abs(qd) / vmax)
    assert np.all(np.abs(tau) <= margins.effort_margin * effort * (1 + 1e-3)), np.max(np.abs(tau) / effort)
    assert np.all(q >= model.lowerPositionLimit - 1e-6) and np.all(q <= model.upperPositionLimit + 1e-6)

    # the tool columns are the URDF's tool0 in the base frame, in Pinocchio and in yourdfpy
    tool0 = model.getFrameId("tool0")
    urdf = yourdfpy.URDF.load(str(out / "winner.urdf"))
    for k in range(len(t)):
        pin.framesForwardKinematics(model, data, q[k])
        assert np.allclose(data.oMf[tool0].translation, tool[k], atol=1e-6), k
    for k in (0, len(t) // 2, len(t) - 1):
        urdf.update_cfg(q[k])
        assert np.allclose(urdf.get_transform("tool0", "base_link")[:3, 3], tool[k], atol=1e-6), k

    # the acceleration contract: each row follows from the one before under its constant qdd,
    # and tau is the URDF's inverse dynamics at the row (no armature in this catalogue)
    h = np.diff(t)[:, None]
    np.testing.assert_allclose(q[1:], q[:-1] + qd[:-1] * h + 0.5 * qdd[:-1] * h * h, rtol=0, atol=1e-9)
    np.testing.assert_allclose(qd[1:], qd[:-1] + qdd[:-1] * h, rtol=0, atol=1e-9)
    assert np.all(qdd[-1] == 0.0)  # at rest from tf on
    for k in range(len(t)):
        expected = pin.rnea(model, data, q[k], qd[k], qdd[k])
        np.testing.assert_allclose(tau[k], expected, rtol=1e-9, atol=1e-9 * effort.max())


def test_small_plots_are_pngs(small_run_1):
    _, out = small_run_1
    for name in ("joints.png", "pruning.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 1000, name


def test_small_ratio_winner_equals_brute_force_winner(small_run_1, small_cli_none):
    ratio, _ = small_run_1
    cli, doc, out = small_cli_none
    assert cli.exit_code == 0, cli.output
    assert re.search(rf"^winner +{SMALL_WINNER}$", cli.output, re.M), cli.output
    assert "steps A+B: 516 compositions checked, 6 feasible\n" in cli.output  # step B's final count shown
    assert doc["status"] == "done" and doc["settings"]["pruning"]["rule"] == "none"
    assert doc["winner"]["composition"] == ratio.winner.name == SMALL_WINNER
    assert doc["winner"]["tf"] == pytest.approx(ratio.winner.tf, rel=1e-6)
    none = {c["composition"]: c for c in doc["candidates"]}
    assert all(c["status"] != "pruned" and c["pruned_at_iteration"] is None for c in none.values())
    assert doc["counts"]["pruned"] == 0
    # pruning does not change the other candidates' optimisations, and saves iterations
    for c in ratio.candidates:
        if c.status != "pruned":
            assert (c.status, c.iterations) == (none[c.name]["status"], none[c.name]["iterations"]), c.name
            assert c.cost == pytest.approx(none[c.name]["cost"], rel=1e-9)
        else:
            assert none[c.name]["iterations"] > c.iterations
            assert none[c.name]["cost_history"][: c.iterations] == pytest.approx(list(c.cost_history), rel=1e-9)
    # every candidate here ends within 1.2x of the best, so the rule may prune none of them; the
    # totals then agree to the iteration, and each pruned candidate is a saving
    saved = sum(none[c.name]["iterations"] - c.iterations for c in ratio.candidates if c.status == "pruned")
    assert ratio.iterations == doc["totals"]["optimizer_iterations"] - saved
    for name in ("winner.urdf", "trajectory.csv", "joints.png", "pruning.png"):
        assert (out / name).is_file()


@pytest.mark.parametrize("jobs", [1, 2])
def test_small_interrupted_run_leaves_a_partial_folder(small_scenario, tmp_path, jobs):
    seen = []

    def interrupt(stage, figures):
        if stage == "optimization":
            seen.append(figures["round"])
            if figures["round"] == 3:
                raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_scenario(small_scenario, tmp_path, jobs=jobs, on_progress=interrupt)
    assert seen == [1, 2, 3]
    doc = json.loads((tmp_path / "result.json").read_text())
    assert doc["status"] == "interrupted" and doc["partial"] is True
    assert doc["winner"] is None
    assert doc["counts"]["feasible"] == 6
    assert len(doc["candidates"]) == 6
    for c in doc["candidates"]:
        assert c["status"] in ("stopped", "pruned", "optimal", "failed")
        assert c["iterations"] <= 3 and len(c["cost_history"]) == c["iterations"]
    statuses = [c["status"] for c in doc["candidates"]]
    assert "stopped" in statuses
    assert {s: doc["counts"].get(s, 0) for s in set(statuses)} == {s: statuses.count(s) for s in set(statuses)}
    assert not (tmp_path / "winner.urdf").exists()
    deadline = time.monotonic() + 5
    while multiprocessing.active_children() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert multiprocessing.active_children() == []


# --------------------------------------------------------------------------------------------
# 6. CLI: the paper's 50 kg scenario has no feasible composition
# --------------------------------------------------------------------------------------------


def test_cli_run_paper_fails_naming_static_torque(tmp_path):
    result = CliRunner().invoke(main, ["run", str(PAPER_SCENARIO), "--out", str(tmp_path), "--jobs", "2"])
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    assert "Error: no composition is feasible" in result.output
    assert "static torque test" in result.output
    match = re.search(r"best torque ratio found: ([0-9.]+) x the limit", result.output)
    assert match and float(match.group(1)) > 1.0, result.output
    doc = json.loads((tmp_path / "result.json").read_text())
    assert doc["status"] == "infeasible" and doc["partial"] is False
    assert doc["counts"]["enumerated"] == 3108 and doc["counts"]["feasible"] == 0
    assert "static torque" in doc["message"] and doc["winner"] is None


def test_a_second_boundary_pair_runs_as_a_candidate_of_its_own(small_scenario, monkeypatch, tmp_path):
    """Step B's second pair for one composition (here its second-fastest IK pair, standing in for
    a clear one: the small scenario has none) becomes the candidate NAME+clear in the worker
    processes. It optimises that pair, whose travel-time bound (at the planned velocity bounds) is
    its cost bound, and the results
    name its composition and pair."""
    name = "B-J1-L3-J1-L3-E2"
    original = feasibility._boundary_pair
    bounds = {}  # filled in this process by the check below (the run's step B is in worker processes)

    def with_second_pair(robot, collision, starts, goals):
        fastest, clear = original(robot, collision, starts, goals)
        if robot.name != name:
            return fastest, clear
        pairs = sorted(itertools.product(starts, goals), key=lambda pair: robot.travel_time_bound(*pair))
        bounds.update(fastest=robot.travel_time_bound(*pairs[0]), clear=robot.travel_time_bound(*pairs[1]))
        return fastest, pairs[1]

    monkeypatch.setattr(feasibility, "_boundary_pair", with_second_pair)
    run = run_scenario(replace(small_scenario, pruning=replace(small_scenario.pruning, rule="none")), tmp_path, jobs=2)
    composition = Composition.from_name(name, small_scenario.catalog)
    verdict = feasibility.check_composition(composition, small_scenario.catalog, small_scenario.task)
    assert verdict.clear_pair is not None and bounds["clear"] > bounds["fastest"]  # the patch, in this process
    by_name = {c.name: c for c in run.candidates}
    assert len(run.candidates) == 7 and {name, f"{name}+clear"} <= set(by_name)
    for pair in ("fastest", "clear"):
        result = by_name[name if pair == "fastest" else f"{name}+clear"]
        assert (result.composition, result.boundary_pair) == (name, pair)
        # the bound of the plan's own velocity bounds (the limits times the margin)
        margin = small_scenario.optimizer.velocity_margin
        assert result.cost_bound == pytest.approx(bounds[pair] / margin, rel=1e-12)
        assert result.status == "optimal" and result.cost >= result.cost_bound
    doc = json.loads((tmp_path / "result.json").read_text())
    assert doc["counts"]["candidates"] == 7 and doc["counts"]["optimized"] == 6
    entries = {c["candidate"]: c for c in doc["candidates"]}
    assert entries[f"{name}+clear"]["composition"] == name and entries[f"{name}+clear"]["boundary_pair"] == "clear"
