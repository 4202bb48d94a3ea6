"""The floor: the plane the robot is mounted on, which nothing a joint moves may cross."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from ._json import json_number
from .plane import PlaneObstacle

if TYPE_CHECKING:
    from .._yamlio import Fields

__all__ = ["FloorObstacle"]


@dataclass(frozen=True, init=False)
class FloorObstacle(PlaneObstacle):
    """Everything below ``z = height`` [m] in the base frame. Only the primitives a joint moves
    are kept above it: the base, and what is rigidly mounted on it, stand on the floor (their
    shapes may reach below the mounting plane: IMPROV's first housings by up to 2.8 cm)."""

    kind: ClassVar[str] = "floor"
    moving_only: ClassVar[bool] = True

    def __init__(self, height: float = 0.0):
        super().__init__((0.0, 0.0, float(height)), (0.0, 0.0, 1.0))

    @property
    def height(self) -> float:
        return self.point[2]

    @classmethod
    def from_fields(cls, f: Fields) -> FloorObstacle:
        height = f.number("height")
        f.done()
        return cls(height)

    @classmethod
    def from_json(cls, data: Any) -> FloorObstacle:
        if not isinstance(data, dict) or set(data) != {"height"}:
            raise ValueError("expected a mapping of height")
        return cls(json_number(data["height"], "height"))

    def to_json(self) -> dict[str, Any]:
        return {"height": self.height}

    def describe(self) -> str:
        return f"the floor at z = {self.height:g} m"

    def page(self, grow: float = 0.0) -> list[dict[str, Any]]:
        """Nothing at the base's mounting plane (the page's grid is drawn there), else a slab."""
        return [] if self.height == 0.0 else super().page(grow)

    def __repr__(self) -> str:
        return f"FloorObstacle(height={self.height!r})"
