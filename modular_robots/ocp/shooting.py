"""Step C: the minimum-time (or minimum-effort) optimal control problem of one robot, transcribed
by direct multiple shooting (SPEC §5).

Decision variables, scaled to order one: the final time ``tf``, the interior node states
``s_1 .. s_{N-1}`` (``s_0`` and ``s_N`` are the fixed rest states at ``q_start`` and ``q_goal``)
and one control per interval ``u_0 .. u_{N-1}``. Constraints: continuity ``Phi(s_m, u_m, tf) =
s_{m+1}``; position and velocity limits at every integration sub-step (plain bounds at the
nodes); obstacle clearance ``>= margin`` at every sub-step (less for an obstacle near the start, a
goal or the end: :func:`end_margins`), and the distance of every checked pair
of the robot's own primitives that can come that close (:mod:`~modular_robots.self_collision`) too
(a pair never sampled twice the margin apart, or nearer than that at the start or the goal: half the smaller distance);
torque limits (plain bounds when the controls are torques, else at every sub-step). Jacobians are
exact and assembled sparse.

When the velocity is linear in time within an interval (the inverse transcription), every
sub-step's velocity lies between the two node velocities, so the node bounds already hold it and
the sub-steps carry no velocity rows: the same feasible set with a sixth fewer inequalities.

Between the sub-steps a motion could break a position limit unseen, so the position limits are
also kept at every sub-step's midpoint, on the cubic Hermite interpolant of its end states,
``(q_j + q_{j+1}) / 2 + h (v_j - v_{j+1}) / 8`` (``h`` the sub-step's duration; exact for the
inverse transcription's parabolas); for a parabola this cuts the largest unseen overshoot from
``|a| h^2 / 8`` to ``|a| h^2 / 32``, and what remains is for verification to catch.

The clearance is kept at the sub-steps only, so a link can still cross an obstacle between two
clear sub-steps; verification catches it. The constraints tried against that and dropped
(midpoint clearance, a "chord" row, a swept-volume row) are in ``docs/design-notes.md``.

The problem is a plain object: it evaluates cost, constraints and their derivatives; solving is
:mod:`~modular_robots.ocp.solver`'s job.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy import sparse

from ..collision import CollisionModel
from ..costs import COSTS, Cost
from ..exceptions import ModularRobotsError, ProblemError
from ..obstacles import Obstacle
from ..orientation import Orientation
from ..robot import RobotModel
from ..scenario import OptimizerSettings
from ..self_collision import SelfCollisionModel
from .ends import ToolEnd, end_rows
from .guess import detour_path, path_times
from .hessian import kinematic_hessians, rnea_curvature, torque_hessians
from .route import NO_ROUTE, Route, route_cost_bound
from .transcription import Propagation, positive_or_one, transcription

__all__ = ["ShootingProblem", "NonFiniteError", "Evaluation", "end_margins"]


class NonFiniteError(ModularRobotsError, ArithmeticError):
    """The dynamics produced NaN or infinite values at a trial point."""


@dataclass(frozen=True)
class Evaluation:
    """Everything the solver needs at one scaled point ``y`` (Jacobians only if asked)."""

    cost: float
    constraints: np.ndarray
    propagation: Propagation
    clearance: np.ndarray
    cost_gradient: np.ndarray | None = None
    jacobian: sparse.csr_matrix | None = None


@dataclass(frozen=True)
class _RouteRows:
    """A group of the route's rows: its ``kind`` (``pose``, ``rest``, ``hold``: the static torque
    where the robot stands still, ``return`` or ``total``),
    their bounds and scales, each row's variable columns (-1 where fixed), the via (``node``: 1
    the first, ``phases`` the goal) they hold, the configuration a return returns to (``ref``)
    and the pose's end."""

    kind: str
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    columns: list[np.ndarray]
    node: int
    ref: int | None = None
    end: ToolEnd | None = None


def end_margins(margin: float, at_ends: np.ndarray) -> np.ndarray:
    """The clearance [m] the rows keep from each obstacle, given the ``margin`` and each
    obstacle's smallest distance to the robot at the start, the goals and the end ``at_ends``.

    Step B holds those configurations to no overlap only. An obstacle nearer than the margin there
    would ask the sub-steps next to a fixed end for more than a motion at rest there can give, and
    the row at a free end for more than the end has. So the rows keep the margin, or less by as
    much as leaves half the margin between the nearest end and its rows (``d - margin / 2``), and
    at least half the end's distance: ``min(margin, max(d / 2, d - margin / 2))``, continuous in
    ``d`` and the margin itself from ``d = 1.5 margin`` on.
    """
    d = np.asarray(at_ends, dtype=float)
    return np.minimum(margin, np.maximum(0.5 * d, d - 0.5 * margin))


class ShootingProblem:
    """Multiple-shooting transcription of "move ``robot`` from rest at ``q_start`` to rest at
    ``q_goal``, clear of ``obstacles``, within its limits, minimising ``cost``".

    Parameters
    ----------
    robot
        Any :class:`~modular_robots.robot.RobotModel` (``nq == nv``); its model's position,
        velocity [rad/s, m/s] and effort [N m, N] limits are the bounds, its collision primitives
        that move are checked against the obstacles.
    q_start, q_goal
        Boundary configurations [rad or m]; the velocity is zero at both.
    obstacles
        Sphere obstacles in the base frame.
    cost
        ``time`` (``tf`` [s]) or ``effort`` (``integral of |tau / tau_max|^2 dt`` [s]).
    settings
        Nodes (intervals + 1), sub-steps per interval and the transcription.
    substeps
        Overrides ``settings.substeps`` (used by refinement).
    waypoints
        Joint-space path ``(K, nv)`` of the initial guess, from ``q_start`` to ``q_goal``
        (default: :func:`~modular_robots.ocp.guess.detour_path`).
    self_collision
        Keep the robot's checked pairs of primitives
        (:func:`~modular_robots.self_collision.checked_pairs`) apart by the clearance margin too
        (the module docstring). Their rows join the ``clearance`` block, after the obstacles' at
        each sub-step.
    orientations
        The tool orientations the task asks at the start and the goal (None: free), for
        verification to measure.
    free_ends
        The tool poses asked at the start and the goal (:class:`~modular_robots.ocp.ends.ToolEnd`):
        the ends become variables ``q_0`` and ``q_N`` (at rest), kept within those poses, with
        ``q_start`` and ``q_goal`` their first guess (None: the ends are fixed there).
    max_time
        The longest the motion may take, pauses included [s] (None: no limit).
    route
        The goals between the start and the goal (:class:`~modular_robots.ocp.route.Route`): the
        motion is then one phase per move, each of ``settings.nodes - 1`` intervals and its own
        free duration, a variable after the free ends (the first phase's is the first variable);
        the via nodes between phases are held by ``route`` rows, and the pauses add their time.
    """

    def __init__(
        self,
        robot: RobotModel,
        q_start: Sequence[float] | np.ndarray,
        q_goal: Sequence[float] | np.ndarray,
        obstacles: Sequence[Obstacle] = (),
        cost: str | Cost = "time",
        settings: OptimizerSettings = OptimizerSettings(),
        substeps: int | None = None,
        waypoints: np.ndarray | None = None,
        self_collision: bool = True,
        orientations: tuple[Orientation | None, Orientation | None] = (None, None),
        free_ends: tuple[ToolEnd, ToolEnd] | None = None,
        max_time: float | None = None,
        route: Route = NO_ROUTE,
    ):
        if robot.nq != robot.nv:
            raise ProblemError(
                f"robot {robot.name!r}: nq = {robot.nq} != nv = {robot.nv}; only joints "
                f"whose configuration is their coordinate (revolute, prismatic) are supported"
            )
        if settings.nodes < 3:
            raise ProblemError(f"nodes must be >= 3 (two or more intervals), got {settings.nodes}")
        if isinstance(cost, str) and cost not in COSTS:
            raise ProblemError(f"unknown cost {cost!r}; expected one of {list(COSTS)}")
        self.robot = robot
        self.design = robot.design
        if max_time is not None and not (math.isfinite(max_time) and max_time > 0.0):
            raise ProblemError(f"max_time must be a positive number of seconds, got {max_time}")
        if max_time is not None and route.hold >= max_time:
            raise ProblemError(f"the pauses take {route.hold:g} s, at least max_time = {max_time:g} s")
        #: The longest the motion may take [s] (None: no limit but the solver's own, 1000 times
        #: the first guess's duration).
        self.max_time = max_time
        self.settings = settings
        #: What the problem minimises (:mod:`~modular_robots.costs`).
        self.objective: Cost = COSTS[cost] if isinstance(cost, str) else cost
        self.cost_name = self.objective.name
        self.obstacles = tuple(obstacles)
        #: The tool orientation the task asks at the start and the goal (None: free), which
        #: ``q_start`` and ``q_goal`` meet (step B's IK) and verification measures.
        self.orientations = orientations
        self.transcription = transcription(settings.transcription)
        #: The goals between the start and the goal, and the pauses.
        self.route = route
        self.phases = route.phases
        #: Intervals of each phase (``N = phases * phase_intervals``), each of a phase's duration
        #: over this.
        self.phase_intervals = settings.nodes - 1
        self.intervals = self.phase_intervals * self.phases
        #: The time the robot stands still in pauses [s]: part of the motion's duration.
        self.hold = route.hold
        self._phase = np.repeat(np.arange(self.phases), self.phase_intervals)  # each interval's phase
        self.substeps = int(substeps or settings.substeps)
        #: The velocity and effort bounds the plan keeps [rad/s | m/s, N m | N]: the robot's limits
        #: times the settings' margins (verification holds the plan to the full limits).
        self.velocity_bound = settings.velocity_margin * robot.velocity_limit
        self.effort_bound = settings.effort_margin * robot.effort_limit
        nv = self.nv = robot.nv
        n = self.nx = 2 * nv
        self.q_start = self._configuration(q_start, "q_start")
        self.q_goal = self._configuration(q_goal, "q_goal")
        self.collision = None
        if self.obstacles and robot.moving_primitives():
            self.collision = CollisionModel(robot, self.obstacles, robot.moving_primitives())
            if not self.collision.obstacles:  # every obstacle is out of reach
                self.collision = None
        if self.collision is not None:
            for label, q in (("q_start", self.q_start), ("q_goal", self.q_goal)):
                if self.collision.min_distance(q) < 0.0:
                    raise ProblemError(f"{label} is in collision with an obstacle")
        #: The checked pairs of the robot's own primitives (None: self-collision off or no pair).
        self.self_collision: SelfCollisionModel | None = None
        if self_collision:
            model = SelfCollisionModel(robot)
            self.self_collision = model if len(model) else None
        if self.self_collision is not None:
            for label, q in (("q_start", self.q_start), ("q_goal", self.q_goal)):
                contact = self.self_collision.closest(q)
                if contact.distance < 0.0:
                    raise ProblemError(f"{label} is in self-collision ({contact.first} and {contact.second})")
        #: The checked pairs that can come within the margin: those the clearance rows keep apart,
        #: each by the margin or, for a pair never seen farther apart than twice the margin (shapes
        #: a design keeps close) or nearer than that at the start or the goal (which step B holds
        #: to no overlap only, and the sub-steps next to them could not leave fast enough), by
        #: half the smaller of those distances.
        self._self_rows = np.zeros(0, dtype=int)
        self._self_margins = np.zeros(0)
        if self.self_collision is not None:
            assert self.self_collision.farthest is not None  # the checked pairs
            self._self_rows = self.self_collision.within(settings.clearance_margin)
            at_ends = self.self_collision.distances(self.chain())[0].min(axis=0)
            self._self_margins = np.minimum(
                settings.clearance_margin,
                0.5 * np.minimum(self.self_collision.farthest, at_ends)[self._self_rows],
            )
        #: Each obstacle's clearance the rows keep [m] (:func:`end_margins`).
        self._obstacle_margins = np.zeros(0)
        if self.collision is not None:
            at_ends = self.collision.closest_many(self.chain())[0].min(axis=0)
            self._obstacle_margins = end_margins(settings.clearance_margin, at_ends)
        N = self.intervals
        #: The tool poses the free ends keep (None: the ends are fixed at ``q_start``, ``q_goal``).
        self.free_ends = free_ends
        #: A lower bound of the cost [s], valid by construction (the cost's
        #: :meth:`~modular_robots.costs.Cost.lower_bound`; with free ends,
        #: :func:`~modular_robots.ocp.ends.free_ends_bound`). Used by step D to prune a candidate
        #: before it is solved.
        self.cost_bound = route_cost_bound(
            self.objective, robot, self.q_start, self.q_goal, self.velocity_bound, free_ends, route
        )
        #: A lower bound on the motion's duration, pauses included [s] (the time cost's bound,
        #: whatever the cost).
        self.time_bound = route_cost_bound(
            COSTS["time"], robot, self.q_start, self.q_goal, self.velocity_bound, free_ends, route
        )
        self.x_start = np.concatenate([self.q_start, np.zeros(nv)])
        self.x_goal = np.concatenate([self.q_goal, np.zeros(nv)])

        #: The joint-space path of the first guess (with several phases: the chain of step B's
        #: configurations, each move walked along its own detour).
        self.waypoints = (
            (self.chain() if self.phases > 1 else detour_path(robot, self.collision, self.q_start, self.q_goal))
            if waypoints is None
            else np.asarray(waypoints, dtype=float)
        )
        phase_tf, guess_nodes, guess_acc = self._initial_motion()
        #: The first guess's duration of the motion, pauses aside [s].
        self.tf_guess = float(np.sum(phase_tf))
        #: The cost in its unit [s] is the scaled cost times this.
        self.cost_unit = self.tf_guess
        lower, upper = robot.lower, robot.upper
        q_scale = np.where(np.isfinite(upper - lower) & (upper > lower), (upper - lower) / 2.0, 1.0)
        v_scale = positive_or_one(robot.velocity_limit)
        self.x_scale = np.concatenate([q_scale, v_scale])
        self.u_scale = self.transcription.control_scale(robot, self.tf_guess, N)
        self.tau_scale = positive_or_one(robot.effort_limit)
        self._u0 = 1 + (N - 1) * n
        #: The first column of the free ends ``q_0, q_N`` (after the controls; none when fixed).
        self._ends0 = self._u0 + N * nv
        ends = 0 if free_ends is None else 2
        #: The columns of the phases' durations: the first variable, then after the free ends.
        self.duration_columns = np.concatenate([[0], self._ends0 + ends * nv + np.arange(self.phases - 1)])
        self.n_variables = self._ends0 + ends * nv + self.phases - 1
        self.variable_scale = np.concatenate(
            [
                [phase_tf[0]],
                np.tile(self.x_scale, N - 1),
                np.tile(self.u_scale, N),
                np.tile(q_scale, ends),
                phase_tf[1:],
            ]
        )
        guess_u = self.transcription.initial_controls(robot, guess_nodes[:-1, :nv], guess_nodes[:-1, nv:], guess_acc)
        if self.transcription.controls_are_torques:
            guess_u = np.clip(guess_u, -self.effort_bound, self.effort_bound)
        if max_time is not None and self.tf_guess > max_time - self.hold:
            phase_tf = phase_tf * ((max_time - self.hold) / self.tf_guess)
        self._guess = self.pack(phase_tf, guess_nodes, guess_u)
        self._build_bounds()
        self._build_pattern()
        self._cache: tuple[bytes, Evaluation] | None = None

    # -- layout --------------------------------------------------------------------------
    def pack(self, tf, nodes: np.ndarray, controls: np.ndarray) -> np.ndarray:
        """Scaled decision vector from ``tf`` [s] (each phase's duration, with several), all
        ``N + 1`` node states and ``N`` controls."""
        nodes = np.asarray(nodes)
        durations = np.broadcast_to(np.asarray(tf, dtype=float), (self.phases,))
        parts: list[np.ndarray] = [durations[:1], nodes[1:-1].ravel(), np.asarray(controls).ravel()]
        if self.free_ends is not None:
            parts += [nodes[0, : self.nv], nodes[-1, : self.nv]]
        parts.append(durations[1:])
        return np.concatenate(parts) / self.variable_scale

    def durations(self, y: np.ndarray) -> np.ndarray:
        """Each phase's duration [s] ``(phases,)``."""
        return np.asarray(y, dtype=float)[self.duration_columns] * self.variable_scale[self.duration_columns]

    def motion_time(self, y: np.ndarray) -> float:
        """The motion's duration [s], its pauses included."""
        return math.fsum(self.durations(y)) + self.hold

    def stop_times(self, y: np.ndarray) -> np.ndarray:
        """When each move ends [s] ``(phases,)``: at each via, then at the goal (the pauses before
        it included; a pause there starts then)."""
        holds = np.asarray(self.route.holds)
        return holds[0] + np.cumsum(self.durations(y)) + np.concatenate([[0.0], np.cumsum(holds[1:-1])])

    def interval_durations(self, y: np.ndarray) -> np.ndarray:
        """Each interval's duration [s] ``(N,)``: its phase's over :attr:`phase_intervals`."""
        return self.durations(y)[self._phase] / self.phase_intervals

    def unpack(self, y: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """``(tf, nodes (N + 1, 2 nv), controls (N, nv))`` in SI units from a scaled vector,
        ``tf`` the motion's duration without the pauses (the phases' sum)."""
        z = np.asarray(y, dtype=float) * self.variable_scale
        inner = z[1 : self._u0].reshape(self.intervals - 1, self.nx)
        first, last = self.x_start, self.x_goal
        if self.free_ends is not None:
            rest = np.zeros(self.nv)
            first = np.concatenate([z[self._ends0 : self._ends0 + self.nv], rest])
            last = np.concatenate([z[self._ends0 + self.nv : self._ends0 + 2 * self.nv], rest])
        nodes = np.vstack([first, inner, last])
        tf = float(z[0]) if self.phases == 1 else math.fsum(z[self.duration_columns])
        return tf, nodes, z[self._u0 : self._ends0].reshape(self.intervals, self.nv)

    def initial_guess(self) -> np.ndarray:
        """Straight line in joint space (or a clear detour, see :mod:`~modular_robots.ocp.guess`), a trapezoidal
        velocity profile, ``tf`` from the velocity limits (scaled)."""
        return self._guess.copy()

    def with_objective(self, cost: Cost) -> ShootingProblem:
        """The same problem minimising ``cost`` (its variables and scaling unchanged): a stage of
        the objective's continuation."""
        return ShootingProblem(
            self.robot,
            self.q_start,
            self.q_goal,
            self.obstacles,
            cost,
            self.settings,
            self.substeps,
            self.waypoints,
            self.self_collision is not None,
            self.orientations,
            self.free_ends,
            self.max_time,
            self.route,
        )

    def phase_problem(self, q_a: np.ndarray, q_b: np.ndarray) -> ShootingProblem | None:
        """The single move from rest at ``q_a`` to rest at ``q_b`` on this problem's robot,
        obstacles and settings, for the least time (None when they are the same configuration):
        what :class:`~modular_robots.ocp.candidate.Candidate` solves first for each phase."""
        if np.allclose(q_a, q_b, rtol=0.0, atol=1e-9):
            return None
        return ShootingProblem(
            self.robot,
            q_a,
            q_b,
            self.obstacles,
            "time",
            self.settings,
            self.substeps,
            None,
            self.self_collision is not None,
        )

    def refined(self, substeps: int | None = None, waypoints: np.ndarray | None = None) -> ShootingProblem:
        """The same problem with ``substeps`` per interval (decision vectors carry over as they
        are) or with the initial guess along ``waypoints`` (they do not: the scaling follows the
        guess)."""
        return ShootingProblem(
            self.robot,
            self.q_start,
            self.q_goal,
            self.obstacles,
            self.objective,
            self.settings,
            substeps or self.substeps,
            self.waypoints if waypoints is None else waypoints,
            self.self_collision is not None,
            self.orientations,
            self.free_ends,
            self.max_time,
            self.route,
        )

    def _configuration(self, q, label) -> np.ndarray:
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (self.nv,) or not np.all(np.isfinite(q)):
            raise ProblemError(f"{label} must be {self.nv} finite joint values, got {q.tolist()}")
        lo, hi = self.robot.lower, self.robot.upper
        if np.any(q < lo - 1e-9) or np.any(q > hi + 1e-9):
            raise ProblemError(f"{label} = {np.round(q, 6).tolist()} is outside the joint limits")
        return q

    def chain(self) -> np.ndarray:
        """The configurations at the start, at each via (step B's) and at the goal ``(P + 1, nv)``."""
        return np.vstack([self.q_start, *(np.asarray(v.q, dtype=float) for v in self.route.vias), self.q_goal])

    def _initial_motion(self):
        """Each phase's duration ``(P,)``, node states and node accelerations of the initial
        guess: the waypoint path (each move's detour, with several phases) walked with a
        trapezoidal profile (one interval to speed up, one to stop), at a cruise speed where the
        busiest joint moves at its velocity limit."""
        if self.phases == 1:
            tf, nodes, acc = self._walk(self.waypoints, self.phase_intervals)
            return np.array([tf]), nodes, acc
        chain = self.waypoints
        walks = [
            self._walk(detour_path(self.robot, self.collision, a, b), self.phase_intervals)
            for a, b in itertools.pairwise(chain)
        ]
        nodes = np.vstack([walks[0][1][:1], *(w[1][1:] for w in walks)])
        return np.array([w[0] for w in walks]), nodes, np.vstack([w[2] for w in walks])

    def _walk(self, path: np.ndarray, N: int):
        """``tf``, the ``N + 1`` node states and ``N`` accelerations of ``path`` walked with the
        trapezoidal profile, at rest at both ends."""
        nv = self.nv
        seg_time = path_times(self.robot, path)
        total = float(seg_time.sum())
        tf = max(total * N / (N - 1), 1e-2)
        h = tf / N
        bounds = np.concatenate([[0.0], np.cumsum(seg_time)])
        nodes = np.zeros((N + 1, 2 * nv))
        for m in range(N + 1):
            lam = min(h * np.clip(m - 0.5, 0.0, N - 1), total)
            k = int(np.clip(np.searchsorted(bounds, lam, side="right") - 1, 0, len(seg_time) - 1))
            slope = (path[k + 1] - path[k]) / seg_time[k] if seg_time[k] > 0 else np.zeros(nv)
            nodes[m, :nv] = path[k] + slope * (lam - bounds[k])
            nodes[m, nv:] = slope if 0 < m < N else 0.0
        nodes[N, :nv] = path[-1]
        acc = np.diff(nodes[:, nv:], axis=0) / h
        return tf, nodes, acc

    # -- bounds and sparsity -----------------------------------------------------------------
    def _build_bounds(self) -> None:
        robot, N, nv = self.robot, self.intervals, self.nv
        x_lo = np.concatenate([robot.lower, -self.velocity_bound])
        x_hi = np.concatenate([robot.upper, self.velocity_bound])
        if self.transcription.controls_are_torques:
            u_lo, u_hi = -self.effort_bound, self.effort_bound
        else:
            u_lo, u_hi = np.full(nv, -np.inf), np.full(nv, np.inf)
        ends = 0 if self.free_ends is None else 2
        phase_tf = self.variable_scale[self.duration_columns]
        shortest = 1e-3 * phase_tf
        longest = 1e3 * phase_tf
        if self.max_time is not None:
            longest = np.minimum(longest, self.max_time - self.hold)
        lb = np.concatenate(
            [shortest[:1], np.tile(x_lo, N - 1), np.tile(u_lo, N), np.tile(robot.lower, ends), shortest[1:]]
        )
        ub = np.concatenate(
            [longest[:1], np.tile(x_hi, N - 1), np.tile(u_hi, N), np.tile(robot.upper, ends), longest[1:]]
        )
        self.variable_lower = lb / self.variable_scale
        self.variable_upper = ub / self.variable_scale
        self._x_lo, self._x_hi = x_lo, x_hi

    def _build_pattern(self) -> None:
        """Row layout, bounds and the fixed sparsity pattern of the constraint Jacobian."""
        N, S, n, nv = self.intervals, self.substeps, self.nx, self.nv
        p = n + nv + 1
        cols = self._cols = np.array([self._interval_columns(m) for m in range(N)])
        pairs = (len(self.collision.obstacles) if self.collision else 0) + len(self._self_rows)
        blocks = [("continuity", 1, n), ("path", S - 1, n), ("midpoint", S, nv), ("clearance", S, pairs)]
        if not self.transcription.controls_are_torques:
            blocks.append(("torque", S + 1, nv))
        rows: dict[str, np.ndarray] = {}
        lower_parts: list[np.ndarray] = []
        upper_parts: list[np.ndarray] = []
        scale_parts: list[np.ndarray] = []
        start = 0
        for name, k, r in blocks:
            rows[name] = start + np.arange(N * k * r).reshape(N, k, r)
            start += N * k * r
            if name == "continuity":
                lo = hi = np.zeros((N, k, r))
                sc = np.broadcast_to(self.x_scale, (N, k, r))
            elif name == "path":
                x_lo, x_hi = self._x_lo.copy(), self._x_hi.copy()
                if self.transcription.velocity_linear_in_time:
                    x_lo[nv:], x_hi[nv:] = -np.inf, np.inf  # the node bounds hold in between
                lo, hi = (np.broadcast_to(b, (N, k, r)) for b in (x_lo, x_hi))
                sc = np.broadcast_to(self.x_scale, (N, k, r))
            elif name == "midpoint":
                lo, hi = (np.broadcast_to(b, (N, k, r)) for b in (self._x_lo[:nv], self._x_hi[:nv]))
                sc = np.broadcast_to(self.x_scale[:nv], (N, k, r))
            elif name == "clearance":
                lo, hi = np.broadcast_to(self.clearance_margins, (N, k, r)), np.full((N, k, r), np.inf)
                sc = np.ones((N, k, r))
            else:
                lo, hi = (np.broadcast_to(b, (N, k, r)) for b in (-self.effort_bound, self.effort_bound))
                sc = np.broadcast_to(self.tau_scale, (N, k, r))
            lower_parts.append(np.ravel(lo))
            upper_parts.append(np.ravel(hi))
            scale_parts.append(np.ravel(sc))
        end_columns = np.zeros((0, nv), dtype=int)
        if self.free_ends is not None:  # the tool poses at q_0 and q_N, then q_N's clearance
            start_end, goal_end = self.free_ends
            q0, qN = self._ends0 + np.arange(nv), self._ends0 + nv + np.arange(nv)
            end_columns = np.vstack([np.tile(q0, (start_end.size, 1)), np.tile(qN, (goal_end.size + pairs, 1))])
            rows["ends"] = start + np.arange(len(end_columns))
            (start_lo, start_hi), (goal_lo, goal_hi) = start_end.bounds(), goal_end.bounds()
            lower_parts.append(np.concatenate([start_lo, goal_lo, self.clearance_margins]))
            upper_parts.append(np.concatenate([start_hi, goal_hi, np.full(pairs, np.inf)]))
            scale_parts.append(np.ones(len(end_columns)))
        self._route_groups = self._route_layout()
        route_columns = [cols for group in self._route_groups for cols in group.columns]
        if route_columns:
            rows["route"] = start + len(end_columns) + np.arange(len(route_columns))
            for group in self._route_groups:
                lower_parts.append(group.lower)
                upper_parts.append(group.upper)
                scale_parts.append(group.scale)
        lower, upper, scale = (np.concatenate(v) for v in (lower_parts, upper_parts, scale_parts))
        self._rows = rows
        self.row_scale = scale
        # Entries in evaluation order: block local Jacobians, then continuity's -I on s_{m+1},
        # then the free ends' rows.
        row_parts = [np.broadcast_to(rows[name][..., None], rows[name].shape + (p,)).ravel() for name, _, _ in blocks]
        col_parts = [np.broadcast_to(cols[:, None, None, :], rows[name].shape + (p,)).ravel() for name, _, _ in blocks]
        goal_cols = np.full(n, -1)
        if self.free_ends is not None:
            goal_cols[:nv] = self._ends0 + nv + np.arange(nv)
        next_cols = np.array([1 + m * n + np.arange(n) if m < N - 1 else goal_cols for m in range(N)])
        row_parts.append(rows["continuity"][:, 0, :].ravel())
        col_parts.append(next_cols.ravel())
        if self.free_ends is not None:
            row_parts.append(np.repeat(rows["ends"], nv))
            col_parts.append(end_columns.ravel())
        if route_columns:
            row_parts.append(np.repeat(rows["route"], [len(c) for c in route_columns]))
            col_parts.append(np.concatenate(route_columns))
        entry_rows, entry_cols = np.concatenate(row_parts), np.concatenate(col_parts)
        # Drop clearance rows of a fixed start point and rows without a finite bound.
        keep_row = np.isfinite(lower) | np.isfinite(upper)
        if pairs and self.free_ends is None:
            keep_row[rows["clearance"][0, 0]] = False
        new_row = np.cumsum(keep_row) - 1
        self._keep_row = keep_row
        block_of = np.empty(len(lower), dtype=object)
        for name in rows:
            block_of[rows[name].ravel()] = name
        self._block_of_row = block_of[keep_row]
        self._keep_entry = (entry_cols >= 0) & keep_row[entry_rows]
        kept_rows, kept_cols = entry_rows[self._keep_entry], entry_cols[self._keep_entry]
        self._entry_factor = self.variable_scale[kept_cols] / scale[kept_rows]
        # The Jacobian's CSR structure, fixed: evaluation only permutes its data into place.
        jac_rows = new_row[kept_rows]
        self._csr_order = np.lexsort((kept_cols, jac_rows))
        self._csr_indices = kept_cols[self._csr_order].astype(np.int32)
        self._csr_indptr = np.concatenate([[0], np.cumsum(np.bincount(jac_rows, minlength=int(keep_row.sum())))])
        self._csr_indptr = self._csr_indptr.astype(np.int32)
        self.n_constraints = int(keep_row.sum())
        self.constraint_lower = (lower / scale)[keep_row]
        self.constraint_upper = (upper / scale)[keep_row]

    # -- evaluation ------------------------------------------------------------------------
    def evaluate(self, y: np.ndarray, derivatives: bool = True) -> Evaluation:
        """Cost, constraints (scaled) and, if ``derivatives``, their exact Jacobians at ``y``.

        The last evaluation is cached, so the solver's separate calls share one propagation.
        """
        y = np.asarray(y, dtype=float)
        key = y.tobytes()
        if (
            self._cache is not None
            and self._cache[0] == key
            and (self._cache[1].jacobian is not None or not derivatives)
        ):
            return self._cache[1]
        N, S, n, nv = self.intervals, self.substeps, self.nx, self.nv
        _, nodes, controls = self.unpack(y)
        tf = self.durations(y)[self._phase]  # each interval's phase's duration
        prop = self.transcription.propagate(self.robot, nodes[:-1], controls, tf, self.phase_intervals, S, derivatives)
        if not (np.all(np.isfinite(prop.states)) and np.all(np.isfinite(prop.torques))):
            raise NonFiniteError(
                f"the dynamics of {self.robot.name!r} gave non-finite states or torques "
                f"(tf = {tf.sum() / self.phase_intervals:.4g} s)"
            )
        middle_q, middle_sens = self._between_substeps(tf, prop, derivatives)
        clear, clear_grad = self._clearance(prop.states[:, :S, :nv].reshape(-1, nv), derivatives)
        values = [
            (prop.states[:, S] - nodes[1:]).ravel(),
            prop.states[:, 1:S].ravel(),
            middle_q.ravel(),
            clear.ravel(),
        ]
        if not self.transcription.controls_are_torques:
            values.append(prop.torques.ravel())
        end_values, end_jacobian = self._end_rows(nodes, derivatives)
        values.append(end_values)
        route_values, route_data = self._route_rows(y, nodes, derivatives)
        values.append(route_values)
        c = (np.concatenate(values) / self.row_scale)[self._keep_row]
        cost, cost_grad = self.objective.evaluate(self, tf, prop, derivatives)
        jac = None
        if derivatives:
            assert prop.state_sens is not None and prop.torque_sens is not None and middle_sens is not None
            blocks = [prop.state_sens[:, S], prop.state_sens[:, 1:S], middle_sens]
            if clear.shape[1]:
                blocks.append(clear_grad.reshape(N, S, -1, nv) @ prop.state_sens[:, :S, :nv])
            if not self.transcription.controls_are_torques:
                blocks.append(prop.torque_sens)
            blocks.append(np.full(N * n, -1.0))
            if end_jacobian is not None:
                blocks.append(end_jacobian)
            blocks.append(route_data)
            data = np.concatenate([b.ravel() for b in blocks])[self._keep_entry] * self._entry_factor
            jac = sparse.csr_matrix(
                (data[self._csr_order], self._csr_indices, self._csr_indptr),
                shape=(self.n_constraints, self.n_variables),
            )
        evaluation = Evaluation(cost, c, prop, clear, cost_grad, jac)
        self._cache = (key, evaluation)
        return evaluation

    def rows_of(self, *blocks: str) -> np.ndarray:
        """Indices in the constraint vector of the rows of ``blocks`` (``continuity``, ``path``,
        ``midpoint``, ``clearance``, ``torque``), in order."""
        unknown = set(blocks) - set(self._rows)
        if unknown:
            raise ProblemError(f"unknown constraint blocks {sorted(unknown)}; expected some of {list(self._rows)}")
        return np.flatnonzero(np.isin(self._block_of_row, blocks))

    @property
    def has_exact_hessian(self) -> bool:
        """Whether :meth:`exact_hessian` is available (the inverse transcription)."""
        return self.transcription.name == "inverse"

    def exact_hessian(self, y: np.ndarray, multipliers: np.ndarray, rows: np.ndarray) -> sparse.csr_matrix:
        """``sum_i multipliers_i * d2 c_i / dy2`` over the constraint rows ``rows`` (none of them a
        clearance row) at the scaled point ``y``: continuity, positions along the intervals and
        their midpoints exactly, torques with RNEA's curvature (:mod:`~modular_robots.ocp.hessian`).
        """
        if not self.has_exact_hessian:
            raise NotImplementedError(f"no exact Hessian for the {self.transcription.name} transcription")
        if np.any(self._block_of_row[rows] == "clearance"):
            raise ProblemError("the clearance rows have no exact Hessian")
        N, S, nv = self.intervals, self.substeps, self.nv
        mu = np.zeros(len(self.row_scale))
        mu[np.flatnonzero(self._keep_row)[rows]] = multipliers
        mu /= self.row_scale
        cont, path, mid, tau = (mu[self._rows[k]] for k in ("continuity", "path", "midpoint", "torque"))
        _, _, controls = self.unpack(y)
        tf = self.durations(y)[self._phase]
        prop = self.evaluate(y, derivatives=False).propagation
        weight_q, weight_v = np.zeros((N, S + 1, nv)), np.zeros((N, S + 1, nv))
        weight_q[:, S] += cont[:, 0, :nv]
        weight_v[:, S] += cont[:, 0, nv:]
        weight_q[:, 1:S] += path[..., :nv]
        weight_v[:, 1:S] += path[..., nv:]
        weight_q[:, :S] += 0.5 * mid
        weight_q[:, 1:] += 0.5 * mid
        q, v = prop.states[..., :nv].reshape(-1, nv), prop.states[..., nv:].reshape(-1, nv)
        M = self.phase_intervals
        fractions = np.arange(S + 1) / (M * S)
        torque_rows = np.any(tau != 0.0)
        if torque_rows:
            weight = tau.reshape(-1, nv)
            curvature = rnea_curvature(self.robot, q, v, np.repeat(controls, S + 1, axis=0), weight)
            if self.robot.has_friction:  # the motor torque adds friction(v), diagonal in v
                curvature[5][:] += weight * self.robot.friction_derivative(v)
                diagonal = np.arange(nv)
                curvature[1][:, diagonal, diagonal] += weight * self.robot.friction_second_derivative(v)
            weight_q += curvature[4].reshape(N, S + 1, nv)
            weight_v += curvature[5].reshape(N, S + 1, nv)
        local = kinematic_hessians(fractions, tf, controls, weight_q, weight_v)
        if torque_rows:
            local += torque_hessians(fractions, tf, controls, prop.states[..., nv:], curvature)
        # The midpoint's Hermite term is -u (tf / (N S))^2 / 8.
        f1 = 1.0 / (M * S)
        u_cols = 2 * nv + np.arange(nv)
        extra = -0.25 * tf[:, None] * f1**2 * mid.sum(axis=1)
        local[:, u_cols, -1] += extra
        local[:, -1, u_cols] += extra
        local[:, -1, -1] += -0.25 * f1**2 * np.einsum("mjk,mk->m", mid, controls)
        r = np.broadcast_to(self._cols[:, :, None], local.shape)
        c = np.broadcast_to(self._cols[:, None, :], local.shape)
        keep = (r >= 0) & (c >= 0)
        r, c = r[keep], c[keep]
        data = local[keep] * self.variable_scale[r] * self.variable_scale[c]
        return sparse.csr_matrix((data, (r, c)), shape=(self.n_variables, self.n_variables))

    def _between_substeps(self, tf: np.ndarray, prop: Propagation, derivatives: bool):
        """Every sub-step's midpoint configuration ``(N, S, nv)`` on the cubic Hermite interpolant
        of its end states (module docstring), and its sensitivities to the interval parameters
        (``tf`` each interval's phase's duration [s])."""
        M, S, nv = self.phase_intervals, self.substeps, self.nv
        h = (tf / (M * S))[:, None, None]
        q, v = prop.states[:, :, :nv], prop.states[:, :, nv:]
        middle = 0.5 * (q[:, :S] + q[:, 1:]) + 0.125 * h * (v[:, :S] - v[:, 1:])
        if not derivatives:
            return middle, None
        assert prop.state_sens is not None, "propagated without sensitivities"
        dq, dv = prop.state_sens[:, :, :nv], prop.state_sens[:, :, nv:]
        sens = 0.5 * (dq[:, :S] + dq[:, 1:]) + 0.125 * h[..., None] * (dv[:, :S] - dv[:, 1:])
        sens[..., -1] += 0.125 * (v[:, :S] - v[:, 1:]) / (M * S)
        return middle, sens

    def _end_rows(self, nodes: np.ndarray, derivatives: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """The free ends' rows (:mod:`~modular_robots.ocp.ends`: the tool poses at ``q_0`` and
        ``q_N``, then ``q_N``'s clearance rows) and their Jacobian with respect to ``q_0`` or
        ``q_N``, one row of ``nv`` each; nothing when the ends are fixed."""
        if self.free_ends is None:
            return np.zeros(0), (np.zeros((0, self.nv)) if derivatives else None)
        start_end, goal_end = self.free_ends
        q0, qN = nodes[0, : self.nv], nodes[-1, : self.nv]
        start_values, start_jacobian = end_rows(self.robot, start_end, q0, derivatives)
        goal_values, goal_jacobian = end_rows(self.robot, goal_end, qN, derivatives)
        clear, clear_grad = self._clearance(qN[None], derivatives)
        values = np.concatenate([start_values, goal_values, clear[0]])
        if not derivatives:
            return values, None
        assert start_jacobian is not None and goal_jacobian is not None and clear_grad is not None
        return values, np.vstack([start_jacobian, goal_jacobian, clear_grad[0]])

    def _node_columns(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The columns of node ``k``'s configuration and velocity (-1 where fixed)."""
        n, nv, N = self.nx, self.nv, self.intervals
        fixed = np.full(nv, -1)
        if 0 < k < N:
            first = 1 + (k - 1) * n
            return first + np.arange(nv), first + nv + np.arange(nv)
        if self.free_ends is None:
            return fixed, fixed
        return self._ends0 + (0 if k == 0 else nv) + np.arange(nv), fixed

    def _via_node(self, index: int) -> int:
        """The node of configuration ``index`` of the route: 0 the start, ``k`` the ``k``-th via."""
        return index * self.phase_intervals

    def _route_layout(self) -> list[_RouteRows]:
        """The route's rows in order (module docstring; :class:`~modular_robots.ocp.route.Route`):
        the torque that holds a free start or goal still through a pause (within the effort bounds),
        each via's pose, its zero velocity, the torque that holds it still through a pause, its
        return; the goal's return (unless both ends are
        the fixed start); the motion's total duration when several phases share ``max_time``."""
        nv, groups = self.nv, []
        q_scale, v_scale = self.x_scale[:nv], self.x_scale[nv:]
        zero = np.zeros(nv)
        if self.free_ends is not None:  # a free end where the robot pauses (step B held the fixed ones)
            for j, node in ((0, 0), (self.phases, self.intervals)):
                if self.route.holds[j] > 0.0:
                    bound, q_cols = self.effort_bound, self._node_columns(node)[0]
                    groups.append(_RouteRows("hold", -bound, bound, self.tau_scale, [q_cols] * nv, j))
        for j, via in enumerate(self.route.vias, start=1):
            q_cols, v_cols = self._node_columns(self._via_node(j))
            if via.end is not None:
                lo, hi = via.end.bounds()
                groups.append(
                    _RouteRows("pose", lo, hi, np.ones(via.end.size), [q_cols] * via.end.size, j, end=via.end)
                )
            if via.rest:
                groups.append(_RouteRows("rest", zero, zero, v_scale, [np.array([c]) for c in v_cols], j))
            if self.route.holds[j] > 0.0:  # standing still there: the drives hold the payload
                bound = self.effort_bound
                groups.append(_RouteRows("hold", -bound, bound, self.tau_scale, [q_cols] * nv, j))
            if via.returns_to is not None:
                ref = self._node_columns(self._via_node(via.returns_to))[0]
                cols = [np.array([a, b]) for a, b in zip(q_cols, ref)]
                groups.append(_RouteRows("return", zero, zero, q_scale, cols, j, via.returns_to))
        back = self.route.goal_returns_to
        if back is not None and (self.free_ends is not None or back != 0):
            q_cols = self._node_columns(self.intervals)[0]
            ref = self._node_columns(self._via_node(back))[0]
            cols = [np.array([a, b]) for a, b in zip(q_cols, ref)]
            groups.append(_RouteRows("return", zero, zero, q_scale, cols, self.phases, back))
        if self.phases > 1 and self.max_time is not None:
            longest = np.array([self.max_time - self.hold])
            groups.append(
                _RouteRows("total", np.array([-np.inf]), longest, np.array([self.tf_guess]), [self.duration_columns], 0)
            )
        return groups

    def _route_rows(self, y: np.ndarray, nodes: np.ndarray, derivatives: bool) -> tuple[np.ndarray, np.ndarray]:
        """The route's rows (:meth:`_route_layout`) and their Jacobian's entries, in the order of
        the layout's columns."""
        nv = self.nv
        values: list[np.ndarray] = []
        data: list[np.ndarray] = []
        for group in self._route_groups:
            node = nodes[self._via_node(group.node), :nv] if group.node < self.phases else nodes[-1, :nv]
            if group.kind == "pose":
                assert group.end is not None
                value, jacobian = end_rows(self.robot, group.end, node, derivatives)
                values.append(value)
                if jacobian is not None:
                    data.append(jacobian.ravel())
            elif group.kind == "rest":
                values.append(nodes[self._via_node(group.node), nv:])
                data.append(np.ones(nv))
            elif group.kind == "hold":
                model, robot_data = self.robot.model, self.robot.data
                values.append(pin.computeGeneralizedGravity(model, robot_data, node).copy())
                if derivatives:
                    data.append(pin.computeGeneralizedGravityDerivatives(model, robot_data, node).ravel())
            elif group.kind == "return":
                assert group.ref is not None
                values.append(node - nodes[self._via_node(group.ref), :nv])
                data.append(np.tile([1.0, -1.0], nv))
            else:
                values.append(np.array([self.durations(y).sum()]))
                data.append(np.ones(self.phases))
        if not values:
            return np.zeros(0), np.zeros(0)
        return np.concatenate(values), (np.concatenate(data) if derivatives else np.zeros(0))

    @property
    def estimated_blocks(self) -> tuple[str, ...]:
        """The blocks whose second derivatives :meth:`exact_hessian` does not give (the solver's
        ``structured`` Hessian estimates them): the clearance, the free ends' and the route's."""
        return tuple(name for name in ("clearance", "ends", "route") if name in self._rows)

    def _clearance(self, qs: np.ndarray, derivatives: bool):
        """The clearance rows' values at ``qs`` ``(K, nv)``: every obstacle's distance to the
        robot, then the distance of every checked pair that can come within the margin, ``(K, r)``,
        and their gradients ``(K, r, nv)``."""
        parts = []
        if self.collision is not None:
            parts.append(self.collision.closest_many(qs, derivatives))
        if len(self._self_rows):
            assert self.self_collision is not None
            distance, grad = self.self_collision.distances(qs, derivatives)
            parts.append((distance[:, self._self_rows], None if grad is None else grad[:, self._self_rows]))
        if not parts:
            return np.zeros((len(qs), 0)), (np.zeros((len(qs), 0, self.nv)) if derivatives else None)
        if len(parts) == 1:
            return parts[0]
        (d1, g1), (d2, g2) = parts
        grad = None if g1 is None or g2 is None else np.concatenate([g1, g2], axis=1)
        return np.concatenate([d1, d2], axis=1), grad

    @property
    def clearance_margins(self) -> np.ndarray:
        """The least distance [m] each clearance row of a sub-step keeps: every obstacle's, then
        every checked pair's of the robot's own (:attr:`self_collision_rows`), ``(r,)``."""
        return np.concatenate([self._obstacle_margins, self._self_margins])

    @property
    def self_collision_rows(self) -> np.ndarray:
        """Indices into ``self_collision.pairs`` of the pairs with clearance rows, in the order of
        their rows (after the obstacles') at each sub-step."""
        return self._self_rows.copy()

    @property
    def interval_columns(self) -> np.ndarray:
        """``(N, p)``: the variable of each of interval ``m``'s parameters ``(s_m, u_m, tf)``
        (``tf`` its phase's duration); -1 for the fixed ``s_0``."""
        return self._cols

    def _interval_columns(self, m: int) -> np.ndarray:
        """Global columns of interval ``m``'s parameters ``(s_m, u_m, tf)``; -1 for fixed ``s_0``
        (with free ends, its velocity only: ``q_0`` is a variable)."""
        n, nv = self.nx, self.nv
        state = 1 + (m - 1) * n + np.arange(n) if m >= 1 else np.full(n, -1)
        if m == 0 and self.free_ends is not None:
            state[:nv] = self._ends0 + np.arange(nv)
        return np.concatenate([state, self._u0 + m * nv + np.arange(nv), [self.duration_columns[self._phase[m]]]])

    # -- conveniences for the solver ----------------------------------------------------------
    def cost(self, y: np.ndarray) -> float:
        return self.evaluate(y, derivatives=False).cost

    def cost_gradient(self, y: np.ndarray) -> np.ndarray:
        gradient = self.evaluate(y).cost_gradient
        assert gradient is not None  # evaluated with derivatives
        return gradient

    def constraints(self, y: np.ndarray) -> np.ndarray:
        return self.evaluate(y, derivatives=False).constraints

    def constraint_jacobian(self, y: np.ndarray) -> sparse.csr_matrix:
        return self.evaluate(y).jacobian
