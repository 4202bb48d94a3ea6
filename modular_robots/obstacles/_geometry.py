"""Closed-form geometry the shapes share: rotations from roll-pitch-yaw and the closest points of
two segments, vectorised over any leading axes."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = [
    "rpy_matrix",
    "segment_parameters",
    "pose_columns",
    "golden_minimum",
    "one_capsule",
    "axes_in_frame",
    "witnesses_in_base",
    "SEARCH_STEPS",
]

#: Golden-section steps of :func:`golden_minimum`: the bracket shrinks to 0.618^64 (about 1e-13).
SEARCH_STEPS = 64
_GOLD = (math.sqrt(5.0) - 1.0) / 2.0


def rpy_matrix(rpy: tuple[float, float, float]) -> np.ndarray:
    """The rotation of fixed-axis roll, pitch, yaw [rad] (URDF's: ``Rz(yaw) Ry(pitch) Rx(roll)``)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def pose_columns(rotation: np.ndarray, position: np.ndarray) -> list[float]:
    """A 4x4 pose as 16 numbers in column-major order (three.js's, the page's)."""
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = rotation, position
    return pose.T.ravel().tolist()


def segment_parameters(p1: np.ndarray, d1: np.ndarray, p2: np.ndarray, d2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Parameters ``s, t`` in [0, 1] of the closest points ``p1 + s d1`` and ``p2 + t d2`` of two
    segments (each may be a point: a zero direction), by the clamped normal equations
    (Ericson, Real-Time Collision Detection, 5.1.9); arrays ``(..., 3)`` broadcast together."""
    r = p1 - p2
    a = np.einsum("...c,...c->...", d1, d1)
    e = np.einsum("...c,...c->...", d2, d2)
    b = np.einsum("...c,...c->...", d1, d2)
    c = np.einsum("...c,...c->...", d1, r)
    f = np.einsum("...c,...c->...", d2, r)
    a, e, b, c, f = np.broadcast_arrays(a, e, b, c, f)
    tiny = 1e-300
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-12 * np.maximum(a * e, tiny), np.clip((b * f - c * e) / denom, 0.0, 1.0), 0.0)
        t = np.where(e > tiny, (b * s + f) / e, 0.0)
        below, above = t < 0.0, t > 1.0
        t = np.clip(t, 0.0, 1.0)
        s = np.where(below, np.clip(-c / np.where(a > tiny, a, 1.0), 0.0, 1.0), s)
        s = np.where(above, np.clip((b - c) / np.where(a > tiny, a, 1.0), 0.0, 1.0), s)
    s = np.where(e > tiny, s, np.clip(-c / np.where(a > tiny, a, 1.0), 0.0, 1.0))  # the second a point
    s = np.where(a > tiny, s, 0.0)
    return s, t


def golden_minimum(f: Callable[[np.ndarray], np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
    """The parameters ``t`` in [0, 1] ``shape`` where the convex functions ``f(t)`` (evaluated
    elementwise on arrays of ``shape``) are smallest, by :data:`SEARCH_STEPS` steps of
    golden-section search; an end where it is no larger than the search's point. The box and
    the cylinder minimise their signed distance along a link with it."""
    low, high = np.zeros(shape), np.ones(shape)
    a, b = high - _GOLD * (high - low), low + _GOLD * (high - low)
    fa, fb = f(a), f(b)
    for _ in range(SEARCH_STEPS):
        left = fa <= fb  # the minimum is in [low, b]
        high = np.where(left, b, high)
        low = np.where(left, low, a)
        new = np.where(left, high - _GOLD * (high - low), low + _GOLD * (high - low))
        fnew = f(new)
        a, b, fa, fb = (
            np.where(left, new, b),
            np.where(left, a, new),
            np.where(left, fnew, fb),
            np.where(left, fa, fnew),
        )
    t = 0.5 * (low + high)
    ends = [np.zeros(shape), np.ones(shape)]
    best = np.argmin(np.stack([f(t), *(f(e) for e in ends)]), axis=0)
    return np.choose(best, [t, *ends])


def one_capsule(
    many: Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    mid: np.ndarray,
    axis: np.ndarray,
    length: float,
    radius: float,
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray | None]:
    """A shape's ``signed_distance`` of one capsule from its ``signed_distances`` (``many``): the
    distance, the witness points, and the gradient (None where ``many`` gives NaN)."""
    d, on_robot, on_shape, gradient = many(
        np.asarray(mid, dtype=float)[None], np.asarray(axis, dtype=float)[None], np.array([length]), np.array([radius])
    )
    return float(d[0]), on_robot[0], on_shape[0], None if np.isnan(gradient[0]).any() else gradient[0]


def axes_in_frame(
    rotation: np.ndarray, center: np.ndarray, mid: np.ndarray, axis: np.ndarray, length: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The capsules' axes (midpoints ``mid`` and unit ``axis`` ``(N, 3)``, ``length`` ``(N,)``) in
    a shape's frame (``rotation``, ``center``): starts and directions ``(N, 3)``."""
    mid, axis = np.asarray(mid, dtype=float).reshape(-1, 3), np.asarray(axis, dtype=float).reshape(-1, 3)
    length = np.asarray(length, dtype=float)
    start = (mid - 0.5 * length[:, None] * axis - center) @ rotation  # rotation^T v, row by row
    return start, (length[:, None] * axis) @ rotation


def witnesses_in_base(
    rotation: np.ndarray,
    center: np.ndarray,
    point: np.ndarray,
    surface: np.ndarray,
    normal: np.ndarray,
    gradient: np.ndarray,
    radius: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From a shape's frame to the base: the robot's witness points (the axes' deepest ``point``
    moved by the capsules' ``radius`` across the ``gradient``, or the ``normal`` where it is
    zero), the shape's (``surface``) and the gradients, each ``(N, 3)``."""
    size = np.linalg.norm(gradient, axis=1, keepdims=True)
    across = np.divide(gradient, size, out=normal.copy(), where=size > 0.0)
    on_robot = center + (point - np.asarray(radius, dtype=float)[:, None] * across) @ rotation.T
    return on_robot, center + surface @ rotation.T, gradient @ rotation.T
