"""Replays of brute-force histories through the real :class:`~modular_robots.pruning.PruningManager`.

A candidate's iterates do not depend on who else is pruned, so feeding each candidate's recorded
history to the manager gives, for any rule and settings, the decisions a live run would take,
without solving again (refinement phases come from each result's ``refinement_history``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from modular_robots.ocp.candidate import CandidateResult, CandidateStatus
from modular_robots.ocp.solver import Iterate
from modular_robots.pruning import PruningManager
from modular_robots.scenario import PruningSettings

__all__ = ["ReplayExecutor", "replay"]


class ReplayExecutor:
    """An executor whose candidates replay recorded results, one iteration per step."""

    def __init__(self, results: list[CandidateResult], bounds: bool = True):
        self.results = {r.name: r if bounds else replace(r, cost_bound=0.0) for r in results}
        self.step = dict.fromkeys(self.results, 0)

    def names(self) -> list[str]:
        return list(self.results)

    def advance(self, names):
        out = {}
        for name in names:
            r, k = self.results[name], self.step[name]
            if k < len(r.cost_history):
                self.step[name] = k + 1
                refinement = r.refinement_history[k] if r.refinement_history else 0
                iterate = Iterate(
                    k + 1,
                    r.cost_history[k],
                    r.violation_history[k],
                    r.cost_history[k],
                    np.empty(0),
                    refinement=refinement,
                    cost_bound=r.cost_bound,
                )
                out[name] = (False, iterate)
            else:
                out[name] = (True, r)
        return out

    def stop(self, names):
        return {n: replace(self.results[n], status=CandidateStatus.STOPPED, iterations=self.step[n]) for n in names}

    def shutdown(self):
        pass


def replay(results: list[CandidateResult], settings: PruningSettings, bounds: bool = True) -> dict:
    """The outcome of ``settings`` on recorded ``results``: iterations used, the winner, whether it
    is the recorded winner, how many were pruned, and the pruned candidates' names with reasons."""
    truth = min((r for r in results if r.status == CandidateStatus.OPTIMAL), key=lambda r: (r.cost, r.name))
    known = {r.name: r.cost_bound for r in results} if bounds else {}
    out = PruningManager(ReplayExecutor(results, bounds), settings, bounds=known).run()
    used = sum(r.pruned_at_iteration if r.status == CandidateStatus.PRUNED else r.iterations for r in out)
    optimal = [r for r in out if r.status == CandidateStatus.OPTIMAL]
    winner = min(optimal, key=lambda r: (r.cost, r.name)) if optimal else None
    return {
        "iterations": used,
        "saving_x": sum(r.iterations for r in results) / used,
        "winner": winner.name if winner else None,
        "same_winner": winner is not None and winner.name == truth.name,
        "pruned": {r.name: r.reason for r in out if r.status == CandidateStatus.PRUNED},
    }
