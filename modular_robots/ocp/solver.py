"""SciPy ``trust-constr`` on a :class:`~modular_robots.ocp.shooting.ShootingProblem`, one iteration at
a time (SPEC §6).

``trust-constr`` owns its loop, so it runs in a helper thread that hands control back after every
iteration: :meth:`ShootingSolver.iterate` is a generator that yields an :class:`Iterate` per
solver iteration, :meth:`ShootingSolver.close` stops the solver cleanly (its callback raises
``StopIteration``) and joins the thread. Only one of the two threads runs at any moment, so the
problem's Pinocchio data is never shared. :meth:`ShootingSolver.solve` runs to the end in the
calling thread, without the hand-over per iteration.
A solver failure never raises into the caller: the generator ends and :attr:`outcome` says why.

The thread that runs trust-constr is marked for :mod:`~modular_robots.ocp._scipy`, whose
replacements (installed before the first solve, where the SciPy is one they are tested on) take
over seven parts of trust-constr there: its projections, canonical constraints and barrier
Jacobian, computed from the problem's structure, its barrier function and box intersections,
vectorised, the quasi-Newton update's transposed products, and its SQP loop, which repeats a
refused step's second-order correction (:mod:`~modular_robots.ocp._scipy.sqp`).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy
from scipy import sparse
from scipy.optimize import SR1, Bounds, NonlinearConstraint, minimize

from ..exceptions import ProblemError, SolverReuseError
from ._scipy import install, solver_thread
from ._scipy.checkpoint import Session, TrustConstrState, session
from .shooting import ShootingProblem

__all__ = [
    "Iterate",
    "SolverOutcome",
    "ShootingSolver",
    "TrustConstrState",
    "STATUSES",
    "HESSIANS",
    "ITERATION_LIMIT",
    "complementarity",
    "resumable",
]

#: How the reason of a solve that stopped at its iteration limit begins.
ITERATION_LIMIT = "iteration limit"

logger = logging.getLogger(__name__)

#: ``optimal``: converged within tolerances; ``failed``: iteration limit, infeasible or
#: non-finite; ``stopped``: closed by the caller.
STATUSES = ("optimal", "failed", "stopped")

#: Initial barrier parameter (and barrier tolerance) of a cold solve. trust-constr's default, 0.1,
#: spends about half of a solve's iterations on barrier subproblems far from the optimum; at 1e-3
#: the paper-5kg candidates need half the iterations (``docs/design-notes.md``).
COLD_BARRIER = 1e-3
#: Initial barrier parameter of a warm start (refinement), with a small trust radius.
WARM_BARRIER = 1e-4


#: The constraints' Hessian (:class:`ShootingSolver`'s ``hessian``): ``sr1``, one SR1 estimate
#: for all rows; ``structured``, the exact second derivatives of every row but the clearance ones
#: (:meth:`ShootingProblem.exact_hessian`) and SR1 for those. ``sr1`` is the default: over whole
#: scenarios ``structured`` takes 8 % fewer iterations on one and 3 % more on another, loses a
#: composition there, and costs about 40 % more per iteration (``docs/design-notes.md``).
HESSIANS = ("sr1", "structured")


@dataclass(frozen=True)
class Iterate:
    """The solver's state after one iteration.

    ``cost`` in its unit (``tf`` [s] for ``time``, ``integral of |tau / tau_max|^2 dt`` [s] for
    ``effort``), ``tf`` [s], ``constraint_violation`` the largest scaled violation (trust-constr's
    measure), ``y`` the scaled decision vector, ``cost_bound`` the problem's lower bound on its
    cost (:attr:`~modular_robots.ocp.shooting.ShootingProblem.cost_bound`).

    ``warm_up`` marks an iterate of a move solved alone before the whole motion (a task of several
    goals): its ``cost`` is then the whole motion's bound and its violation the move's, so it is
    not a point of the candidate's problem, and step D neither trusts nor judges it.
    """

    iteration: int
    cost: float
    constraint_violation: float
    tf: float
    y: np.ndarray
    optimality: float = float("nan")
    #: How many times the sub-steps had been refined (0: the first solve).
    refinement: int = 0
    cost_bound: float = 0.0
    warm_up: bool = False


@dataclass(frozen=True)
class SolverOutcome:
    """How a solve ended: ``status`` (one of :data:`STATUSES`), a human ``reason``, the number of
    iterations, the seconds spent inside the solver, the last iterate (None if none) and whether
    it stopped at the iteration limit."""

    status: str
    reason: str
    iterations: int
    seconds: float
    final: Iterate | None
    limit_reached: bool = False
    #: The last iterate's :func:`complementarity` (NaN when the solver returned none).
    complementarity: float = float("nan")

    @property
    def converged(self) -> bool:
        return self.status == "optimal"


def complementarity(values, multipliers, lower, upper) -> float:
    """The largest ``|multiplier| * gap`` over two-sided rows (or variables) whose ``values`` lie
    between ``lower`` and ``upper``, ``gap`` the distance to the nearer bound (0 outside them):
    zero at a KKT point, where a row off its bounds has no multiplier. Equality rows and rows
    without bounds are left out. The solvers' own measures differ (trust-constr's stopping test
    never looks at it; IPOPT's scales it), so a comparison of the two takes this one for both."""
    values, multipliers = np.asarray(values, float), np.asarray(multipliers, float)
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    gap = np.minimum(values - lower, upper - values)
    rows = (lower < upper) & np.isfinite(gap)
    products = np.abs(multipliers[rows]) * np.maximum(gap[rows], 0.0)
    return float(products.max(initial=0.0))


class ShootingSolver:
    """Solve ``problem`` with ``trust-constr`` (exact sparse Jacobians, SR1 Hessians).

    SR1 rather than damped BFGS for the constraints' Hessian: on the paper-5kg survivors BFGS
    converged as many candidates, more slowly (``docs/design-notes.md``).

    Parameters
    ----------
    problem
        The transcribed optimal control problem.
    y0
        Scaled starting point (default: the problem's straight-line guess); a given point is a
        warm start (small initial trust radius and barrier parameter).
    max_iterations, tolerance, constraint_tolerance
        Default to the problem's :class:`~modular_robots.scenario.OptimizerSettings`.
    jacobian
        ``exact`` (the product) or ``finite-difference`` (2-point; for checks and benchmarks).
    hessian
        One of :data:`HESSIANS` (``structured`` needs exact Jacobians and the inverse
        transcription; otherwise ``sr1`` is used).
    iteration_offset
        Added to reported iteration numbers (refinement continues a count).
    resume
        A :meth:`checkpoint` of a solve of the same problem by a solver made with the same
        arguments (``y0`` aside): this solve goes on from there, through the iterates the stopped
        one would have taken; its first iterate is the one after the checkpoint's. Needs the
        project's SQP loop in trust-constr (:func:`resumable`).
    """

    def __init__(
        self,
        problem: ShootingProblem,
        y0: np.ndarray | None = None,
        *,
        max_iterations: int | None = None,
        tolerance: float | None = None,
        constraint_tolerance: float | None = None,
        jacobian: str = "exact",
        iteration_offset: int = 0,
        hessian: str = "sr1",
        resume: TrustConstrState | None = None,
    ):
        if jacobian not in ("exact", "finite-difference"):
            raise ProblemError(f"jacobian must be 'exact' or 'finite-difference', got {jacobian!r}")
        if hessian not in HESSIANS:
            raise ProblemError(f"hessian must be one of {list(HESSIANS)}, got {hessian!r}")
        self.hessian = hessian
        s = problem.settings
        self.problem = problem
        if resume is not None and not resumable(resume):
            raise ProblemError(
                "a checkpoint needs the project's SQP loop in trust-constr and the SciPy it was taken with "
                f"({resume.arrays.get('solver.scipy', '?')}; this is {scipy.__version__})"
            )
        self._checkpoint = resume
        if resume is not None:
            self.warm = bool(resume.arrays["solver.warm"])
            self.y0 = resume.x
        else:
            self.warm = y0 is not None
            self.y0 = problem.initial_guess() if y0 is None else np.asarray(y0, dtype=float).copy()
        self.max_iterations = max_iterations or s.max_iterations
        self.tolerance = tolerance or s.tolerance
        self.constraint_tolerance = constraint_tolerance or s.constraint_tolerance
        self.jacobian = jacobian
        self.iteration_offset = iteration_offset
        self.outcome: SolverOutcome | None = None
        self.last: Iterate | None = None
        self._started = False
        self._thread: threading.Thread | None = None
        self._to_caller: queue.Queue = queue.Queue()
        self._resume = threading.Semaphore(0)
        self._stop = False
        self._direct = False
        self._seconds = 0.0 if resume is None else resume.scalar("solver.seconds")
        self._clock = 0.0  # perf_counter() when the solver last took over from the caller
        self._session: Session | None = None
        #: A resumed solve's first callback is the checkpoint's iteration again (not yielded).
        self._again = resume is not None
        #: The state a stop found the solve in, taken in its last callback (when not taken before).
        self._late: tuple[Iterate, TrustConstrState | None] | None = None
        self._taken: Iterate | None = None  # the iterate :meth:`checkpoint` last took the state at

    # -- public ------------------------------------------------------------------------------
    def iterate(self) -> Iterator[Iterate]:
        """Yield one :class:`Iterate` per solver iteration; afterwards :attr:`outcome` is set."""
        if self._thread is None and self.outcome is not None:  # closed before it started
            return
        if self._started:
            raise SolverReuseError("a ShootingSolver iterates once; create a new one to solve again")
        self._started = True
        thread = threading.Thread(target=self._run, name="trust-constr", daemon=True)
        try:
            thread.start()
        except RuntimeError as exc:  # no memory for a thread (ulimit -v): the caller sees this error, not close()'s
            self.outcome = self._outcome_without_result("failed", f"cannot start the solver's thread: {exc}")
            raise
        self._thread = thread
        try:
            while self.outcome is None:
                message = self._receive()
                if isinstance(message, SolverOutcome):
                    self.outcome = message
                    return
                self.last = message
                yield message
                if self.outcome is not None:  # closed while suspended
                    return
                self._resume.release()
        finally:
            self._shutdown()

    def close(self) -> None:
        """Stop the solver (if running) and free its thread; :attr:`outcome` becomes ``stopped``.
        A :meth:`solve` running (in another thread, or calling this from a callback) stops at its
        next iteration and returns that outcome."""
        if self._direct:
            self._stop = self.outcome is None
            return
        if self._thread is None:
            self._started = True
            if self.outcome is None:
                self.outcome = SolverOutcome("stopped", "closed before the first iteration", 0, 0.0, None)
            return
        self._shutdown()

    def solve(self) -> SolverOutcome:
        """Run to the end in the calling thread and return the :class:`SolverOutcome`: the
        iterates of :meth:`iterate`, without a thread handing each one over (on the OCP
        benchmark's candidates that hand-over costs 1-3 % of a solve). Once it has ended (or
        was closed), the same outcome."""
        if self._thread is None and self.outcome is not None:
            return self.outcome
        if self._started:
            raise SolverReuseError("a ShootingSolver iterates once; create a new one to solve again")
        self._started = self._direct = True
        try:
            self._run()
        except Exception as exc:  # outside trust-constr's loop, whose own failures are outcomes
            logger.debug("solver for %s failed", self.problem.robot.name, exc_info=True)
            self.outcome = self._posted() or self._outcome_without_result("failed", f"{type(exc).__name__}: {exc}")
            return self.outcome
        except BaseException as exc:  # Ctrl-C, SystemExit: raised to the caller, the solver stopped
            reason = f"interrupted ({type(exc).__name__})"
            self.outcome = self._posted() or self._outcome_without_result("stopped", reason)
            raise
        self.outcome = self._posted() or self._outcome_without_result("failed", "the solver ended without an outcome")
        return self.outcome

    def checkpoint(self) -> TrustConstrState | None:
        """trust-constr's state after the last iterate :meth:`iterate` yielded, while the solve
        waits there, for a solver made with ``resume=``; after a stop that came while an iteration
        ran (Ctrl-C in the caller's thread), the state at the iterate that iteration ended on,
        which the caller never got (:attr:`unseen`). None when there is none: not waiting at an
        iterate, ended otherwise, run by :meth:`solve`, or SciPy's own SQP loop in place."""
        if self._late is not None:
            return self._late[1]
        if self.outcome is not None or self.last is None or self._direct:
            return None
        self._taken = self.last
        return self._capture()

    @property
    def unseen(self) -> Iterate | None:
        """The iterate a stop during its iteration kept from the caller (None: none), which
        :meth:`checkpoint` is then taken at."""
        if self._late is None or self._late[0] is self.last:
            return None
        return self._late[0]

    def _capture(self) -> TrustConstrState | None:
        if self._session is None:
            return None
        state = self._session.capture()
        if state is None:
            return None
        extra: dict[str, Any] = {
            "solver.warm": np.bool_(self.warm),
            "solver.seconds": np.float64(self._seconds),
            "solver.scipy": np.str_(scipy.__version__),
        }
        return TrustConstrState({**state.arrays, **extra})

    # -- internals ---------------------------------------------------------------------------
    def _shutdown(self) -> None:
        thread = self._thread
        if thread is None:
            return
        if self.outcome is None:
            if thread.is_alive():
                self._stop = True
                self._resume.release()
            while True:
                message = self._receive()
                if isinstance(message, SolverOutcome):
                    self.outcome = message
                    break
                self._resume.release()
        # Once the outcome is in, the thread has nothing left to send; it may still be on its way
        # out, so join rather than ask it to stop (asking would wait for a message never sent).
        thread.join()

    def _receive(self) -> Iterate | SolverOutcome:
        """The solver thread's next message; an outcome of its own if the thread ended silently."""
        while True:
            try:
                return self._to_caller.get(timeout=1.0)
            except queue.Empty:
                if (self._thread is None or not self._thread.is_alive()) and self._to_caller.empty():
                    return self._outcome_without_result("failed", "the solver thread ended without an outcome")

    def _posted(self) -> SolverOutcome | None:
        """The outcome the solver posted, if it did (a direct solve posts nothing else)."""
        try:
            return self._to_caller.get_nowait()
        except queue.Empty:
            return None

    def _outcome_without_result(self, status: str, reason: str) -> SolverOutcome:
        """An outcome from the last iterate, for a solve that ended without posting one."""
        last = self.last
        return SolverOutcome(status, reason, last.iteration - self.iteration_offset if last else 0, self._seconds, last)

    def _callback(self, intermediate_result) -> bool:
        state = intermediate_result  # scipy passes the new-style result only under this name
        self._seconds += time.perf_counter() - self._clock
        if self._again:  # (the checkpoint's iterate, yielded by the solve it was taken from)
            self._again = False
            self._clock = time.perf_counter()
            if self._stop:
                raise StopIteration
            return False
        problem = self.problem
        y = np.array(state.x, dtype=float)
        tf = problem.motion_time(y)
        iterate = Iterate(
            self.iteration_offset + int(state.nit),
            float(state.fun) * problem.cost_unit,
            float(state.constr_violation),
            tf,
            y,
            float(state.optimality),
            cost_bound=problem.cost_bound,
        )
        if self._direct:
            self.last = iterate
        else:
            self._to_caller.put(iterate)
            self._resume.acquire()
        self._clock = time.perf_counter()
        if self._stop:
            if self._taken is not iterate:  # (a stop that came while this or the last iteration ran)
                self._late = (iterate, self._capture())
            raise StopIteration
        return False

    def _run(self) -> None:
        problem = self.problem
        self._clock = time.perf_counter()
        try:
            install()  # the replacements of parts of trust-constr, once per process
            with solver_thread(problem.n_variables), session(self._checkpoint) as current:
                self._session = current
                result = self._minimize()
        except Exception as exc:
            logger.debug("solver for %s failed", problem.robot.name, exc_info=True)
            self._finish("failed", f"{type(exc).__name__}: {exc}")
            return
        violation = float(result.constr_violation)
        if result.status == 3:
            self._finish("stopped", "closed by the caller", result)
        elif not np.all(np.isfinite(result.x)):
            self._finish("failed", "non-finite decision variables", result)
        elif result.status == 0:
            self._finish(
                "failed",
                f"{ITERATION_LIMIT} ({self.max_iterations}) reached, constraint violation {violation:.2g}",
                result,
                limit_reached=True,
            )
        elif violation > self.constraint_tolerance:
            self._finish(
                "failed",
                f"infeasible: the solver stopped ({result.message}) with constraint violation {violation:.2g}",
                result,
            )
        else:
            stalled = self._session.stalled if self._session is not None else None
            self._finish("optimal", stalled or str(result.message), result)

    def _finish(self, status: str, reason: str, result=None, limit_reached: bool = False) -> None:
        self._seconds += time.perf_counter() - self._clock
        final = self.last
        if result is not None and (final is None or final.iteration != self.iteration_offset + result.nit):
            y = np.array(result.x, dtype=float)
            final = Iterate(
                self.iteration_offset + int(result.nit),
                float(result.fun) * self.problem.cost_unit,
                float(result.constr_violation),
                self.problem.motion_time(y),
                y,
                float(result.optimality),
                cost_bound=self.problem.cost_bound,
            )
        iterations = final.iteration - self.iteration_offset if final is not None else 0
        slackness = float("nan")
        if result is not None and getattr(result, "v", None) is not None:
            slackness = max(
                complementarity(c, v, lower, upper)
                for c, v, (lower, upper) in zip(result.constr, result.v, self._row_bounds, strict=True)
            )
        self._to_caller.put(SolverOutcome(status, reason, iterations, self._seconds, final, limit_reached, slackness))

    def _minimize(self):
        problem = self.problem
        exact = self.jacobian == "exact"
        exact_objective = problem.objective.hessian(problem) if exact else None
        objective_hessian = exact_objective if exact_objective is not None else _SR1()

        # With exact Jacobians every point is evaluated with its derivatives at once: trust-constr
        # asks for them at nearly every point whose values it asked for, and a second pass would
        # redo the propagation and every FCL query.
        def evaluate(y):
            return problem.evaluate(y, derivatives=exact)

        if exact and problem.has_exact_hessian and self.hessian == "structured":
            exact_rows = problem.rows_of("continuity", "path", "midpoint", "torque")
            clearance_rows = problem.rows_of(*problem.estimated_blocks)
            parts = (
                _rows_constraint(problem, exact_rows, lambda y, v: problem.exact_hessian(y, v, exact_rows)),
                _rows_constraint(problem, clearance_rows, _SR1()),
            )
            constraints = [c for c in parts if c is not None]
        else:
            constraints = [
                NonlinearConstraint(
                    lambda y: evaluate(y).constraints,
                    problem.constraint_lower,
                    problem.constraint_upper,
                    jac=problem.constraint_jacobian if exact else "2-point",
                    hess=_SR1(),
                )
            ]
        self._row_bounds = [(c.lb, c.ub) for c in constraints] + [(problem.variable_lower, problem.variable_upper)]
        options = {
            "maxiter": self.max_iterations,
            "gtol": self.tolerance,
            "xtol": self.tolerance,
            "barrier_tol": self.tolerance,
            "sparse_jacobian": True,
            "verbose": 0,
        }
        if self.warm:
            # Start close to the given point: with the defaults (radius 1, barrier 0.1) a refined
            # re-solve first wandered to 3x its final tf (76 iterations); with these, 19.
            options.update(initial_tr_radius=0.1, initial_barrier_parameter=WARM_BARRIER)
        else:
            options.update(initial_barrier_parameter=COLD_BARRIER, initial_barrier_tolerance=COLD_BARRIER)
        if self._checkpoint is not None:  # the subproblem in progress (later ones follow from it)
            options.update(
                initial_barrier_parameter=self._checkpoint.scalar("barrier_parameter"),
                initial_barrier_tolerance=self._checkpoint.scalar("barrier_tolerance"),
            )
        # Floating-point warnings through NumPy's error state, which is per thread: a warnings
        # filter held for the whole solve would be restored out of order by the lockstep's threads.
        with np.errstate(all="ignore"):
            return minimize(
                lambda y: evaluate(y).cost,
                self.y0,
                method="trust-constr",
                jac=problem.cost_gradient if exact else "2-point",
                hess=objective_hessian,
                bounds=_bounds(problem),
                constraints=constraints,
                callback=self._callback,
                options=options,
            )


def _bounds(problem: ShootingProblem) -> Bounds:
    """The variables' bounds. With several phases, their durations' bounds (lower and upper) are
    kept feasible at every iterate (trust-constr's ``keep_feasible``): measured on CoBRA's PTP_3, the
    cold solve otherwise stepped to negative durations at its fifth iteration (both phases'
    motions run backwards, the cost falls below zero) and stayed there to the iteration limit."""
    keep = np.zeros(problem.n_variables, dtype=bool)
    if problem.phases > 1:
        keep[problem.duration_columns] = True
    return Bounds(problem.variable_lower, problem.variable_upper, keep_feasible=keep)


def resumable(state: TrustConstrState | None = None) -> bool:
    """Whether a solve can be resumed here from a :meth:`ShootingSolver.checkpoint` (``state``, if
    given): the project's SQP loop is in trust-constr (:func:`~modular_robots.ocp._scipy.install`),
    and the state is whole and was taken with this SciPy (whose objects it fills in)."""
    if state is not None and (str(state.arrays.get("solver.scipy", "")) != scipy.__version__ or not state.complete):
        return False
    return "SQP loop" in install()


class _SR1(SR1):
    """SciPy's SR1, silent when a step leaves the gradient unchanged (as after a rejected
    trust-constr step): SciPy then keeps the matrix too, but warns "delta_grad == 0.0" each time.
    Returning first needs no warnings filter, which would swap the process's filters under the
    other solver threads."""

    def update(self, delta_x, delta_grad):
        if np.all(delta_grad == 0.0):
            return
        super().update(delta_x, delta_grad)


def _rows_constraint(problem: ShootingProblem, rows: np.ndarray, hess) -> NonlinearConstraint | None:
    """The constraint rows ``rows`` of ``problem`` as one trust-constr constraint (exact
    Jacobian), None if there are none."""
    if len(rows) == 0:
        return None
    return NonlinearConstraint(
        lambda y: problem.evaluate(y).constraints[rows],
        problem.constraint_lower[rows],
        problem.constraint_upper[rows],
        jac=lambda y: _jacobian(problem, y)[rows],
        hess=hess,
    )


def _jacobian(problem: ShootingProblem, y: np.ndarray) -> sparse.csr_matrix:
    jacobian = problem.evaluate(y).jacobian
    assert jacobian is not None  # evaluated with derivatives
    return jacobian
