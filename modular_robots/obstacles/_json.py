"""Checked reads of the numbers a shape's JSON form holds (``result.json`` is data a user may edit)."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["json_number", "json_vector"]


def json_number(value: Any, key: str) -> float:
    """``value`` as a finite float; ``ValueError`` naming ``key`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{key}: expected a finite number, got {value!r:.60}")
    return float(value)


def json_vector(value: Any, size: int, key: str) -> tuple[float, ...]:
    """``value`` as ``size`` finite floats; ``ValueError`` naming ``key`` otherwise."""
    if not isinstance(value, list) or len(value) != size:
        raise ValueError(f"{key}: expected a list of {size} numbers, got {value!r:.60}")
    return tuple(json_number(v, f"{key}[{i}]") for i, v in enumerate(value))
