"""One candidate's trajectory optimisation, from problem to verified result, as a generator.

A :class:`Candidate` chains :class:`~modular_robots.ocp.solver.ShootingSolver` runs: it solves,
verifies (:func:`~modular_robots.ocp.verification.verify`) and, when the re-integrated motion misses
the goal by more than 1 cm or breaks a limit or the clearance between sub-steps, doubles the RK4
sub-steps and solves again warm-started from the coarse solution (SPEC §5). When the first solve
itself fails, it solves once more from a second initial guess
(:func:`~modular_robots.ocp.guess.swing_path`). Iteration numbers run on across all of these, so the
pruning manager sees one sequence per candidate.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from enum import StrEnum

import numpy as np

from ..catalog import Catalog
from ..composition import Composition
from ..robot import robot_model
from ..scenario import OptimizerSettings, Scenario, Task
from .guess import swing_path
from .shooting import ShootingProblem
from .solver import Iterate, ShootingSolver
from .trajectory import Trajectory, sample_trajectory
from .verification import Verification, verify

__all__ = [
    "BoundaryPair",
    "Candidate",
    "CandidateResult",
    "CandidateSpec",
    "CandidateStatus",
    "composition_problem",
    "make_candidate",
]


class CandidateStatus(StrEnum):
    """How a candidate's optimisation ended."""

    #: Converged and verified.
    OPTIMAL = "optimal"
    #: The solver failed (iteration limit, infeasible, non-finite) or verification failed.
    FAILED = "failed"
    #: Closed before it ended (by the caller, or when a run stops).
    STOPPED = "stopped"
    #: Discarded by the pruning manager.
    PRUNED = "pruned"


class BoundaryPair(StrEnum):
    """Which of step B's boundary pairs a candidate starts from (see :func:`composition_problem`)."""

    #: The IK pair with the smallest velocity-limited travel time.
    FASTEST = "fastest"
    #: The fastest pair whose straight joint-space line clears the obstacles.
    CLEAR = "clear"


@dataclass(frozen=True)
class CandidateSpec:
    """A step-C candidate to build: a composition and the rest configurations it moves between
    (``q_start``, ``q_goal`` [rad | m]), taken from step B's ``boundary_pair``."""

    composition: Composition
    q_start: tuple[float, ...]
    q_goal: tuple[float, ...]
    boundary_pair: BoundaryPair = BoundaryPair.FASTEST

    @property
    def name(self) -> str:
        """The composition's name, suffixed ``+clear`` for its clear boundary pair."""
        name = self.composition.name
        return name if self.boundary_pair == BoundaryPair.FASTEST else f"{name}+{self.boundary_pair}"


@dataclass(frozen=True, kw_only=True)
class CandidateResult:
    """How one candidate's optimisation ended (SPEC §7's per-candidate record).

    ``name`` names the candidate (unique in a run), ``composition`` its composition and
    ``boundary_pair`` the boundary pair it started from. ``cost`` in its unit [s], ``tf`` [s],
    ``cost_history`` and ``violation_history`` the cost and scaled constraint violation after
    every iteration, ``seconds`` spent in the solver and in verification. ``cost_bound`` is the
    problem's lower bound on the cost (:attr:`~modular_robots.ocp.shooting.ShootingProblem.cost_bound`).
    ``y`` is the last scaled decision vector and ``waypoints`` the joint-space path of the initial
    guess it is scaled by. An optimal result also carries what the report needs, in SI units:
    ``trajectory``, the plan sampled at every integration sub-step, and ``urdf``, the robot's URDF.
    """

    name: str
    dof: int
    status: CandidateStatus
    reason: str
    iterations: int = 0
    seconds: float = 0.0
    cost: float = float("nan")
    tf: float = float("nan")
    constraint_violation: float = float("nan")
    cost_history: tuple[float, ...] = ()
    violation_history: tuple[float, ...] = ()
    #: Per iteration, how many times the sub-steps had been refined (0: the first solve).
    refinement_history: tuple[int, ...] = ()
    verification: Verification | None = None
    substeps: int = 0
    pruned_at_iteration: int | None = None
    cost_bound: float = 0.0
    composition: str = ""
    boundary_pair: BoundaryPair = BoundaryPair.FASTEST
    #: The rest configurations it moves between [rad | m] (empty if it never started).
    q_start: tuple[float, ...] = ()
    q_goal: tuple[float, ...] = ()
    y: np.ndarray | None = field(default=None, repr=False, compare=False)
    waypoints: np.ndarray | None = field(default=None, repr=False, compare=False)
    trajectory: Trajectory | None = field(default=None, repr=False, compare=False)
    urdf: str | None = field(default=None, repr=False, compare=False)
    #: The drives' armature and friction, which URDF cannot hold (:meth:`RobotModel.drive`).
    drive: dict | None = field(default=None, repr=False, compare=False)

    @classmethod
    def never_started(cls, name: str, reason: str = "stopped before it started") -> CandidateResult:
        """The result of a candidate stopped before its first iteration."""
        return cls(name=name, dof=0, status=CandidateStatus.STOPPED, reason=reason, cost_bound=float("nan"))

    def to_json(self) -> dict:
        return {
            "composition": self.composition or self.name,
            "candidate": self.name,
            "boundary_pair": str(self.boundary_pair),
            "dof": self.dof,
            "q_start": list(self.q_start),
            "q_goal": list(self.q_goal),
            "status": str(self.status),
            "reason": self.reason,
            "iterations": self.iterations,
            "seconds": round(self.seconds, 4),
            "cost": _finite(self.cost),
            "tf": _finite(self.tf),
            "constraint_violation": _finite(self.constraint_violation),
            "pruned_at_iteration": self.pruned_at_iteration,
            "cost_bound": _finite(self.cost_bound),
            "substeps": self.substeps,
            "verification": self.verification.to_json() if self.verification else None,
            "cost_history": [_finite(c) for c in self.cost_history],
            "violation_history": [_finite(c) for c in self.violation_history],
            "refinement_history": list(self.refinement_history),
        }

    def pruned(self, iteration: int, reason: str = "") -> CandidateResult:
        """This result, pruned at ``iteration`` for ``reason`` (which rule, which bound or ratio)."""
        return replace(
            self,
            status=CandidateStatus.PRUNED,
            reason=f"pruned at iteration {iteration}" + (f" by the {reason}" if reason else ""),
            pruned_at_iteration=iteration,
        )


def _finite(value: float) -> float | None:
    return float(value) if value is not None and np.isfinite(value) else None


class Candidate:
    """Optimise ``problem`` to a verified trajectory, one solver iteration per ``next()``.

    Parameters
    ----------
    problem
        The shooting problem (its settings give tolerances and the iteration limit).
    name
        Shown in results (default: the robot's name).
    max_refinements
        How many times the sub-steps may be doubled after a failed verification. Refinement
        removes sampling errors (what a limit or the clearance does between sub-steps shrinks with
        the sub-step squared); a clearance deficit that one refinement did not halve is a link
        crossing an obstacle between two clear sub-steps, which no warm start removes: the
        candidate is then solved once more, cold (from the problem's first guess, the swing
        guess if one was taken), at the refined sub-steps, whose clearance rows keep the link
        from crossing where the coarser ones let it; unless that refinement was the last one
        allowed. The cold motion is refined like any other, and a crossing found after it ends
        the candidate. On paper-5kg that verified B-J1-L3-J1-L2-J2-L3-J1-L1-E2 (83 iterations
        at 8 sub-steps), which crossed an obstacle 28 mm deep before.
    jacobian
        ``exact`` or ``finite-difference`` (see :class:`~modular_robots.ocp.solver.ShootingSolver`).
    composition, boundary_pair
        Recorded in the result (default: ``name`` and ``fastest``).
    restart
        When a solve stops at the iteration limit, solve once more from where it stopped, with a
        fresh solver. Near some optima the SR1 approximation degenerates and trust-constr crawls
        (one conjugate-gradient step per iteration, ended by negative curvature or the trust
        region), and a fresh solver gets out of it.
    swing
        When the first solve fails (after its restart), solve once more, cold, from
        :func:`~modular_robots.ocp.guess.swing_path`'s guess, if it gives one: it made the two
        paper-5kg compositions that hold the goal at the edge of a joint's torque limit converge.
        Only a failed candidate pays for it, so the candidates that converge are unchanged.
    """

    def __init__(
        self,
        problem: ShootingProblem,
        name: str | None = None,
        max_refinements: int = 3,
        jacobian: str = "exact",
        restart: bool = True,
        composition: str | None = None,
        boundary_pair: BoundaryPair = BoundaryPair.FASTEST,
        swing: bool = True,
    ):
        self.problem = problem
        self.restart = restart
        self.swing = swing
        self.name = name or problem.robot.name
        self.composition = composition or self.name
        self.boundary_pair = BoundaryPair(boundary_pair)
        self.max_refinements = max_refinements
        self.jacobian = jacobian
        self.result: CandidateResult | None = None
        self.history: list[float] = []
        self.violations: list[float] = []
        self.refinements: list[int] = []
        self.last: Iterate | None = None
        self._generator: Iterator[Iterate] | None = None
        self._seconds = 0.0
        self._note = ""

    @property
    def seconds(self) -> float:
        """Seconds spent so far in the solver and in verification."""
        return self._seconds

    def iterate(self) -> Iterator[Iterate]:
        """Yield an :class:`~modular_robots.ocp.solver.Iterate` per solver iteration; afterwards
        :attr:`result` is set. Never raises for a failed optimisation."""
        if self._generator is None:
            self._generator = self._run()
        return self._generator

    def solve(self) -> CandidateResult:
        for _ in self.iterate():
            pass
        return self.result

    def close(self) -> None:
        """Stop now; :attr:`result` records the last iterate with status ``stopped``."""
        if self._generator is not None:
            self._generator.close()
        if self.result is None:
            self._finish(CandidateStatus.STOPPED, "closed before convergence" + self._note, None)

    def _solve(self, problem: ShootingProblem, y0, offset: int, attempt: int):
        """One solver run, its iterates yielded; returns its outcome."""
        solver = ShootingSolver(problem, y0, jacobian=self.jacobian, iteration_offset=offset)
        try:
            for it in solver.iterate():
                it = replace(it, refinement=attempt)
                self.last = it
                self.history.append(it.cost)
                self.violations.append(it.constraint_violation)
                self.refinements.append(attempt)
                yield it
        finally:
            solver.close()
            self._seconds += solver.outcome.seconds if solver.outcome else 0.0
        if solver.outcome.final is not None:
            self.last = replace(solver.outcome.final, refinement=attempt)
        return solver.outcome

    def _run(self) -> Iterator[Iterate]:
        """Solve, swing once if the first solve fails, verify, refine. :attr:`problem` always
        holds the problem being solved, so that a result taken on :meth:`close` unpacks its
        ``y`` with the right sub-steps and guess."""
        y0, offset, verification, cold, refined = None, 0, None, False, 0
        for attempt in range(self.max_refinements + 2):  # + 1: the cold solve after a crossing
            outcome = yield from self._solve_restarting(self.problem, y0, offset, refined)
            swung = (
                swing_path(self.problem.robot, self.problem.collision, self.problem.waypoints)
                if (outcome.status != "optimal" and attempt == 0 and self.swing)
                else None
            )
            if swung is not None:
                self._note = f" (from a swing guess; from the first guess: {outcome.reason})"
                offset = self.last.iteration if self.last is not None else 0
                self.problem = self.problem.refined(waypoints=swung)
                outcome = yield from self._solve_restarting(self.problem, None, offset, refined)
            if outcome.status != "optimal":
                held = _held_beyond_share(self.problem) if outcome.status == "failed" else ""
                self._finish(CandidateStatus(outcome.status), outcome.reason + self._note + held, None)
                return
            start = time.perf_counter()
            previous, verification = verification, verify(self.problem, outcome.final.y)
            self._seconds += time.perf_counter() - start
            if verification.passed:
                self._finish(CandidateStatus.OPTIMAL, outcome.reason + self._note, verification)
                return
            crossing = _crossing(previous, verification)
            if refined == self.max_refinements or (crossing and cold):
                break
            offset = outcome.final.iteration
            if crossing:  # the same sub-steps, from the first guess
                cold, y0, verification = True, None, None
                substeps = self.problem.substeps
                self._note += (
                    f" (a link crossed an obstacle: solved again from the first guess at {substeps} sub-steps)"
                )
                continue
            self.problem = self.problem.refined(2 * self.problem.substeps)
            y0, refined = outcome.final.y, refined + 1
        self._finish(CandidateStatus.FAILED, _verification_failure(verification) + self._note, verification)

    def _solve_restarting(self, problem: ShootingProblem, y0, offset: int, attempt: int):
        """:meth:`_solve`, and once more from where it stopped if it hit the iteration limit
        (``restart``)."""
        outcome = yield from self._solve(problem, y0, offset, attempt)
        if outcome.limit_reached and self.restart and outcome.final is not None:
            outcome = yield from self._solve(problem, outcome.final.y, outcome.final.iteration, attempt)
        return outcome

    def _finish(self, status: CandidateStatus, reason: str, verification: Verification | None):
        last, problem = self.last, self.problem
        optimal = status == CandidateStatus.OPTIMAL
        self.result = CandidateResult(
            name=self.name,
            dof=problem.nv,
            status=CandidateStatus(status),
            reason=reason,
            iterations=last.iteration if last else 0,
            seconds=self._seconds,
            cost=last.cost if last else np.nan,
            tf=last.tf if last else np.nan,
            constraint_violation=last.constraint_violation if last else np.nan,
            cost_history=tuple(self.history),
            violation_history=tuple(self.violations),
            refinement_history=tuple(self.refinements),
            verification=verification,
            substeps=problem.substeps,
            cost_bound=problem.cost_bound,
            composition=self.composition,
            boundary_pair=self.boundary_pair,
            q_start=tuple(float(v) for v in problem.q_start),
            q_goal=tuple(float(v) for v in problem.q_goal),
            y=last.y if last else None,
            waypoints=problem.waypoints,
            trajectory=sample_trajectory(problem, last.y) if optimal else None,
            urdf=problem.robot.urdf if optimal else None,
            drive=problem.robot.drive() if optimal else None,
        )


def _crossing(previous: Verification | None, v: Verification) -> bool:
    """True if a refinement left more than half the clearance deficit (see ``max_refinements``): a
    sampling error shrinks to about a quarter when the sub-steps are halved."""
    return (
        previous is not None
        and not previous.clearance_ok
        and not v.clearance_ok
        and v.min_clearance <= 0.5 * previous.min_clearance
    )


def _held_beyond_share(problem: ShootingProblem) -> str:
    """Why a failed plan may have had no feasible point: holding the payload at rest at the start
    or the goal needs more of a joint's effort limit than the plan may use (``effort_margin``);
    empty if it does not. A plan can still leave the start accelerating, so this is a hint."""
    robot, zero = problem.robot, np.zeros(problem.nv)
    shares = {
        label: np.abs(robot.rnea(q, zero, zero)) / robot.effort_limit
        for label, q in (("start", problem.q_start), ("goal", problem.q_goal))
    }
    label = max(shares, key=lambda k: shares[k].max())
    j = int(np.argmax(shares[label]))
    if shares[label][j] <= problem.settings.effort_margin:
        return ""
    return (
        f"; holding the payload at the {label} takes {shares[label][j]:.2f} of joint {j + 1}'s effort limit, "
        f"more than the plan may use (effort_margin {problem.settings.effort_margin:g})"
    )


def _verification_failure(v: Verification) -> str:
    parts = []
    if not v.terminal_ok:
        parts.append(f"terminal error {v.terminal_error * 100:.2f} cm > 1 cm")
    if not v.defect_ok:
        parts.append(f"defect {v.max_defect:.2g} (an interval's summed sub-step re-integration gaps)")
    if not v.clearance_ok:
        parts.append(f"clearance {v.min_clearance:.4f} m < 0 between sub-steps")
    if not v.limits_ok:
        parts.append(
            f"limits exceeded (velocity x{v.velocity_ratio:.3f}, torque x{v.torque_ratio:.3f}, "
            f"position +{v.position_excess:.2g} of the range)"
        )
    return f"verification failed after {v.substeps} sub-steps per interval: " + "; ".join(parts)


def composition_problem(
    composition: Composition,
    catalog: Catalog,
    task: Task,
    q_start: Sequence[float],
    q_goal: Sequence[float],
    settings: OptimizerSettings = OptimizerSettings(),
) -> ShootingProblem:
    """The shooting problem of ``composition`` for ``task``, from rest at ``q_start`` to rest at
    ``q_goal`` (step B's boundary configurations, :class:`CandidateSpec`)."""
    robot = robot_model(composition, catalog, task.payload)
    return ShootingProblem(robot, q_start, q_goal, task.obstacles, task.cost, settings)


def make_candidate(scenario: Scenario, spec: CandidateSpec) -> Candidate:
    """The step-C candidate of ``spec`` for ``scenario`` (the picklable entry point of worker
    processes).

    Step B offers up to two boundary pairs per composition (:class:`BoundaryPair`), and they can
    lead to different optima. From the fastest pair the initial guess detours through a via
    configuration when its straight line crosses an obstacle
    (:class:`~modular_robots.ocp.shooting.ShootingProblem`), and the solver usually finds its way
    round; but it can also settle on a link that jumps through the obstacle between two
    sub-steps, which verification rejects. The clear pair avoids that start. So a composition with
    both is optimised from both, as two candidates (``docs/known-limits.md``).
    """
    problem = composition_problem(
        spec.composition, scenario.catalog, scenario.task, spec.q_start, spec.q_goal, scenario.optimizer
    )
    return Candidate(problem, spec.name, composition=spec.composition.name, boundary_pair=spec.boundary_pair)
