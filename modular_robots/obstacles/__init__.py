"""Obstacle shapes around the robot, behind one protocol (:class:`~.base.Obstacle`).

Adding a shape is a file in this package and a line in :data:`SHAPES`; the scenario reader,
collision model, step C, verification, ``result.json`` and the page take it from there
(``docs/extending.md``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .base import Obstacle, Witness
from .box import BoxObstacle
from .capsule import CapsuleObstacle
from .cylinder import CylinderObstacle
from .floor import FloorObstacle
from .mesh import MeshObstacle
from .plane import PlaneObstacle
from .sphere import SphereObstacle

if TYPE_CHECKING:
    from .._yamlio import Fields

__all__ = [
    "Obstacle",
    "Witness",
    "SphereObstacle",
    "BoxObstacle",
    "CapsuleObstacle",
    "CylinderObstacle",
    "MeshObstacle",
    "PlaneObstacle",
    "FloorObstacle",
    "SHAPES",
    "obstacle_from_fields",
    "obstacle_from_json",
    "obstacle_to_json",
    "obstacle_label",
]

#: Every shape, by its key in a scenario's ``task.obstacles`` and in ``result.json``.
SHAPES: dict[str, type[Obstacle]] = {
    cls.kind: cls
    for cls in (SphereObstacle, BoxObstacle, CapsuleObstacle, CylinderObstacle, MeshObstacle, PlaneObstacle)
}


def obstacle_from_fields(item: Fields) -> Obstacle:
    """The obstacle of one ``task.obstacles`` entry: a mapping of one shape key to its fields."""
    given = [kind for kind in SHAPES if item.has(kind)]
    for kind in SHAPES:  # any other key is then reported as unknown, listing the shapes
        item.raw(kind, None)
    item.done()
    if len(given) != 1:
        expected = ", ".join(SHAPES)
        got = "none" if not given else " and ".join(given)
        raise item.fail(None, f"expected one shape key (one of: {expected}), got {got}")
    return SHAPES[given[0]].from_fields(item.mapping(given[0]))


def obstacle_from_json(data: Any) -> Obstacle:
    """The obstacle of one ``result.json`` entry (``{"sphere": {...}}``; a bare ``{center,
    radius}``, written before shapes had keys, is a sphere). ``ValueError`` on bad data."""
    if isinstance(data, dict) and set(data) == {"center", "radius"}:
        return SphereObstacle.from_json(data)
    kinds: dict[str, type[Obstacle]] = {**SHAPES, FloorObstacle.kind: FloorObstacle}  # floor: task.floor
    if not isinstance(data, dict) or len(data) != 1 or next(iter(data)) not in kinds:
        raise ValueError(f"expected a mapping of one shape key (one of: {', '.join(kinds)}), got {data!r:.60}")
    kind, fields = next(iter(data.items()))
    try:
        return kinds[kind].from_json(fields)
    except ValueError as e:
        raise ValueError(f"{kind}.{e}") from None


def obstacle_label(obstacle: Obstacle, index: int) -> str:
    """How messages name the obstacle at ``index`` of a task's obstacles: ``task.obstacles[i]``, or
    ``task.floor`` (the floor follows the scenario's obstacles)."""
    return "task.floor" if isinstance(obstacle, FloorObstacle) else f"task.obstacles[{index}]"


def obstacle_to_json(obstacle: Obstacle) -> dict[str, Any]:
    """The ``result.json`` form of ``obstacle``: its shape key and fields."""
    return {obstacle.kind: obstacle.to_json()}
