"""The stall test of trust-constr's barrier subproblems: one that no longer makes progress ends.

SciPy ends a barrier subproblem when its optimality and constraint violation are below the
subproblem's tolerance, or when the trust radius has fallen below ``xtol``. Where the merit
function's model keeps promising a decrease the functions do not give (a clearance row whose
nearest pair changes between the points compared, a torque row at its kink), neither comes soon:
the iterate is feasible and still, steps are refused and the radius, cut to a tenth at each
refusal and doubled at each tiny accepted step, takes tens of iterations to fall to ``xtol``.
On the OCP benchmark's B-J1-L2-J1-L1-J1-L2-J2-L1-E2 such crawls took 40 to 45 iterations at
each of three barrier parameters (of 248 in all), its cost unchanged to 1e-9
(``docs/design-notes.md``).

:class:`StallTest` ends such a subproblem as SciPy's ``xtol`` test would, sooner: when, over the
last :data:`STALL_ITERATIONS` iterations, every iterate was feasible to the subproblem's tolerance
and its barrier function stayed within ``xtol`` relative, and the trust radius is below
:data:`STALL_RADIUS`. The barrier parameter then decreases as after any subproblem. A stall at a
barrier parameter already below trust-constr's ``barrier_tol``, feasible to its ``gtol``, ends
the solve, with SciPy's status for an ``xtol`` end (2): nothing is left to decrease. As with
SciPy's end by ``xtol``, the optimality is not asked of that point; the plan's verification
follows, as after any solve.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

__all__ = ["STALL_ITERATIONS", "STALL_RADIUS", "StallTest", "closure_values"]

#: Iterations over which a feasible barrier subproblem whose barrier function stayed within
#: ``xtol`` relative has stalled (0: never).
STALL_ITERATIONS = 10
#: The trust radius (of trust-constr's scaled step) below which a subproblem may have stalled. A
#: flat stretch at a larger radius is more often a pause on the way: without this condition the
#: test changed 42 of the 92 paper-5kg candidates' paths, one optimum by 12 %; with it 6, by at
#: most 2.5e-4 (``docs/design-notes.md``).
STALL_RADIUS = 1e-2


def closure_values(function) -> dict[str, Any]:
    """The values of the names a nested function takes from its enclosing one (SciPy keeps
    trust-constr's objective, constraints and ``barrier_tol`` nowhere else)."""
    code, cells = function.__code__, function.__closure__
    return dict(zip(code.co_freevars, (cell.cell_contents for cell in cells or ()), strict=True))


class StallTest:
    """The stall test of one barrier subproblem (module docstring).

    ``subproblem`` is SciPy's ``BarrierSubproblem`` (its ``tolerance``, ``xtol``,
    ``barrier_parameter`` and ``global_stop_criteria`` are read); None, or ``iterations`` 0,
    tests nothing. ``window`` the ``(barrier function, constraint violation)`` pairs the test had
    seen (a checkpoint's).
    """

    def __init__(self, subproblem, iterations: int = STALL_ITERATIONS, window: Iterable = ()):
        self.iterations = iterations if subproblem is not None else 0
        self.subproblem = subproblem
        #: The barrier function and constraint violation at the last ``iterations + 1``
        #: iterations, oldest first.
        self.window: list[tuple[float, float]] = [(float(f), float(c)) for f, c in window]

    def stalled(self, f: float, constraint_violation: float, trust_radius: float) -> bool:
        """Note the barrier function ``f`` and ``constraint_violation`` at this iteration's point
        and say whether the subproblem has stalled there, the trust radius being ``trust_radius``."""
        if not self.iterations:
            return False
        self.window.append((float(f), float(constraint_violation)))
        del self.window[: -self.iterations - 1]
        subproblem = self.subproblem
        if len(self.window) <= self.iterations or not trust_radius < STALL_RADIUS:
            return False
        values, violations = zip(*self.window)
        flat = max(values) - min(values) <= subproblem.xtol * (1.0 + abs(f))
        return flat and max(violations) < subproblem.tolerance

    def ends_solve(self, constraint_violation: float) -> bool:
        """Whether a stall now ends the whole solve: its barrier parameter is already below
        trust-constr's ``barrier_tol`` and the point is feasible to its ``gtol`` (otherwise the
        barrier parameter decreases, as after any subproblem)."""
        subproblem = self.subproblem
        try:
            found = closure_values(subproblem.global_stop_criteria)
            barrier_tol, gtol = found["barrier_tol"], found["gtol"]
        except (AttributeError, KeyError, TypeError):
            return False
        return bool(subproblem.barrier_parameter < barrier_tol and constraint_violation < gtol)

    def describe(self) -> str:
        """What the test found, for a solve's reason."""
        subproblem = self.subproblem
        return (
            f"stalled: feasible over the last {self.iterations} iterations, the barrier function within "
            f"{subproblem.xtol:g} relative, the trust radius below {STALL_RADIUS:g}, at barrier parameter "
            f"{subproblem.barrier_parameter:.2g}"
        )

    def state(self) -> np.ndarray:
        """The window, ``(n, 2)``, for a checkpoint."""
        return np.array(self.window, dtype=float).reshape(-1, 2)
