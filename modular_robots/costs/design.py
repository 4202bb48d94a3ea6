"""The costs of a robot's design: its mass, its joints, its modules and its price.

Each is a number of the composition, the same for every motion: in step C it adds a constant to
the objective (no gradient), and its lower bound before any solve is its value. Alone it ranks the
robots that can do the task by what they are made of; in a weighted sum or after the time in a
lexicographic order (:mod:`~.objective`) it breaks ties toward simpler robots.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import ProblemError
from .base import Bounds, Design, Evaluated, Motion, Problem

if TYPE_CHECKING:
    from scipy import sparse

    from ..catalog import Catalog

__all__ = ["DesignCost", "MASS", "JOINTS", "MODULES", "PRICE", "design_of"]


def design_of(modules: Sequence[str], catalog: Catalog) -> Design:
    """The :class:`~.base.Design` of the modules ``modules`` (ids, base first) of ``catalog``."""
    parts = [catalog.general_module(m) if catalog.general else catalog.module(m) for m in modules]
    prices = [p.price for p in parts]
    return Design(  # fsum: the same modules in another order weigh the same to the last bit
        mass=math.fsum(p.mass for p in parts),
        joints=sum(p.dof for p in parts),
        modules=len(parts),
        price=None if any(p is None for p in prices) else math.fsum(prices),  # type: ignore[arg-type]
    )


class DesignCost:
    """A cost that is a number of the design: the field ``field`` of :class:`~.base.Design`, in
    ``unit``, named ``name`` in a scenario."""

    bounded = True

    def __init__(self, name: str, unit: str, field: str, what: str):
        self.name, self.unit, self.field = name, unit, field
        self.__doc__ = what

    def __repr__(self) -> str:
        return f"DesignCost({self.name!r})"

    def value(self, design: Design | None) -> float:
        """The cost of ``design`` in :attr:`unit`."""
        value = None if design is None else getattr(design, self.field)
        if value is None:
            raise ProblemError(f"the {self.name} cost needs the robot's {self.field}, which is not known here")
        return float(value)

    def lower_bound(self, robot: Bounds, q_start: np.ndarray, q_goal: np.ndarray, velocity_bound: np.ndarray) -> float:
        return self.value(robot.design)

    def evaluate(self, problem: Problem, tf: np.ndarray, motion: Motion, derivatives: bool) -> Evaluated:
        grad = np.zeros(problem.n_variables) if derivatives else None
        return self.value(problem.design) / problem.tf_guess, grad

    def hessian(self, problem: Problem) -> Callable[[np.ndarray], sparse.csr_matrix]:
        """Zero: the cost is a constant of the problem."""
        from scipy import sparse  # at solve time: the scenario reader imports this module

        zero = sparse.csr_matrix((problem.n_variables, problem.n_variables))
        return lambda y: zero


#: The mass of the robot's modules [kg], without the payload.
MASS = DesignCost("mass", "kg", "mass", "The mass of the robot's modules [kg], without the payload.")
#: The number of joints (degrees of freedom).
JOINTS = DesignCost("joints", "", "joints", "The number of joints (degrees of freedom).")
#: The number of modules, base and effector included.
MODULES = DesignCost("modules", "", "modules", "The number of modules, base and effector included.")
#: The sum of the modules' catalogue ``price`` (every module of the catalogue needs one).
PRICE = DesignCost("price", "", "price", "The sum of the modules' catalogue price.")
