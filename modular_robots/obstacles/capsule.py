"""A capsule obstacle (a column, a pipe, a rounded beam): every distance to it in closed form."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ._geometry import pose_columns, rpy_matrix, segment_parameters
from ._json import json_number, json_vector
from .base import Obstacle, Witness, members

if TYPE_CHECKING:
    import fcl

    from .._yamlio import Fields

__all__ = ["CapsuleObstacle"]


@dataclass(frozen=True)
class CapsuleObstacle:
    """The points within ``radius`` [m] of a segment of ``length`` [m] along the local z axis,
    centred at ``center`` [m] and turned by ``rpy`` (fixed-axis roll, pitch, yaw [rad]), in the
    base frame."""

    center: tuple[float, float, float]
    radius: float
    length: float
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    kind: ClassVar[str] = "capsule"
    closed_form: ClassVar[bool] = True
    moving_only: ClassVar[bool] = False

    def __post_init__(self) -> None:  # any sequences of numbers in, a hashable value out
        object.__setattr__(self, "center", tuple(float(c) for c in self.center))
        object.__setattr__(self, "rpy", tuple(float(c) for c in self.rpy))
        object.__setattr__(self, "radius", float(self.radius))
        object.__setattr__(self, "length", float(self.length))

    @classmethod
    def from_fields(cls, f: Fields) -> CapsuleObstacle:
        center = f.vector("center", 3)
        radius = f.number("radius", exclusive_minimum=0.0)
        length = f.number("length", exclusive_minimum=0.0)
        rpy = f.rpy(default=(0.0, 0.0, 0.0))
        f.done()
        return cls(center, radius, length, rpy)

    @classmethod
    def from_json(cls, data: Any) -> CapsuleObstacle:
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

    @property
    def axis(self) -> np.ndarray:
        """The unit direction of the segment, the local z axis, in the base frame."""
        return rpy_matrix(self.rpy)[:, 2]

    def _ends(self) -> tuple[np.ndarray, np.ndarray]:
        """The segment's start and its direction (end minus start) [m]."""
        half = 0.5 * self.length * self.axis
        return np.asarray(self.center) - half, 2.0 * half

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        return np.asarray(self.center, dtype=float), 0.5 * self.length + self.radius

    def contains(self, point: Sequence[float]) -> bool:
        start, direction = self._ends()
        p = np.asarray(point, dtype=float)
        t = float(np.clip((p - start) @ direction / (direction @ direction), 0.0, 1.0))
        return float(np.linalg.norm(p - start - t * direction)) <= self.radius

    def collision_object(self) -> fcl.CollisionObject:
        import fcl  # at model time: the scenario reader imports this module

        return fcl.CollisionObject(
            fcl.Capsule(self.radius, self.length), fcl.Transform(rpy_matrix(self.rpy), np.asarray(self.center))
        )

    @classmethod
    def batch(cls, obstacles: Sequence[Obstacle]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Segment starts and directions ``(O, 3)`` [m] and radii ``(O,)`` [m]."""
        capsules = members(obstacles, CapsuleObstacle)
        ends = [o._ends() for o in capsules]
        starts = np.array([e[0] for e in ends], dtype=float).reshape(-1, 3)
        directions = np.array([e[1] for e in ends], dtype=float).reshape(-1, 3)
        return starts, directions, np.array([o.radius for o in capsules], dtype=float)

    @classmethod
    def capsule_bounds(
        cls, batch: Any, axis: np.ndarray, mid: np.ndarray, half_length: np.ndarray, radius: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The distance between the two segments less both radii: exact, so both bounds."""
        starts, directions, radii = batch
        p1 = (mid - half_length[None, :, None] * axis)[:, :, None]  # (K, P, 1, 3)
        d1 = (2.0 * half_length[None, :, None] * axis)[:, :, None]
        s, t = segment_parameters(p1, d1, starts[None, None], directions[None, None])
        gap = p1 + s[..., None] * d1 - starts - t[..., None] * directions
        distance = np.linalg.norm(gap, axis=-1) - radius[None, :, None] - radii[None, None, :]
        return distance, distance

    def signed_distance(self, mid: np.ndarray, axis: np.ndarray, length: float, radius: float) -> Witness:
        start, direction = self._ends()
        p1 = np.asarray(mid, dtype=float) - 0.5 * length * np.asarray(axis, dtype=float)
        d1 = length * np.asarray(axis, dtype=float)
        s, t = (float(v) for v in segment_parameters(p1, d1, start, direction))
        on_robot_axis, on_axis = p1 + s * d1, start + t * direction
        apart = float(np.linalg.norm(on_robot_axis - on_axis))
        # crossing axes: any direction across both (the distance is -r - R either way)
        toward = (on_robot_axis - on_axis) / apart if apart > 0.0 else _across(d1, direction)
        distance = apart - radius - self.radius
        return distance, on_robot_axis - radius * toward, on_axis + self.radius * toward, toward

    @classmethod
    def normals(cls, batch: Any, on_robot: np.ndarray, on_obstacle: np.ndarray) -> np.ndarray:
        """From the closest point of the obstacle's axis to its witness point: right inside too."""
        starts, directions, _ = batch
        t = np.clip(
            np.einsum("koc,oc->ko", on_obstacle - starts, directions) / np.einsum("oc,oc->o", directions, directions),
            0.0,
            1.0,
        )
        return on_obstacle - (starts + t[..., None] * directions)

    def page(self, grow: float = 0.0) -> list[dict[str, Any]]:
        origin = pose_columns(rpy_matrix(self.rpy), np.asarray(self.center))
        return [{"type": "capsule", "radius": self.radius + grow, "length": self.length, "origin": origin}]


def _across(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A unit vector across both ``a`` and ``b`` (either may be zero)."""
    n = np.cross(a, b)
    if np.linalg.norm(n) < 1e-12:
        n = np.cross(a if np.linalg.norm(a) > 0 else b, [1.0, 0.0, 0.0])
        if np.linalg.norm(n) < 1e-12:
            n = np.cross(a if np.linalg.norm(a) > 0 else b, [0.0, 1.0, 0.0])
    if np.linalg.norm(n) < 1e-12:  # both zero: cannot happen, a capsule obstacle has a length
        n = np.array([0.0, 0.0, 1.0])
    return n / np.linalg.norm(n)
