"""Step D's lockstep, replayed where it has been recorded.

A search stopped in the middle of a batch (a budget, Ctrl-C, a crash) has recorded the candidates
that ended before the stop, each with its *trace*: the iterates step D saw from it, round by round.
Run again, the batch is formed anew; :class:`ReplayingExecutor` gives step D the recorded
candidates' traces and ends (no solve), and hosts the others: those the stop cut short go on from
their checkpoints (:mod:`~modular_robots.ocp.resume`; they yield their iterates again first), the
rest start. Step C and step D are deterministic, so the lockstep takes the same decisions as the
uninterrupted run: the same candidates are pruned in the same rounds, and the batch ends as it
would have without the stop, while no candidate that had ended is solved twice.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

from .execution import Executor
from .ocp.resume import NO_Y
from .ocp.resume import trace_from_rows as trace_from_json
from .ocp.resume import trace_rows as trace_json
from .ocp.solver import Iterate
from .plan.candidate import CandidateResult

__all__ = ["ReplayingExecutor", "trace_json", "trace_from_json"]


class ReplayingExecutor:
    """An :class:`~modular_robots.execution.Executor` of ``names`` (step D's order) whose
    ``recorded`` jobs (name -> trace and result) replay, one iterate per step, then end with their
    result, while ``make_inner(names)`` hosts the others. It keeps the trace of every job it
    advances (:attr:`traces`), so that a job's end can be recorded with it."""

    def __init__(
        self,
        names: Sequence[str],
        recorded: dict[str, tuple[list[Iterate], CandidateResult]],
        make_inner: Callable[[list[str]], Executor],
    ):
        self._names = list(names)
        self._recorded = recorded
        self._position = dict.fromkeys(recorded, 0)
        live = [name for name in self._names if name not in recorded]
        self._inner = make_inner(live) if live else None
        #: The iterates each job has given so far (without their decision vectors).
        self.traces: dict[str, list[Iterate]] = {name: [] for name in self._names}

    def names(self) -> list[str]:
        return list(self._names)

    def advance(self, names: Sequence[str]) -> dict[str, tuple[bool, Any]]:
        live = [name for name in names if name not in self._recorded]
        out = self._inner.advance(live) if live and self._inner is not None else {}
        for name in names:
            if name in self._recorded:
                trace, result = self._recorded[name]
                k = self._position[name]
                self._position[name] = k + 1
                out[name] = (False, trace[k]) if k < len(trace) else (True, result)
            ended, value = out[name]
            if not ended:
                self.traces[name].append(replace(value, y=NO_Y))
        return out

    def stop(self, names: Sequence[str]) -> dict[str, Any]:
        live = [name for name in names if name not in self._recorded]
        out = self._inner.stop(live) if live and self._inner is not None else {}
        out.update((name, self._recorded[name][1]) for name in names if name in self._recorded)
        return out

    def checkpoints(self, names: Sequence[str]) -> dict[str, Any]:
        live = [name for name in names if name not in self._recorded]
        out = dict.fromkeys(names)
        if live and self._inner is not None:
            out.update(self._inner.checkpoints(live))
        return out

    def shutdown(self) -> None:
        if self._inner is not None:
            self._inner.shutdown()
