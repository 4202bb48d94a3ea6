"""Steps A to E in one call: from a scenario to the best composition, its trajectory and the
results folder (SPEC §2, §7). The ``run`` command is a thin shell over :func:`run_scenario`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

from .candidate import BOUNDARY_PAIRS, Candidate, CandidateResult, composition_problem
from .exceptions import InfeasibleError
from .execution import make_engine
from .feasibility import FeasibilitySettings, FeasibilitySummary, Verdict, filter_compositions
from .pruning import InProcessExecutor, ProcessExecutor, Progress, PruningManager
from .report import (PRUNING_PLOT, ResultsFolder, plot_pruning_history, result_document, settings_json,
                     winner_json)
from .scenario import Scenario

__all__ = ["CandidateSpec", "RunResult", "candidate_specs", "run_scenario", "make_candidate", "with_pruning"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunResult:
    """The outcome of :func:`run_scenario`: every optimised candidate, the winner's result, the
    feasibility summary, round count and wall seconds per stage."""

    candidates: tuple[CandidateResult, ...]
    winner: CandidateResult
    feasibility: FeasibilitySummary
    rounds: int
    seconds: dict

    @property
    def iterations(self) -> int:
        return sum(c.iterations for c in self.candidates)


@dataclass(frozen=True)
class CandidateSpec:
    """A step-C candidate to build: a step-B survivor and the boundary pair it starts from."""

    verdict: Verdict
    boundary_pair: str = "fastest"

    @property
    def name(self) -> str:
        """The composition's name, suffixed ``+clear`` for its clear boundary pair."""
        name = self.verdict.composition.name
        return name if self.boundary_pair == "fastest" else f"{name}+{self.boundary_pair}"


def candidate_specs(survivors: Iterable[Verdict]) -> Iterator[CandidateSpec]:
    """Every candidate of the survivors: one per boundary pair step B offers (the fastest, and the
    fastest clear one when that is another pair; see
    :func:`~modular_robots.candidate.composition_problem`)."""
    for verdict in survivors:
        yield CandidateSpec(verdict, BOUNDARY_PAIRS[0])
        if verdict.clear_pair is not None:
            yield CandidateSpec(verdict, BOUNDARY_PAIRS[1])


def make_candidate(scenario: Scenario, spec: CandidateSpec) -> Candidate:
    """The step-C candidate of ``spec`` (the picklable entry point for worker processes)."""
    composition = spec.verdict.composition
    problem = composition_problem(composition, scenario.catalog, scenario.task, scenario.optimizer, spec.verdict,
                                  boundary_pair=spec.boundary_pair)
    return Candidate(problem, spec.name, composition=composition.name, boundary_pair=spec.boundary_pair)


def run_scenario(scenario: Scenario, out: str | Path | None = None, jobs: int | None = None,
                 feasibility: FeasibilitySettings = FeasibilitySettings(),
                 on_progress: Callable[[str, dict], None] | None = None) -> RunResult:
    """Enumerate, filter, optimise in lockstep with pruning, pick and export the winner.

    Parameters
    ----------
    scenario
        The task, catalogue and settings (its ``pruning`` block chooses the rule).
    out
        Results folder (SPEC §7), written as results arrive; None writes nothing.
    jobs
        Worker processes (None or 0: every core; 1: this process only).
    on_progress
        Called with ``(stage, figures)`` during the run (``feasibility`` / ``optimization``).

    Raises
    ------
    InfeasibleError
        If no composition passes step B, or every candidate's optimisation fails; ``result.json``
        then says why.
    """
    notify = on_progress or (lambda stage, figures: None)
    folder = ResultsFolder(out) if out is not None else None
    start = time.perf_counter()
    engine = make_engine(jobs)
    summary = FeasibilitySummary()
    seconds: dict[str, float] = {}
    manager: PruningManager | None = None
    specs: list[CandidateSpec] = []
    state = {"status": "running", "message": ""}

    def counts() -> dict:
        remaining = summary.remaining_after()
        out_counts = {"enumerated": summary.checked,
                      "removed": dict(summary.removed), "remaining_after": remaining,
                      "feasible": len(summary.survivors)}
        if manager is not None:
            results = list(manager.results.values())
            out_counts.update({"optimized": len(summary.survivors), "candidates": len(specs),
                               "pruned": sum(r.status == "pruned" for r in results),
                               "failed": sum(r.status == "failed" for r in results),
                               "optimal": sum(r.status == "optimal" for r in results)})
        return out_counts

    def write(winner=None, partial=True):
        if folder is None:
            return
        results = _labelled(manager.results.values(), specs) if manager else []
        folder.write_result(result_document(
            scenario, settings_json(scenario, jobs=engine.jobs), counts(), seconds, results, winner,
            time.perf_counter() - start, partial, state["status"], state["message"]))

    try:
        write()
        for verdict in filter_compositions(scenario, engine=engine, settings=feasibility):
            summary.add(verdict)
            notify("feasibility", {"checked": summary.checked, "feasible": len(summary.survivors)})
        seconds["feasibility"] = time.perf_counter() - start
        if not summary.survivors:
            state.update(status="infeasible", message=summary.diagnosis())
            write(partial=False)
            raise InfeasibleError(summary.diagnosis())

        survivors = sorted(summary.survivors, key=lambda v: (v.time_bound, v.composition.name))
        specs = list(candidate_specs(survivors))
        names = [spec.name for spec in specs]
        if engine.jobs == 1:
            executor = InProcessExecutor(make_candidate, scenario, specs, names)
        else:
            executor = ProcessExecutor(make_candidate, scenario, specs, names, engine.jobs)
        manager = PruningManager(executor, scenario.pruning)
        optimization_start = time.perf_counter()
        last_write = 0.0
        rounds = 0
        for progress in manager.rounds():
            rounds = progress.round
            notify("optimization", _progress_figures(progress, len(specs)))
            if folder is not None and time.perf_counter() - last_write > 1.0:
                seconds["optimization"] = time.perf_counter() - optimization_start
                write()
                last_write = time.perf_counter()
        seconds["optimization"] = time.perf_counter() - optimization_start
        results = _labelled(manager.results.values(), specs)
        optimal = [r for r in results if r.status == "optimal"]
        if not optimal:
            reasons = "; ".join(f"{r.name}: {r.reason}" for r in results[:3])
            state.update(status="failed", message=f"every candidate failed ({reasons})")
            write(partial=False)
            raise InfeasibleError(f"no candidate converged to a verified trajectory ({reasons})")
        winner = min(optimal, key=lambda r: (r.cost, r.name))
        winner_block = None
        if folder is not None:
            report_start = time.perf_counter()
            problem = make_candidate(scenario, specs[names.index(winner.name)]).problem
            problem = problem.refined(winner.substeps, winner.waypoints)
            files = folder.write_winner(problem, winner)
            plot_pruning_history(results, winner.name, folder.file(PRUNING_PLOT),
                                 f"{scenario.name}: rule {scenario.pruning.rule}")
            files["pruning_plot"] = PRUNING_PLOT
            seconds["report"] = time.perf_counter() - report_start
            winner_block = winner_json(winner, files)
        state.update(status="done")
        write(winner_block, partial=False)
        return RunResult(tuple(results), winner, summary, rounds, dict(seconds))
    except KeyboardInterrupt:
        state.update(status="interrupted", message="interrupted by the user; candidates still running "
                                                   "were stopped")
        write()
        raise


def _labelled(results: Iterable[CandidateResult], specs: list[CandidateSpec]) -> list[CandidateResult]:
    """``results`` with their composition and boundary pair filled in where a candidate never ran
    (a result made without its :class:`~modular_robots.candidate.Candidate`)."""
    by_name = {spec.name: spec for spec in specs}
    return [r if r.composition or r.name not in by_name else
            replace(r, composition=by_name[r.name].verdict.composition.name,
                    boundary_pair=by_name[r.name].boundary_pair) for r in results]


def _progress_figures(progress: Progress, total: int) -> dict:
    return {"round": progress.round, "alive": progress.alive, "total": total, "best_cost": progress.best_cost,
            "best_optimal": progress.best_optimal,
            "pruned": progress.pruned, "finished": progress.finished}


def with_pruning(scenario: Scenario, rule: str | None = None, threshold: float | None = None) -> Scenario:
    """``scenario`` with its pruning rule and/or threshold overridden."""
    overrides = {k: v for k, v in (("rule", rule), ("threshold", threshold)) if v is not None}
    return replace(scenario, pruning=replace(scenario.pruning, **overrides)) if overrides else scenario

