"""A best-first search over a catalogue's compositions that proves its answer (``run --search
best-first``): lower bounds first, step B only where a bound leaves a chance, and a
:class:`~modular_robots.certificate.Certificate` of what was excluded and why.

Every composition enters a frontier ordered by a lower bound on its optimal cost, which each
stage it passes raises:

0. from catalogue numbers alone (:func:`~modular_robots.bounds.catalog_bound`, microseconds);
1. after the *relaxed* step B (reach, workspace, IK from every seed step B may use, static torque;
   no collision, :meth:`~modular_robots.feasibility.FeasibilitySettings.relaxed`): the joint
   travel time of the fastest pair of its solutions, at most that of any pair step B can keep;
2. after step B itself, per candidate: the bound its problem has
   (:func:`~modular_robots.pipeline.cost_bound`).

The frontier holds one queue per stage. Each step takes from the queues the items of smallest
bound that are still below the best verified cost (a batch of each; candidates first, so that a
cost verified in the step lets the others skip what it excludes), advances them one stage
(stages 0 and 1 on the engine's workers, candidates in the lockstep of
:class:`~modular_robots.pruning.PruningManager` with the best verified cost so far as its
incumbent) and puts back what passes with its new bound. While compositions still wait for the
relaxed step B, the later stages advance once every ``interleave`` steps only: the search is
*anytime* (candidates are verified from its first steps on, however large the space; one queue in
bound order would run the relaxed step B on the whole space before any candidate, a stage-0
bound being far below the stage-1 bound of the same composition), and the share of work spent on
candidates that a later, better cost would have excluded stays bounded. The search ends when the
smallest bound left is not below the best verified cost (the winner is then the best of
everything the bounds did not exclude), when nothing is left, or at the budget.

What each step found is appended to ``search.jsonl`` in the results folder as it comes (its first
line says which scenario and settings it is of). Run again into that folder, the search reads it
back and replays the same steps without redoing their work, so it ends as an uninterrupted run
would; the steps are deterministic (step B's verdicts and each candidate's iterates do not depend
on the engine or the number of workers).
"""

from __future__ import annotations

import hashlib
import heapq
import json
import logging
import math
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import IO

import numpy as np

from .bounds import DESIGN, IK_TRAVEL, JOINT_TRAVEL, TOOL_SPEED, joint_levers, objective_bound
from .certificate import Certificate, Ledger
from .composition import Composition
from .costs import design_of
from .exceptions import CheckpointWarning, InfeasibleError, InputError, shorten
from .execution import Engine, make_engine, make_executor, single_threaded_blas
from .feasibility import (
    FeasibilitySettings,
    FeasibilitySummary,
    Verdict,
    check_compositions,
    composition_space,
)
from .folder import naming_the_file
from .frontier import bound_chunks, take_pass
from .ocp.candidate import CandidateSpec, make_candidate
from .ocp.resume import CandidateCheckpoint, CheckpointFolder
from .ocp.solver import Iterate
from .pipeline import RunResult, _labelled, candidate_specs, cost_bound, ranked, record_final_winner
from .plan.boundary import BoundaryPair
from .plan.candidate import CandidateResult, CandidateStatus
from .plan.document import stage_counts, status_counts
from .plan.verification import LIMIT_TOLERANCE
from .pruning import PruningManager
from .recorder import RunRecorder
from .replay import ReplayingExecutor, trace_from_json, trace_json
from .scenario import Scenario
from .verdicts import verdict_from_json

__all__ = ["SearchSettings", "SearchResult", "search_scenario", "STATE", "SEARCHES"]

logger = logging.getLogger(__name__)

#: ``run --search``: every composition through step B (the paper's pipeline), or this search.
SEARCHES = ("all", "best-first")
#: The search's record in the results folder.
STATE = "search.jsonl"
#: The folder (in the results folder) of the checkpoints of candidates a stop interrupted or that
#: were running (:data:`CHECKPOINT_SECONDS`).
CHECKPOINTS = "search-checkpoints"
#: While step C runs, the running candidates' checkpoints are written this often [s]: a kill -9
#: or a crash then loses at most this much of their work (a stop writes them as it ends).
CHECKPOINT_SECONDS = 60.0
#: The ``search`` version of its first line.
FORMAT = 1
#: Configurations step B keeps as one when within this distance (max norm) [rad | m]
#: (:func:`~modular_robots.ik.distinct`): the relaxed and the full cascade may keep different
#: members of such a cluster (each end can move by this), so the stage-1 bound is lowered by
#: twice this over the slowest joint's limit.
_CLUSTER = 1e-3

#: While a pass lists and bounds the space, its progress is reported this often [s] (a
#: ``("pass", figures)`` call of ``on_progress``: ``pass``, ``bounded``, ``space``, ``eta`` [s]).
PASS_PROGRESS = 2.0

#: Frontier kinds: a composition not checked yet, one through the relaxed step B, a candidate.
_UNCHECKED, _RELAXED, _CANDIDATE = 0, 1, 2
_BOUND_NAME = {_UNCHECKED: TOOL_SPEED, _RELAXED: IK_TRAVEL, _CANDIDATE: JOINT_TRAVEL}


@dataclass(frozen=True)
class SearchSettings:
    """``budget``: wall seconds after which the search ends with the best verified robot and its
    gap (None: no limit). ``batch``: compositions advanced per step through each stage of step B;
    ``candidates``: candidates optimised per step. ``interleave``: while compositions wait for
    the relaxed step B below the best cost, the whole step B and step C advance once every this
    many steps (anytime, at a bounded share of the work: their bounds cannot be compared with the
    catalogue bounds of the waiting, and a best cost found early excludes less). None of these
    depends on the number of workers, so neither does the answer, and a search stopped on one
    machine goes on on another (a cluster of many CPUs wants a larger ``batch``). ``frontier``:
    compositions held at once; a larger space is taken in passes of this many, in the order of
    their catalogue bounds (bounded memory). All but the budget are part of what a record is of."""

    budget: float | None = None
    batch: int = 64
    candidates: int = 16
    interleave: int = 8
    frontier: int = 500_000


#: A search's outcome: a :class:`~modular_robots.pipeline.RunResult` (its ``certificate`` set).
SearchResult = RunResult


@dataclass(order=True)
class _Item:
    bound: float
    order: tuple
    kind: int = field(compare=False)
    composition: Composition = field(compare=False)
    spec: CandidateSpec | None = field(default=None, compare=False)


def search_scenario(
    scenario: Scenario,
    out: str | Path | None = None,
    jobs: int | None = None,
    settings: SearchSettings = SearchSettings(),
    feasibility: FeasibilitySettings = FeasibilitySettings(),
    on_progress: Callable[[str, dict], None] | None = None,
    max_compositions: int | None = None,
) -> SearchResult:
    """The best composition of ``scenario`` by best-first search, its plan, the results folder
    (with ``search.jsonl``, resumed if it is there) and the certificate (in ``result.json``).

    Parameters are those of :func:`~modular_robots.pipeline.run_scenario`, and ``settings``.
    ``on_progress`` is called with ``("search", figures)`` after every step, and with
    ``("pass", figures)`` every :data:`PASS_PROGRESS` seconds of a pass over a large space. ``max_compositions``
    (default: none) refuses a larger space before any work.

    Raises
    ------
    InfeasibleError
        If no composition verifies (every one removed by step B, or every candidate failed) and the
        search ended; ``result.json`` then says why.
    """
    notify = on_progress or (lambda stage, figures: None)
    engine = make_engine(jobs, scenario.execution, keep=True)  # step B's batches share the workers
    try:
        return _Search(scenario, out, engine, settings, feasibility, notify, max_compositions).run()
    finally:
        engine.close()


class _Search:
    def __init__(self, scenario, out, engine: Engine, settings, feasibility, notify, max_compositions):
        self.scenario, self.out, self.engine = scenario, out, engine
        self.settings, self.feasibility, self.notify = settings, feasibility, notify
        self.space = composition_space(scenario.catalog, max_compositions or 2**62, engine.jobs)
        self.batch = settings.batch
        self.tolerance = feasibility.tolerance
        #: A composition has a chance only when its bound is below the best cost times this.
        self.band = scenario.task.cost.band
        self.ledger = Ledger.of(self.space, scenario.task.cost)
        self.summary = FeasibilitySummary()
        self.results: dict[str, CandidateResult] = {}
        self.specs: dict[str, CandidateSpec] = {}
        self.best: CandidateResult | None = None
        self.queues: dict[int, list[_Item]] = {_UNCHECKED: [], _RELAXED: [], _CANDIDATE: []}
        self.passed = 0  # compositions of the space taken into the frontier so far
        self.beyond: tuple[int, float] = (0, math.inf)  # the rest: how many, their smallest bound
        self.seconds = {"search": 0.0, "feasibility": 0.0, "optimization": 0.0}
        self.log = _Log(out, scenario, feasibility, replace(settings, budget=None))
        self.certificate: dict | None = None
        self.unchecked = 0  # compositions in the frontier not through any step B yet
        self.relaxed_cpu = [0, 0.0]  # compositions through the relaxed step B here, their CPU seconds
        self.rounds = 0
        #: Whether the budget stopped a batch of step C before its end.
        self.cut = False
        #: Candidates the budget stopped no further than a run before did (they start over: stopped
        #: before their first iterate, or their checkpoints lost).
        self.cut_again: set[str] = set()
        #: Step C's batch under way: its candidates not ended yet and its lockstep round.
        self.running = (0, 0)
        self.steps = 0
        self.stage_counts = {_UNCHECKED: 0, _RELAXED: 0}  # compositions through each step B
        #: What step B's workers get once: the catalogue, the task and each stage's settings.
        self.check_context = (
            scenario.catalog,
            scenario.task,
            {_UNCHECKED: feasibility.relaxed(), _RELAXED: feasibility},
        )
        self.first_estimate: dict | None = None
        self.passes = 0  # passes over the space so far (:meth:`_take_pass`)

    # -- the loop ---------------------------------------------------------------------------------
    def run(self) -> SearchResult:
        start = time.perf_counter()
        deadline = math.inf if self.settings.budget is None else start + self.settings.budget
        self.log.check()  # before the recorder replaces the folder's results
        with (
            RunRecorder(
                self.out,
                self.scenario,
                jobs=self.engine.jobs,
                engine=self.scenario.execution.engine,
                search="best-first",
            ) as recorder,
            self.log,
        ):
            self.recorder = recorder
            try:
                ended = self._loop(start, deadline)
            except BaseException:  # Ctrl-C, SIGTERM, an error: result.json says what had ended
                self._record(write=False)  # (the recorder writes it as it records the ending)
                raise
            certificate = self._certificate(ended)
            self.certificate = certificate.to_json()
            self._record()
            return self._finish(recorder, certificate, start)

    def _loop(self, start: float, deadline: float) -> str:
        """Step B and step C until the search ends; returns how (:class:`~modular_robots.certificate.Certificate`'s
        ``ended``)."""
        self._take_pass(None, deadline)
        while True:
            self.seconds["search"] = time.perf_counter() - start
            self._record(every=1.0)  # (result.json is rewritten at most once a second: the record keeps the work)
            lowest = self._lowest()
            if self.cut:  # candidates stopped at the budget are still open
                return "budget"
            if lowest is None:
                return "exhausted"
            if lowest >= self._limit():
                return "certified"
            if time.perf_counter() >= deadline:
                return "budget"
            if not self.queues[_UNCHECKED] and self.beyond[0] and self.beyond[1] < self._limit():
                self._take_pass(self.last_key, deadline)
                continue
            self._step(deadline)

    def _keep_results(self) -> None:
        """Give the recorder every candidate result so far and the counts, without writing."""
        results = self._ranked()
        self.recorder.update(results=results, counts=self._counts(results), every=math.inf)

    def _counts(self, results: list[CandidateResult]) -> dict:
        """``result.json``'s ``counts``: step B's over the compositions it decided, then step C's."""
        compositions = len({r.composition for r in results})  # (labelled, so never-run ones too)
        return {**self.summary.counts(), **stage_counts(compositions, len(results)), **status_counts(results)}

    def _best_cost(self) -> float:
        """The smallest verified cost so far (inf: none)."""
        return self.best.cost if self.best is not None else math.inf

    def _limit(self) -> float:
        """The bound below which a composition may still win: the best cost, times a
        lexicographic objective's tie band, a tie included where tie-breaks decide ties
        (:meth:`~modular_robots.costs.Objective.limit`)."""
        return self.scenario.task.cost.limit(self._best_cost())

    def _lowest(self) -> float | None:
        """The smallest bound left (None: nothing is left)."""
        tops = [queue[0].bound for queue in self.queues.values() if queue]
        if self.beyond[0]:
            tops.append(self.beyond[1])
        return min(tops, default=None)

    def _take(self, kind: int, count: int) -> list[_Item]:
        queue, taken = self.queues[kind], list[_Item]()
        while queue and len(taken) < count and queue[0].bound < self._limit():
            taken.append(heapq.heappop(queue))
        return taken

    def _step(self, deadline: float) -> None:
        self.steps += 1
        best = self._limit()
        unchecked = self.queues[_UNCHECKED]
        waiting = (unchecked and unchecked[0].bound < best) or (self.beyond[0] and self.beyond[1] < best)
        later = not waiting or self.steps % self.settings.interleave == 0
        candidates = self._take(_CANDIDATE, self.settings.candidates) if later else []
        if candidates:
            t0 = time.perf_counter()
            try:
                self._optimise(candidates, deadline)
            finally:  # (an interrupted run's seconds too)
                self.seconds["optimization"] += time.perf_counter() - t0
            if self.cut:  # the budget: no step B after it
                return
        checks = (self._take(_RELAXED, self.batch) if later else []) + self._take(_UNCHECKED, self.batch)
        self.unchecked -= sum(item.kind == _UNCHECKED for item in checks)
        if checks:
            t0 = time.perf_counter()
            try:
                self._check(checks)
            finally:
                self.seconds["feasibility"] += time.perf_counter() - t0

    # -- stage 0: the catalogue bounds --------------------------------------------------------------
    def _take_pass(self, after: tuple | None, deadline: float) -> None:
        """Put into the frontier the ``frontier`` compositions of smallest catalogue bound after
        the key ``after`` (all of them when the space is small enough). At the ``deadline`` the
        pass ends where it is: the compositions it has not bounded count as beyond the frontier
        with a bound of 0 (nothing is known of them)."""
        self.passes += 1
        started = shown = time.perf_counter()

        def progress(bounded: int) -> None:
            nonlocal shown
            now = time.perf_counter()
            if bounded and now - shown >= PASS_PROGRESS:
                shown = now
                left = (self.space - bounded) * (now - started) / bounded
                self.notify("pass", {"pass": self.passes, "bounded": bounded, "space": self.space, "eta": left})

        scenario = self.scenario
        taken = take_pass(
            bound_chunks(scenario.catalog, scenario.task, self.tolerance),
            self.settings.frontier,
            after,
            lambda: time.perf_counter() >= deadline,
            progress,
        )
        queue = self.queues[_UNCHECKED]
        queue.extend(_Item(bound, (bound, index), _UNCHECKED, composition) for bound, index, composition in taken.kept)
        heapq.heapify(queue)
        self.last_key = taken.kept[-1][:2] if taken.kept else after
        if taken.complete:
            self.beyond = (taken.beyond, taken.smallest)
        else:  # nothing is known of the compositions the pass did not bound
            self.beyond = (self.space - self.passed - len(taken.kept), 0.0)
        self.passed += len(taken.kept)
        self.unchecked += len(taken.kept)

    # -- stages 1 and 2: step B, relaxed then whole -------------------------------------------------
    def _check(self, items: list[_Item]) -> None:
        todo: dict[int, list[Composition]] = {_UNCHECKED: [], _RELAXED: []}
        found: dict[tuple[int, str], Verdict] = {}
        for item in items:
            cached = self.log.verdict(item.kind, item.composition)
            if cached is None:
                todo[item.kind].append(item.composition)
            else:
                found[item.kind, item.composition.name] = cached
        for kind, compositions in todo.items():
            if compositions:
                tagged = [(kind, composition) for composition in compositions]
                for verdict in self.engine.map_chunks(_check_chunk, self.check_context, tagged, chunksize=8):
                    found[kind, verdict.composition.name] = verdict
                    self.log.write_verdict(kind, verdict)
                    if kind == _UNCHECKED:
                        self.relaxed_cpu[0] += 1
                        self.relaxed_cpu[1] += sum(verdict.seconds.values())
        for item in items:
            verdict = found[item.kind, item.composition.name]
            self.stage_counts[item.kind] += 1
            if not verdict.passed:
                self.summary.add(verdict)
                self.ledger.removed(item.composition.name, verdict.failed_test or "")
            elif item.kind == _UNCHECKED:
                bound = max(item.bound, ik_bound(self.scenario, verdict))
                heapq.heappush(
                    self.queues[_RELAXED], _Item(bound, (bound, *item.order[1:]), _RELAXED, item.composition)
                )
            else:
                self.summary.add(verdict)
                for spec in candidate_specs([verdict]):
                    bound = max(item.bound, cost_bound(self.scenario, spec))
                    self.specs[spec.name] = spec
                    order = (bound, *item.order[1:], spec.name)
                    heapq.heappush(self.queues[_CANDIDATE], _Item(bound, order, _CANDIDATE, item.composition, spec))

    # -- stage 3: step C ------------------------------------------------------------------------------
    def _optimise(self, items: list[_Item], deadline: float) -> None:
        """Step C on the candidates of ``items`` in lockstep (:class:`~modular_robots.pruning.PruningManager`),
        each written to the record with its trace as it ends (a stop loses none); those the record
        has replay their trace (:class:`~modular_robots.replay.ReplayingExecutor`), so that the
        batch ends as it would have without a stop. At the ``deadline`` the lockstep stops: the
        candidates still running end ``stopped`` (unexplored, with their bound, in the
        certificate), each with a checkpoint (:mod:`~modular_robots.ocp.resume`) that a run that
        goes on resumes."""
        names = [item.spec.name for item in items if item.spec is not None]
        bounds = {item.spec.name: item.bound for item in items if item.spec is not None}
        recorded = {name: found for name in names if (found := self.log.result(name)) is not None}
        if len(recorded) < len(names):
            traced = {name: (trace, result) for name, (result, trace) in recorded.items() if trace is not None}
            scenario, jobs = self.scenario, self.engine.jobs

            def hosts(live: list[str]):
                specs = [replace(self.specs[name], checkpoint=self.log.checkpoint(name)) for name in live]
                return make_executor(make_candidate, scenario, specs, live, jobs, scenario.execution)

            executor = ReplayingExecutor(names, traced, hosts)
            incumbent = self.best.cost if self.best is not None else None
            manager = PruningManager(
                executor, self.scenario.pruning, bounds=bounds, incumbent=incumbent, band=self.band
            )
            rounds, written = manager.rounds(), set(traced)

            def record(ended) -> None:
                for name in ended:
                    if name not in written:
                        written.add(name)
                        self.results[name] = result = _labelled(manager.results[name], self.specs[name])
                        self.log.write_result(result, executor.traces[name])
                        self._better(result)

            cut = False
            saved = time.perf_counter()
            try:
                for progress in rounds:
                    self.rounds += 1
                    self.running = (progress.alive, progress.round)
                    record((*progress.finished, *progress.pruned))
                    self._record(every=1.0)
                    if progress.alive and time.perf_counter() >= deadline:
                        cut = True
                        break
                    if progress.alive and time.perf_counter() - saved >= CHECKPOINT_SECONDS:
                        self._keep_running(executor, [name for name in names if name not in manager.results])
                        saved = time.perf_counter()
            except BaseException:  # the candidates it stopped: their checkpoints, and result.json (not the record)
                rounds.close()
                for name in names:
                    if name in manager.results and name not in self.results:
                        self.results[name] = _labelled(manager.results[name], self.specs[name])
                        self.log.write_checkpoint(manager.results[name])
                raise
            finally:
                self.running = (0, 0)
                rounds.close()
                executor.shutdown()
            # (candidates dropped at admission after the last round are not in a progress)
            record(name for name in names if name in manager.results)
            recorded = {name: (_labelled(manager.results[name], self.specs[name]), None) for name in names}
            self.cut = cut and any(r.status == CandidateStatus.STOPPED for r, _ in recorded.values())
            for name, (result, _) in recorded.items():
                # (how far it got: a candidate still giving back its checkpoint's iterates keeps it)
                reached = max(result.iterations, result.checkpoint.iteration if result.checkpoint else 0)
                if self.cut and result.status == CandidateStatus.STOPPED and reached:
                    if reached <= self.log.cuts.get(name, -1):
                        self.cut_again.add(name)
                    self.log.write_checkpoint(result)
                    self.log.write_cut(name, reached)
        for name in names:
            result = recorded[name][0]
            self.results[name] = result
            self.ledger.candidate(result, bounds[name])
            self._better(result)

    def _keep_running(self, executor, running: list[str]) -> None:
        """Write the running candidates' checkpoints, for a run that goes on after a crash: best
        effort, as a stop's (a candidate whose checkpoint cannot be taken goes on from an older
        one or its start; a warning says why)."""
        if self.log.checkpoints is None:
            return
        try:
            checkpoints = executor.checkpoints(running)
        except Exception as exc:  # (a worker's error in taking one, raised here)
            warnings.warn(
                f"the running candidates' checkpoints were not taken ({exc})", CheckpointWarning, stacklevel=2
            )
            return
        self.log.write_running(checkpoints.values())

    def _better(self, result: CandidateResult) -> None:
        """Make ``result`` the best so far if it is verified and below it (ties by name). A batch's
        candidates count as they end, for the progress and ``result.json``; its own decisions were
        taken against the best before it."""
        if result.status == CandidateStatus.OPTIMAL and (
            self.best is None or (result.cost, result.name) < (self.best.cost, self.best.name)
        ):
            self.best = result

    # -- the end ---------------------------------------------------------------------------------
    def _certificate(self, ended: str) -> Certificate:
        best = self._best_cost()
        for item in (item for queue in self.queues.values() for item in queue):
            self.ledger.left(item.composition.name, item.bound, self._bound_name(item.kind), best)
        if self.beyond[0]:
            self.ledger.beyond(self.beyond[0], self.beyond[1], self._bound_name(_UNCHECKED), best)
        winner = self._winner()
        if winner is None:
            return self.ledger.certificate(None, best, ended)
        return self.ledger.certificate(winner.composition, winner.cost, ended, best)

    def _bound_name(self, kind: int) -> str:
        """The name the certificate gives a stage's bound (before step B without the time in the
        objective: the costs of the design alone)."""
        if kind == _UNCHECKED and not self.scenario.task.cost.counts_time:
            return DESIGN
        return _BOUND_NAME[kind]

    def _winner(self) -> CandidateResult | None:
        """The best verified result by the task's objective (:func:`~modular_robots.pipeline.ranked`)."""
        best = ranked(self.results.values(), self.scenario)
        return best[0] if best else None

    def _finish(self, recorder: RunRecorder, certificate: Certificate, start: float) -> SearchResult:
        results = self._ranked()
        recorder.update(results=results, counts=self._counts(results), message=certificate.line())
        if self.best is None:
            if certificate.ended == "budget":
                message = "no composition verified within the budget (run again into this folder to go on); "
                recorder.finish("failed", message + certificate.line())
            else:
                message = "no composition verified; "
                if not self.summary.feasible:  # why step B removed them all, as the exhaustive run says
                    message = f"{self.summary.diagnosis()}\n{message}"
                recorder.finish("infeasible" if not results else "failed", message + certificate.line())
            raise InfeasibleError(message + certificate.line())
        winner = self._winner()
        assert winner is not None  # there is a best verified result
        if winner.trajectory is None:  # found in an earlier session: solved again (deterministic)
            winner = _solve(self.scenario, self.specs[winner.name], winner)
            self.results[winner.name] = winner
        record_final_winner(
            recorder, winner, self.scenario, f"{self.scenario.name}: best-first search", certificate.line()
        )
        self.seconds["search"] = time.perf_counter() - start
        return SearchResult(tuple(self._ranked()), winner, self.summary, self.rounds, dict(self.seconds), certificate)

    def _ranked(self) -> list[CandidateResult]:
        """Every result: the verified by the task's objective, then the others by cost."""
        rest = (r for r in self.results.values() if r.status != CandidateStatus.OPTIMAL)
        return ranked(self.results.values(), self.scenario) + sorted(rest, key=lambda r: (r.cost, r.name))

    def _eta(self) -> float | None:
        """An estimate of the wall seconds of the relaxed step B still ahead [s]: every composition
        not through it yet, at the CPU seconds each has taken so far (None before any was
        measured). A bound may stop the search before; on improv-science2019-pick the first
        estimate was a quarter below the step B that followed (``benchmarks/RESULTS.md``)."""
        done, seconds = self.relaxed_cpu
        if not done:
            return None
        left = self.unchecked + (self.space - self.passed)
        return left * seconds / done / max(self.engine.jobs, 1)

    def _record(self, every: float = 0.0, write: bool = True) -> None:
        """Give the recorder the progress (and, when it writes, the results) and tell ``notify``;
        ``write`` False: everything, without writing or telling (the search is ending)."""
        eta = self._eta()
        figures = {
            "space": self.space,
            "checked": self.ledger.checked,
            "step_b_relaxed": self.stage_counts[_UNCHECKED],
            "step_b": self.stage_counts[_RELAXED],
            "candidates": len(self.results),
            "running": {"candidates": self.running[0], "round": self.running[1]},
            "waiting": {
                "step_b_relaxed": self.unchecked + self.space - self.passed,
                "step_b": len(self.queues[_RELAXED]),
                "step_c": len(self.queues[_CANDIDATE]),
            },
            "lowest_bound": self._lowest(),
            "best": self.best.cost if self.best is not None else None,
            "eta": eta,
            "cut_again": sorted(self.cut_again),
        }
        if self.first_estimate is None and eta is not None:
            self.first_estimate = {"at_s": round(self.seconds["search"], 3), "step_b_left_s": round(eta, 3)}
        block = {
            "kind": "best-first",
            "progress": figures,
            "first_estimate": self.first_estimate,
            "certificate": self.certificate,
        }
        if not write or self.recorder.due(every):
            self._keep_results()
        self.recorder.update(search=block, seconds=self.seconds, every=every if write else math.inf)
        if write:
            self.notify("search", figures)


def ik_bound(scenario: Scenario, verdict: Verdict) -> float:
    """The stage-1 bound of a composition through the relaxed step B: for the objective's
    time, the joint travel time of its fastest pair (:attr:`Verdict.time_bound`), less what
    the clusters' members may differ by, within the limits verification allows (0 with free
    ends: step C then chooses its own ends); with several goals, the travel between the first
    and the last configuration, which step C keeps (those between are free there), plus the
    pauses; with the objective's costs of the design
    (:func:`~modular_robots.bounds.objective_bound`)."""
    objective, catalog = scenario.task.cost, scenario.catalog
    time = 0.0
    if objective.counts_time and not scenario.optimizer.free_ends and verdict.time_bound is not None:
        limits = np.array([lever.velocity for lever in joint_levers(verdict.composition, catalog)])
        slowest = min((v for v in limits if 0.0 < v < math.inf), default=math.inf)
        travel, pauses = verdict.time_bound, 0.0
        if verdict.q_via:
            assert verdict.q_start is not None and verdict.q_goal is not None  # (a time bound has them)
            limited = np.isfinite(limits) & (limits > 0.0)
            moved = np.abs(np.subtract(verdict.q_goal, verdict.q_start))[limited] / limits[limited]
            travel = float(np.max(moved, initial=0.0))
            pauses = math.fsum(g.duration for g in scenario.task.goals if g.kind == "pause")
        time = (max(travel - 2 * _CLUSTER / slowest, 0.0) + pauses) / (1.0 + LIMIT_TOLERANCE)
    design = design_of(verdict.composition.modules, catalog) if objective.counts_design else None
    return objective_bound(objective, time, design)


def _check_chunk(context, chunk: list[tuple[int, Composition]]) -> list[Verdict]:
    """Step B of a chunk of one stage's compositions (``(stage, composition)``): the relaxed
    cascade for stage 1, the whole for stage 2."""
    catalog, task, settings = context
    return check_compositions([composition for _, composition in chunk], catalog, task, settings[chunk[0][0]])


def _solve(scenario: Scenario, spec: CandidateSpec, expected: CandidateResult) -> CandidateResult:
    """``spec``'s candidate solved again in this process: the plan of a winner found before a stop."""
    candidate = make_candidate(scenario, spec)
    with single_threaded_blas():  # as on the worker that solved it: BLAS threads round differently
        for _ in candidate.iterate():
            pass
    result = candidate.result
    assert result is not None
    if result.status != CandidateStatus.OPTIMAL or not math.isclose(result.cost, expected.cost, rel_tol=1e-9):
        raise InfeasibleError(
            f"{spec.name}: solved again after a stop, it ended {result.status} at {result.cost:.6g}, not at the "
            f"recorded {expected.cost:.6g}; remove {STATE} from the results folder and run again"
        )
    return result


# -- the record of the search ------------------------------------------------------------------------
_SUMMARY_FIELDS = (
    "name",
    "dof",
    "status",
    "reason",
    "iterations",
    "seconds",
    "cost",
    "tf",
    "constraint_violation",
    "cost_history",
    "violation_history",
    "refinement_history",
    "substeps",
    "pruned_at_iteration",
    "cost_bound",
    "composition",
    "boundary_pair",
    "q_start",
    "q_goal",
)


def _result_json(result: CandidateResult) -> dict:
    return {name: getattr(result, name) for name in (*_SUMMARY_FIELDS, "stop_times")}


def _result_from_json(document: dict) -> CandidateResult:
    values = {name: document[name] for name in _SUMMARY_FIELDS}
    values["stop_times"] = document.get("stop_times", ())  # (a record from before several goals has none)
    for name in ("cost_history", "violation_history", "refinement_history", "q_start", "q_goal", "stop_times"):
        values[name] = tuple(values[name])
    values["status"] = CandidateStatus(values["status"])
    values["boundary_pair"] = BoundaryPair(values["boundary_pair"])
    return CandidateResult(**values)


class _Log:
    """``search.jsonl``: what each step found, appended and flushed as it comes; read back when
    the search starts in a folder that has it (of the same scenario and settings)."""

    def __init__(self, out, scenario: Scenario, feasibility: FeasibilitySettings, settings: SearchSettings):
        self.path = Path(out) / STATE if out is not None else None

        def fingerprint(catalog) -> str:
            text = repr((catalog, scenario.task, scenario.optimizer, scenario.pruning, feasibility, settings))
            return hashlib.sha256(text.encode()).hexdigest()[:16]

        # Of the catalogue's modules, not of the path it was read by (relative or absolute); a
        # record written when the path was part of it is still read.
        self.fingerprint = fingerprint(replace(scenario.catalog, source=""))
        self.fingerprints = {self.fingerprint, fingerprint(scenario.catalog)}
        self.checkpoints = CheckpointFolder(Path(out) / CHECKPOINTS, self.fingerprint) if out is not None else None
        self.scenario = scenario
        self.verdicts: dict[tuple[int, str], dict] = {}
        self.results: dict[str, dict] = {}
        self.traces: dict[str, list] = {}
        #: The most iterations each candidate stopped by a budget had reached in a run before.
        self.cuts: dict[str, int] = {}
        self.file: IO[str] | None = None

    def check(self) -> None:
        """Refuse a record of another search (or not a record) before anything in the folder
        changes: the results of the run it belongs to stay as they are."""
        lines = self._lines()
        if not lines:
            return
        try:
            header = json.loads(lines[0])
        except ValueError:
            header = {}
        if (
            not isinstance(header, dict)
            or header.get("search") != FORMAT
            or header.get("fingerprint") not in self.fingerprints
        ):
            raise InputError(
                f"{shorten(self.path, 200, quote=False)}: not the record of a search of this scenario with these "
                "settings; remove it to start afresh, or choose another folder (--out)"
            )

    def _lines(self) -> list[str]:
        """The record's complete lines (a last line cut short by a stop is not one; none if the
        file is missing, or was cut before its first line ended)."""
        if self.path is None or not self.path.exists():
            return []
        with open(self.path, encoding="utf-8") as file:
            return file.read().split("\n")[:-1]

    def __enter__(self) -> _Log:
        if self.path is None:
            return self
        self.check()  # again, in the folder now locked
        lines = self._lines()
        if not lines:
            if self.checkpoints is not None:
                self.checkpoints.clear()  # (of a record removed to start afresh)
            self.file = open(self.path, "w", encoding="utf-8")
            self._write({"search": FORMAT, "fingerprint": self.fingerprint, "scenario": self.scenario.name})
            return self
        self._read(lines)
        with open(self.path, "r+", encoding="utf-8") as file:  # drop a last line cut short
            file.truncate(sum(len(line.encode()) + 1 for line in lines))
        self.file = open(self.path, "a", encoding="utf-8")
        return self

    def __exit__(self, *exc: object) -> None:
        if self.file is not None:
            file, self.file = self.file, None
            with naming_the_file(self.path or STATE):  # (what a failed write left buffered fails again)
                file.close()

    def _read(self, lines: list[str]) -> None:
        for number, line in enumerate(lines[1:], start=2):
            if not line:
                continue
            try:
                entry = json.loads(line)
                if "result" in entry:
                    self.results[entry["result"]["name"]] = entry["result"]
                    self.traces[entry["result"]["name"]] = entry["trace"]
                elif "cut" in entry:
                    self.cuts[entry["cut"]] = max(self.cuts.get(entry["cut"], 0), int(entry["iterations"]))
                elif "batch" in entry:  # a record of before results were written one by one
                    self.results.update((d["name"], d) for d in entry["results"] if d["status"] != "stopped")
                else:
                    self.verdicts[entry["stage"], entry["verdict"]["composition"]] = entry["verdict"]
            except (ValueError, KeyError, TypeError) as exc:
                raise InputError(
                    f"{shorten(self.path, 200, quote=False)}, line {number}: not a search record ({exc})"
                ) from None

    def _write(self, entry: dict) -> None:
        if self.file is not None:
            with naming_the_file(self.path or STATE):
                self.file.write(json.dumps(entry) + "\n")
                self.file.flush()

    def verdict(self, stage: int, composition: Composition) -> Verdict | None:
        document = self.verdicts.get((stage, composition.name))
        return None if document is None else verdict_from_json(document, composition)

    def write_verdict(self, stage: int, verdict: Verdict) -> None:
        self._write({"stage": stage, "verdict": {**verdict.to_json(), "seconds": verdict.seconds}})

    def checkpoint(self, name: str):
        """Candidate ``name``'s checkpoint, if a stop or a running search left one."""
        return self.checkpoints.load(name) if self.checkpoints is not None else None

    def write_checkpoint(self, result: CandidateResult) -> None:
        """Keep a stopped candidate's checkpoint, for the run that goes on (a checkpoint of a
        candidate stopped before its first iterate, or by a solver without one: none)."""
        if self.checkpoints is not None and result.status == CandidateStatus.STOPPED and result.checkpoint is not None:
            self.checkpoints.save(result.checkpoint)

    def write_running(self, checkpoints: Iterable[CandidateCheckpoint | None]) -> None:
        """Keep running candidates' checkpoints (None: a candidate without one), for a run that
        goes on after a crash."""
        if self.checkpoints is not None:
            for checkpoint in checkpoints:
                if checkpoint is not None:
                    self.checkpoints.save(checkpoint)

    def write_cut(self, name: str, iterations: int) -> None:
        """Record that a budget stopped candidate ``name`` after ``iterations`` of its own."""
        self._write({"cut": name, "iterations": iterations})

    def result(self, name: str) -> tuple[CandidateResult, list[Iterate] | None] | None:
        """The recorded end of candidate ``name`` and the trace step D saw of it (None: no trace,
        a record of whole batches), or None if it is not recorded."""
        document = self.results.get(name)
        if document is None:
            return None
        trace = self.traces.get(name)
        return _result_from_json(document), None if trace is None else trace_from_json(trace)

    def write_result(self, result: CandidateResult, trace: list[Iterate]) -> None:
        """Record how a candidate ended and its trace (never a stopped one: a run that goes on
        solves it)."""
        if result.status != CandidateStatus.STOPPED:
            self._write({"result": _result_json(result), "trace": trace_json(trace)})
            if self.checkpoints is not None:
                self.checkpoints.discard(result.name)
