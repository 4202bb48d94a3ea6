"""The solver protocol of step C, and the solvers by name (``optimizer.solver``).

A solver runs one :class:`~modular_robots.ocp.shooting.ShootingProblem` and hands out its
iterates one at a time, so that step D (:class:`~modular_robots.pruning.PruningManager`) can
advance many candidates in lockstep and stop any of them between two iterations. Adding a
solver is a file implementing :class:`Solver` and a line in :data:`SOLVERS` (its name also goes
into :data:`modular_robots.scenario.SOLVERS`, which the scenario reader checks;
``docs/extending.md``).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Protocol, runtime_checkable

import numpy as np

from ..exceptions import ProblemError
from .shooting import ShootingProblem
from .solver import Iterate, ShootingSolver, SolverOutcome

__all__ = ["Solver", "SolverFactory", "SOLVERS", "RESUMABLE", "make_solver", "UnknownSolverError"]


@runtime_checkable
class Solver(Protocol):
    """One solve of one problem, one iteration at a time: the contract step D relies on.

    - A solver runs once, by :meth:`iterate` or by :meth:`solve`. :meth:`iterate` yields one
      :class:`~.solver.Iterate` per iteration, numbered from the ``iteration_offset`` the solver
      was made with; the caller may stop pulling at any yield and call :meth:`close`. Nothing
      runs between two pulls that the caller did not ask for (the solver is suspended, holding
      no lock the caller needs). :meth:`solve` runs to the end without yielding (the same
      iterates) and returns the outcome; a second run raises
      :class:`~modular_robots.exceptions.SolverReuseError` (``iterate`` after ``solve`` yields
      nothing).
    - When :meth:`iterate` returns, :attr:`outcome` is set; :meth:`solve` returns it.
    - :meth:`close` is idempotent, may be called before, during or after :meth:`iterate`, frees
      what the solve holds (threads) and leaves :attr:`outcome` set (``stopped`` if the solve had
      not ended). Called during :meth:`solve` (from its callback or another thread), it makes
      that solve stop at its next iteration and return a ``stopped`` outcome.
    - :attr:`last` is the last iterate handed out (None before the first).
    - Exceptions inside the algorithm end the solve as ``failed``; ``KeyboardInterrupt`` and
      ``SystemExit`` reach the caller after the solve is stopped.

    What the candidate and step D read: every field of :class:`~.solver.Iterate` (``cost`` in SI
    units of the problem's cost, ``constraint_violation`` in the scaled variables, ``tf``, ``y``,
    ``cost_bound`` the problem's), and of :class:`~.solver.SolverOutcome` (``status``
    ``optimal``, ``failed`` or ``stopped``; ``limit_reached`` when it stopped at the iteration
    limit, which makes the candidate restart from ``final``; ``seconds`` inside the solver).
    """

    outcome: SolverOutcome | None
    last: Iterate | None

    def iterate(self) -> Iterator[Iterate]: ...

    def solve(self) -> SolverOutcome: ...

    def close(self) -> None: ...


class SolverFactory(Protocol):
    """Makes a :class:`Solver` for ``problem``, started at the scaled point ``y0`` (default: the
    problem's guess; a given point is a warm start), with ``jacobian`` ``exact`` or
    ``finite-difference`` and iterations numbered from ``iteration_offset``."""

    def __call__(
        self,
        problem: ShootingProblem,
        y0: np.ndarray | None = None,
        *,
        jacobian: str = "exact",
        iteration_offset: int = 0,
    ) -> Solver: ...


#: Every solver, by its name in a scenario's ``optimizer.solver``.
SOLVERS: dict[str, SolverFactory] = {"trust-constr": ShootingSolver}
#: The solvers that can stop at an iterate and go on later, in another process: a ``checkpoint()``
#: method (None when there is none to take) and a factory's ``resume=`` taking what it returned.
RESUMABLE = frozenset({"trust-constr"})


class UnknownSolverError(ProblemError):
    """A solver name that :data:`SOLVERS` does not hold."""


def make_solver(
    name: str,
    problem: ShootingProblem,
    y0: np.ndarray | None = None,
    *,
    jacobian: str = "exact",
    iteration_offset: int = 0,
    resume: object | None = None,
) -> Solver:
    """The solver called ``name`` for ``problem`` (see :class:`SolverFactory`); with ``resume``,
    a solver's ``checkpoint()``, the solve that goes on from it (:data:`RESUMABLE` solvers)."""
    factory = SOLVERS.get(name)
    if factory is None:
        raise UnknownSolverError(f"unknown solver {name!r}; expected one of {list(SOLVERS)}")
    if resume is None:
        return factory(problem, y0, jacobian=jacobian, iteration_offset=iteration_offset)
    if name not in RESUMABLE:
        raise ProblemError(f"solver {name!r} cannot resume a stopped solve")
    return factory(problem, y0, jacobian=jacobian, iteration_offset=iteration_offset, resume=resume)  # type: ignore[call-arg]
