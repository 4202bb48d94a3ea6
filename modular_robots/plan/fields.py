"""Checked reads of JSON values: each read names the file and the value's path in it, so that a
damaged document is refused with what is wrong and where, e.g.
``result.json: candidates[0].iterations: expected an integer >= 0, got '<img>'``.

The keys themselves are :mod:`modular_robots.plan.document`'s; this module knows none.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from ..exceptions import InputError, shorten
from ..obstacles import Obstacle, obstacle_from_json

__all__ = ["Node", "MISSING"]

T = TypeVar("T")


class _Missing:
    def __repr__(self) -> str:
        return "nothing"


#: The value of a key an object does not have.
MISSING: Any = _Missing()


@dataclass(frozen=True)
class Node:
    """A JSON ``value`` at ``path`` (``winner.files``, ``candidates[3]``; empty at the top) of the
    file ``source``."""

    value: Any
    source: str
    path: str = ""

    def fail(self, expected: str) -> InputError:
        """The error for this value not being what was ``expected``."""
        where = f"{self.source}: {self.path}" if self.path else self.source
        got = "nothing (no such key)" if self.value is MISSING else shorten(self.value)
        return InputError(f"{where}: expected {expected}, got {got}")

    def __getitem__(self, key: str) -> Node:
        """The value of ``key`` of this object (:data:`MISSING` if it has none)."""
        value = self.obj()
        return Node(value.get(key, MISSING), self.source, f"{self.path}.{key}" if self.path else key)

    def has(self, key: str) -> bool:
        return isinstance(self.value, dict) and key in self.value

    def obj(self) -> dict[str, Any]:
        if not isinstance(self.value, dict):
            raise self.fail("an object")
        return self.value

    def obstacle(self) -> Obstacle:
        """This value as an obstacle shape (:func:`~modular_robots.obstacles.obstacle_from_json`)."""
        try:
            return obstacle_from_json(self.value)
        except ValueError as exc:
            where = f"{self.source}: {self.path}" if self.path else self.source
            raise InputError(f"{where}: {shorten(exc, 200, quote=False)}") from None

    def items(self) -> list[Node]:
        """The elements of this list, each with its index in its path."""
        if not isinstance(self.value, list):
            raise self.fail("a list")
        return [Node(v, self.source, f"{self.path}[{i}]") for i, v in enumerate(self.value)]

    def optional(self, read: Callable[[Node], T]) -> T | None:
        """None for a null (or missing) value, else ``read(self)``."""
        return None if self.value is None or self.value is MISSING else read(self)

    def string(self, choices: tuple[str, ...] | None = None) -> str:
        if not isinstance(self.value, str):
            raise self.fail("a string")
        if choices is not None and self.value not in choices:
            raise self.fail(f"one of {', '.join(choices)}")
        return self.value

    def boolean(self) -> bool:
        if not isinstance(self.value, bool):
            raise self.fail("true or false")
        return self.value

    def integer(self, minimum: int = 0) -> int:
        if isinstance(self.value, bool) or not isinstance(self.value, int) or self.value < minimum:
            raise self.fail(f"an integer >= {minimum}")
        return self.value

    def number(self, minimum: float = -math.inf, above: bool = False) -> float:
        """A finite number ``>= minimum`` (``> minimum`` if ``above``), as written (an integer
        stays one, so that what is read can be written back unchanged)."""
        value = self.value
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
            or value < minimum
            or (above and value == minimum)
        ):
            bound = "" if minimum == -math.inf else f" {'>' if above else '>='} {minimum:g}"
            raise self.fail(f"a finite number{bound}")
        return value

    def numbers(self, minimum: float = -math.inf, size: int | None = None) -> tuple[float, ...]:
        """A list of finite numbers ``>= minimum`` (of ``size`` of them, if given)."""
        if size is not None and (not isinstance(self.value, list) or len(self.value) != size):
            raise self.fail(f"a list of {size} numbers")
        return tuple(item.number(minimum) for item in self.items())

    def counts(self) -> dict[str, Any]:
        """An object of integers ``>= 0``, or of such objects (one level deep)."""
        out: dict[str, Any] = {}
        for key, value in self.obj().items():
            item = self[key]
            out[key] = {k: item[k].integer() for k in value} if isinstance(value, dict) else item.integer()
        return out
