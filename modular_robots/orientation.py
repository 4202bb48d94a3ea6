"""The tool's orientation at an end of the task: a full rotation or the direction of its z axis,
within an angle tolerance.

A task's ``start`` or ``goal`` may ask for the ``tool0`` frame's orientation in the base frame:
``rpy`` (fixed-axis X-Y-Z roll, pitch, yaw [rad]; the tolerance bounds the angle of the rotation
from the asked orientation to the tool's) or ``axis`` (the direction of ``tool0``'s z axis, the
rotation about it free, e.g. a gripper pointing down; the tolerance bounds the angle between the
two directions). Step B's inverse kinematics (:mod:`modular_robots.ik`) solves for it, and
verification measures it at the ends of the plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .obstacles._geometry import rpy_matrix

__all__ = ["Orientation", "DEFAULT_ANGLE_TOLERANCE"]

#: The angle tolerance [rad] of an end that gives an orientation but no tolerance (about 0.6 deg).
DEFAULT_ANGLE_TOLERANCE = 0.01


@dataclass(frozen=True)
class Orientation:
    """The orientation ``tool0`` must have at one end, within ``tolerance`` [rad]: ``rpy`` [rad],
    or ``axis`` (a unit vector, the tool's z axis, in the base frame); exactly one is given."""

    rpy: tuple[float, float, float] | None = None
    axis: tuple[float, float, float] | None = None
    tolerance: float = DEFAULT_ANGLE_TOLERANCE

    def __post_init__(self) -> None:
        if (self.rpy is None) == (self.axis is None):
            raise ValueError("an orientation gives exactly one of rpy and axis")
        if not (math.isfinite(self.tolerance) and 0.0 < self.tolerance <= math.pi):
            raise ValueError(f"angle tolerance: expected a number in (0, pi] rad, got {self.tolerance!r}")
        if self.rpy is not None:
            object.__setattr__(self, "rpy", tuple(float(c) for c in self.rpy))
            if not all(math.isfinite(c) for c in self.rpy):
                raise ValueError(f"rpy: expected finite angles, got {list(self.rpy)}")
        if self.axis is not None:
            axis = np.asarray(self.axis, dtype=float)
            norm = float(np.linalg.norm(axis))
            if not (np.all(np.isfinite(axis)) and norm > 1e-9):
                raise ValueError(f"axis: expected a finite vector of non-zero length, got {list(self.axis)}")
            object.__setattr__(self, "axis", tuple(float(c) for c in axis / norm))

    @property
    def rotation(self) -> np.ndarray | None:
        """The asked rotation ``(3, 3)`` of ``tool0`` in the base frame (None for an ``axis``)."""
        return None if self.rpy is None else rpy_matrix(self.rpy)

    def angle(self, rotation: np.ndarray) -> float:
        """The angle [rad] between the tool's ``rotation`` ``(3, 3)`` and the asked one: of the
        relative rotation for ``rpy``, between the z axes for ``axis``."""
        return float(np.linalg.norm(self.error(rotation)))

    def error(self, rotation: np.ndarray) -> np.ndarray:
        """The rotation vector ``(3,)`` [rad], in the base frame, that turns the tool's
        ``rotation`` onto the asked orientation (for an ``axis``: the shortest such turn, normal
        to the tool's z axis). Its norm is :meth:`angle`."""
        if self.rpy is not None:
            return np.asarray(pin.log3(rpy_matrix(self.rpy) @ rotation.T))
        z, target = rotation[:, 2], np.asarray(self.axis)
        normal = np.cross(z, target)
        sine = float(np.linalg.norm(normal))
        angle = math.atan2(sine, float(z @ target))
        if sine < 1e-12:  # aligned, or opposite: any normal turn will do
            if angle < 1e-12:
                return np.zeros(3)
            normal = np.cross(z, np.eye(3)[int(np.argmin(np.abs(z)))])
            sine = float(np.linalg.norm(normal))
        return normal * (angle / sine)

    def free_about_z(self) -> bool:
        """Whether the rotation about the tool's z axis is free (an ``axis`` orientation)."""
        return self.axis is not None

    def to_json(self) -> dict:
        """The scenario's form: ``rpy`` or ``axis``, and ``angle_tolerance``."""
        key, value = ("rpy", self.rpy) if self.rpy is not None else ("axis", self.axis)
        return {key: list(value or ()), "angle_tolerance": self.tolerance}

    def describe(self) -> str:
        key, value = ("rpy", self.rpy) if self.rpy is not None else ("axis", self.axis)
        return f"{key} {[round(c, 4) for c in value or ()]} within {self.tolerance:g} rad"
