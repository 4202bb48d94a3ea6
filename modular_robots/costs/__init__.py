"""What a task minimises, behind one protocol (:class:`~.base.Cost`).

Adding a cost is a file in this package and a line in :data:`COSTS` (``docs/extending.md``).
"""

from __future__ import annotations

from .base import Bounds, Cost, Evaluated, Motion, Problem
from .effort import Effort
from .time import Time

__all__ = ["Cost", "Problem", "Motion", "Bounds", "Evaluated", "Time", "Effort", "COSTS", "cost_named"]

#: Every cost, by its name in a scenario's ``task.cost``.
COSTS: dict[str, Cost] = {cost.name: cost for cost in (Time(), Effort())}


def cost_named(name: str) -> Cost:
    """The cost called ``name``; ``KeyError`` naming the known ones otherwise."""
    try:
        return COSTS[name]
    except KeyError:
        raise KeyError(f"unknown cost {name!r}; expected one of {list(COSTS)}") from None
