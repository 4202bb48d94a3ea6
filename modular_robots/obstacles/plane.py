"""A half-space obstacle (a floor, a wall, a table top seen from above): every distance to it in
closed form. FCL is never asked: its distance to a half-space crashes the process."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ._geometry import one_capsule
from ._json import json_vector
from .base import Obstacle, Witness, members

if TYPE_CHECKING:
    import fcl

    from .._yamlio import Fields

__all__ = ["PlaneObstacle"]

#: The side [m] of the square the page draws for a plane, centred on the point of the plane
#: nearest the base.
PAGE_SIDE = 3.0


@dataclass(frozen=True)
class PlaneObstacle:
    """Everything behind the plane through ``point`` [m] with the unit ``normal`` (pointing into
    the free side), in the base frame: ``(x - point) . normal <= 0`` is inside."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    kind: ClassVar[str] = "plane"
    closed_form: ClassVar[bool] = True
    moving_only: ClassVar[bool] = False

    def __post_init__(self) -> None:  # any sequences of numbers in; the normal made unit
        n = np.asarray([float(c) for c in self.normal])
        length = float(np.linalg.norm(n))
        if not (math.isfinite(length) and length > 0.0):
            raise ValueError(f"normal: expected a non-zero vector, got {list(self.normal)}")
        object.__setattr__(self, "point", tuple(float(c) for c in self.point))
        object.__setattr__(self, "normal", tuple(float(c) for c in n / length))

    @classmethod
    def from_fields(cls, f: Fields) -> PlaneObstacle:
        point = f.vector("point", 3)
        normal = f.vector("normal", 3)
        f.check("normal", any(c != 0.0 for c in normal), f"expected a non-zero vector, got {list(normal)}")
        f.done()
        return cls(point, normal)

    @classmethod
    def from_json(cls, data: Any) -> PlaneObstacle:
        if not isinstance(data, dict) or set(data) != {"point", "normal"}:
            raise ValueError("expected a mapping of point and normal")
        return cls(json_vector(data["point"], 3, "point"), json_vector(data["normal"], 3, "normal"))  # type: ignore[arg-type]

    def to_json(self) -> dict[str, Any]:
        return {"point": list(self.point), "normal": list(self.normal)}

    def describe(self) -> str:
        return f"plane through {list(self.point)}, normal {[round(c, 6) for c in self.normal]}"

    @property
    def offset(self) -> float:
        """``normal . point`` [m]: the plane is ``normal . x = offset``."""
        return float(np.dot(self.normal, self.point))

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        return np.asarray(self.point, dtype=float), math.inf

    def contains(self, point: Sequence[float]) -> bool:
        return float(np.dot(self.normal, point)) - self.offset <= 0.0

    def collision_object(self) -> fcl.CollisionObject:
        import fcl  # never measured with FCL (closed_form); an object for whoever asks

        return fcl.CollisionObject(fcl.Halfspace(np.asarray(self.normal), self.offset))

    @classmethod
    def batch(cls, obstacles: Sequence[Obstacle]) -> tuple[np.ndarray, np.ndarray]:
        """Unit normals ``(O, 3)`` and offsets ``(O,)`` [m]."""
        planes = members(obstacles, PlaneObstacle)
        normals = np.array([o.normal for o in planes], dtype=float).reshape(-1, 3)
        return normals, np.array([o.offset for o in planes], dtype=float)

    @classmethod
    def capsule_bounds(
        cls, batch: Any, axis: np.ndarray, mid: np.ndarray, half_length: np.ndarray, radius: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The height of the capsule's lower end above the plane, less its radius: exact."""
        normals, offsets = batch
        centre = np.einsum("kpc,oc->kpo", mid, normals) - offsets
        spread = np.abs(np.einsum("kpc,oc->kpo", axis, normals)) * half_length[None, :, None]
        distance = centre - spread - radius[None, :, None]
        return distance, distance

    def signed_distance(self, mid: np.ndarray, axis: np.ndarray, length: float, radius: float) -> Witness:
        return one_capsule(self.signed_distances, mid, axis, length, radius)

    def signed_distances(
        self, mid: np.ndarray, axis: np.ndarray, length: np.ndarray, radius: np.ndarray, deep: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Signed distances ``(N,)`` of ``N`` capsules (``mid``, ``axis`` ``(N, 3)``, ``length``,
        ``radius`` ``(N,)``): the height of each capsule's lower axis end above the plane, less its
        radius; witness points ``(N, 3)`` that end moved down by the radius and its foot on the
        plane; gradients the normal. ``deep`` changes nothing: every distance is exact."""
        n = np.asarray(self.normal)
        mid, axis = np.asarray(mid, dtype=float).reshape(-1, 3), np.asarray(axis, dtype=float).reshape(-1, 3)
        length, radius = np.asarray(length, dtype=float), np.asarray(radius, dtype=float)
        spread = 0.5 * length[:, None] * axis
        ends = np.stack([mid - spread, mid + spread])  # (2, N, 3), the lower end first on a tie
        heights = ends @ n - self.offset
        low = np.argmin(heights, axis=0)
        rows = np.arange(len(mid))
        end, height = ends[low, rows], heights[low, rows]
        return (
            height - radius,
            end - radius[:, None] * n,
            end - height[:, None] * n,
            np.broadcast_to(n, end.shape).copy(),
        )

    @classmethod
    def normals(cls, batch: Any, on_robot: np.ndarray, on_obstacle: np.ndarray) -> np.ndarray:
        return np.broadcast_to(batch[0], on_obstacle.shape).copy()

    def page(self, grow: float = 0.0) -> list[dict[str, Any]]:
        """A thin square slab under the plane, around the point of the plane nearest the base."""
        n = np.asarray(self.normal)
        z = n
        x = np.cross([0.0, 1.0, 0.0] if abs(n[1]) < 0.9 else [1.0, 0.0, 0.0], z)
        x /= np.linalg.norm(x)
        rotation = np.column_stack([x, np.cross(z, x), z])
        thickness = 0.002
        centre = (self.offset + grow - 0.5 * thickness) * n
        origin = np.eye(4)
        origin[:3, :3], origin[:3, 3] = rotation, centre
        return [{"type": "box", "size": [PAGE_SIDE, PAGE_SIDE, thickness], "origin": origin.T.ravel().tolist()}]
