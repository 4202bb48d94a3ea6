"""What a task asks to minimise: a cost, a weighted sum of costs, or a lexicographic order.

An :class:`Objective` is a value: ``terms`` (the weighted sum step C minimises, each a cost of
:data:`~modular_robots.costs.COSTS` and its weight), then ``then`` (costs of the design that
break ties among the robots whose first cost is within ``within`` of the best). Its descriptor
string (``str(objective)``) is what ``result.json`` writes and :func:`parse_objective` reads:

``time``
    minimum time;
``time + 0.05*mass``
    the time plus 0.05 s per kilogram of robot;
``time then modules, mass within 0.01``
    minimum time; among the robots within 1 % of the fastest, the fewest modules, then the
    lightest.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import cached_property
from typing import TypeVar

from ..exceptions import shorten
from .base import Cost, Design
from .design import DesignCost
from .weighted import WeightedSum

__all__ = ["Objective", "parse_objective", "DEFAULT_WITHIN"]

#: The default tie band of a lexicographic order: robots within 1 % of the best first cost tie.
DEFAULT_WITHIN = 0.01
#: The widest tie band: wider, the first cost no longer ranks anything.
MAX_WITHIN = 1.0
_TERM = re.compile(r"^(?:(?P<weight>[0-9.eE+-]+)\s*\*\s*)?(?P<name>[a-z_]+)$")

T = TypeVar("T")


@dataclass(frozen=True)
class Objective:
    """Minimise ``sum(weight * cost for cost, weight in terms)``; among the robots whose sum is
    within ``within`` (a fraction) of the best, prefer the smallest ``then`` costs, in order."""

    terms: tuple[tuple[str, float], ...] = (("time", 1.0),)
    then: tuple[str, ...] = ()
    within: float = 0.0

    def __post_init__(self) -> None:
        costs = _costs()
        for name in (*(n for n, _ in self.terms), *self.then):
            if name not in costs:
                raise ValueError(f"expected one of {', '.join(costs)}; got {shorten(name)}")
        if not self.terms:
            raise ValueError("expected at least one cost to minimise")
        names = [n for n, _ in self.terms]
        if len(set(names)) != len(names):
            twice = next(n for n in names if names.count(n) > 1)
            raise ValueError(f"a cost appears twice in the sum: {shorten(twice)}")
        for name, weight in self.terms:
            if not (math.isfinite(weight) and weight > 0.0):
                raise ValueError(f"the weight of {name!r} is {weight}; expected a positive number")
        for name in self.then:
            if not isinstance(costs[name], DesignCost):
                raise ValueError(
                    f"{name!r} cannot come after the first cost: a tie-break is a cost of the design "
                    f"({', '.join(n for n, c in costs.items() if isinstance(c, DesignCost))}); a cost of the "
                    f"motion would need another solve"
                )
        if not 0.0 <= self.within <= MAX_WITHIN:
            raise ValueError(f"within is {self.within}; expected a fraction in [0, {MAX_WITHIN:g}]")
        if self.within and not self.then:
            raise ValueError("within sets the tie band of a lexicographic order: add the costs that break ties")

    def __str__(self) -> str:
        text = " + ".join(name if weight == 1.0 else f"{weight!r}*{name}" for name, weight in self.terms)
        if self.then:
            text += f" then {', '.join(self.then)} within {self.within!r}"
        return text

    @property
    def name(self) -> str:
        """The descriptor (``str(self)``)."""
        return str(self)

    @property
    def unit(self) -> str:
        """The unit of the value the winner is ranked by (``s``, ``J``, ``kg``...), or ``""`` when
        it has none (a count, a weighted sum)."""
        if len(self.terms) == 1 and self.terms[0][1] == 1.0:
            return str(getattr(_costs()[self.terms[0][0]], "unit", ""))
        return ""

    @property
    def names(self) -> tuple[str, ...]:
        """Every cost the objective names, the sum's first."""
        return (*(n for n, _ in self.terms), *self.then)

    @property
    def cost(self) -> Cost:
        """What step C minimises: the cost of the single term of weight 1, or the weighted sum."""
        costs = _costs()
        if len(self.terms) == 1 and self.terms[0][1] == 1.0:
            return costs[self.terms[0][0]]
        return WeightedSum(tuple((costs[n], w) for n, w in self.terms), " + ".join(n for n, _ in self.terms))

    @cached_property
    def counts_time(self) -> bool:
        """Whether the sum counts the time (its bound then counts the time's)."""
        return any(name == "time" for name, _ in self.terms)

    @cached_property
    def counts_design(self) -> bool:
        """Whether the sum counts a cost of the design (its bound then needs the robot's design)."""
        costs = _costs()
        return any(isinstance(costs[name], DesignCost) for name, _ in self.terms)

    @property
    def design_only(self) -> bool:
        """Whether the sum counts costs of the design alone (the motion's duration is then free)."""
        costs = _costs()
        return all(isinstance(costs[name], DesignCost) for name, _ in self.terms)

    @property
    def band(self) -> float:
        """``1 + within``: a robot whose first cost exceeds the best's by this factor cannot win
        (1 without tie-breaks). The safe bound rules of pruning and search compare against the
        best cost times this."""
        return 1.0 + self.within

    def limit(self, best: float) -> float:
        """A robot whose bound on the sum is below this may still win against a verified ``best``:
        the best times :attr:`band`; with tie-breaks a bound equal to it too (:meth:`rank` counts
        costs equal to 12 digits as tied, and the design decides among them)."""
        return best * self.band * (1.0 + 2.0 * EQUAL if self.then else 1.0)

    def rank(self, items: Iterable[T], cost: Callable[[T], float], design: Callable[[T], Design], name=str) -> list[T]:
        """``items`` (verified results) best first: by the sum; with tie-breaks, those within the
        band of the best by the ``then`` costs of their design, in order, then by the sum; ties
        by ``name``. Costs equal to 12 significant digits are equal (a cost of the design comes
        back from the solver's scaling a rounding off its value)."""
        items = list(items)
        if not items:
            return []
        best = min(cost(i) for i in items)
        costs = _costs()

        def key(item: T) -> tuple:
            c = _rounded(cost(item))
            if self.then and c <= best * self.band * (1.0 + EQUAL):
                d = design(item)
                tiebreak = tuple(costs[n].value(d) for n in self.then)  # type: ignore[attr-defined]
                return (0, *tiebreak, c, name(item))
            return (1, c, name(item))

        return sorted(items, key=key)


#: Costs closer than this share are equal when robots are ranked (rounding, not physics).
EQUAL = 1e-12


def _rounded(cost: float) -> float:
    return float(f"{cost:.12g}")


def parse_objective(text: str | Objective) -> Objective:
    """The :class:`Objective` of a descriptor (module docstring), e.g. ``time + 0.05*mass`` or
    ``time then modules within 0.01``; an :class:`Objective` is returned as it is.

    Raises
    ------
    ValueError
        Saying which part of ``text`` is not understood and what was expected.
    """
    if isinstance(text, Objective):
        return text
    rest, within = text.strip(), None
    if " within " in rest:
        rest, _, band = rest.rpartition(" within ")
        within = _number(band, "within")
    rest, _, after = rest.partition(" then ")
    then = tuple(n.strip() for n in after.split(",")) if after else ()
    terms = []
    for part in re.split(r"(?<![0-9.][eE])\+", rest):
        match = _TERM.match(part.strip())
        if not match:
            if re.fullmatch(r"[A-Za-z_]\w*", part.strip()):
                raise ValueError(f"expected one of {', '.join(_costs())}; got {shorten(part.strip())}")
            raise ValueError(
                f"cannot read {shorten(part.strip())}; expected a cost name or weight*name, e.g. 0.05*mass"
            )
        weight = match["weight"]
        terms.append((match["name"], 1.0 if weight is None else _number(weight, match["name"])))
    if then and within is None:
        within = DEFAULT_WITHIN
    return Objective(tuple(terms), then, within or 0.0)


def _number(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"the number of {what!r} is {shorten(text.strip())}; expected a number") from None


def _costs() -> dict[str, Cost]:
    from . import COSTS  # the registry imports this module

    return COSTS
