"""Position inverse kinematics within joint limits (Levenberg-Marquardt on Pinocchio Jacobians).

Only the tool position is constrained (orientation is free, SPEC §1). Joints at a limit whose
step would push them further out are frozen for that step (a one-pass active set), so a target
that needs a joint at its limit is still reached. A run stops early when the error stalls, which
is what makes unreachable targets cheap.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .robot import RobotModel

__all__ = ["IKResult", "solve_position_ik", "solve_position_ik_many", "ik_seeds"]

DEFAULT_TOLERANCE = 1e-4
"""Success threshold on the tool position error [m] (SPEC step B)."""


@dataclass(frozen=True)
class IKResult:
    """One IK run: final ``q`` (within limits), tool position ``error`` [m], ``iterations``."""

    q: np.ndarray
    error: float
    iterations: int

    def success(self, tolerance: float = DEFAULT_TOLERANCE) -> bool:
        return self.error <= tolerance


def ik_seeds(robot: RobotModel, count: int, seed: int = 0) -> np.ndarray:
    """``count`` deterministic start configurations: the middle of the limits, then uniform
    draws within them (``numpy`` generator seeded with ``seed``)."""
    lower, upper = robot.lower, robot.upper
    rng = np.random.default_rng(seed)
    draws = rng.uniform(lower, upper, size=(max(count - 1, 0), robot.nq))
    return np.vstack([(lower + upper) / 2.0, draws])[:count]


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
    """:func:`solve_position_ik` from every row of ``seeds`` ``(S, nq)``, one result per row.

    The runs advance in lockstep, each with exactly its own arithmetic, so every result is bit
    for bit the one a run of its own gives. The joint-limit bookkeeping of all runs (which joints
    block, the clipping into the limits) then costs one numpy call per iteration instead of one
    per run: on arrays of a few elements numpy's call overhead, not the arithmetic, is what an
    iteration costs. The Jacobian products stay one per run, as BLAS may round a batched product
    differently.
    """
    model, data, frame = robot.model, robot.data, robot.tool_frame_id
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    target = np.asarray(target, dtype=float)
    q = np.clip(np.asarray(seeds, dtype=float).reshape(-1, model.nq), lower, upper)
    count = len(q)
    best_q, best_error = list(q), [math.inf] * count
    since_best, iterations = [0] * count, [max_iterations] * count
    running = list(range(count))  # the run of each row of q
    for iteration in range(1, max_iterations + 1):
        rows, steps, systems = [], [], []
        for row, run in enumerate(running):
            jacobian = pin.computeFrameJacobian(model, data, q[row], frame, pin.LOCAL_WORLD_ALIGNED)[:3]
            error_vector = target - data.oMf[frame].translation
            error = math.sqrt(error_vector @ error_vector)
            since_best[run] = 0 if error < best_error[run] * stall_ratio else since_best[run] + 1
            if error < best_error[run]:
                best_q[run], best_error[run] = q[row], error
            if error <= tolerance or since_best[run] >= stall_iterations:
                iterations[run] = iteration
                continue
            rows.append(row)
            steps.append(_lm_step(jacobian, error_vector, error))
            systems.append((jacobian, error_vector, error))
        if not rows:
            break
        q, step = q[rows], np.array(steps)
        blocked = ((q <= lower) & (step < 0.0)) | ((q >= upper) & (step > 0.0))
        for row in np.flatnonzero(blocked.any(axis=1)).tolist():
            jacobian, error_vector, error = systems[row]
            free = ~blocked[row]
            step[row] = 0.0
            step[row, free] = _lm_step(jacobian[:, free], error_vector, error)
        q = np.minimum(np.maximum(q + step, lower), upper)
        running = [running[row] for row in rows]
    return [IKResult(best_q[run].copy(), best_error[run], iterations[run]) for run in range(count)]


def _lm_step(jacobian: np.ndarray, error_vector: np.ndarray, error: float) -> np.ndarray:
    """Levenberg-Marquardt step ``(J^T J + w I)^-1 J^T e`` with ``w = |e|^2 / 2 + 1e-4``
    (Sugihara 2011), in its 3 x 3 dual form ``J^T (J J^T + w I)^-1 e``.

    The symmetric positive definite 3 x 3 system is solved by Cramer's rule on scalars: this
    loop runs millions of times in step B and numpy's general solver costs more than the
    arithmetic (``tests/test_feasibility.py`` checks it against the plain normal equations).
    """
    damping = 0.5 * error * error + 1e-4
    (a, b, c), (_, d, e), (_, _, f) = (jacobian @ jacobian.T).tolist()
    a += damping
    d += damping
    f += damping
    x, y, z = error_vector.tolist()
    co_a, co_b, co_c = d * f - e * e, c * e - b * f, b * e - c * d
    det = a * co_a + b * co_b + c * co_c
    if not det > 0.0:  # only for absurd geometry (metres beyond 1e8): no step rather than a crash
        return np.zeros(jacobian.shape[1])
    u = (co_a * x + co_b * y + co_c * z) / det
    v = (co_b * x + (a * f - c * c) * y + (b * c - a * e) * z) / det
    w = (co_c * x + (b * c - a * e) * y + (a * d - b * b) * z) / det
    return jacobian.T @ np.array((u, v, w))


def distinct(solutions: Iterator[np.ndarray], atol: float = 1e-3) -> list[np.ndarray]:
    """Drop configurations within ``atol`` (max norm) of an earlier one."""
    kept: list[np.ndarray] = []
    for q in solutions:
        if all(np.max(np.abs(q - k)) > atol for k in kept):
            kept.append(q)
    return kept
