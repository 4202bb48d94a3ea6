"""A cylinder obstacle (a column, a pillar, a drum, a tank), flat-ended: its distance to a capsule
by the cylinder's signed distance along the capsule's axis, exact per point and minimised over the
axis by golden-section search (the signed distance of a convex set is convex), as for the box.

FCL is never asked: there is no closed form for a segment and a finite cylinder, and FCL's GJK
answer for a capsule and a cylinder was off by up to 7e-5 m, and its direction by 1e-2, on 291
apart pairs round a tilted cylinder, which the gradient would inherit; the search also gives
the depth of overlapping pairs, which the optimiser's guesses need.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ._geometry import axes_in_frame, golden_minimum, one_capsule, pose_columns, rpy_matrix, witnesses_in_base
from ._json import json_number, json_vector
from .base import Obstacle, Witness, members

if TYPE_CHECKING:
    import fcl

    from .._yamlio import Fields

__all__ = ["CylinderObstacle"]


@dataclass(frozen=True)
class CylinderObstacle:
    """A solid cylinder of ``radius`` [m] and ``length`` [m] along its local z axis, centred at
    ``center`` [m] and turned by ``rpy`` (fixed-axis roll, pitch, yaw [rad]), in the base frame."""

    center: tuple[float, float, float]
    radius: float
    length: float
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    kind: ClassVar[str] = "cylinder"
    closed_form: ClassVar[bool] = True
    moving_only: ClassVar[bool] = False

    def __post_init__(self) -> None:  # any sequences of numbers in, a hashable value out
        object.__setattr__(self, "center", tuple(float(c) for c in self.center))
        object.__setattr__(self, "rpy", tuple(float(c) for c in self.rpy))
        object.__setattr__(self, "radius", float(self.radius))
        object.__setattr__(self, "length", float(self.length))

    @classmethod
    def from_fields(cls, f: Fields) -> CylinderObstacle:
        center = f.vector("center", 3)
        radius = f.number("radius", exclusive_minimum=0.0)
        length = f.number("length", exclusive_minimum=0.0)
        rpy = f.rpy(default=(0.0, 0.0, 0.0))
        f.done()
        return cls(center, radius, length, rpy)

    @classmethod
    def from_json(cls, data: Any) -> CylinderObstacle:
        if not isinstance(data, dict) or set(data) != {"center", "radius", "length", "rpy"}:
            raise ValueError("expected a mapping of center, radius, length and rpy")
        center = json_vector(data["center"], 3, "center")
        rpy = json_vector(data["rpy"], 3, "rpy")
        radius, length = json_number(data["radius"], "radius"), json_number(data["length"], "length")
        if not (radius > 0.0 and length > 0.0):
            raise ValueError(f"radius, length: expected numbers > 0, got {radius!r}, {length!r}")
        return cls((center[0], center[1], center[2]), radius, length, (rpy[0], rpy[1], rpy[2]))

    def to_json(self) -> dict[str, Any]:
        return {"center": list(self.center), "radius": self.radius, "length": self.length, "rpy": list(self.rpy)}

    def describe(self) -> str:
        return f"centre {list(self.center)}, radius {self.radius:g}, length {self.length:g}, rpy {list(self.rpy)}"

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        return np.asarray(self.center, dtype=float), math.hypot(self.radius, 0.5 * self.length)

    def contains(self, point: Sequence[float]) -> bool:
        local = rpy_matrix(self.rpy).T @ (np.asarray(point, dtype=float) - self.center)
        return bool(math.hypot(local[0], local[1]) <= self.radius and abs(local[2]) <= 0.5 * self.length)

    def collision_object(self) -> fcl.CollisionObject:
        import fcl  # never measured with FCL (closed_form); an object for whoever asks

        return fcl.CollisionObject(
            fcl.Cylinder(self.radius, self.length), fcl.Transform(rpy_matrix(self.rpy), np.asarray(self.center))
        )

    @classmethod
    def batch(cls, obstacles: Sequence[Obstacle]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centres ``(O, 3)`` [m], rotations ``(O, 3, 3)`` and (radius, half length) ``(O, 2)`` [m]."""
        cylinders = members(obstacles, CylinderObstacle)
        centers = np.array([o.center for o in cylinders], dtype=float).reshape(-1, 3)
        rotations = np.array([rpy_matrix(o.rpy) for o in cylinders], dtype=float).reshape(-1, 3, 3)
        sizes = np.array([(o.radius, 0.5 * o.length) for o in cylinders], dtype=float).reshape(-1, 2)
        return centers, rotations, sizes

    @classmethod
    def capsule_bounds(
        cls, batch: Any, axis: np.ndarray, mid: np.ndarray, half_length: np.ndarray, radius: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The cylinder's smallest signed distance along each capsule's axis, less its radius:
        exact to rounding, so both bounds."""
        centers, rotations, sizes = batch
        start = (mid - half_length[None, :, None] * axis)[:, :, None]  # (K, P, 1, 3)
        direction = (2.0 * half_length[None, :, None] * axis)[:, :, None]
        local_start = np.einsum("oji,kpoj->kpoi", rotations, start - centers)  # (K, P, O, 3), cylinder frames
        local_direction = np.einsum("oji,kpoj->kpoi", rotations, np.broadcast_to(direction, local_start.shape))
        along = lambda t: _signed_distance(local_start + t[..., None] * local_direction, sizes)  # noqa: E731
        distance = along(golden_minimum(along, local_start.shape[:-1])) - radius[None, :, None]
        return distance, distance

    def signed_distance(self, mid: np.ndarray, axis: np.ndarray, length: float, radius: float) -> Witness:
        return one_capsule(self.signed_distances, mid, axis, length, radius)

    def signed_distances(
        self, mid: np.ndarray, axis: np.ndarray, length: np.ndarray, radius: np.ndarray, deep: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Signed distances ``(N,)`` of ``N`` capsules (``mid``, ``axis`` ``(N, 3)``, ``length``,
        ``radius`` ``(N,)``): the cylinder's smallest signed distance along each capsule's axis,
        less its radius; witness points on the robot and on the cylinder and gradients
        (:func:`_gradient`) ``(N, 3)``. ``deep`` changes nothing: every distance is exact."""
        rotation, center = rpy_matrix(self.rpy), np.asarray(self.center)
        dimensions = np.array([self.radius, 0.5 * self.length])
        local_start, local_direction = axes_in_frame(rotation, center, mid, axis, length)
        radius = np.asarray(radius, dtype=float)
        along = lambda t: _signed_distance(local_start + t[..., None] * local_direction, dimensions)  # noqa: E731
        point = local_start + golden_minimum(along, (len(local_start),))[:, None] * local_direction
        distance = _signed_distance(point, dimensions)
        surface, normal = _surface_and_normal(point, dimensions, local_direction)
        gradient = _gradient(point, dimensions, local_direction, normal, distance)
        return distance - radius, *witnesses_in_base(rotation, center, point, surface, normal, gradient, radius)

    @classmethod
    def normals(cls, batch: Any, on_robot: np.ndarray, on_obstacle: np.ndarray) -> np.ndarray:
        """Outside, from the cylinder's witness point to the robot's; inside, the outward normal
        of the side or end that holds the cylinder's witness point."""
        centers, rotations, sizes = batch
        local = np.einsum("oji,koj->koi", rotations, on_obstacle - centers)
        rho = np.hypot(local[..., 0], local[..., 1])
        end = (np.abs(local[..., 2]) - sizes[:, 1]) >= (rho - sizes[:, 0])  # nearer an end than the side
        with np.errstate(divide="ignore", invalid="ignore"):
            side = np.stack([local[..., 0] / rho, local[..., 1] / rho, np.zeros_like(rho)], axis=-1)
        side = np.nan_to_num(side)
        ends = np.stack([np.zeros_like(rho), np.zeros_like(rho), np.sign(local[..., 2])], axis=-1)
        face_normal = np.einsum("oij,koj->koi", rotations, np.where(end[..., None], ends, side))
        apart = on_robot - on_obstacle
        outside = np.einsum("koc,koc->ko", apart, face_normal) > 0.0
        return np.where(outside[..., None], apart, face_normal)

    def page(self, grow: float = 0.0) -> list[dict[str, Any]]:
        origin = pose_columns(rpy_matrix(self.rpy), np.asarray(self.center))
        return [
            {"type": "cylinder", "radius": self.radius + grow, "length": self.length + 2.0 * grow, "origin": origin}
        ]


def _signed_distance(local: np.ndarray, size: np.ndarray) -> np.ndarray:
    """The signed distance [m] of points ``(..., 3)`` in a cylinder's frame to the cylinder of
    (radius, half length) ``size`` ``(..., 2)``: outside, the distance to it; inside, minus the
    depth below the nearest of the side and the two ends."""
    excess = np.stack([np.hypot(local[..., 0], local[..., 1]) - size[..., 0], np.abs(local[..., 2]) - size[..., 1]], -1)
    return np.linalg.norm(np.maximum(excess, 0.0), axis=-1) + np.minimum(excess.max(axis=-1), 0.0)


def _radial(point: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """The unit directions ``(N, 3)`` away from the cylinder's axis at ``point`` ``(N, 3)``
    (cylinder frame); on the axis, one across the axis and ``direction`` (a subgradient of the
    distance from the axis)."""
    rho = np.hypot(point[:, 0], point[:, 1])[:, None]
    flat = np.column_stack([point[:, 0], point[:, 1], np.zeros(len(point))])
    across = np.cross([0.0, 0.0, 1.0], direction)
    across_size = np.linalg.norm(across, axis=1, keepdims=True)
    on_axis = np.divide(across, across_size, out=np.tile([1.0, 0.0, 0.0], (len(point), 1)), where=across_size > 1e-12)
    return np.divide(flat, rho, out=on_axis, where=rho > 1e-12)


def _surface_and_normal(point: np.ndarray, size: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The nearest points of the cylinder's surface to the points ``point`` ``(N, 3)`` (cylinder
    frame) and the unit directions in which the signed distance grows there."""
    radius, half = size
    radial = _radial(point, direction)
    rho, z = np.hypot(point[:, 0], point[:, 1]), point[:, 2]
    outside = (rho > radius) | (np.abs(z) > half)
    clamped = np.minimum(rho, radius)[:, None] * radial
    clamped[:, 2] = np.clip(z, -half, half)  # clamped radially and along the axis
    gap = point - clamped
    gap_size = np.linalg.norm(gap, axis=1, keepdims=True)
    away = np.divide(gap, gap_size, out=radial.copy(), where=gap_size > 0.0)
    nearest_side = (rho - radius >= np.abs(z) - half)[:, None]  # inside: the side, else an end
    end = np.where(z >= 0.0, 1.0, -1.0)
    on_side = radius * radial
    on_side[:, 2] = z
    on_end = point.copy()
    on_end[:, 2] = end * half
    end_normal = np.zeros_like(point)
    end_normal[:, 2] = end
    surface = np.where(outside[:, None], clamped, np.where(nearest_side, on_side, on_end))
    normal = np.where(outside[:, None], away, np.where(nearest_side, radial, end_normal))
    return surface, normal


def _gradient(
    point: np.ndarray, size: np.ndarray, direction: np.ndarray, normal: np.ndarray, distance: np.ndarray
) -> np.ndarray:
    """The gradients ``(N, 3)`` of the axes' smallest signed distances with respect to a
    translation of each axis, at their deepest points ``point`` ``(N, 3)`` (cylinder frame).
    Outside, the unit ``normal``. Inside, the signed distance is the largest of ``rho - R`` (the
    side) and ``+-z - h`` (the ends), and along the axis it is usually smallest where two of them
    cross: there the gradient is the combination ``l_a n_a + l_b n_b`` with ``l_a + l_b = 1`` and
    ``l_a n_a . d + l_b n_b . d = 0`` (``d`` the axis) that keeps them crossing, as for the box."""
    radius, half = size
    rho, z = np.hypot(point[:, 0], point[:, 1]), point[:, 2]
    up = np.tile([0.0, 0.0, 1.0], (len(point), 1))
    faces = np.stack([_radial(point, direction), up, -up], axis=1)  # (N, 3 faces, 3)
    values = np.column_stack([rho - radius, z - half, -z - half])
    order = np.argsort(values, axis=1)[:, ::-1]
    rows = np.arange(len(point))
    a, b = order[:, 0], order[:, 1]
    face_a, face_b = faces[rows, a], faces[rows, b]
    slope_a = np.einsum("nc,nc->n", face_a, direction)
    slope_b = np.einsum("nc,nc->n", face_b, direction)
    kink = (
        (distance <= 0.0)
        & (values[rows, a] - values[rows, b] <= 1e-9 * max(1.0, radius, half))
        & (slope_a * slope_b < 0.0)  # they cross inside the axis (else the axis ends there)
    )
    weight = np.divide(slope_b, slope_b - slope_a, out=np.zeros_like(slope_a), where=kink)[:, None]
    return np.where(kink[:, None], weight * face_a + (1.0 - weight) * face_b, normal)
