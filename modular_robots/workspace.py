"""A box around every tool position a robot reaches within its joint limits: step B's
``workspace`` test, which rejects most unreachable targets without an IK run.

Walking from the tool back to the base, the set of tool positions in each joint's frame is kept
inside an axis-aligned box:

* a prismatic joint stretches the box along its axis by its stroke;
* a revolute joint sweeps the box around its axis; the swept set lies in the cylinder around the
  axis through the box's corner farthest from it, whatever the joint's range;
* a fixed placement (Pinocchio's joint placements, fixed URDF joints folded in) rotates and
  moves the box: the new box encloses the rotated one.

Every step encloses the set before it, so a target outside the final box cannot be reached: its
distance to the box (:meth:`WorkspaceBox.excess`) is a lower bound on the error of any IK
solution. The box can be loose, and a target inside it may still be out of reach; IK decides
those. On the paper's 5 kg task it removes 2,164 of the 2,394 compositions that IK rejected
before the box was there.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

from .catalog import Catalog, Module
from .composition import Composition
from .robot import RobotModel

__all__ = ["WorkspaceBox", "workspace_box", "catalog_workspace_box"]

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class WorkspaceBox:
    """An axis-aligned box ``[lower, upper]`` [m] in the base frame (``base_link``) that holds
    every position of the tool frame within the joint limits; unbounded (``-inf``/``inf``) for
    a robot with a joint this module cannot bound (spherical, planar, free-flyer, helical, a
    prismatic joint without finite limits)."""

    lower: tuple[float, float, float]
    upper: tuple[float, float, float]

    def excess(self, point) -> float:
        """Distance [m] from ``point`` to the box, 0 inside: no configuration within the limits
        brings the tool closer to ``point``."""
        outside = [max(low - p, p - high, 0.0) for p, low, high in zip(map(float, point), self.lower, self.upper)]
        return math.sqrt(sum(d * d for d in outside))


_UNBOUNDED = WorkspaceBox((-math.inf,) * 3, (math.inf,) * 3)


def workspace_box(robot: RobotModel) -> WorkspaceBox:
    """The :class:`WorkspaceBox` of ``robot``'s tool frame, from its Pinocchio model (any
    catalogue, or a URDF of elsewhere)."""
    model = robot.model
    frame = model.frames[robot.tool_frame_id]
    lower = frame.placement.translation.tolist()
    upper = list(lower)
    joint = frame.parentJoint
    while joint > 0:
        motion = _motion(model, joint)
        if motion is None:
            return _UNBOUNDED
        lower, upper = _moved(lower, upper, *motion)
        placement = model.jointPlacements[joint]
        lower, upper = _placed(lower, upper, placement.rotation.tolist(), placement.translation.tolist())
        joint = model.parents[joint]
    return WorkspaceBox(tuple(lower), tuple(upper))


def catalog_workspace_box(composition: Composition, catalog: Catalog) -> WorkspaceBox:
    """:func:`workspace_box` of a composition of a catalogue of modules
    ``Rx(twist_in) M(q) Tz(length) Rx(twist_out)`` (``catalog.general`` False), from the
    catalogue's numbers alone, before any model is built: step B runs it on every composition
    that passes the reach test.

    The rigid transforms between two joints are composed before the box is turned by them, as
    Pinocchio folds them into one joint placement, so the box is the model's
    (``tests/test_workspace.py`` checks it to 1e-12). Compositions share their last modules,
    and what each chain of last modules gives is kept."""
    base, *rest = composition.modules
    tail_lower, tail_upper, rotation, offset = _through(
        catalog.module(base), _tail(catalog, tuple(rest)), mounted=False
    )
    lower, upper = _placed(tail_lower, tail_upper, rotation, offset)
    return WorkspaceBox(_point(lower), _point(upper))


def _point(coordinates: list[float]) -> tuple[float, float, float]:
    """A box corner ``[x, y, z]`` as the tuple :class:`WorkspaceBox` holds."""
    x, y, z = coordinates
    return x, y, z


_Tail = tuple[tuple[float, ...], tuple[float, ...], tuple[tuple[float, ...], ...], tuple[float, ...]]


@lru_cache(maxsize=16384)
def _tail(catalog: Catalog, modules: tuple[str, ...]) -> _Tail:
    """The tool positions at the end of ``modules`` as ``(lower, upper, R, t)``: ``R b + t``
    for ``b`` in the box ``[lower, upper]``, in the frame where the first module is mounted.
    ``R, t`` is the rigid transform from the first joint's frame on (the identity if a module
    begins with a joint)."""
    if not modules:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), _IDENTITY, (0.0, 0.0, 0.0)
    return _through(catalog.module(modules[0]), _tail(catalog, modules[1:]), mounted=True)


def _through(module: Module, tail: _Tail, mounted: bool) -> _Tail:
    """``tail``, given at ``module``'s outlet, carried to where the module is mounted
    (``mounted``) or, for the base, which the URDF places at the origin without its
    ``twist_in``, to its own frame."""
    lower: Sequence[float]
    upper: Sequence[float]
    lower, upper, rotation, offset = tail
    rotation, offset = _composed(_rx(module.twist_out), (0.0, 0.0, module.length), rotation, offset)
    if module.joint != "fixed":
        lower, upper = _placed(lower, upper, rotation, offset)
        if module.joint == "revolute":
            lower, upper = _moved(lower, upper, "revolute", _AXES["Z"], None)
        else:
            limits = module.limits
            assert limits is not None  # a movable module has limits
            lower, upper = _moved(lower, upper, "prismatic", _AXES["Z"], (limits.lower, limits.upper))
        rotation, offset = _IDENTITY, (0.0, 0.0, 0.0)
    if mounted:
        rotation, offset = _composed(_rx(module.twist_in), (0.0, 0.0, 0.0), rotation, offset)
    return tuple(lower), tuple(upper), rotation, offset


_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _composed(rotation, offset, then_rotation, then_offset) -> tuple[tuple[tuple[float, ...], ...], tuple[float, ...]]:
    """The rigid transform ``(R1, t1) (R2, t2)`` = ``(R1 R2, R1 t2 + t1)`` (rotations as rows),
    written out: it runs for every module of every composition step B sees."""
    (a, b, c), (d, e, f), (g, h, i) = rotation
    (p, q, r), (s, t, u), (v, w, x) = then_rotation
    y0, y1, y2 = then_offset
    return (
        (
            (a * p + b * s + c * v, a * q + b * t + c * w, a * r + b * u + c * x),
            (d * p + e * s + f * v, d * q + e * t + f * w, d * r + e * u + f * x),
            (g * p + h * s + i * v, g * q + h * t + i * w, g * r + h * u + i * x),
        ),
        (
            a * y0 + b * y1 + c * y2 + offset[0],
            d * y0 + e * y1 + f * y2 + offset[1],
            g * y0 + h * y1 + i * y2 + offset[2],
        ),
    )


@lru_cache(maxsize=256)
def _rx(angle: float) -> tuple[tuple[float, float, float], ...]:
    c, s = math.cos(angle), math.sin(angle)
    return ((1.0, 0.0, 0.0), (0.0, c, -s), (0.0, s, c))


def _motion(model, joint: int) -> tuple[str, tuple[float, float, float], tuple[float, float] | None] | None:
    """``(kind, unit axis in the joint's frame, (lower, upper) stroke [m] or None for a
    revolute joint)`` of a one-axis joint; None for any other joint and for a stroke without
    finite limits."""
    name = model.joints[joint].shortname().removeprefix("JointModel")
    if name in ("RevoluteUnaligned", "RevoluteUnboundedUnaligned", "PrismaticUnaligned"):
        x, y, z = model.joints[joint].extract().axis.tolist()
        norm = math.sqrt(x * x + y * y + z * z)
        axis = (x / norm, y / norm, z / norm)
    elif name[-1:] in _AXES and name[:-1] in ("R", "RUB", "P"):
        axis = _AXES[name[-1]]
    else:
        return None
    if name.startswith("P"):
        index = model.idx_qs[joint]
        stroke = (float(model.lowerPositionLimit[index]), float(model.upperPositionLimit[index]))
        return ("prismatic", axis, stroke) if all(map(math.isfinite, stroke)) else None
    return "revolute", axis, None


def _moved(lower, upper, kind: str, axis, stroke) -> tuple[list[float], list[float]]:
    """A box around the box ``[lower, upper]`` moved by a joint about or along ``axis`` (a unit
    vector through the origin).

    Prismatic: the box stretched along the axis by the ``stroke``. Revolute, by any angle:
    along the axis the positions keep their span; across it they stay within the largest
    distance of a corner from the axis (the distance is convex, so a corner is farthest)."""
    if kind == "prismatic":
        ends = [(stroke[0] * a, stroke[1] * a) for a in axis]
        return [low + min(e) for low, e in zip(lower, ends)], [high + max(e) for high, e in zip(upper, ends)]
    if axis in _AXES.values():  # about x, y or z: that span stays, the others become +-radius
        k = axis.index(1.0)
        radius = math.sqrt(sum(max(-low, high) ** 2 for i, (low, high) in enumerate(zip(lower, upper)) if i != k))
        return (
            [low if i == k else -radius for i, low in enumerate(lower)],
            [high if i == k else radius for i, high in enumerate(upper)],
        )
    along, radius = [], 0.0
    for corner in itertools.product(*zip(lower, upper)):
        s = sum(c * a for c, a in zip(corner, axis))
        along.append(s)
        radius = max(radius, math.sqrt(sum((c - s * a) ** 2 for c, a in zip(corner, axis))))
    low, high = min(along), max(along)
    spread = [radius * math.sqrt(max(1.0 - a * a, 0.0)) for a in axis]
    return (
        [min(low * a, high * a) - w for a, w in zip(axis, spread)],
        [max(low * a, high * a) + w for a, w in zip(axis, spread)],
    )


def _placed(lower, upper, rotation, offset) -> tuple[list[float], list[float]]:
    """The box around the box ``[lower, upper]`` rotated by ``rotation`` (rows) and moved by
    ``offset``."""
    cx, cy, cz = ((low + high) / 2.0 for low, high in zip(lower, upper))
    hx, hy, hz = ((high - low) / 2.0 for low, high in zip(lower, upper))
    new_lower, new_upper = [], []
    for (r0, r1, r2), shift in zip(rotation, offset):
        middle = shift + r0 * cx + r1 * cy + r2 * cz
        spread = abs(r0) * hx + abs(r1) * hy + abs(r2) * hz
        new_lower.append(middle - spread)
        new_upper.append(middle + spread)
    return new_lower, new_upper
