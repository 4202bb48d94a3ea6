"""Check a shooting solution independently of the transcription that produced it (SPEC §5).

The controls are re-applied to the robot's forward dynamics (Pinocchio ABA) and every
integration sub-step is integrated from its planned state with an adaptive Runge-Kutta method
(SciPy ``DOP853``, tight tolerances). The gap between where a sub-step's re-integration ends and
where the plan says it ends (the next node, for the last sub-step of an interval) is the local
error; summed over an interval's sub-steps it is the interval's *defect*: for the forward
transcription RK4's discretisation error, which more sub-steps remove, and for the inverse one
(exact parabolas) only a continuity gap. The terminal tool-position error comes from one
re-integration of the whole last interval from its node. On a dense time grid of the re-integrated
motion we measure the obstacle clearance (FCL), the joint limits and the torques, and, unless
self-collision is off, the distance of every checked pair of the robot's own primitives
(:mod:`~modular_robots.self_collision`, closed form): a pair that overlaps on the grid gives the
clearance its (negative) distance, so that a link passing through another between two sub-steps
fails the plan as one passing through an obstacle does; the clearance of a plan clear of itself is
its obstacles'.

Why restart at every sub-step and not integrate open loop over an interval or the whole motion:
a serial arm under gravity is an unstable open-loop system, so a long integration amplifies
1e-10 integration errors exponentially and says nothing about the plan (measured on paper
compositions: velocity limits exceeded 857 times after 27 s over the whole motion; a scaled gap
of 3.5e-3 over one 0.57 s interval of an arm with a light wrist, for a plan whose sub-steps each
re-integrate to 1e-8). A robot follows a plan with feedback.

The figures' value type and pass tolerances are :mod:`modular_robots.plan.verification`'s.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import DOP853

from ..plan.verification import TERMINAL_TOLERANCE, Verification
from .shooting import ShootingProblem

__all__ = ["Verification", "verify", "grid_density", "MIN_GRID_POINTS", "TERMINAL_TOLERANCE"]

#: The fewest points of the dense grid over a whole plan: a coarse transcription (3 nodes, one
#: sub-step) measured at 8 points per sub-step saw 18 instants over 3.5 s, and reported a clearance
#: 1.65 mm above the plan's. The default 8 nodes and 4 sub-steps give 224 already.
MIN_GRID_POINTS = 200


def grid_density(problem: ShootingProblem, points_per_substep: int = 8) -> int:
    """Grid points per sub-step: ``points_per_substep``, or more when the plan has so few sub-steps
    that the whole grid would hold fewer than :data:`MIN_GRID_POINTS`."""
    return max(points_per_substep, -(-MIN_GRID_POINTS // (problem.intervals * problem.substeps)))


class _StackedDOP853(DOP853):
    """SciPy's DOP853 on ``blocks`` independent systems stacked into one state: a step is accepted
    only if every system's own DOP853 error norm accepts it (their largest is the step's norm), so
    each system is held to ``rtol`` and ``atol`` as if integrated alone."""

    def __init__(self, fun, t0, y0, t_bound, blocks: int, **options):
        self.blocks = blocks
        super().__init__(fun, t0, y0, t_bound, **options)

    def _estimate_error_norm(self, K, h, scale):
        err5 = (np.dot(K.T, self.E5) / scale).reshape(self.blocks, -1)
        err3 = (np.dot(K.T, self.E3) / scale).reshape(self.blocks, -1)
        e5, e3 = np.einsum("bi,bi->b", err5, err5), np.einsum("bi,bi->b", err3, err3)
        denominator = (e5 + 0.01 * e3) * err5.shape[1]
        norms = np.abs(h) * e5 / np.sqrt(np.where(denominator > 0, denominator, 1.0))
        return float(np.max(norms))  # NaN when a system blew up: the step is refused


#: Steps the joint integration of all sub-steps may take before each sub-step is integrated on its
#: own: the shared steps follow the hardest sub-step (4-30 on the paper's plans, refined ones too), so a
#: plan with one much harder sub-step is cheaper one sub-step at a time. A bound on cost, not on
#: accuracy.
JOINT_STEPS = 64

_TOO_LONG = "too long"


def _integrate(problem, nodes, controls, starts, x0, duration, rtol, atol, grid=(), max_steps=None):
    """Integrate ``B`` sub-steps under the plan's control law (``Transcription.plan_dynamics``)
    from states ``x0`` ``(B, 2 nv)`` for ``duration`` seconds with :class:`_StackedDOP853`.
    Returns the end states ``(B, 2 nv)`` and the states ``(B, len(grid), 2 nv)`` at the times
    ``grid`` (increasing, in ``[0, duration]``), each read from the interpolant of the step it falls
    in as the integration passes it (memory: the results only); None if the integration fails,
    :data:`_TOO_LONG` after ``max_steps`` steps.

    Time runs from ``duration`` to ``2 duration``: SciPy refuses a step below ten spacings of the
    floating-point numbers at ``t``, which at ``t = 0`` is 1e-322 s, so a plan that blows up would
    be followed almost forever; from ``duration`` it fails within a few steps.
    """
    x0 = np.asarray(x0, dtype=float)
    if not np.all(np.isfinite(x0)):
        return None
    rhs = problem.transcription.plan_dynamics(
        problem.robot, nodes, controls, np.asarray(starts, dtype=float) - duration
    )
    solver = _StackedDOP853(rhs, duration, x0.ravel(), 2 * duration, len(x0), rtol=rtol, atol=atol)
    times = np.asarray(grid, dtype=float) + duration
    at = np.empty((len(times), x0.size))
    done, steps = 0, 0
    while solver.status == "running":
        if steps == max_steps:
            return _TOO_LONG
        solver.step()
        steps += 1
        if solver.status == "failed":
            return None
        # the last step takes any grid time that rounding put beyond the end
        upto = len(times) if solver.status == "finished" else int(np.searchsorted(times, solver.t, side="right"))
        if upto > done:
            at[done:upto] = solver.dense_output()(times[done:upto]).T
            done = upto
    return solver.y.reshape(x0.shape), at.reshape(len(times), *x0.shape).transpose(1, 0, 2)


def _substeps(problem, nodes, controls, starts, x0, duration, rtol, atol, grid):
    """Every one of ``B`` sub-steps integrated from ``x0`` for ``duration`` s: at once, or one at a
    time if that takes more than :data:`JOINT_STEPS` steps. Returns the end states ``(B, 2 nv)`` and
    the states ``(B, len(grid), 2 nv)`` at the times ``grid`` into the sub-steps; None if an
    integration fails."""
    joint = _integrate(problem, nodes, controls, starts, x0, duration, rtol, atol, grid, JOINT_STEPS)
    if joint is not _TOO_LONG:
        return joint
    runs = []
    for b in range(len(x0)):
        one = slice(b, b + 1)
        run = _integrate(problem, nodes[one], controls[one], starts[one], x0[one], duration, rtol, atol, grid)
        if run is None:
            return None
        runs.append(run)
    return np.concatenate([end for end, _ in runs]), np.concatenate([at for _, at in runs])


def verify(
    problem: ShootingProblem, y: np.ndarray, points_per_substep: int = 8, rtol: float = 1e-10, atol: float = 1e-10
) -> Verification:
    """Re-integrate the solution ``y`` of ``problem`` adaptively and measure it (module docstring).

    The ``N S`` sub-steps are integrated as one system of ``N S`` independent states over a
    sub-step's duration: one adaptive step sequence serves all, so SciPy's per-step work is paid
    once, and a step is accepted only if every sub-step's own error test accepts it
    (:class:`_StackedDOP853`).
    """
    robot, tr = problem.robot, problem.transcription
    tf, nodes, controls = problem.unpack(y)
    N, S, nv, M = problem.intervals, problem.substeps, problem.nv, problem.phase_intervals
    durations = problem.durations(y)
    vmax, tmax = robot.velocity_limit, robot.effort_limit
    span = np.where(
        np.isfinite(robot.upper - robot.lower) & (robot.upper > robot.lower), robot.upper - robot.lower, 1.0
    )
    phase_tf = np.repeat(durations, M)
    planned = problem.transcription.propagate(robot, nodes[:-1], controls, phase_tf, M, S, False).states
    ends = np.concatenate([planned[:, 1:S], nodes[1:, None]], axis=1)  # (N, S, 2 nv)
    # The dense grid: points per sub-step (grid_density), and the interval's end after its last.
    grid_points = grid_density(problem, points_per_substep) + 1
    end = np.empty((N * S, 2 * nv))
    dense = np.empty((N * S, grid_points, 2 * nv))
    seconds = np.empty((N, S, grid_points))
    for k, duration in enumerate(durations):  # a phase's sub-steps share their duration
        hs = float(duration) / (M * S)
        rows = slice(k * M * S, (k + 1) * M * S)
        starts = np.tile(np.arange(S) * hs, M)  # each sub-step's offset into its interval [s]
        phase = slice(k * M, (k + 1) * M)
        x0 = planned[phase, :S].reshape(M * S, 2 * nv)
        grid = np.linspace(0.0, hs, grid_points)
        interval_nodes, interval_controls = np.repeat(nodes[phase], S, axis=0), np.repeat(controls[phase], S, axis=0)
        run = _substeps(problem, interval_nodes, interval_controls, starts, x0, hs, rtol, atol, grid)
        if run is None:
            return Verification(np.inf, np.inf, np.inf, -np.inf, np.inf, np.inf, np.inf, 0, S)
        end[rows], dense[rows] = run
        seconds[phase] = starts.reshape(M, S, 1) + grid
    gap = np.abs(end.reshape(N, S, 2 * nv) - ends) / problem.x_scale
    defect = float(np.max(gap.sum(axis=1)))
    samples = np.zeros((N, S, grid_points), dtype=bool)
    samples[:, :, :-1] = samples[:, -1, -1] = True
    states = dense.reshape(N, S, grid_points, 2 * nv)[samples]
    q, v = states[:, :nv], states[:, nv:]
    where = np.nonzero(samples)
    torques = tr.torque(robot, nodes[where[0]], controls[where[0]], seconds[samples])
    clearance = np.inf
    if problem.collision is not None:  # an interval's samples at a time: bounded memory
        clearance = min(float(problem.collision.closest_many(part)[0].min()) for part in np.array_split(q, N))
    if problem.self_collision is not None:
        own = min(float(problem.self_collision.distances(part)[0].min()) for part in np.array_split(q, N))
        if own < 0.0:
            clearance = min(clearance, own)
    pos_excess = float(np.max(np.maximum(robot.lower - q, q - robot.upper) / span))
    vel_share = np.max(np.abs(v) / vmax, axis=0)
    tau_share = np.max(np.abs(torques) / tmax, axis=0)
    held = _held(problem, nodes)
    if len(held):  # the drives hold the payload still there
        tau_share = np.maximum(
            tau_share, np.max(np.abs(robot.rnea(held, np.zeros_like(held), np.zeros_like(held))) / tmax, axis=0)
        )
    points = len(states)
    last_node = nodes[N - 1 : N]
    last = _integrate(problem, last_node, controls[N - 1 :], np.zeros(1), last_node, durations[-1] / M, rtol, atol)
    x = last[0][0] if last is not None else np.full(2 * nv, np.inf)
    error = float(np.linalg.norm(robot.tool_position(x[:nv]) - robot.tool_position(nodes[N, :nv])))
    excess = 0.0
    for orientation, q in zip(problem.orientations, (nodes[0, :nv], nodes[N, :nv])):
        if orientation is not None:
            excess = max(excess, orientation.angle(robot.tool_rotation(q)) - orientation.tolerance)
    goal_excess, goal_angle = _goals(problem, nodes)
    return Verification(
        error,
        float(np.max(np.abs(x[nv:]))),
        defect,
        clearance,
        max(pos_excess, 0.0),
        float(vel_share.max()),
        float(tau_share.max()),
        points,
        S,
        tuple(map(float, vel_share)),
        tuple(map(float, tau_share)),
        max(excess, goal_angle),
        max((tf + problem.hold) / problem.max_time - 1.0, 0.0) if problem.max_time is not None else 0.0,
        goal_excess,
    )


def _held(problem: ShootingProblem, nodes: np.ndarray) -> np.ndarray:
    """The configurations ``(K, nv)`` where the robot holds the payload still: the start and the
    goal (before and after the motion; the plan's first and last rows), and a via with a pause."""
    at = [0, *(j * problem.phase_intervals for j in range(1, problem.phases)), problem.intervals]
    ends = (0, len(at) - 1)
    return np.array(
        [nodes[k, : problem.nv] for j, (k, hold) in enumerate(zip(at, problem.route.holds)) if hold > 0.0 or j in ends]
    )


def _goals(problem: ShootingProblem, nodes: np.ndarray) -> tuple[float, float]:
    """At each via of the plan (the goals between the start and the end), measured on the
    planned node with Pinocchio's kinematics: the largest distance [m] beyond a pose's position
    tolerance, the largest joint distance [rad | m] from the configuration a return asks, or
    speed [rad/s | m/s] where the goal asks rest (the larger of these, 0 when all hold), and the
    largest angle [rad] beyond an orientation tolerance."""
    robot, nv, excess, angle = problem.robot, problem.nv, 0.0, 0.0
    route = problem.route
    node = [0, *(j * problem.phase_intervals for j in range(1, route.phases)), problem.intervals]
    for j, via in enumerate(route.vias, start=1):
        q, v = nodes[node[j], :nv], nodes[node[j], nv:]
        if via.end is not None:
            distance = float(np.linalg.norm(robot.tool_position(q) - np.asarray(via.end.position)))
            excess = max(excess, distance - via.end.tolerance)
            if via.end.orientation is not None:
                orientation = via.end.orientation
                angle = max(angle, orientation.angle(robot.tool_rotation(q)) - orientation.tolerance)
        if via.rest:
            excess = max(excess, float(np.max(np.abs(v))))
        if via.returns_to is not None:
            excess = max(excess, float(np.max(np.abs(q - nodes[node[via.returns_to], :nv]))))
    if route.goal_returns_to is not None:
        excess = max(excess, float(np.max(np.abs(nodes[-1, :nv] - nodes[node[route.goal_returns_to], :nv]))))
    return excess, angle
