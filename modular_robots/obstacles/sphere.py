"""A sphere obstacle: every distance to it in closed form."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ._geometry import one_capsule
from ._json import json_number, json_vector
from .base import Obstacle, Witness, members

if TYPE_CHECKING:
    import fcl

    from .._yamlio import Fields

__all__ = ["SphereObstacle", "capsule_sphere"]

#: A batch of spheres: centres ``(O, 3)`` and radii ``(O,)`` [m].
SphereBatch = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class SphereObstacle:
    """A sphere obstacle: ``center`` in the base frame [m], ``radius`` [m]."""

    center: tuple[float, float, float]
    radius: float
    kind: ClassVar[str] = "sphere"
    closed_form: ClassVar[bool] = True  # capsule_sphere, all of a query's pairs at once
    moving_only: ClassVar[bool] = False

    def __post_init__(self) -> None:  # any sequence of three numbers in, a hashable value out
        x, y, z = (float(c) for c in self.center)
        object.__setattr__(self, "center", (x, y, z))
        object.__setattr__(self, "radius", float(self.radius))

    @classmethod
    def from_fields(cls, f: Fields) -> SphereObstacle:
        center = f.vector("center", 3)
        radius = f.number("radius", exclusive_minimum=0.0)
        f.done()
        return cls((center[0], center[1], center[2]), radius)

    @classmethod
    def from_json(cls, data: Any) -> SphereObstacle:
        if not isinstance(data, dict) or set(data) != {"center", "radius"}:
            raise ValueError("expected a mapping of center and radius")
        center = json_vector(data["center"], 3, "center")
        radius = json_number(data["radius"], "radius")
        if not radius > 0.0:
            raise ValueError(f"radius: expected a number > 0, got {radius!r}")
        return cls((center[0], center[1], center[2]), radius)

    def to_json(self) -> dict[str, Any]:
        return {"center": list(self.center), "radius": self.radius}

    def describe(self) -> str:
        return f"centre {list(self.center)}, radius {self.radius:g}"

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        return np.asarray(self.center, dtype=float), self.radius

    def contains(self, point: Sequence[float]) -> bool:
        return math.dist(self.center, point) <= self.radius

    def collision_object(self) -> fcl.CollisionObject:
        import fcl  # at model time: the scenario reader imports this module

        return fcl.CollisionObject(fcl.Sphere(self.radius), fcl.Transform(np.asarray(self.center, dtype=float)))

    @classmethod
    def batch(cls, obstacles: Sequence[Obstacle]) -> SphereBatch:
        """The centres ``(O, 3)`` and radii ``(O,)`` [m] of ``obstacles`` (spheres only)."""
        spheres = members(obstacles, SphereObstacle)
        centers = np.array([o.center for o in spheres], dtype=float).reshape(-1, 3)
        return centers, np.array([o.radius for o in spheres], dtype=float)

    @classmethod
    def capsule_bounds(
        cls,
        batch: Any,
        axis: np.ndarray,
        mid: np.ndarray,
        half_length: np.ndarray,
        radius: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The distance from each centre to each capsule's axis segment, less both radii: exact
        (to rounding), so both bounds are that distance."""
        centers, radii = batch
        offset = centers[None, None] - mid[:, :, None]  # (K, P, O, 3)
        half = half_length[None, :, None]
        along = np.clip(np.einsum("kpoc,kpc->kpo", offset, axis), -half, half)
        apart = np.linalg.norm(offset - along[..., None] * axis[:, :, None], axis=3)
        gap = apart - radius[None, :, None] - radii[None, None, :]
        return gap, gap

    def signed_distance(self, mid: np.ndarray, axis: np.ndarray, length: float, radius: float) -> Witness:
        return one_capsule(self.signed_distances, mid, axis, length, radius)

    def signed_distances(
        self, mid: np.ndarray, axis: np.ndarray, length: np.ndarray, radius: np.ndarray, deep: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:func:`capsule_sphere` of ``N`` capsules (``mid``, ``axis`` ``(N, 3)``, ``length``,
        ``radius`` ``(N,)``) and this sphere. ``deep`` changes nothing: every distance is exact."""
        return capsule_sphere(mid, axis, length, radius, np.asarray(self.center, dtype=float), self.radius)

    @classmethod
    def normals(cls, batch: Any, on_robot: np.ndarray, on_obstacle: np.ndarray) -> np.ndarray:
        """From the centre to the obstacle's witness point: right whether the robot is outside
        or inside the sphere."""
        return on_obstacle - batch[0]

    def page(self, grow: float = 0.0) -> list[dict[str, Any]]:
        origin = np.eye(4)
        origin[:3, 3] = self.center
        return [{"type": "sphere", "radius": self.radius + grow, "origin": origin.T.ravel().tolist()}]


def capsule_sphere(
    mid: np.ndarray,
    axis: np.ndarray,
    length: np.ndarray,
    radius: np.ndarray,
    center: np.ndarray,
    obstacle_radius: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Signed distances [m] ``(N,)``, witness points on the capsules and on the sphere ``(N, 3)``
    and NaN gradients ``(N, 3)`` (:meth:`SphereObstacle.normals` gives them) of ``N`` capsules
    (axis midpoints ``mid`` and unit ``axis`` ``(N, 3)``, ``length`` and ``radius`` ``(N,)``; a
    sphere where ``length`` is 0) and one sphere: the distance from the sphere's centre to each
    capsule's axis segment, less both radii.

    In closed form because both shapes are swept spheres. FCL's plain distance is the same while
    they are apart (to 4e-16 m), but its signed-distance query (EPA) can abort the whole process
    near contact with a C++ ``std::logic_error`` that Python cannot catch (FCL issues #390, #445,
    #493; reproduced with python-fcl 0.7 on a 0.1 m port sphere 4.5 mm inside a 0.35 m
    obstacle), and it does not return for nearly concentric spheres.
    """
    mid, axis = np.asarray(mid, dtype=float).reshape(-1, 3), np.asarray(axis, dtype=float).reshape(-1, 3)
    length, radius = np.asarray(length, dtype=float), np.asarray(radius, dtype=float)
    half = 0.5 * length
    along = np.clip(np.einsum("nc,nc->n", center - mid, axis), -half, half)
    core = mid + along[:, None] * axis
    offset = center - core
    apart = np.sqrt(np.einsum("nc,nc->n", offset, offset))
    toward = np.empty_like(offset)
    toward[:] = (0.0, 0.0, 1.0)  # any direction on the axis
    np.divide(offset, apart[:, None], out=toward, where=apart[:, None] > 0.0)
    on_robot = core + radius[:, None] * toward
    on_sphere = center - obstacle_radius * toward
    return apart - radius - obstacle_radius, on_robot, on_sphere, np.full_like(offset, np.nan)
