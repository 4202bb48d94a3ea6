"""A box obstacle (a fence, a machine housing, a table seen as a block): its distance to a capsule
by the box's signed distance along the capsule's axis, in closed form per point and minimised
over the axis (the signed distance of a convex set is convex, so a golden-section search finds the
minimum to rounding in :data:`SEARCH_STEPS` steps). FCL is never asked."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ._geometry import (
    SEARCH_STEPS,
    axes_in_frame,
    golden_minimum,
    one_capsule,
    pose_columns,
    rpy_matrix,
    witnesses_in_base,
)
from ._json import json_vector
from .base import Obstacle, Witness, members

if TYPE_CHECKING:
    import fcl

    from .._yamlio import Fields

__all__ = ["BoxObstacle", "SEARCH_STEPS"]

#: Golden-section steps along a capsule's axis: the bracket shrinks to 0.618^64 = 4e-14 of the
#: axis's length, far below any clearance the package asks for.


@dataclass(frozen=True)
class BoxObstacle:
    """A box of side lengths ``size`` [m] along its local axes, centred at ``center`` [m] and
    turned by ``rpy`` (fixed-axis roll, pitch, yaw [rad]), in the base frame."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    kind: ClassVar[str] = "box"
    closed_form: ClassVar[bool] = True
    moving_only: ClassVar[bool] = False

    def __post_init__(self) -> None:  # any sequences of numbers in, a hashable value out
        for name in ("center", "size", "rpy"):
            object.__setattr__(self, name, tuple(float(c) for c in getattr(self, name)))

    @classmethod
    def from_fields(cls, f: Fields) -> BoxObstacle:
        center = f.vector("center", 3)
        size = f.vector("size", 3)
        f.check("size", all(s > 0.0 for s in size), f"expected three side lengths > 0 [m], got {list(size)}")
        rpy = f.rpy(default=(0.0, 0.0, 0.0))
        f.done()
        return cls(center, size, rpy)

    @classmethod
    def from_json(cls, data: Any) -> BoxObstacle:
        if not isinstance(data, dict) or set(data) != {"center", "size", "rpy"}:
            raise ValueError("expected a mapping of center, size and rpy")
        center, size, rpy = (json_vector(data[k], 3, k) for k in ("center", "size", "rpy"))
        if not all(s > 0.0 for s in size):
            raise ValueError(f"size: expected three side lengths > 0, got {list(size)}")
        return cls(center, size, rpy)  # type: ignore[arg-type]

    def to_json(self) -> dict[str, Any]:
        return {"center": list(self.center), "size": list(self.size), "rpy": list(self.rpy)}

    def describe(self) -> str:
        return f"centre {list(self.center)}, size {list(self.size)}, rpy {list(self.rpy)}"

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        return np.asarray(self.center, dtype=float), 0.5 * float(np.linalg.norm(self.size))

    def contains(self, point: Sequence[float]) -> bool:
        local = rpy_matrix(self.rpy).T @ (np.asarray(point, dtype=float) - self.center)
        return bool(np.all(np.abs(local) <= 0.5 * np.asarray(self.size)))

    def collision_object(self) -> fcl.CollisionObject:
        import fcl  # never measured with FCL (closed_form); an object for whoever asks

        return fcl.CollisionObject(fcl.Box(*self.size), fcl.Transform(rpy_matrix(self.rpy), np.asarray(self.center)))

    @classmethod
    def batch(cls, obstacles: Sequence[Obstacle]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centres ``(O, 3)`` [m], rotations ``(O, 3, 3)`` and half sizes ``(O, 3)`` [m]."""
        boxes = members(obstacles, BoxObstacle)
        centers = np.array([o.center for o in boxes], dtype=float).reshape(-1, 3)
        rotations = np.array([rpy_matrix(o.rpy) for o in boxes], dtype=float).reshape(-1, 3, 3)
        return centers, rotations, 0.5 * np.array([o.size for o in boxes], dtype=float).reshape(-1, 3)

    @classmethod
    def capsule_bounds(
        cls, batch: Any, axis: np.ndarray, mid: np.ndarray, half_length: np.ndarray, radius: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The box's smallest signed distance along each capsule's axis, less its radius: exact
        to rounding, so both bounds."""
        centers, rotations, halves = batch
        start = (mid - half_length[None, :, None] * axis)[:, :, None]  # (K, P, 1, 3)
        direction = (2.0 * half_length[None, :, None] * axis)[:, :, None]
        # in each box's frame: (K, P, O, 3)
        local_start = np.einsum("oji,kpoj->kpoi", rotations, start - centers)
        local_direction = np.einsum("oji,kpoj->kpoi", rotations, np.broadcast_to(direction, local_start.shape))
        t = _minimising_parameter(local_start, local_direction, halves)
        distance = _signed_distance(local_start + t[..., None] * local_direction, halves)
        distance = distance - radius[None, :, None]
        return distance, distance

    def signed_distance(self, mid: np.ndarray, axis: np.ndarray, length: float, radius: float) -> Witness:
        return one_capsule(self.signed_distances, mid, axis, length, radius)

    def signed_distances(
        self, mid: np.ndarray, axis: np.ndarray, length: np.ndarray, radius: np.ndarray, deep: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Signed distances ``(N,)`` of ``N`` capsules (``mid``, ``axis`` ``(N, 3)``, ``length``,
        ``radius`` ``(N,)``): the box's smallest signed distance along each capsule's axis (the
        module docstring), less its radius; witness points on the robot and on the box and
        gradients (:func:`_gradient`) ``(N, 3)``. ``deep`` changes nothing: every distance is exact."""
        rotation, center = rpy_matrix(self.rpy), np.asarray(self.center)
        half = 0.5 * np.asarray(self.size)
        local_start, local_direction = axes_in_frame(rotation, center, mid, axis, length)
        radius = np.asarray(radius, dtype=float)
        t = _minimising_parameter(local_start, local_direction, half)
        point = local_start + t[:, None] * local_direction
        distance = _signed_distance(point, half)
        surface, normal = _surface_and_normal(point, half)
        gradient = _gradient(point, half, local_direction, normal, distance)
        return distance - radius, *witnesses_in_base(rotation, center, point, surface, normal, gradient, radius)

    @classmethod
    def normals(cls, batch: Any, on_robot: np.ndarray, on_obstacle: np.ndarray) -> np.ndarray:
        """Outside, from the box's witness point to the robot's; inside (the two on opposite
        sides of the face), the outward normal of the face that holds the box's witness point."""
        centers, rotations, halves = batch
        local = np.einsum("oji,koj->koi", rotations, on_obstacle - centers)
        face = np.argmax(np.abs(local) / halves, axis=-1)  # (K, O)
        sign = np.sign(np.take_along_axis(local, face[..., None], axis=-1))
        face_normal = np.einsum("oji,koi->koj", rotations, np.eye(3)[face] * sign)
        apart = on_robot - on_obstacle
        outside = np.einsum("koc,koc->ko", apart, face_normal) > 0.0
        return np.where(outside[..., None], apart, face_normal)

    def page(self, grow: float = 0.0) -> list[dict[str, Any]]:
        size = [s + 2.0 * grow for s in self.size]
        return [{"type": "box", "size": size, "origin": pose_columns(rpy_matrix(self.rpy), np.asarray(self.center))}]


def _signed_distance(local: np.ndarray, half: np.ndarray) -> np.ndarray:
    """The signed distance [m] of points ``(..., 3)`` in a box's frame to the box of half sizes
    ``half``: the distance to it outside, minus the depth inside."""
    excess = np.abs(local) - half
    outside = np.linalg.norm(np.maximum(excess, 0.0), axis=-1)
    inside = np.minimum(excess.max(axis=-1), 0.0)
    return outside + inside


def _minimising_parameter(start: np.ndarray, direction: np.ndarray, half: np.ndarray) -> np.ndarray:
    """The parameter ``t`` in [0, 1] of the point of ``start + t direction`` where the box's
    signed distance is smallest (:func:`~._geometry.golden_minimum`; convex in ``t``)."""
    shape = np.broadcast_shapes(start.shape, direction.shape)[:-1]
    return golden_minimum(lambda t: _signed_distance(start + t[..., None] * direction, half), shape)


def _gradient(
    point: np.ndarray, half: np.ndarray, direction: np.ndarray, normal: np.ndarray, distance: np.ndarray
) -> np.ndarray:
    """The gradients ``(N, 3)`` of the axes' smallest signed distances with respect to a
    translation of each axis, at their deepest points ``point`` ``(N, 3)`` (box frame). Outside,
    the unit ``normal``. Inside, the signed distance is the largest of the six faces'
    ``n_i . p - h_i``, and along the axis it is usually smallest where two of them cross (two
    adjacent faces, or a face and its opposite at the mid-plane): there the gradient is the
    combination ``l_a n_a + l_b n_b`` with ``l_a + l_b = 1`` and ``l_a n_a . d + l_b n_b . d = 0``
    (``d`` the axis) that keeps them crossing; the nearest face's normal where one face is
    nearest or the axis ends there."""
    faces = np.vstack([np.eye(3), -np.eye(3)])
    values = point @ faces.T - np.concatenate([half, half])  # (N, 6)
    order = np.argsort(values, axis=1)[:, ::-1]
    rows = np.arange(len(point))
    a, b = order[:, 0], order[:, 1]
    slope_a = np.einsum("nc,nc->n", faces[a], direction)
    slope_b = np.einsum("nc,nc->n", faces[b], direction)
    kink = (
        (distance <= 0.0)
        & (values[rows, a] - values[rows, b] <= 1e-9 * max(1.0, float(half.max())))
        & (slope_a * slope_b < 0.0)  # they cross inside the axis (else the axis ends there)
    )
    weight = np.divide(slope_b, slope_b - slope_a, out=np.zeros_like(slope_a), where=kink)[:, None]
    return np.where(kink[:, None], weight * faces[a] + (1.0 - weight) * faces[b], normal)


def _surface_and_normal(local: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The nearest points of the box's surface to the points ``local`` ``(N, 3)`` (box frame) and
    the unit directions in which the signed distance grows there."""
    outside = np.any(np.abs(local) > half, axis=1)
    clamped = np.clip(local, -half, half)
    gap = local - clamped
    gap_size = np.linalg.norm(gap, axis=1, keepdims=True)
    face = np.argmax(np.abs(local) - half, axis=1)  # inside: the nearest face
    rows = np.arange(len(local))
    face_normal = np.zeros_like(local)
    face_normal[rows, face] = np.where(local[rows, face] >= 0.0, 1.0, -1.0)
    on_face = local.copy()
    on_face[rows, face] = face_normal[rows, face] * half[face]
    away = np.divide(gap, gap_size, out=face_normal.copy(), where=gap_size > 0.0)
    return np.where(outside[:, None], clamped, on_face), np.where(outside[:, None], away, face_normal)
