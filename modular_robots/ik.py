"""Position inverse kinematics within joint limits (Levenberg-Marquardt on Pinocchio Jacobians).

Only the tool position is constrained (orientation is free, SPEC §1). Joints at a limit whose
step would push them further out are frozen for that step (a one-pass active set), so a target
that needs a joint at its limit is still reached. A run stops early when the error stalls, which
is what makes unreachable targets cheap.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pinocchio as pin

from .robot import RobotModel

__all__ = [
    "IKResult",
    "IKProblem",
    "solve_position_ik",
    "solve_position_ik_many",
    "solve_position_ik_batch",
    "ik_seeds",
]

DEFAULT_TOLERANCE = 1e-4
"""Success threshold on the tool position error [m] (SPEC step B)."""


@dataclass(frozen=True)
class IKResult:
    """One IK run: final ``q`` (within limits), tool position ``error`` [m], ``iterations``, and
    for a run that also asks an orientation (:mod:`modular_robots.pose_ik`) its ``angle`` error
    and the ``angle_tolerance`` [rad] it had to meet."""

    q: np.ndarray
    error: float
    iterations: int
    angle: float = 0.0
    angle_tolerance: float = math.inf

    def success(self, tolerance: float = DEFAULT_TOLERANCE) -> bool:
        """Whether the position is within ``tolerance`` [m] and the angle within its own."""
        return self.error <= tolerance and self.angle <= self.angle_tolerance


IKProblem = tuple[RobotModel, np.ndarray, np.ndarray]
"""A robot, a tool position target [m] and start configurations ``(S, nq)``."""


def ik_seeds(robot: RobotModel, count: int, seed: int = 0) -> np.ndarray:
    """``count`` deterministic start configurations: the middle of the limits, then uniform
    draws within them (``numpy`` generator seeded with ``seed``)."""
    return _seeds(tuple(robot.lower.tolist()), tuple(robot.upper.tolist()), count, seed).copy()


@lru_cache(maxsize=1024)  # compositions with the same joints in the same order share their seeds
def _seeds(lower: tuple[float, ...], upper: tuple[float, ...], count: int, seed: int) -> np.ndarray:
    lower_limits, upper_limits = np.array(lower), np.array(upper)
    rng = np.random.default_rng(seed)
    draws = rng.uniform(lower_limits, upper_limits, size=(max(count - 1, 0), len(lower)))
    return np.vstack([(lower_limits + upper_limits) / 2.0, draws])[:count]


def solve_position_ik(
    robot: RobotModel,
    target: np.ndarray,
    q0: np.ndarray,
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 100,
    stall_iterations: int = 6,
    stall_ratio: float = 0.995,
) -> IKResult:
    """Move the tool point to ``target`` [m] from ``q0`` without leaving the joint limits.

    Parameters
    ----------
    robot
        The robot model (its Pinocchio limits bound the search).
    target
        Tool position in the base frame [m].
    q0
        Start configuration (clipped into the limits).
    tolerance
        Stop when the position error is below this [m].
    max_iterations
        Iteration cap.
    stall_iterations, stall_ratio
        Stop when the best error has not dropped below ``stall_ratio`` times itself for
        ``stall_iterations`` iterations in a row (a local minimum: usually out of reach).
    """
    (result,) = solve_position_ik_many(
        robot,
        target,
        np.asarray(q0, dtype=float)[None],
        tolerance=tolerance,
        max_iterations=max_iterations,
        stall_iterations=stall_iterations,
        stall_ratio=stall_ratio,
    )
    return result


def solve_position_ik_many(
    robot: RobotModel,
    target: np.ndarray,
    seeds: np.ndarray,
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 100,
    stall_iterations: int = 6,
    stall_ratio: float = 0.995,
) -> list[IKResult]:
    """:func:`solve_position_ik` from every row of ``seeds`` ``(S, nq)``, one result per row, in
    lockstep (see :func:`solve_position_ik_batch`)."""
    (results,) = solve_position_ik_batch(
        [(robot, target, seeds)],
        tolerance=tolerance,
        max_iterations=max_iterations,
        stall_iterations=stall_iterations,
        stall_ratio=stall_ratio,
    )
    return results


def solve_position_ik_batch(
    problems: Sequence[IKProblem],
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 100,
    stall_iterations: int = 6,
    stall_ratio: float = 0.995,
) -> list[list[IKResult]]:
    """:func:`solve_position_ik` from every start configuration of every ``(robot, target,
    seeds)`` of ``problems``: for each problem, one result per row of its ``seeds``.

    All runs of robots with as many joints advance in lockstep and each keeps exactly its own
    arithmetic, so every result is bit for bit the one a run of its own gives. On arrays of a few
    elements numpy's call overhead, not the arithmetic, is what an iteration costs, so every
    numpy operation acts on all runs at once: the elementwise ones (errors, blocked joints,
    clipping) trivially, and the products (``e . e``, ``J J^T``, ``J^T x``) as stacked matmuls,
    which numpy performs as one BLAS call per run with the same routine and strides as the run's
    own product (BLAS kernels may fuse multiply-adds, so no elementwise formula would round the
    same). Runs whose step a joint limit blocks are solved again stacked by their number of free
    joints; only Pinocchio's Jacobian needs a call per run. An iteration of 8 runs costs about
    1.7 times as much per run as one of 32.
    """
    results: list[list[IKResult]] = [[] for _ in problems]
    by_size: dict[int, list[int]] = {}
    for index, (robot, _, _) in enumerate(problems):
        by_size.setdefault(robot.nq, []).append(index)
    for indices in by_size.values():
        found = _lockstep([problems[i] for i in indices], tolerance, max_iterations, stall_iterations, stall_ratio)
        for index, runs in zip(indices, found):
            results[index] = runs
    return results


def _lockstep(
    problems: Sequence[IKProblem], tolerance: float, max_iterations: int, stall_iterations: int, stall_ratio: float
) -> list[list[IKResult]]:
    """The runs of ``problems`` (robots with as many joints) together, one row of ``q`` each."""
    frames: list[tuple[pin.Model, pin.Data, int]] = []
    starts: list[np.ndarray] = []
    lower_rows: list[np.ndarray] = []
    upper_rows: list[np.ndarray] = []
    target_rows: list[np.ndarray] = []
    for robot, target, seeds in problems:
        model = robot.model
        low, high = model.lowerPositionLimit, model.upperPositionLimit
        start = np.clip(np.asarray(seeds, dtype=float).reshape(-1, model.nq), low, high)
        frames += [(model, robot.data, robot.tool_frame_id)] * len(start)
        starts.append(start)
        lower_rows.append(np.broadcast_to(low, start.shape))
        upper_rows.append(np.broadcast_to(high, start.shape))
        target_rows.append(np.broadcast_to(np.asarray(target, dtype=float), (len(start), 3)))
    q, lower, upper, targets = (np.concatenate(rows) for rows in (starts, lower_rows, upper_rows, target_rows))
    count = len(q)
    best_q, best_error = list(q), [math.inf] * count
    since_best, iterations = [0] * count, [max_iterations] * count
    running = list(range(count))  # the run of each row of q
    for iteration in range(1, max_iterations + 1):
        jacobians, positions = _frame_jacobians(frames, q)
        error_vectors = targets - positions
        error_array = np.sqrt(np.vecdot(error_vectors, error_vectors))
        errors = error_array.tolist()
        rows = []
        for row, (run, error) in enumerate(zip(running, errors)):
            since_best[run] = 0 if error < best_error[run] * stall_ratio else since_best[run] + 1
            if error < best_error[run]:
                best_q[run], best_error[run] = q[row], error
            if error <= tolerance or since_best[run] >= stall_iterations:
                iterations[run] = iteration
            else:
                rows.append(row)
        if not rows:
            break
        if len(rows) < len(q):
            q, jacobians, error_vectors, error_array = q[rows], jacobians[rows], error_vectors[rows], error_array[rows]
            lower, upper, targets = lower[rows], upper[rows], targets[rows]
            frames, running = [frames[row] for row in rows], [running[row] for row in rows]
        q = _lm_iteration(q, lower, upper, jacobians[:, :3], error_vectors, error_array)
    results = iter([IKResult(best_q[run].copy(), best_error[run], iterations[run]) for run in range(count)])
    return [list(itertools.islice(results, len(start))) for start in starts]


def _frame_jacobians(frames: list[tuple[pin.Model, pin.Data, int]], q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinocchio's Jacobian ``(K, 6, nv)`` (base-frame axes) and position ``(K, 3)`` of the frame
    ``(model, data, frame id)`` of each row of ``q`` ``(K, nq)``."""
    jacobians, positions = np.empty((len(q), 6, q.shape[1])), np.empty((len(q), 3))
    for row, ((model, data, frame), q_row) in enumerate(zip(frames, q)):
        # Pinocchio returns a one-column matrix as a vector (6,): one joint gives (6,), not (6, 1).
        jacobians[row] = pin.computeFrameJacobian(model, data, q_row, frame, pin.LOCAL_WORLD_ALIGNED).reshape(6, -1)
        positions[row] = data.oMf[frame].translation
    return jacobians, positions


def _lm_iteration(
    q: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    jacobians: np.ndarray,
    error_vectors: np.ndarray,
    errors: np.ndarray,
) -> np.ndarray:
    """The next configuration of every run ``(K, nq)``: the Levenberg-Marquardt step of its
    position Jacobian ``(K, 3, nv)``, except that joints at a limit which the step would push
    further out stay (the others take the step of the Jacobian without them), clipped into the
    limits."""
    step = _lm_steps(jacobians, error_vectors, errors)
    blocked = ((q <= lower) & (step < 0.0)) | ((q >= upper) & (step > 0.0))
    stuck = np.flatnonzero(blocked.any(axis=1)).tolist()
    if stuck:
        step[stuck] = 0.0
        _free_steps(step, stuck, ~blocked[stuck], jacobians, error_vectors, errors)
    return np.minimum(np.maximum(q + step, lower), upper)


def _free_steps(
    step: np.ndarray,
    rows: list[int],
    free: np.ndarray,
    jacobians: np.ndarray,
    error_vectors: np.ndarray,
    errors: np.ndarray,
) -> None:
    """Write into ``step`` the Levenberg-Marquardt step of the Jacobian ``J[:, free]`` of the
    runs ``rows`` (``free``: their free joints, one row each).

    Runs with as many free joints are solved together. numpy lays ``J[:, free]`` out as the
    transpose of a C-ordered ``(free joints, 3)`` block, so all runs' blocks are gathered in one
    array, sorted by size, and each size's slice, reshaped, is a stack with that very layout:
    the stacked products are the BLAS calls of each run's own ``J[:, free]``.
    """
    sizes = free.sum(axis=1).tolist()
    order = sorted(range(len(rows)), key=sizes.__getitem__)
    runs, joints = np.nonzero(free[order])
    runs = np.array([rows[i] for i in order])[runs]
    blocks = jacobians.mT[runs, joints]
    steps, start = [], 0
    for size, group in itertools.groupby(order, key=sizes.__getitem__):
        members = [rows[i] for i in group]
        end = start + size * len(members)
        if size:
            stacked = blocks[start:end].reshape(len(members), size, 3).mT
            found = _lm_steps(stacked, error_vectors[members], errors[members])
            steps.append(found.ravel())
        start = end
    if steps:
        step[runs, joints] = np.concatenate(steps)


def _lm_steps(jacobians: np.ndarray, error_vectors: np.ndarray, errors: np.ndarray) -> np.ndarray:
    """Levenberg-Marquardt steps ``(J^T J + w I)^-1 J^T e`` with ``w = |e|^2 / 2 + 1e-4``
    (Sugihara 2011), in their 3 x 3 dual form ``J^T (J J^T + w I)^-1 e``, of every run: Jacobians
    ``(K, 3, nv)``, error vectors ``e`` ``(K, 3)`` and errors ``|e|`` ``(K,)``; steps ``(K, nv)``.

    The symmetric positive definite 3 x 3 systems are solved by Cramer's rule, all runs at once
    (each operation is one array operation over the runs, in the order a scalar Cramer's rule
    takes: the same floating-point results; ``tests/test_feasibility.py`` checks them against
    the plain normal equations). A system that is not positive definite, which only absurd
    geometry (metres beyond 1e8) gives, gets no step rather than a crash.
    """
    products = jacobians @ jacobians.mT
    damping = 0.5 * errors * errors + 1e-4
    a, b, c = products[:, 0, 0] + damping, products[:, 0, 1], products[:, 0, 2]
    d, e, f = products[:, 1, 1] + damping, products[:, 1, 2], products[:, 2, 2] + damping
    x, y, z = error_vectors[:, 0], error_vectors[:, 1], error_vectors[:, 2]
    co_a, co_b, co_c = d * f - e * e, c * e - b * f, b * e - c * d
    det = a * co_a + b * co_b + c * co_c
    solvable = det > 0.0
    det = np.where(solvable, det, 1.0)
    solutions = np.empty((len(det), 3, 1))
    solutions[:, 0, 0] = (co_a * x + co_b * y + co_c * z) / det
    solutions[:, 1, 0] = (co_b * x + (a * f - c * c) * y + (b * c - a * e) * z) / det
    solutions[:, 2, 0] = (co_c * x + (b * c - a * e) * y + (a * d - b * b) * z) / det
    steps = (jacobians.mT @ solutions)[:, :, 0]
    if not solvable.all():
        steps[~solvable] = 0.0
    return steps


def distinct(solutions: Iterator[np.ndarray], atol: float = 1e-3) -> list[np.ndarray]:
    """Drop configurations within ``atol`` (max norm) of an earlier one (configurations are
    finite): which pairs are apart is one array operation, the greedy pass plain Python."""
    found = list(solutions)
    if len(found) < 2:
        return found
    rows = np.array(found)
    apart = (np.abs(rows[:, None, :] - rows[None, :, :]) > atol).any(axis=2).tolist()
    kept: list[int] = []
    for i, row in enumerate(apart):
        if all(row[j] for j in kept):
            kept.append(i)
    return [found[i] for i in kept]
