"""Steps A to E in one call: from a scenario to the best composition, its trajectory and the
results folder (SPEC §2, §7). The ``run`` and ``optimize`` commands are thin shells over
:func:`run_scenario` and :func:`optimize_composition`.

Data flows one way: step B's verdicts become :class:`~modular_robots.ocp.candidate.CandidateSpec`
values (a composition and its boundary states), step C turns each into a
:class:`~modular_robots.plan.candidate.CandidateResult` that carries its sampled trajectory, and
the :class:`~modular_robots.recorder.RunRecorder` writes what it is given.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable, Generator, Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import cast

import numpy as np

from .certificate import Certificate, Ledger
from .collision import Approach, CollisionModel, closest_approach
from .composition import Composition
from .costs import Objective
from .exceptions import CompositionError, InfeasibleError, Terminated, shorten
from .execution import make_engine, make_executor, single_threaded_blas
from .feasibility import (
    MAX_COMPOSITIONS,
    FeasibilitySettings,
    FeasibilitySummary,
    Verdict,
    check_composition,
    composition_space,
    filter_compositions,
)
from .ocp.candidate import CandidateSpec, make_candidate
from .ocp.ends import task_ends
from .ocp.route import route_cost_bound, task_route
from .ocp.solver import ITERATION_LIMIT, Iterate
from .plan.boundary import BoundaryPair
from .plan.candidate import CandidateResult, CandidateStatus
from .plan.document import result_design, single_composition_counts, stage_counts, status_counts
from .plan.tracking import Tracking, track
from .pruning import Progress, PruningManager
from .recorder import RunRecorder
from .robot import robot_from_urdf, robot_model
from .scenario import Scenario

__all__ = [
    "RunResult",
    "candidate_specs",
    "cost_bound",
    "exhaustive_certificate",
    "optimize_composition",
    "ranked",
    "result_design",
    "run_scenario",
    "track_winner",
    "winner_approach",
    "with_execution",
    "with_pruning",
]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunResult:
    """The outcome of :func:`run_scenario` (or :func:`optimize_composition`): every optimised
    candidate, the winner's result, the feasibility summary, round count and wall seconds per
    stage."""

    candidates: tuple[CandidateResult, ...]
    winner: CandidateResult
    feasibility: FeasibilitySummary
    rounds: int
    seconds: dict
    #: What the run proves about its winner (:mod:`~modular_robots.certificate`); None for
    #: :func:`optimize_composition`, which looks at one composition.
    certificate: Certificate | None = None

    @property
    def iterations(self) -> int:
        return sum(c.iterations for c in self.candidates)

    def unconverged_below_winner(self, constraint_tolerance: float, band: float = 1.0) -> tuple[CandidateResult, ...]:
        """The candidates that failed at the iteration limit with a plan feasible at its nodes
        (scaled constraint violation at most ``constraint_tolerance``) and a cost below the
        winner's (with a lexicographic objective's tie ``band``: below the best verified cost
        times it, where a robot may still win on its tie-breaks), lowest cost first. Only
        converged candidates are ranked (SPEC §2), so none of these can win; a higher iteration
        limit might let one converge and win."""
        verified = [c.cost for c in self.candidates if c.status == CandidateStatus.OPTIMAL]
        limit = min(verified, default=self.winner.cost) * band if band != 1.0 else self.winner.cost
        below = (
            c
            for c in self.candidates
            if c.status == CandidateStatus.FAILED
            and c.reason.startswith(ITERATION_LIMIT)
            and c.constraint_violation <= constraint_tolerance
            and c.cost < limit
        )
        return tuple(sorted(below, key=lambda c: c.cost))


def candidate_specs(survivors: Iterable[Verdict]) -> Iterator[CandidateSpec]:
    """Every step-C candidate of step B's survivors: one per boundary pair a verdict offers (the
    fastest, and the fastest clear one when that is another pair; see
    :func:`~modular_robots.ocp.candidate.make_candidate`)."""
    for verdict in survivors:
        assert verdict.q_start is not None and verdict.q_goal is not None  # a survivor has its boundary pair
        yield CandidateSpec(verdict.composition, verdict.q_start, verdict.q_goal, BoundaryPair.FASTEST, verdict.q_via)
        if verdict.clear_pair is not None:
            yield CandidateSpec(verdict.composition, *verdict.clear_pair, BoundaryPair.CLEAR)


def cost_bound(scenario: Scenario, spec: CandidateSpec) -> float:
    """The lower bound on ``spec``'s optimal cost before it is optimised, the one its problem will
    have (:attr:`~modular_robots.ocp.shooting.ShootingProblem.cost_bound`): the task's cost's
    :meth:`~modular_robots.costs.Cost.lower_bound` at the plan's velocity bounds."""
    cost = scenario.task.cost.cost
    if not cost.bounded:  # (no time: the pauses add nothing)
        return 0.0
    route = task_route(scenario.task, spec.q_via)
    robot = robot_model(spec.composition, scenario.catalog, scenario.task.payload)
    velocity_bound = scenario.optimizer.velocity_margin * robot.velocity_limit
    free_ends = task_ends(scenario.task) if scenario.optimizer.free_ends else None
    q_start, q_goal = np.asarray(spec.q_start, dtype=float), np.asarray(spec.q_goal, dtype=float)
    return route_cost_bound(cost, robot, q_start, q_goal, velocity_bound, free_ends, route)


def ranked(results: Iterable[CandidateResult], scenario: Scenario) -> list[CandidateResult]:
    """The verified results, best first by the task's objective
    (:meth:`~modular_robots.costs.Objective.rank`: the cost, and within a lexicographic order's
    tie band the costs of the design)."""
    optimal = [r for r in results if r.status == CandidateStatus.OPTIMAL]
    return scenario.task.cost.rank(optimal, lambda r: r.cost, lambda r: result_design(r, scenario), lambda r: r.name)


def _winner(results: Iterable[CandidateResult], scenario: Scenario) -> CandidateResult | None:
    best = ranked(results, scenario)
    return best[0] if best else None


def run_scenario(
    scenario: Scenario,
    out: str | Path | None = None,
    jobs: int | None = None,
    feasibility: FeasibilitySettings = FeasibilitySettings(),
    on_progress: Callable[[str, dict], None] | None = None,
    max_compositions: int = MAX_COMPOSITIONS,
) -> RunResult:
    """Enumerate, filter, optimise in lockstep with pruning, pick and export the winner.

    Parameters
    ----------
    scenario
        The task, catalogue and settings (its ``pruning`` block chooses the rule).
    out
        Results folder (SPEC §7), written as results arrive; None writes nothing.
    jobs
        Worker processes (None or 0: every core; 1: this process only); with the ``ray`` engine
        (``scenario.execution``), the CPUs of a Ray instance of the run's own (a cluster at an
        address has its own).
    on_progress
        Called with ``(stage, figures)`` during the run (``feasibility`` / ``optimization``).
    max_compositions
        Refuse a catalogue whose grammar allows more compositions, before any work
        (:func:`~modular_robots.feasibility.composition_space`).

    Raises
    ------
    InputError
        If the catalogue allows more than ``max_compositions`` compositions.
    InfeasibleError
        If no composition passes step B, or every candidate's optimisation fails; ``result.json``
        then says why.
    """
    notify = on_progress or (lambda stage, figures: None)
    engine = make_engine(jobs, scenario.execution)
    try:
        return _run(scenario, out, engine, feasibility, notify, max_compositions)
    finally:
        engine.close()


def _run(scenario, out, engine, feasibility, notify, max_compositions) -> RunResult:
    composition_space(scenario.catalog, max_compositions, engine.jobs)
    summary = FeasibilitySummary()
    start = time.perf_counter()
    with RunRecorder(out, scenario, jobs=engine.jobs, engine=scenario.execution.engine) as recorder:
        stream = filter_compositions(scenario, engine=engine, settings=feasibility, max_compositions=max_compositions)
        with contextlib.closing(cast(Generator, stream)):  # an ending stops step B's workers here, then is recorded
            for verdict in stream:
                summary.add(verdict)
                notify("feasibility", {"checked": summary.checked, "feasible": summary.feasible})
        recorder.update(counts=summary.counts(), seconds={"feasibility": time.perf_counter() - start})
        if not summary.feasible:
            recorder.finish("infeasible", summary.diagnosis())
            raise InfeasibleError(summary.diagnosis())

        survivors = sorted(summary.survivors, key=lambda v: (v.time_bound, v.composition.name))
        bounds = {spec.name: cost_bound(scenario, spec) for spec in candidate_specs(survivors)}
        # in the order of their bounds: the order they are admitted in, and (round robin) the
        # workers' shares, so that the candidates iterating together are spread over the workers
        specs = sorted(candidate_specs(survivors), key=lambda spec: (bounds[spec.name], spec.name))
        optimization_start = time.perf_counter()
        rounds = 0
        manager: PruningManager | None = None

        def record(every: float = 0.0) -> list[CandidateResult]:
            if not recorder.due(every):  # a round is milliseconds; gathering 30,000 results is not
                return []
            done: dict[str, CandidateResult] = manager.results if manager is not None else {}
            results = [
                _labelled(done.get(spec.name) or CandidateResult.never_started(spec.name), spec) for spec in specs
            ]
            recorder.update(
                counts=status_counts(results),
                results=results,
                every=every,
                seconds={"optimization": time.perf_counter() - optimization_start},
            )
            return results

        executor = make_executor(
            make_candidate, scenario, specs, [s.name for s in specs], engine.jobs, scenario.execution
        )
        try:  # from here on, any ending stops the workers and records every candidate
            manager = PruningManager(executor, scenario.pruning, bounds=bounds, band=scenario.task.cost.band)
            recorder.update(counts=stage_counts(len(survivors), len(specs)))
            for progress in manager.rounds():
                rounds = progress.round
                notify("optimization", _progress_figures(progress, len(specs)))
                record(every=1.0)
        finally:
            executor.shutdown()
            results = record()
        winner = _winner(results, scenario)
        if winner is None:
            reasons = "; ".join(f"{r.name}: {r.reason}" for r in results[:3])
            recorder.finish("failed", f"every candidate failed ({reasons})")
            raise InfeasibleError(f"no candidate converged to a verified trajectory ({reasons})")
        certificate = exhaustive_certificate(summary, results, bounds, winner, scenario.task.cost)
        recorder.update(search={"kind": "all", "certificate": certificate.to_json()})
        record_final_winner(recorder, winner, scenario, f"{scenario.name}: rule {scenario.pruning.rule}")
        return RunResult(tuple(results), winner, summary, rounds, dict(recorder.seconds), certificate)


def exhaustive_certificate(
    summary: FeasibilitySummary,
    results: Iterable[CandidateResult],
    bounds: dict[str, float],
    winner: CandidateResult,
    objective: Objective | None = None,
) -> Certificate:
    """The certificate of a run that put every composition through step B: each removed by its
    test, each of the others by its candidates' ends (:class:`~modular_robots.certificate.Ledger`,
    with ``objective``'s :meth:`~modular_robots.costs.Objective.limit` and bound name)."""
    results = list(results)
    ledger = Ledger.of(summary.checked, objective)
    for test, count in summary.removed.items():
        ledger.removed_many(test, count)
    for result in results:
        ledger.candidate(result, bounds.get(result.name, 0.0))
    best = min(r.cost for r in results if r.status == CandidateStatus.OPTIMAL)
    return ledger.certificate(winner.composition, winner.cost, "exhausted", best)


def optimize_composition(
    scenario: Scenario,
    name: str,
    out: str | Path | None = None,
    on_iterate: Callable[[str, Iterate], None] | None = None,
) -> RunResult:
    """Step C for one composition, in this process: a verified minimum-cost trajectory and its
    results folder (``result.json`` has the best candidate as the winner).

    ``name`` is a composition (optimised from each boundary pair step B offers, one after the
    other, the better verified motion winning) or ``NAME+clear`` / ``NAME+fastest`` (that pair
    only). ``on_iterate(candidate, iterate)`` is called after every solver iteration.

    Raises
    ------
    CompositionError
        If ``name`` is not a composition of the catalogue, or names a pair it does not have.
    InfeasibleError
        If the composition fails step B, or no candidate verifies.
    """
    base, _, only = name.partition("+")
    if only and only not in tuple(BoundaryPair):
        raise CompositionError(f"{shorten(name)}: the suffix after '+' must be one of {', '.join(tuple(BoundaryPair))}")
    chain = Composition.from_name(base, scenario.catalog)
    start = time.perf_counter()
    verdict = check_composition(chain, scenario.catalog, scenario.task)
    summary = FeasibilitySummary()
    summary.add(verdict)
    if not verdict.passed:
        raise InfeasibleError(f"{chain.name} cannot do the task: {verdict.message}")
    specs = [s for s in candidate_specs([verdict]) if not only or s.boundary_pair == only]
    if not specs:
        raise CompositionError(
            f"{chain.name} has no clear boundary pair: the straight line of its fastest pair "
            "already clears the obstacles, or no pair's line does"
        )
    notify = on_iterate or (lambda candidate, iterate: None)
    candidates = [make_candidate(scenario, spec) for spec in specs]
    with RunRecorder(out, scenario, rule="single composition") as recorder:
        recorder.update(
            counts=single_composition_counts(len(candidates)),
            seconds={"feasibility": time.perf_counter() - start},
        )

        def record() -> list[CandidateResult]:
            results = [c.result for c in candidates if c.result is not None]
            recorder.update(
                counts=status_counts(results),
                results=results,
                seconds={"optimization": sum(c.seconds for c in candidates)},
            )
            return results

        try:
            with single_threaded_blas():
                for candidate in candidates:
                    for it in candidate.iterate():
                        notify(candidate.name, it)
                    record()
        except KeyboardInterrupt as exc:
            for candidate in candidates:
                candidate.close()
            done = _winner(record(), scenario)
            if done is not None:
                recorder.record_winner(done)
            recorder.finish(
                "interrupted",
                (str(exc) if isinstance(exc, Terminated) else "interrupted by the user")
                + (f"; {done.name} had already verified and is written as the winner so far" if done else ""),
            )
            raise
        finally:
            for candidate in candidates:
                if candidate.result is None:
                    candidate.close()
        results = record()
        winner = _winner(results, scenario)
        if winner is None:
            reason = "; ".join(f"{r.name}: {r.reason}" for r in results)
            recorder.finish("failed", reason)
            raise InfeasibleError(reason)
        record_final_winner(recorder, winner, scenario)
        return RunResult(tuple(results), winner, summary, 0, dict(recorder.seconds))


def _labelled(result: CandidateResult, spec: CandidateSpec) -> CandidateResult:
    """``result`` with its composition and boundary pair filled in if it never ran."""
    if result.composition:
        return result
    return replace(result, composition=spec.composition.name, boundary_pair=spec.boundary_pair)


def record_final_winner(
    recorder: RunRecorder, winner: CandidateResult, scenario: Scenario, title: str | None = None, message: str = ""
) -> None:
    """Write the verified ``winner`` with its closed-loop check and closest approach, and end the
    run ``done`` with ``message``. Interrupted meanwhile (the check and the files take about a
    second), the winner is still written, without the check, and the run ends ``interrupted``:
    a Ctrl-C in the last second of a long run lost it."""
    try:
        recorder.record_winner(winner, title, track_winner(winner), winner_approach(winner, scenario))
    except KeyboardInterrupt as exc:
        reason = str(exc) if isinstance(exc, Terminated) else "interrupted by the user"
        recorder.record_winner(winner, title)
        recorder.finish("interrupted", f"{reason}; {winner.name} had verified and is written as the winner")
        raise
    recorder.finish("done", message)


def winner_approach(result: CandidateResult, scenario: Scenario, samples: int = 401) -> Approach | None:
    """Where an optimal result's plan comes closest to an obstacle, on ``samples`` instants of its
    trajectory (:func:`~modular_robots.collision.closest_approach`); None without obstacles."""
    if not scenario.task.collision_obstacles:
        return None
    trajectory = result.trajectory
    assert trajectory is not None  # an optimal result carries its plan
    composition = Composition.from_name(result.composition or result.name, scenario.catalog)
    robot = robot_model(composition, scenario.catalog, scenario.task.payload)
    times = np.linspace(0.0, float(trajectory.t[-1]), samples)
    collision = CollisionModel(robot, scenario.task.collision_obstacles)
    return closest_approach(collision, times, trajectory.at(times)[0])


def track_winner(result: CandidateResult) -> Tracking:
    """The closed-loop check of an optimal result's plan on its exported URDF and drives
    (:func:`~modular_robots.plan.tracking.track`)."""
    urdf, drive, trajectory = result.urdf, result.drive, result.trajectory
    assert urdf is not None and drive is not None and trajectory is not None  # an optimal result has all three
    return track(robot_from_urdf(urdf, drive["armature"]), trajectory)


def _progress_figures(progress: Progress, total: int) -> dict:
    return {
        "round": progress.round,
        "alive": progress.alive,
        "total": total,
        "best_cost": progress.best_cost,
        "best_optimal": progress.best_optimal,
        "pruned": progress.pruned,
        "finished": progress.finished,
    }


def with_execution(scenario: Scenario, engine: str | None = None, address: str | None = None) -> Scenario:
    """``scenario`` with its engine and/or Ray address overridden (an address implies ``ray``)."""
    if engine is None and address is None:
        return scenario
    engine = engine or ("ray" if address is not None else scenario.execution.engine)
    if address is None and engine == scenario.execution.engine:
        address = scenario.execution.address
    return replace(
        scenario, execution=replace(scenario.execution, engine=engine, address=address if engine == "ray" else None)
    )


def with_pruning(scenario: Scenario, rule: str | None = None, threshold: float | None = None) -> Scenario:
    """``scenario`` with its pruning rule and/or threshold overridden."""
    if rule is None and threshold is None:
        return scenario
    pruning = scenario.pruning
    rule = pruning.rule if rule is None else rule
    threshold = pruning.threshold if threshold is None else threshold
    return replace(scenario, pruning=replace(pruning, rule=rule, threshold=threshold))
