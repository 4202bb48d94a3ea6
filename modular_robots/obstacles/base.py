"""The obstacle protocol: what every shape around the robot provides to the pipeline.

A shape is one file in this package (a frozen dataclass implementing :class:`Obstacle`) and one
line in :data:`~modular_robots.obstacles.SHAPES`. Everything else (the scenario reader, step B's
collision test, step C's clearance rows, verification, ``result.json`` and the page) goes through
this protocol.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, TypeVar, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    import fcl

    from .._yamlio import Fields

__all__ = ["Obstacle", "Witness", "members"]

#: Signed distance [m], the witness points on the robot and on the obstacle (base frame), and the
#: distance's gradient with respect to a translation of the robot's witness point (a unit vector,
#: or shorter where the distance has a kink), or None: the shape's :meth:`Obstacle.normals` gives
#: its direction from the witness points.
Witness = tuple[float, np.ndarray, np.ndarray, np.ndarray | None]


@runtime_checkable
class Obstacle(Protocol):
    """A rigid shape fixed in the base frame that the robot must keep clear of (SI units).

    Distances are signed: negative when the robot's primitive (a capsule: a segment swept by a
    sphere; a sphere is a capsule of length 0) overlaps the shape. An obstacle is a value:
    hashable, equal to another of the same fields, with a repr that depends only on them (the
    collision model shares FCL objects by obstacle; step B's verdicts are keyed by the task's
    repr), so its fields are tuples and numbers, never arrays.
    """

    #: The shape's key in a scenario's ``task.obstacles`` and in ``result.json`` (``sphere``).
    kind: ClassVar[str]
    #: True: :meth:`signed_distance` gives every distance and FCL is never asked (FCL has no
    #: distance for some shapes: a half-space crashes the process). False: FCL
    #: measures apart pairs and :meth:`signed_distance` only overlapping ones.
    closed_form: ClassVar[bool]
    #: True: only the robot's primitives that a joint moves are kept clear of it (the floor, on
    #: which the base and what is rigidly mounted on it stand).
    moving_only: ClassVar[bool]

    @classmethod
    def from_fields(cls, f: Fields) -> Obstacle:
        """Read the shape's mapping (``task.obstacles[i].<kind>``), naming the key on bad input."""
        ...

    @classmethod
    def from_json(cls, data: Any) -> Obstacle:
        """The inverse of :meth:`to_json`'s inner mapping; ``ValueError`` naming what is wrong."""
        ...

    def to_json(self) -> dict[str, Any]:
        """The shape's fields as the scenario writes them (the inner mapping)."""
        ...

    def describe(self) -> str:
        """A short human-readable form for messages, e.g. ``centre [0.5, 0, 0.4], radius 0.1``."""
        ...

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """Centre [m] and radius [m] of a sphere holding the whole shape: culls far obstacles."""
        ...

    def contains(self, point: Sequence[float]) -> bool:
        """True if ``point`` [m] is inside the shape or on its surface."""
        ...

    def collision_object(self) -> fcl.CollisionObject:
        """FCL's object for the shape, placed in the base frame."""
        ...

    @classmethod
    def batch(cls, obstacles: Sequence[Obstacle]) -> Any:
        """What the batch methods below need of ``obstacles`` (all of this class), computed once
        per collision model (arrays of centres and sizes): they run at every clearance query."""
        ...

    @classmethod
    def capsule_bounds(
        cls,
        batch: Any,
        axis: np.ndarray,
        mid: np.ndarray,
        half_length: np.ndarray,
        radius: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds ``(K, P, O)`` [m] on the signed distance between capsules and
        the obstacles of ``batch`` (:meth:`batch`): capsule axes ``axis`` and midpoints ``mid``
        ``(K, P, 3)``, half lengths and radii ``(P,)``. Equal where a closed form is exact;
        the collision model asks FCL only for the pairs the bounds do not decide (an upper bound
        may be ``inf``)."""
        ...

    def signed_distance(self, mid: np.ndarray, axis: np.ndarray, length: float, radius: float) -> Witness | None:
        """Signed distance and witness points of a capsule (axis midpoint ``mid``, unit ``axis``,
        ``length``, ``radius``) in closed form, or None to keep FCL's answer (overlapping: FCL's
        contact, :func:`~modular_robots.collision._penetration`). Asked for every
        pair of a :attr:`closed_form` shape, else only where FCL reports an overlap (FCL's signed
        distance can abort near contact: see :func:`~modular_robots.obstacles.sphere.capsule_sphere`)."""
        ...

    # A closed-form shape may also give (every built-in one but the capsule does)
    # ``signed_distances(mid (N, 3), axis (N, 3), length (N,), radius (N,), deep=True)``:
    # :meth:`signed_distance` of N capsules at once, as arrays (distances (N,), witness points and
    # gradients (N, 3)); with ``deep=False`` the distance of a capsule whose axis meets the shape
    # may be any value in [its distance, -radius] (the collision model then asks only whether a
    # pair is too near). The collision model measures all its pairs of a query in one call.

    @classmethod
    def normals(cls, batch: Any, on_robot: np.ndarray, on_obstacle: np.ndarray) -> np.ndarray:
        """Directions ``(K, O, 3)`` (not normalised) in which the signed distance grows when the
        robot's witness point ``on_robot`` moves; witness points ``(K, O, 3)`` of the obstacles
        of ``batch``. Used where a distance came without its gradient (FCL's, or a
        :meth:`signed_distance` that gave None). Right inside the shape too: where
        :meth:`signed_distance` returns None, the witness points are FCL's contact's, on which
        ``on_robot - on_obstacle`` points where the distance grows."""
        ...

    def page(self, grow: float = 0.0) -> list[dict[str, Any]]:
        """How the page draws the shape grown by ``grow`` [m]: parts in the page's shape
        vocabulary (``type`` sphere, capsule, box, cylinder or mesh, their sizes, and ``origin``,
        a column-major 4x4 pose in the base frame)."""
        ...


S = TypeVar("S")


def members(obstacles: Sequence[Obstacle], shape: type[S]) -> list[S]:
    """``obstacles`` as the shape class's own (its batch methods take no other): ``TypeError``
    when one is not of ``shape``."""
    if not all(isinstance(o, shape) for o in obstacles):
        raise TypeError(f"a batch of {shape.__name__} holds only {shape.__name__}s")
    return [o for o in obstacles if isinstance(o, shape)]
