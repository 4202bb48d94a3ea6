"""What a search proves about its winner: every composition of the space in one class, and from
the classes whether the winner is optimal or how far from optimal it can be.

The classes (they add up to the space):

* **solved**: at least one of its candidates was optimised to its end (verified, or failed with
  a diagnosis);
* **removed by step B**, by test (reach, workspace, inverse kinematics, static torque,
  collision);
* **excluded by a bound**, by the bound's name: its lower bound is not below the winner's cost
  (:mod:`~modular_robots.bounds`, the search's stages);
* **pruned by the ratio rule**: not certified, the rule is a heuristic;
* **unexplored**: the search ended (at its budget) before it looked at them.

The winner is **certified optimal** among the certified classes when no unexplored composition
and no failed candidate has a bound below its cost; the ratio-pruned are named apart. The
**gap** counts everything that is not excluded, the ratio-pruned too: the winner's cost over the
smallest bound among them (1: nothing can be better).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from .bounds import DESIGN, JOINT_TRAVEL
from .costs import Objective
from .plan.candidate import CandidateResult, CandidateStatus

__all__ = ["Certificate", "Ledger"]

#: A bound below the best cost by less than this share is taken as equal (rounding).
_EQUAL = 1e-12


@dataclass(frozen=True)
class Certificate:
    """The classes' counts (``removed`` by step-B test, ``bounded`` by bound name), the smallest
    bound of the unexplored, the winner and its cost [SI], ``open_bound`` (the smallest bound of
    what is neither solved nor excluded, ratio-pruned included; None: nothing), ``certified``,
    ``gap`` and how the search ``ended`` (``certified``: the smallest bound left reached the best
    cost; ``exhausted``: nothing was left; ``budget``)."""

    space: int = 0
    solved: int = 0
    verified: int = 0
    removed: dict[str, int] = field(default_factory=dict)
    bounded: dict[str, int] = field(default_factory=dict)
    ratio: int = 0
    unexplored: int = 0
    unexplored_bound: float | None = None
    winner: str | None = None
    winner_cost: float | None = None
    open_bound: float | None = None
    certified: bool = False
    gap: float | None = None
    ended: str = ""

    @property
    def total(self) -> int:
        """The classes' sum (the space, when the ledger is whole)."""
        return self.solved + sum(self.removed.values()) + sum(self.bounded.values()) + self.ratio + self.unexplored

    def to_json(self) -> dict:
        return {
            "space": self.space,
            "solved": self.solved,
            "verified": self.verified,
            "removed_by_step_b": dict(self.removed),
            "excluded_by_bound": dict(self.bounded),
            "pruned_by_ratio": self.ratio,
            "unexplored": self.unexplored,
            "unexplored_smallest_bound": self.unexplored_bound,
            "winner": self.winner,
            "winner_cost": self.winner_cost,
            "smallest_open_bound": self.open_bound,
            "certified_optimal": self.certified,
            "gap": self.gap if self.gap is None or math.isfinite(self.gap) else None,
            "gap_unbounded": self.gap is not None and not math.isfinite(self.gap),
            "ended": self.ended,
        }

    def line(self) -> str:
        """The certificate in one line, as ``run`` prints it."""
        parts = [
            f"{self.solved:,} solved",
            f"{sum(self.removed.values()):,} removed by step B",
            f"{sum(self.bounded.values()):,} excluded by bounds",
        ]
        if self.ratio:
            parts.append(f"{self.ratio:,} pruned by the ratio rule (not certified)")
        if self.unexplored:
            parts.append(f"{self.unexplored:,} unexplored (smallest bound {self.unexplored_bound:.4g})")
        classes = ", ".join(parts)
        if self.winner is None:
            return f"no verified composition among {self.space:,}: {classes}"
        verdict = "certified optimal" if self.certified else "not certified"
        if self.gap is None or self.gap <= 1.0:
            gap = ""
        elif math.isfinite(self.gap):
            gap = f"; gap {self.gap:.3g}x"
        else:
            gap = "; gap unbounded (a composition left has no bound above 0)"
        return f"{self.winner} ({self.winner_cost:.4g}) {verdict} among {self.space:,} compositions: {classes}{gap}"


_SOLVED, _UNEXPLORED, _RATIO = "solved", "unexplored", "ratio"
#: A composition's class when its candidates end differently: the first of these it has.
_RANK = {_SOLVED: 0, _UNEXPLORED: 1, _RATIO: 2}


class Ledger:
    """The class of every composition a search has looked at, kept as it goes (a composition whose
    candidates end differently takes the first of: solved, unexplored, ratio-pruned, excluded by
    a bound)."""

    def __init__(self, space: int, limit: Callable[[float], float] | None = None, bound_name: str = JOINT_TRAVEL):
        self.space = space
        #: A composition can win only when its bound is below this of the best cost
        #: (:meth:`~modular_robots.costs.Objective.limit`: the best times a lexicographic
        #: objective's tie band, equal bounds too where tie-breaks decide ties); the best itself
        #: when not given.
        self.limit = limit if limit is not None else float
        #: The name of a candidate's own bound (:data:`~modular_robots.bounds.JOINT_TRAVEL`, or
        #: :data:`~modular_robots.bounds.DESIGN` for an objective of the design's costs alone).
        self.bound_name = bound_name
        self.classes: dict[str, str] = {}
        self.verified: set[str] = set()
        self.open: list[float] = []  # bounds of what may still be better: failed, ratio-pruned, unexplored
        self.uncertain: list[float] = []  # the same without the ratio-pruned
        self.unexplored: list[float] = []
        self.extra: Counter[str] = Counter()  # compositions counted without a name (beyond the frontier)
        self._unexplored_named = 0  # of ``classes``, those unexplored

    @classmethod
    def of(cls, space: int, objective: Objective | None = None) -> Ledger:
        """The ledger of a space searched for ``objective`` (its limit, and its bound's name: the
        joint travel, or ``design`` for the costs of the design alone); None: the time."""
        if objective is None:
            return cls(space)
        return cls(space, objective.limit, JOINT_TRAVEL if objective.counts_time else DESIGN)

    @property
    def checked(self) -> int:
        """Compositions settled so far: with a class other than unexplored."""
        return len(self.classes) - self._unexplored_named

    def _set(self, composition: str, kind: str) -> None:
        old = self.classes.get(composition)
        if old is None or _RANK.get(kind, 3) < _RANK.get(old, 3):
            self._put(composition, old, kind)

    def _put(self, composition: str, old: str | None, kind: str) -> None:
        self._unexplored_named += (kind == _UNEXPLORED) - (old == _UNEXPLORED)
        self.classes[composition] = kind

    def removed(self, composition: str, test: str) -> None:
        self._put(composition, self.classes.get(composition), f"removed:{test}")

    def removed_many(self, test: str, count: int) -> None:
        """``count`` compositions removed by ``test``, not named (a run that counts them only)."""
        self.extra[f"removed:{test}"] += count

    def candidate(self, result: CandidateResult, bound: float) -> None:
        composition = result.composition or result.name
        if result.status == CandidateStatus.OPTIMAL:
            self.verified.add(composition)
            self._set(composition, _SOLVED)
        elif result.status == CandidateStatus.FAILED:
            self._set(composition, _SOLVED)
            self.open.append(bound)
            self.uncertain.append(bound)
        elif result.pruned_by_bound:
            self._set(composition, f"bound:{self.bound_name}")
        elif result.status == CandidateStatus.PRUNED:  # by the ratio rule
            self._set(composition, _RATIO)
            self.open.append(bound)
        else:  # stopped before its end (a run cut short)
            self._set(composition, _UNEXPLORED)
            self._still_open(bound)

    def left(self, composition: str, bound: float, name: str, best: float) -> None:
        """A composition (or one of its candidates) still in the frontier when the search ended."""
        if self._excluded(bound, best):
            self._set(composition, f"bound:{name}")
        else:
            self._set(composition, _UNEXPLORED)
            self._still_open(bound)

    def beyond(self, count: int, smallest: float, name: str, best: float) -> None:
        """``count`` compositions never taken into the frontier, their smallest bound ``smallest``."""
        if self._excluded(smallest, best):
            self.extra[f"bound:{name}"] += count
        else:
            self.extra["unexplored"] += count
            self._still_open(smallest)

    def _excluded(self, bound: float, best: float) -> bool:
        """Whether a composition of this bound cannot win against the verified ``best``."""
        return bound >= self.limit(best) * (1.0 - _EQUAL)

    def _still_open(self, bound: float) -> None:
        """An unexplored composition's bound: it may still hide a better one."""
        self.open.append(bound)
        self.uncertain.append(bound)
        self.unexplored.append(bound)

    def certificate(self, winner: str | None, cost: float, ended: str, best: float | None = None) -> Certificate:
        """The certificate of ``winner`` at ``cost``; ``best`` is the smallest verified cost (the
        winner's unless a lexicographic objective chose a robot within the tie band)."""
        counts = Counter(self.classes.values()) + self.extra
        reference = cost if best is None else best
        open_bound = min(self.open) if self.open else None
        certified = winner is not None and all(self._excluded(b, reference) for b in self.uncertain)
        gap = None
        if winner is not None and open_bound is not None and open_bound < reference:
            gap = reference / open_bound if open_bound > 0 else math.inf
        return Certificate(
            space=self.space,
            solved=counts[_SOLVED],
            verified=len(self.verified),
            removed={k.split(":", 1)[1]: v for k, v in sorted(counts.items()) if k.startswith("removed:")},
            bounded={k.split(":", 1)[1]: v for k, v in sorted(counts.items()) if k.startswith("bound:")},
            ratio=counts[_RATIO],
            unexplored=counts["unexplored"],
            unexplored_bound=min(self.unexplored) if self.unexplored else None,
            winner=winner,
            winner_cost=cost if winner is not None else None,
            open_bound=open_bound,
            certified=certified,
            gap=gap,
            ended=ended,
        )
