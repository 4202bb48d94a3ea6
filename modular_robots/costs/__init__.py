"""What a task minimises, behind one protocol (:class:`~.base.Cost`).

Adding a cost is a file in this package and a line in :data:`COSTS` (``docs/extending.md``). A
task's ``cost`` is an :class:`~.objective.Objective`: one of them, a weighted sum, or a
lexicographic order whose tie-breaks are costs of the design.
"""

from __future__ import annotations

from .base import Bounds, Cost, Design, Evaluated, Motion, Problem, continuation
from .design import JOINTS, MASS, MODULES, PRICE, DesignCost, design_of
from .effort import Effort
from .energy import FIRST_SMOOTHING, POWER_SMOOTHING, Energy
from .objective import DEFAULT_WITHIN, Objective, parse_objective
from .time import Time
from .weighted import WeightedSum

__all__ = [
    "Cost",
    "Problem",
    "Motion",
    "Bounds",
    "Evaluated",
    "Design",
    "design_of",
    "Time",
    "Effort",
    "Energy",
    "POWER_SMOOTHING",
    "FIRST_SMOOTHING",
    "continuation",
    "DesignCost",
    "MASS",
    "JOINTS",
    "MODULES",
    "PRICE",
    "WeightedSum",
    "Objective",
    "parse_objective",
    "DEFAULT_WITHIN",
    "COSTS",
]

#: Every cost, by its name in a scenario's ``task.cost``.
COSTS: dict[str, Cost] = {cost.name: cost for cost in (Time(), Effort(), Energy(), MASS, JOINTS, MODULES, PRICE)}
