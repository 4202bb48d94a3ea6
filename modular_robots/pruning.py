"""Step D: advance every candidate's optimisation in lockstep and prune the clearly worse ones
(SPEC §6).

One *round* advances every live candidate by one solver iteration, then applies the rule to all
of them. The rules are plain functions of the round's costs:

* ``none`` (brute force) never prunes;
* ``ratio`` (the paper's) prunes candidate ``k`` at iteration ``l >= start_iteration`` when
  ``(c_k - c_ref) / c_ref > threshold``.

**The guard.** A cost read at an infeasible iterate can be far too low (a minimum-time iterate
that still cuts through an obstacle or breaks continuity is "fast"), and pruning against it would
discard the true winner. So the reference ``c_ref`` is the smallest cost among *trusted* iterates
only: a candidate that has converged (its verified cost), or a live one whose constraint
violation is at most ``guard_violation``. While no iterate is trusted, nobody is pruned. The
same holds for the other side of the comparison: a candidate is pruned only on a trusted cost of
its own, because trust-constr typically lengthens ``tf`` while it restores feasibility and
shortens it afterwards (measured on the small test scenario: the eventual winner went from 1.57 s
to 3.44 s and back to 1.57 s, and the unguarded rule pruned it at 3.44 s). A candidate that has
converged is never pruned. One that is re-solving after a failed verification is judged on the
optimum of its previous solve, not on its iterates (they are transients of the refinement): for
the inverse transcription the refined problem keeps every constraint of the coarse one and adds
more, so that optimum is a lower bound of what the re-solve can reach. And every candidate is
also judged on a lower bound of its final cost, whether or not its iterates are trusted: the
minimum time its busiest joint needs at its velocity limit
(:attr:`~modular_robots.shooting.ShootingProblem.cost_bound`; 0 for the ``effort`` cost). A
candidate whose bound alone is clearly worse than the reference is pruned from
``start_iteration`` on, as soon as there is a reference, before it spends iterations on becoming
feasible.

Two refinements of the guard, both in :class:`~modular_robots.scenario.PruningSettings`:

* **progress** (``window``, ``lookahead``): a trusted cost can still be far from the
  candidate's optimum. Measured on low-10kg: the brute-force winner is first trusted at 6.7 s
  (iteration 16) and comes within 1 % of its optimum, 1.02 s, only at iteration 209; the bare
  rule prunes it on a trusted cost at any threshold up to 1.5. So a candidate is judged only
  when it was already trusted ``window`` iterations ago, and it is kept while the fall of its cost over that window,
  repeated ``lookahead`` more times, would bring it back within the threshold: a candidate far
  above the reference needs a steep fall to be kept, one just above it a gentle one. The
  defaults (an 8-iteration window, 2 more: 16 iterations ahead) were chosen by replaying
  brute-force runs of paper-5kg and of low-10kg through this manager on two sets of histories:
  those of the commit that first set a window (swept over windows 3-20 and lookaheads 0-3; it
  chose 6 and 3) and those after the solver changes of the next session, which move every
  candidate's path (swept over windows 3-12 and lookaheads 1-3). trust-constr's progress is
  bursty, so the boundary moves: on the second set (6, 3) prunes the low-10kg winner at
  iteration 45 (cost 4.14 s, falling 0.6 s over the window; the next iteration it was at
  3.16 s, and it ends at 1.02 s), and so does every window below 7, and a lookahead of 1 with
  windows 7-9. (8, 2) sits inside the region that keeps both
  winners on both sets, with every neighbour (windows 7-9, lookaheads 1.5-2.5) keeping them
  too; it saves 3.04x and 2.99x iterations on the two paper-5kg replays, against 3.12x and
  3.15x for (6, 3).
* **patience**: a candidate whose iterates are never trusted is never judged by the ratio, and
  such candidates mostly end at the iteration limit. Once a reference exists, a candidate that
  has not been trusted for ``patience`` iterations in a row is pruned (measured: every candidate
  that converged on paper-5kg and low-10kg was first trusted by iteration 49, but one at 358, at
  1.96 times the winner's cost).

Where the candidates run is an :class:`Executor`'s business (this process, or worker processes
that each host several candidates and advance them on command), so the lockstep and the pruning
decisions do not depend on the number of workers.
"""

from __future__ import annotations

import logging
import multiprocessing
import signal
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from .candidate import Candidate, CandidateResult
from .exceptions import ModularRobotsError
from .scenario import PruningSettings
from .solver import Iterate

__all__ = ["Progress", "Executor", "InProcessExecutor", "ProcessExecutor", "PruningManager", "ratio_rule", "reference_cost",
           "GUARD_VIOLATION"]

logger = logging.getLogger(__name__)

#: Largest scaled constraint violation of an iterate trusted as the pruning reference.
GUARD_VIOLATION = 1e-3


def reference_cost(costs: Mapping[str, float], violations: Mapping[str, float],
                   converged: Mapping[str, float], guard_violation: float = GUARD_VIOLATION) -> float | None:
    """The guarded reference: the smallest converged cost or cost of a live iterate whose
    violation is ``<= guard_violation``; None when nothing is trusted yet."""
    trusted = [c for k, c in costs.items() if violations[k] <= guard_violation]
    trusted += list(converged.values())
    return min(trusted) if trusted else None


def ratio_rule(costs: Mapping[str, float], violations: Mapping[str, float], converged: Mapping[str, float],
               iteration: int, threshold: float = 0.5, start_iteration: int = 2,
               guard_violation: float = GUARD_VIOLATION, earlier: Mapping[str, float] | None = None,
               lookahead: float = 0.0, untrusted_for: Mapping[str, int] | None = None,
               patience: int = 0, floors: Mapping[str, float] | None = None) -> set[str]:
    """Names of the live candidates (keys of ``costs``) to prune after round ``iteration``: those
    whose own iterate is trusted and whose cost exceeds the guarded reference by more than
    ``threshold`` (relative).

    With ``earlier`` (the progress guard), a candidate is judged only if it also had a trusted
    cost ``earlier[k]`` a window of iterations ago, and it is kept while
    ``c_k - lookahead * (earlier[k] - c_k)`` is within the threshold: still converging towards it.
    With ``patience > 0``, a candidate whose iterates have not been trusted for
    ``untrusted_for[k] >= patience`` iterations is pruned too, once a reference exists.
    ``floors`` are lower bounds of candidates' final costs (the problem's
    :attr:`~modular_robots.shooting.ShootingProblem.cost_bound`, or a re-solve's previous optimum):
    a candidate whose bound exceeds the threshold is pruned whatever its iterate; one absent from
    ``costs`` is judged on its bound only and is no reference.
    """
    if iteration < start_iteration:
        return set()
    reference = reference_cost(costs, violations, converged, guard_violation)
    if reference is None or reference <= 0.0:
        return set()
    chosen = set()
    for k, c in costs.items():
        if violations[k] > guard_violation:
            if patience and untrusted_for is not None and untrusted_for.get(k, 0) >= patience:
                chosen.add(k)
            continue
        if (c - reference) / reference <= threshold:
            continue
        if earlier is not None and (k not in earlier
                                    or (c - lookahead * (earlier[k] - c) - reference) / reference <= threshold):
            continue
        chosen.add(k)
    chosen |= {k for k, b in (floors or {}).items() if (b - reference) / reference > threshold}
    return chosen


@dataclass(frozen=True)
class Progress:
    """After each round: its number, the candidates still live, the rule's guarded reference
    ``best_cost`` (the best trusted cost in this round, None before any: it can rise when a
    trusted iterate loses its trust), who was pruned or finished in this round, and
    ``best_optimal``, the smallest cost of a candidate that has converged so far (None before
    any; it never rises)."""

    round: int
    alive: int
    best_cost: float | None
    pruned: tuple[str, ...] = ()
    finished: tuple[str, ...] = ()
    best_optimal: float | None = None


class Executor(Protocol):
    """Hosts the candidates and advances them on command (one solver iteration each)."""

    def names(self) -> list[str]: ...

    def advance(self, names: Sequence[str]) -> dict[str, Iterate | CandidateResult]:
        """One iteration of each named candidate: its new iterate, or its result if it ended."""
        ...

    def stop(self, names: Sequence[str]) -> dict[str, CandidateResult]:
        """Close the named candidates and return their results (status ``stopped``)."""
        ...

    def shutdown(self) -> None: ...


def _advance(candidates: dict, iterators: dict, names) -> dict:
    out = {}
    for name in names:
        try:
            out[name] = next(iterators[name])
        except StopIteration:
            out[name] = candidates[name].result
    return out


def _stop(candidates: dict, names) -> dict:
    out = {}
    for name in names:
        candidates[name].close()
        out[name] = candidates[name].result
    return out


class InProcessExecutor:
    """The candidates as generators in this process: ``factory(context, spec)`` builds one
    :class:`~modular_robots.candidate.Candidate` per spec, when first advanced."""

    def __init__(self, factory: Callable[[Any, Any], Candidate], context: Any, specs: Sequence[Any],
                 names: Sequence[str]):
        self._names = list(names)
        self._pending = dict(zip(self._names, specs))
        self._factory, self._context = factory, context
        self._candidates: dict[str, Candidate] = {}
        self._iterators: dict = {}

    def names(self) -> list[str]:
        return list(self._names)

    def _build(self, names) -> None:
        for name in names:
            if name not in self._candidates:
                candidate = self._factory(self._context, self._pending[name])
                del self._pending[name]
                self._candidates[name] = candidate
                self._iterators[name] = candidate.iterate()

    def advance(self, names):
        self._build(names)
        return _advance(self._candidates, self._iterators, names)

    def stop(self, names):
        out = {name: _never_started(name) for name in names if name not in self._candidates}
        out.update(_stop(self._candidates, [n for n in names if n in self._candidates]))
        return out

    def shutdown(self) -> None:
        for candidate in self._candidates.values():
            if candidate.result is None:
                candidate.close()


def _never_started(name: str) -> CandidateResult:
    nan = float("nan")
    return CandidateResult(name, 0, "stopped", "stopped before it started", 0, 0.0, nan, nan, nan, cost_bound=nan)


def _worker(conn, factory, context, specs, names) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when to stop (Ctrl-C)
    executor = InProcessExecutor(factory, context, specs, names)
    try:
        while True:
            command, names = conn.recv()
            if command == "advance":
                conn.send(executor.advance(names))
            elif command == "stop":
                conn.send(executor.stop(names))
            else:
                break
    except (EOFError, KeyboardInterrupt):
        pass
    finally:
        executor.shutdown()
        conn.close()


class ProcessExecutor:
    """Worker processes that each host a fixed share of the candidates (round robin) and advance
    them on command, so the lockstep holds across processes. A distributed engine only has to
    offer the same four methods."""

    def __init__(self, factory: Callable[[Any, Any], Candidate], context: Any, specs: Sequence[Any],
                 names: Sequence[str], jobs: int):
        self._names = list(names)
        jobs = max(1, min(jobs, len(self._names)))
        ctx = multiprocessing.get_context()
        self._owner = {name: i % jobs for i, name in enumerate(self._names)}
        self._conns, self._procs = [], []
        self._awaiting: set[int] = set()
        for w in range(jobs):
            mine = [i for i, n in enumerate(self._names) if self._owner[n] == w]
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, factory, context, [specs[i] for i in mine],
                                                     [self._names[i] for i in mine]), daemon=True)
            proc.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(proc)

    def names(self) -> list[str]:
        return list(self._names)

    def _command(self, command: str, names, tolerate_dead: bool = False) -> dict:
        by_worker: dict[int, list[str]] = {}
        for name in names:
            by_worker.setdefault(self._owner[name], []).append(name)
        out = {}
        for w, mine in by_worker.items():
            try:
                if w in self._awaiting:  # a reply left unread by an interruption
                    self._conns[w].recv()
                    self._awaiting.discard(w)
                self._conns[w].send((command, mine))
                self._awaiting.add(w)
            except (EOFError, OSError) as exc:
                if not tolerate_dead:
                    raise ModularRobotsError(f"worker process {w} died ({exc!r})") from exc
                out.update({name: _never_started(name) for name in mine})
        for w in by_worker:
            if w not in self._awaiting:
                continue
            try:
                out.update(self._conns[w].recv())
                self._awaiting.discard(w)
            except (EOFError, OSError) as exc:
                self._awaiting.discard(w)
                if not tolerate_dead:
                    raise ModularRobotsError(f"worker process {w} died ({exc!r})") from exc
                out.update({name: _never_started(name) for name in by_worker[w]})
        return out

    def advance(self, names):
        return self._command("advance", names)

    def stop(self, names):
        return self._command("stop", names, tolerate_dead=True)

    def shutdown(self) -> None:
        for conn in self._conns:
            try:
                conn.send(("exit", []))
            except (BrokenPipeError, OSError):
                pass
        for proc in self._procs:
            proc.join(timeout=10)
            if proc.is_alive():
                proc.terminate()


@dataclass
class PruningManager:
    """Run the candidates of ``executor`` in lockstep under ``settings`` (see the module docstring).

    :meth:`rounds` is a generator of :class:`Progress`; afterwards :attr:`results` holds one
    :class:`~modular_robots.candidate.CandidateResult` per candidate, in the executor's order.
    """

    executor: Executor
    settings: PruningSettings = field(default_factory=PruningSettings)
    guard_violation: float = GUARD_VIOLATION
    results: dict[str, CandidateResult] = field(default_factory=dict)
    last: dict[str, Iterate] = field(default_factory=dict)
    #: Per candidate seen: its trusted cost (None if untrusted) in each of its last window + 1
    #: rounds, and how many rounds in a row its iterate has not been trusted.
    trusted: dict[str, deque] = field(default_factory=dict)
    untrusted_for: dict[str, int] = field(default_factory=dict)
    #: Per candidate re-solving after a failed verification: the cost its previous solve reached.
    floor: dict[str, float] = field(default_factory=dict)

    def rounds(self) -> Iterator[Progress]:
        order = self.executor.names()
        alive = list(order)
        converged: dict[str, float] = {}
        round_ = 0
        try:
            while alive:
                round_ += 1
                stepped = self.executor.advance(alive)
                finished = []
                for name in alive:
                    value = stepped[name]
                    if isinstance(value, CandidateResult):
                        self.results[name] = value
                        finished.append(name)
                        if value.status == "optimal":
                            converged[name] = value.cost
                    else:
                        self._remember(name, value)
                alive = [n for n in alive if n not in self.results]
                pruned = self._prune(alive, converged, round_)
                if pruned:
                    for name, result in self.executor.stop(pruned).items():
                        self.results[name] = result.pruned(round_)
                    alive = [n for n in alive if n not in pruned]
                best = reference_cost({n: self.last[n].cost for n in alive if n in self.last},
                                      {n: self.last[n].constraint_violation for n in alive if n in self.last},
                                      converged, self.guard_violation)
                yield Progress(round_, len(alive), best, tuple(sorted(pruned)), tuple(finished),
                               min(converged.values()) if converged else None)
        finally:
            try:
                if alive:
                    for name, result in self.executor.stop(alive).items():
                        self.results.setdefault(name, result)
            except Exception:  # noqa: BLE001 - a dead worker must not hide the original error
                logger.debug("stopping the live candidates failed", exc_info=True)
            finally:
                self.executor.shutdown()
        self.results = {name: self.results[name] for name in order}

    def run(self) -> list[CandidateResult]:
        for _ in self.rounds():
            pass
        return list(self.results.values())

    def _prune(self, alive: list[str], converged: dict[str, float], round_: int) -> list[str]:
        if self.settings.rule == "none":
            return []
        # A candidate re-solving with refined sub-steps starts from an optimum that failed
        # verification; its cost jumps while the new sub-step constraints are restored (measured:
        # 2.13 s -> 11.5 s -> 2.14 s), so it is judged on that optimum and is no reference.
        live = [n for n in alive if n in self.last and self.last[n].refinement == 0]
        floors = {n: max(self.last[n].cost_bound, self.floor.get(n, 0.0) if self.last[n].refinement > 0 else 0.0)
                  for n in alive if n in self.last}
        costs = {n: self.last[n].cost for n in live}
        violations = {n: self.last[n].constraint_violation for n in live}
        s = self.settings
        earlier = None
        if s.window:
            earlier = {n: self.trusted[n][0] for n in live
                       if len(self.trusted[n]) == s.window + 1 and self.trusted[n][0] is not None}
        chosen = ratio_rule(costs, violations, converged, round_, s.threshold, s.start_iteration,
                            self.guard_violation, earlier, s.lookahead, self.untrusted_for, s.patience,
                            floors)
        return [n for n in alive if n in chosen]

    def _remember(self, name: str, iterate: Iterate) -> None:
        previous = self.last.get(name)
        if previous is not None and iterate.refinement > previous.refinement:
            self.floor[name] = previous.cost
        self.last[name] = iterate
        ok = iterate.constraint_violation <= self.guard_violation
        self.trusted.setdefault(name, deque(maxlen=self.settings.window + 1)).append(
            iterate.cost if ok else None)
        self.untrusted_for[name] = 0 if ok else self.untrusted_for.get(name, 0) + 1
