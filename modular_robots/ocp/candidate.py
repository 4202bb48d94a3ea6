"""One candidate's trajectory optimisation, from problem to verified result, as a generator.

A :class:`Candidate` chains runs of the scenario's solver (:mod:`~modular_robots.ocp.solvers`;
:class:`~modular_robots.ocp.solver.ShootingSolver` by default): it solves,
verifies (:func:`~modular_robots.ocp.verification.verify`) and, when the re-integrated motion misses
the goal by more than 1 cm or breaks a limit or the clearance between sub-steps, doubles the RK4
sub-steps and solves again warm-started from the coarse solution (SPEC §5). When the first solve
itself fails, it solves once more from a second initial guess
(:func:`~modular_robots.ocp.guess.swing_path`). Iteration numbers run on across all of these, so the
pruning manager sees one sequence per candidate.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Generator, Iterator, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..catalog import Catalog
from ..composition import Composition
from ..costs import continuation
from ..exceptions import ProblemError
from ..plan.boundary import BoundaryPair
from ..plan.candidate import CandidateResult, CandidateStatus
from ..plan.verification import Verification
from ..robot import robot_model
from ..scenario import OptimizerSettings, Scenario, Task
from .ends import task_ends
from .guess import swing_path
from .resume import NO_Y, CandidateCheckpoint, SolverRun
from .route import task_route
from .shooting import ShootingProblem
from .solver import Iterate, SolverOutcome, resumable
from .solvers import RESUMABLE, Solver, make_solver
from .trajectory import sample_trajectory
from .verification import verify

__all__ = [
    "BoundaryPair",
    "Candidate",
    "CandidateResult",
    "CandidateSpec",
    "CandidateStatus",
    "composition_problem",
    "make_candidate",
]


@dataclass(frozen=True)
class CandidateSpec:
    """A step-C candidate to build: a composition and the rest configurations it moves between
    (``q_start``, ``q_goal`` [rad | m]), taken from step B's ``boundary_pair``."""

    composition: Composition
    q_start: tuple[float, ...]
    q_goal: tuple[float, ...]
    boundary_pair: BoundaryPair = BoundaryPair.FASTEST
    #: Among several goals, step B's configurations at the vias (:class:`~modular_robots.ocp.route.Via`).
    q_via: tuple[tuple[float, ...], ...] = ()
    #: Where a run before stopped it, to go on from (:class:`~modular_robots.ocp.resume.CandidateCheckpoint`).
    checkpoint: CandidateCheckpoint | None = field(default=None, compare=False, repr=False)

    @property
    def name(self) -> str:
        """The composition's name, suffixed ``+clear`` for its clear boundary pair."""
        name = self.composition.name
        return name if self.boundary_pair == BoundaryPair.FASTEST else f"{name}+{self.boundary_pair}"


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
    resume
        A :meth:`checkpoint` of a candidate made with the same arguments: this one yields and
        ends as that one would have had it not been stopped (:mod:`~modular_robots.ocp.resume`),
        without solving again what it had solved. Ignored where the solver cannot resume.
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
        resume: CandidateCheckpoint | None = None,
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
        self._generator: Generator[Iterate, None, None] | None = None
        self._seconds = 0.0
        self._note = ""
        if resume is not None and not (problem.settings.solver in RESUMABLE and resumable(resume.state)):
            resume = None  # (solved from its start: the same result, later)
        #: The checkpoint resumed from, while its runs are given back; then None.
        self._resume = resume
        self._runs: list[SolverRun] = []  # the runs ended (solved here or given back)
        self._iterates: list[Iterate] = []  # of the run in progress, without decision vectors
        self._solver: Solver | None = None  # the run in progress's solver
        self._late: CandidateCheckpoint | None = None  # taken as a stop ended the run in progress
        if resume is not None:
            self._seconds = resume.seconds

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
        assert self.result is not None  # set before the generator ends
        return self.result

    def close(self) -> None:
        """Stop now; :attr:`result` records the last iterate with status ``stopped`` and, where
        there is one, the :meth:`checkpoint` to go on from."""
        checkpoint = self.checkpoint()
        if self._generator is not None:
            self._generator.close()
        if self.result is None:
            moves = " (while solving its moves one at a time)" if self.last is not None and self.last.warm_up else ""
            self._finish(CandidateStatus.STOPPED, "closed before convergence" + moves + self._note, None)
            assert self.result is not None
            self.result = replace(self.result, checkpoint=checkpoint)

    def checkpoint(self) -> CandidateCheckpoint | None:
        """Where the candidate stands while it waits at an iterate, for a candidate made with
        ``resume=`` (None: not started, ended, or its solver keeps no state to go on from)."""
        if self.result is not None:
            return None
        if self._late is not None:
            return self._late
        if self._resume is not None:  # still giving back the runs of the one it resumes
            return self._resume if self.last is not None else None
        take = getattr(self._solver, "checkpoint", None)
        state = take() if take is not None else None
        if state is None:
            return None
        return CandidateCheckpoint(self.name, tuple(self._runs), tuple(self._iterates), state, self._seconds)

    def _step(self, it: Iterate) -> None:
        self.last = it
        self.history.append(it.cost)
        self.violations.append(it.constraint_violation)
        self.refinements.append(it.refinement)

    def _solver_run(
        self, problem: ShootingProblem, y0: np.ndarray | None, offset: int, mark
    ) -> Generator[Iterate, None, SolverOutcome]:
        """One solver run from ``y0``, each iterate yielded as ``mark`` makes it; returns its
        outcome. A run of the checkpoint being resumed is not solved again: an ended one gives
        back its iterates and outcome, the one in progress its iterates, and its solver goes on."""
        resume, state = self._resume, None
        if resume is not None and len(self._runs) < len(resume.runs):
            run = resume.runs[len(self._runs)]
            for it in run.iterates:
                self._step(it)
                yield it
            self._runs.append(run)
            return run.outcome
        if resume is not None:
            for it in resume.iterates:
                self._iterates.append(it)
                self._step(it)
                yield it
            self._resume, state = None, resume.state
            if len(state.x) != problem.n_variables:
                raise ProblemError(
                    f"{self.name}: its checkpoint is of a problem of {len(state.x)} variables, not "
                    f"{problem.n_variables}; remove the checkpoint to solve it from its start"
                )
        solver = make_solver(
            problem.settings.solver, problem, y0, jacobian=self.jacobian, iteration_offset=offset, resume=state
        )
        self._solver = solver
        try:
            for it in solver.iterate():
                it = mark(it)
                self._iterates.append(replace(it, y=NO_Y))
                self._step(it)
                yield it
        finally:
            self._solver = None
            solver.close()
            self._keep_late(solver, mark)
            self._seconds += solver.outcome.seconds if solver.outcome else 0.0
        outcome = solver.outcome
        assert outcome is not None  # set once iterate() has returned (the Solver contract)
        self._runs.append(SolverRun(tuple(self._iterates), outcome))
        self._iterates = []
        return outcome

    def _keep_late(self, solver: Solver, mark) -> None:
        """After a stop that came while an iteration ran (the generator ends by the exception),
        the checkpoint at the iterate the solver stopped on (with it, if it was never yielded)."""
        take = getattr(solver, "checkpoint", None)
        state = (
            take() if take is not None and solver.outcome is not None and solver.outcome.status == "stopped" else None
        )
        if state is not None:
            unseen = getattr(solver, "unseen", None)
            iterates = (*self._iterates, *([replace(mark(unseen), y=NO_Y)] if unseen is not None else []))
            self._late = CandidateCheckpoint(self.name, tuple(self._runs), iterates, state, self._seconds)

    def _solve(
        self, problem: ShootingProblem, y0: np.ndarray | None, offset: int, attempt: int
    ) -> Generator[Iterate, None, SolverOutcome]:
        """One solver run, its iterates yielded; returns its outcome."""
        outcome = yield from self._solver_run(problem, y0, offset, lambda it: replace(it, refinement=attempt))
        if outcome.final is not None:
            self.last = replace(outcome.final, refinement=attempt)
        return outcome

    def _run(self) -> Generator[Iterate, None, None]:
        """Solve, swing once if the first solve fails, verify, refine. :attr:`problem` always
        holds the problem being solved, so that a result taken on :meth:`close` unpacks its
        ``y`` with the right sub-steps and guess."""
        y0: np.ndarray | None = None
        verification: Verification | None = None
        offset, cold, refined = 0, False, 0
        longest, shortest = self.problem.max_time, self.problem.time_bound
        if longest is not None and shortest > longest:
            reason = (
                f"cannot finish within task.max_time = {longest:g} s: no move of it within the velocity bounds is "
                f"shorter than {shortest:.4g} s"
            )
            self._finish(CandidateStatus.FAILED, reason, None)
            return
        y0, offset = yield from self._continuation()
        for attempt in range(self.max_refinements + 2):  # + 1: the cold solve after a crossing
            outcome = yield from self._solve_restarting(self.problem, y0, offset, refined)
            swung = (
                swing_path(self.problem.robot, self.problem.collision, self.problem.waypoints)
                if (outcome.status != "optimal" and attempt == 0 and self.swing and self.problem.phases == 1)
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
            final = outcome.final
            assert final is not None  # an optimal solve ends on an iterate
            start = time.perf_counter()
            previous, verification = verification, verify(self.problem, final.y)
            self._seconds += time.perf_counter() - start
            if verification.passed:
                self._finish(CandidateStatus.OPTIMAL, outcome.reason + self._note, verification)
                return
            crossing = _crossing(previous, verification)
            only_duration = not verification.duration_ok and replace(verification, duration_excess=0.0).passed
            if refined == self.max_refinements or (crossing and cold) or only_duration:
                break  # (more sub-steps cannot shorten the move)
            offset = final.iteration
            if crossing:  # the same sub-steps, from the first guess
                cold, y0, verification = True, None, None
                substeps = self.problem.substeps
                self._note += (
                    f" (a link crossed an obstacle: solved again from the first guess at {substeps} sub-steps)"
                )
                continue
            self.problem = self.problem.refined(2 * self.problem.substeps)
            y0, refined = final.y, refined + 1
        assert verification is not None  # the loop is only left by a break, after a failed verification
        self._finish(CandidateStatus.FAILED, _verification_failure(verification) + self._note, verification)

    def _continuation(self) -> Generator[Iterate, None, tuple[np.ndarray | None, int]]:
        """Solve the objective's smoother stages (:func:`~modular_robots.costs.continuation`) in
        turn, each from the last one's end; return where the solve of the objective itself starts
        (None: its first guess) and the iterations so far. A stage that ends infeasible is not
        followed: the objective is then solved from its first guess. With several phases, every
        stage starts from the moves solved one at a time (:meth:`_phases_first`)."""
        final = self.problem
        y0, offset = yield from self._phases_first()
        start = y0
        for cost in continuation(final.objective):
            self.problem = final.with_objective(cost)
            outcome = yield from self._solve(self.problem, y0, offset, 0)
            offset = self.last.iteration if self.last is not None else offset
            if outcome.final is None or outcome.final.constraint_violation > self.problem.settings.constraint_tolerance:
                y0 = start
                break
            y0 = outcome.final.y
        self.problem = final
        return y0, offset

    def _phases_first(self) -> Generator[Iterate, None, tuple[np.ndarray | None, int]]:
        """With several phases, a first point that keeps every goal's rows: each move solved alone
        for the least time, at rest at both ends, from step B's configuration to the next
        (:meth:`~modular_robots.ocp.shooting.ShootingProblem.phase_problem`), chained (None: one
        phase, or a move whose solve did not end feasible: the full problem's own first guess).

        Measured on CoBRA's PTP_3 (6 joints, a machine's mesh, 0.01 rad at the goal in between):
        from the walked first guess, 600 iterations ended infeasible (violation 0.016); the moves
        alone converge as single moves do.

        The moves' iterates are yielded (so that a budget, a stop or step D's lockstep are not held
        up by them), each with the whole motion's lower bound for its cost (the problem's
        ``cost_bound``) and marked ``warm_up``: a move's own cost and violation are not the
        motion's, so step D prunes on them by the bound only, and a candidate stopped among them
        records no cost. Returns the first point and the iterations so far."""
        full, offset = self.problem, 0
        if full.phases == 1:
            return None, offset
        durations, nodes, controls = [], [], []
        for k, (a, b) in enumerate(itertools.pairwise(full.chain())):
            phase = full.phase_problem(a, b)
            if phase is None:  # no move (a return to where it is): rest there
                durations.append(full.variable_scale[full.duration_columns[k]])
                nodes.append(np.tile(np.concatenate([a, np.zeros(full.nv)]), (full.phase_intervals, 1)))
                controls.append(np.zeros((full.phase_intervals, full.nv)))
                continue
            outcome = yield from self._solver_run(
                phase,
                None,
                offset,
                lambda it: replace(
                    it, cost=full.cost_bound, tf=full.time_bound, cost_bound=full.cost_bound, warm_up=True, refinement=0
                ),
            )
            offset = self.last.iteration if self.last is not None else offset
            final = outcome.final
            if final is None or final.constraint_violation > phase.settings.constraint_tolerance:
                return None, offset
            tf, phase_nodes, phase_controls = phase.unpack(final.y)
            durations.append(tf)
            nodes.append(phase_nodes[:-1])
            controls.append(phase_controls)
        last = np.concatenate([full.chain()[-1], np.zeros(full.nv)])
        y0 = full.pack(np.array(durations), np.vstack([*nodes, last]), np.vstack(controls))
        # within the durations' bounds, which are kept feasible (a move alone may take longer than
        # the task's max_time allows the whole motion: the total row then says it is infeasible)
        columns = full.duration_columns
        y0[columns] = np.clip(y0[columns], full.variable_lower[columns], full.variable_upper[columns])
        return y0, offset

    def _solve_restarting(
        self, problem: ShootingProblem, y0: np.ndarray | None, offset: int, attempt: int
    ) -> Generator[Iterate, None, SolverOutcome]:
        """:meth:`_solve`, and once more from where it stopped if it hit the iteration limit
        (``restart``)."""
        outcome = yield from self._solve(problem, y0, offset, attempt)
        if outcome.limit_reached and self.restart and outcome.final is not None:
            outcome = yield from self._solve(problem, outcome.final.y, outcome.final.iteration, attempt)
            if outcome.limit_reached:
                outcome = replace(
                    outcome, reason=outcome.reason + " (in two solves, the second from where the first stopped)"
                )
        return outcome

    def _finish(self, status: CandidateStatus, reason: str, verification: Verification | None):
        last, problem = self.last, self.problem
        # (a move's iterate has no cost of the motion; trust-constr's iterates may leave tf's bounds)
        whole = last is not None and not last.warm_up
        optimal = status == CandidateStatus.OPTIMAL
        ends = (problem.q_start, problem.q_goal)  # where the plan starts and ends
        if problem.free_ends is not None and last is not None and len(last.y) == problem.n_variables:
            nodes = problem.unpack(last.y)[1][:, : problem.nv]
            ends = (nodes[0], nodes[-1])
        trajectory = None
        if optimal:
            assert last is not None  # an optimal solve ends on an iterate
            trajectory = sample_trajectory(problem, last.y)
        self.result = CandidateResult(
            name=self.name,
            dof=problem.nv,
            status=CandidateStatus(status),
            reason=reason,
            iterations=last.iteration if last else 0,
            seconds=self._seconds,
            cost=last.cost if last and whole else np.nan,
            tf=last.tf if last and whole and last.tf >= 0.0 else np.nan,
            constraint_violation=last.constraint_violation if last and whole else np.nan,
            cost_history=tuple(self.history),
            violation_history=tuple(self.violations),
            refinement_history=tuple(self.refinements),
            verification=verification,
            substeps=problem.substeps,
            cost_bound=problem.cost_bound,
            composition=self.composition,
            boundary_pair=self.boundary_pair,
            q_start=tuple(float(v) for v in ends[0]),
            q_goal=tuple(float(v) for v in ends[-1]),
            stop_times=tuple(map(float, problem.stop_times(last.y)))
            if last and optimal and (problem.route.vias or any(problem.route.holds))
            else (),
            y=last.y if last else None,
            waypoints=problem.waypoints,
            trajectory=trajectory,
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
    if not v.orientation_ok:
        parts.append(f"the tool's orientation at an end is {v.orientation_excess:.3g} rad beyond its tolerance")
    if not v.duration_ok:
        parts.append(f"the move takes {v.duration_excess:.2%} longer than task.max_time")
    if not v.goals_ok:
        parts.append(f"a goal between the start and the end is missed by {v.goal_excess:.3g} (m, rad/s or rad)")
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
    q_via: tuple[tuple[float, ...], ...] = (),
) -> ShootingProblem:
    """The shooting problem of ``composition`` for ``task``, from rest at ``q_start`` to rest at
    ``q_goal`` through the task's goals, if several, from ``q_via`` (step B's configurations,
    :class:`CandidateSpec`)."""
    robot = robot_model(composition, catalog, task.payload)
    return ShootingProblem(
        robot,
        q_start,
        q_goal,
        task.collision_obstacles,
        task.cost.cost,
        settings,
        self_collision=task.self_collision,
        orientations=(task.start_orientation, task.goal_orientation),
        free_ends=task_ends(task) if settings.free_ends else None,
        max_time=task.max_time,
        route=task_route(task, q_via),
    )


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
        spec.composition, scenario.catalog, scenario.task, spec.q_start, spec.q_goal, scenario.optimizer, spec.q_via
    )
    return Candidate(
        problem,
        spec.name,
        composition=spec.composition.name,
        boundary_pair=spec.boundary_pair,
        resume=spec.checkpoint,
    )
