"""What a task minimises, behind one protocol (:class:`~.base.Cost`).

Adding a cost is a file in this package and a line in :data:`COSTS` (``docs/extending.md``).
"""

from __future__ import annotations

from .base import Bounds, Cost, Evaluated, Motion, Problem
from .effort import Effort
from .time import Time

__all__ = ["Cost", "Problem", "Motion", "Bounds", "Evaluated", "Time", "Effort", "COSTS"]

#: Every cost, by its name in a scenario's ``task.cost``.
COSTS: dict[str, Cost] = {cost.name: cost for cost in (Time(), Effort())}
