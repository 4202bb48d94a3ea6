"""Step D: advance every candidate's optimisation in lockstep and prune the clearly worse ones
(SPEC §6).

One *round* advances every live candidate by one solver iteration, then applies the rule to all
of them. The rules are plain functions of the round's costs:

* ``none`` (brute force) never prunes;
* ``paper`` (the paper's, as printed, for comparison) prunes candidate ``k`` at iteration
  ``l >= start_iteration`` when ``(c_k - c_min) / c_min > threshold``, ``c_min`` the smallest
  current cost, feasible or not;
* ``ratio`` (the default) is the paper's ratio behind a guard, with a safe bound rule beside it.

**The bound rule (safe).** Every candidate has a lower bound on its optimal cost, valid by
construction: no motion within the plan's velocity bounds is faster than its busiest joint
moving at its bound all the way
(:attr:`~modular_robots.ocp.shooting.ShootingProblem.cost_bound`; 0 for the ``effort`` cost). A
candidate whose bound exceeds the best *verified* cost can never win, and is dropped.

**Admission by bound.** Candidates enter the lockstep in the order of their lower bounds, at most
``admission`` (8) at a time, so that the likely winners verify early; a candidate admitted after a
verified cost exists and whose bound exceeds it is dropped before its first iteration.

**The guard.** A cost read at an infeasible iterate can be far too low (a minimum-time iterate
that still cuts through an obstacle or breaks continuity is "fast"), and a feasible iterate's
cost can be several times the candidate's optimum (trust-constr lengthens ``tf`` while it
restores feasibility and shortens it afterwards; on the scenario suite, winners were trusted at
up to 7.7 times their final cost). So:

* the reference ``c_ref`` is the best *verified* cost (``reference: verified``, the default;
  ``trusted`` also admits live iterates whose constraint violation is at most
  ``guard_violation``); while there is none, nobody is pruned by the ratio;
* a candidate is pruned only on a *trusted* cost of its own;
* the **gate**: a candidate whose lower bound is below ``gate`` times the reference is judged on
  its bound only, never on its iterates: it may still beat the reference, however its iterates
  look. Only candidates whose bound already comes close to the reference are judged on their
  (trusted) iterates, and those rarely fall far;
* a candidate that has converged is never pruned, and one re-solving after a failed verification
  is judged on the optimum of its previous solve (a refined problem keeps every constraint of the
  coarse one) and is no reference;
* a candidate whose bound alone is clearly worse than the reference is pruned, whether or not its
  iterates are trusted.

How the defaults were chosen, and what each part costs or saves on the scenario suite, is in
``docs/design-notes.md``.

Two refinements of the guard, both in :class:`~modular_robots.scenario.PruningSettings`:

* **progress** (``window``, ``lookahead``): a trusted cost can still be far from the
  candidate's optimum (on low-10kg the brute-force winner is first trusted at 6.6 times its
  final cost). So a candidate is judged only when it was already trusted ``window`` iterations
  ago, and it is kept while the fall of its cost over that window, repeated ``lookahead`` more
  times, would bring it back within the threshold: a candidate far above the reference needs a
  steep fall to be kept, one just above it a gentle one. How the defaults (16, 2) were chosen, on
  replays of brute-force histories, is in ``docs/design-notes.md``.
* **patience**: a candidate whose iterates are never trusted is never judged by the ratio, and
  such candidates mostly end at the iteration limit. Once a reference exists, a candidate that
  has not been trusted for ``patience`` iterations in a row is pruned.

Where the candidates run is :mod:`~modular_robots.execution`'s business (this process, worker
processes that each host several candidates and advance them on command, or a Ray actor per
candidate); the manager only decides, so its decisions do not depend on the number of workers or
the engine. A candidate whose worker dies under it (:class:`~modular_robots.execution.Lost`) is
reported ``failed`` with the reason, and the others go on.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Generator, Mapping
from dataclasses import dataclass, field, replace

from .execution import Executor, Lost
from .ocp.candidate import CandidateResult, CandidateStatus
from .ocp.solver import Iterate
from .scenario import PruningSettings

__all__ = [
    "Progress",
    "PruningManager",
    "RoundCosts",
    "bound_rule",
    "paper_rule",
    "ratio_rule",
    "reference_cost",
    "GUARD_VIOLATION",
]

logger = logging.getLogger(__name__)

#: The name the incumbent cost goes by among the converged candidates (no candidate's: names are
#: never empty).
INCUMBENT = ""

#: Largest scaled constraint violation of an iterate trusted as the pruning reference.
GUARD_VIOLATION = 1e-3


def reference_cost(
    costs: Mapping[str, float],
    violations: Mapping[str, float],
    converged: Mapping[str, float],
    guard_violation: float = GUARD_VIOLATION,
) -> float | None:
    """The guarded reference: the smallest converged cost or cost of a live iterate whose
    violation is ``<= guard_violation``; None when nothing is trusted yet."""
    trusted = [c for k, c in costs.items() if violations[k] <= guard_violation]
    trusted += list(converged.values())
    return min(trusted) if trusted else None


@dataclass(frozen=True)
class RoundCosts:
    """What the rule sees after round ``iteration``.

    ``costs`` and ``violations``: the current iterate of each live candidate that is judged on
    its iterates; ``converged``: the verified cost of each candidate that has converged;
    ``earlier``: each live candidate's trusted cost a window of iterations ago (None: no progress
    guard); ``untrusted_for``: how many iterations in a row each has not been trusted;
    ``floors``: lower bounds of candidates' final costs (the problem's
    :attr:`~modular_robots.ocp.shooting.ShootingProblem.cost_bound`, or a re-solve's previous
    optimum).
    """

    iteration: int
    costs: Mapping[str, float]
    violations: Mapping[str, float]
    converged: Mapping[str, float] = field(default_factory=dict)
    earlier: Mapping[str, float] | None = None
    untrusted_for: Mapping[str, int] = field(default_factory=dict)
    floors: Mapping[str, float] = field(default_factory=dict)


def ratio_rule(
    view: RoundCosts,
    settings: PruningSettings = PruningSettings(),
    guard_violation: float = GUARD_VIOLATION,
    band: float = 1.0,
) -> dict[str, str]:
    """The candidates to prune after a round, each with the reason: those whose own iterate is
    trusted and whose cost exceeds the guarded reference by more than ``settings.threshold``
    (relative), from ``settings.start_iteration`` on.

    With ``view.earlier`` (the progress guard), a candidate is judged only if it also had a
    trusted cost ``earlier[k]`` a window of iterations ago, and it is kept while
    ``c_k - lookahead * (earlier[k] - c_k)`` is within the threshold: still converging towards it.
    With ``settings.patience > 0``, a candidate whose iterates have not been trusted for
    ``untrusted_for[k] >= patience`` iterations is pruned too, once a reference exists. A
    candidate whose floor exceeds the threshold is pruned whatever its iterate. Nothing within
    ``band`` (a lexicographic objective's tie band) of the reference is pruned, where the band is
    wider than the threshold: the design may still choose it. One absent from ``view.costs`` is
    judged on its floor only and is no reference.
    """
    if view.iteration < settings.start_iteration:
        return {}
    live = view.costs if settings.reference == "trusted" else {}
    reference = reference_cost(live, view.violations, view.converged, guard_violation)
    if reference is None or reference <= 0.0:
        return {}

    margin = max(settings.threshold, band - 1.0)  # a robot within the tie band may still win

    def above(cost: float) -> bool:
        return (cost - reference) / reference > margin

    def versus(what: str, cost: float) -> str:
        return (
            f"ratio rule: {what} {cost:.4g} is {cost / reference:.2f}x the reference {reference:.4g} "
            f"(threshold {settings.threshold:g})"
        )

    chosen: dict[str, str] = {}
    for k, c in view.costs.items():
        if view.floors.get(k, 0.0) < settings.gate * reference:
            continue  # its lower bound leaves it a chance to win: only its bound can prune it
        if view.violations[k] > guard_violation:
            if settings.patience and view.untrusted_for.get(k, 0) >= settings.patience:
                chosen[k] = (
                    f"ratio rule: not trusted (violation > {guard_violation:g}) for "
                    f"{view.untrusted_for[k]} iterations, patience {settings.patience}"
                )
            continue
        if not above(c):
            continue
        if view.earlier is not None and (
            k not in view.earlier or not above(c - settings.lookahead * (view.earlier[k] - c))
        ):
            continue
        chosen[k] = versus("trusted cost", c)
    for k, b in view.floors.items():
        if above(b) and b > reference * band and k not in chosen:
            chosen[k] = versus("lower bound", b)
    return chosen


def paper_rule(view: RoundCosts, settings: PruningSettings = PruningSettings()) -> dict[str, str]:
    """The paper's rule as printed, for comparison: from ``start_iteration`` on, prune ``k`` when
    ``(c_k - c_min) / c_min > threshold``, ``c_min`` the smallest current cost of any candidate
    (feasible or not) or converged one; no guard, no bounds."""
    costs = list(view.costs.values()) + list(view.converged.values())
    if view.iteration < settings.start_iteration or not costs or min(costs) <= 0.0:
        return {}
    reference = min(costs)
    return {
        k: f"paper rule: cost {c:.4g} is {c / reference:.2f}x the best {reference:.4g} "
        f"(threshold {settings.threshold:g})"
        for k, c in view.costs.items()
        if (c - reference) / reference > settings.threshold
    }


def bound_rule(bounds: Mapping[str, float], converged: Mapping[str, float], band: float = 1.0) -> dict[str, str]:
    """Safe pruning: a candidate whose lower bound on its optimal cost exceeds the best verified
    cost (times ``band``, a lexicographic objective's tie band,
    :attr:`~modular_robots.costs.Objective.band`) can never win, whatever its iterates; no
    threshold and no heuristic."""
    if not converged:
        return {}
    best = min(converged.values())
    within = "" if band == 1.0 else f" and its tie band of {band - 1.0:.3g}"
    return {
        k: f"bound: no plan of it costs less than {b:.4g}, above the best verified cost {best:.4g}{within}"
        for k, b in bounds.items()
        if b > best * band * (1.0 + 1e-12)
    }


@dataclass(frozen=True)
class Progress:
    """After each round: its number, the candidates still live, ``best_cost``, the best trusted
    cost in this round (None before any: it can rise when a trusted iterate loses its trust; the
    ratio rule's reference only under ``reference: trusted``), who was pruned or finished in this round, and
    ``best_optimal``, the smallest cost of a candidate that has converged so far (None before
    any; it never rises)."""

    round: int
    alive: int
    best_cost: float | None
    pruned: tuple[str, ...] = ()
    finished: tuple[str, ...] = ()
    best_optimal: float | None = None


@dataclass
class PruningManager:
    """Run the candidates of ``executor`` in lockstep under ``settings`` (see the module docstring).

    :meth:`rounds` is a generator of :class:`Progress`; afterwards :attr:`results` holds one
    :class:`~modular_robots.ocp.candidate.CandidateResult` per candidate, in the executor's order.
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
    #: Lower bounds of the candidates' costs known before they start (for admission by bound).
    bounds: Mapping[str, float] = field(default_factory=dict)
    #: The best verified cost of candidates outside this manager (an earlier batch of a search),
    #: None if none: a reference from the first round, as if one of these had converged to it.
    incumbent: float | None = None
    #: A lexicographic objective's tie band (:attr:`~modular_robots.costs.Objective.band`): the
    #: bound rule drops a candidate only when its bound exceeds the best verified cost times this.
    band: float = 1.0

    def rounds(self) -> Generator[Progress, None, None]:
        order = self.executor.names()
        admit = self.settings.admission if self.settings.rule == "ratio" else 0
        # With admission, candidates enter the lockstep in the order of their lower bounds, at
        # most ``admit`` at a time, so that a verified cost can drop the others before they start.
        waiting = deque(sorted(order, key=lambda n: self.bounds.get(n, 0.0)) if admit else [])
        alive = [] if admit else list(order)
        converged: dict[str, float] = {} if self.incumbent is None else {INCUMBENT: self.incumbent}
        round_ = 0
        try:
            while True:
                round_ += 1
                dropped = self._admit(alive, waiting, admit, converged)
                if not alive:
                    break
                stepped = self.executor.advance(alive)
                finished = []
                for name in alive:
                    ended, value = stepped[name]
                    if isinstance(value, Lost):
                        value = self._lost(name, value.reason)
                    if ended:
                        self.results[name] = value
                        finished.append(name)
                        if value.status == CandidateStatus.OPTIMAL:
                            converged[name] = value.cost
                    else:
                        self._remember(name, value)
                alive[:] = [n for n in alive if n not in self.results]
                reasons = self._prune(alive, converged, round_)
                pruned = [n for n in alive if n in reasons]
                if pruned:
                    for name, result in self._stop(pruned).items():
                        own = self.last[name].iteration if name in self.last else 0
                        self.results[name] = result.pruned(own, reasons[name])
                    alive[:] = [n for n in alive if n not in reasons]
                whole = [n for n in alive if n in self.last and not self.last[n].warm_up]
                best = reference_cost(
                    {n: self.last[n].cost for n in whole},
                    {n: self.last[n].constraint_violation for n in whole},
                    converged,
                    self.guard_violation,
                )
                yield Progress(
                    round_,
                    len(alive) + len(waiting),
                    best,
                    tuple(sorted(pruned + dropped)),
                    tuple(finished),
                    min(converged.values()) if converged else None,
                )
        finally:
            try:
                if alive:
                    for name, result in self._stop(alive).items():
                        self.results.setdefault(name, result)
            except Exception:
                logger.debug("stopping the live candidates failed", exc_info=True)
                for name in alive:
                    stopped = CandidateResult.never_started(name, "stopped; its worker did not answer")
                    self.results.setdefault(name, stopped)
            finally:
                self.executor.shutdown()
            for name in waiting:
                self.results.setdefault(name, CandidateResult.never_started(name))
        self.results = {name: self.results[name] for name in order}

    def _admit(self, alive: list[str], waiting: deque, admit: int, converged: dict[str, float]) -> list[str]:
        """Move waiting candidates into ``alive`` up to ``admit`` live ones; one whose bound
        already exceeds the best verified cost is dropped before its first iteration. Returns
        the dropped names."""
        dropped = []
        while waiting and len(alive) < admit:
            name = waiting.popleft()
            reason = bound_rule({name: self.bounds.get(name, 0.0)}, converged, self.band).get(name)
            if reason is None:
                alive.append(name)
            else:
                self.results[name] = CandidateResult.never_started(name).pruned(0, reason)
                dropped.append(name)
        return dropped

    def run(self) -> list[CandidateResult]:
        for _ in self.rounds():
            pass
        return list(self.results.values())

    def _lost(self, name: str, reason: str) -> CandidateResult:
        """The result of a candidate whose worker died: ``failed``, after the iterations it had
        reported."""
        own = self.last[name].iteration if name in self.last else 0
        return replace(
            CandidateResult.never_started(name),
            status=CandidateStatus.FAILED,
            reason=f"{reason} (after {own} iteration(s))",
            iterations=own,
        )

    def _stop(self, names: list[str]) -> dict[str, CandidateResult]:
        return {
            name: result if result is not None else CandidateResult.never_started(name)
            for name, result in self.executor.stop(names).items()
        }

    def _prune(self, alive: list[str], converged: dict[str, float], round_: int) -> dict[str, str]:
        """The live candidates to prune after round ``round_``, with the reason of each."""
        rule = self.settings.rule
        if rule == "none":
            return {}
        # A candidate re-solving with refined sub-steps starts from an optimum that failed
        # verification; its cost jumps while the new sub-step constraints are restored, so it is
        # judged on that optimum and is no reference. One solving its moves alone (``warm_up``)
        # has no cost of its own yet: only its bound can prune it.
        live = [n for n in alive if n in self.last and self.last[n].refinement == 0 and not self.last[n].warm_up]
        costs = {n: self.last[n].cost for n in live}
        violations = {n: self.last[n].constraint_violation for n in live}
        if rule == "paper":
            return paper_rule(RoundCosts(round_, costs, violations, converged), self.settings)
        bounds = {n: self.last[n].cost_bound for n in alive if n in self.last}
        floors = {n: max(bounds[n], self.floor.get(n, 0.0) if self.last[n].refinement > 0 else 0.0) for n in bounds}
        s = self.settings
        earlier = None
        if s.window:
            earlier = {
                n: self.trusted[n][0]
                for n in live
                if len(self.trusted[n]) == s.window + 1 and self.trusted[n][0] is not None
            }
        view = RoundCosts(round_, costs, violations, converged, earlier, self.untrusted_for, floors)
        return {**ratio_rule(view, s, self.guard_violation, self.band), **bound_rule(bounds, converged, self.band)}

    def _remember(self, name: str, iterate: Iterate) -> None:
        previous = self.last.get(name)
        if previous is not None and iterate.refinement > previous.refinement:
            self.floor[name] = previous.cost
        self.last[name] = iterate
        ok = iterate.constraint_violation <= self.guard_violation and not iterate.warm_up
        self.trusted.setdefault(name, deque(maxlen=self.settings.window + 1)).append(iterate.cost if ok else None)
        if not iterate.warm_up:  # (patience counts the whole motion's iterates)
            self.untrusted_for[name] = 0 if ok else self.untrusted_for.get(name, 0) + 1
