"""A weighted sum of costs: ``sum_k w_k c_k``, what CoBRA writes as ``cyc_2,mass_0.1``."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from .base import Bounds, Cost, Evaluated, Motion, Problem, continuation

if TYPE_CHECKING:
    from scipy import sparse

__all__ = ["WeightedSum"]


class WeightedSum:
    """``sum_k weight_k * cost_k`` over ``terms`` (each a :class:`~.base.Cost` and its weight > 0),
    in the units of the terms times their weights. Its lower bound is the weighted sum of the
    terms' bounds (the minimum of a sum is at least the sum of the minima); its Hessian is exact
    when every term's is, else approximated (SR1)."""

    def __init__(self, terms: tuple[tuple[Cost, float], ...], name: str):
        self.terms = terms
        self.name = name
        self.bounded = any(cost.bounded for cost, _ in terms)

    @property
    def continuation(self) -> tuple[WeightedSum, ...]:
        """The sum of the terms' :func:`~.base.continuation` stages (a term without as itself)."""
        stages = [continuation(cost) for cost, _ in self.terms]
        return tuple(
            WeightedSum(tuple((s[k] if k < len(s) else c, w) for (c, w), s in zip(self.terms, stages)), self.name)
            for k in range(max(map(len, stages), default=0))
        )

    def lower_bound(self, robot: Bounds, q_start: np.ndarray, q_goal: np.ndarray, velocity_bound: np.ndarray) -> float:
        return sum(w * c.lower_bound(robot, q_start, q_goal, velocity_bound) for c, w in self.terms)

    def evaluate(self, problem: Problem, tf: np.ndarray, motion: Motion, derivatives: bool) -> Evaluated:
        total, grad = 0.0, np.zeros(problem.n_variables) if derivatives else None
        for cost, weight in self.terms:
            value, g = cost.evaluate(problem, tf, motion, derivatives)
            total += weight * value
            if grad is not None:
                assert g is not None
                grad += weight * g
        return total, grad

    def hessian(self, problem: Problem) -> Callable[[np.ndarray], sparse.csr_matrix] | None:
        parts = [(c.hessian(problem), w) for c, w in self.terms]
        exact = [(h, w) for h, w in parts if h is not None]
        if len(exact) < len(parts):
            return None
        return lambda y: sum(w * h(y) for h, w in exact)
