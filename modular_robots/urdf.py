"""URDF of a composition, filled from the templates in ``urdf_templates/``.

Frames: ``base_link``, one URDF link per module named ``m<i>_<ID>`` (``i`` = position in the
chain, base = 0), ``tool0`` at the effector's output port and a fixed ``payload`` body there.
Movable joints are ``joint_1`` … ``joint_n``. (General catalogues: see
:mod:`~modular_robots.urdf_assembly`.) A module's URDF link frame is its body frame
(input · Rx(twist_in) · M(q)), so the mount of module i+1 on module i is
``Tz(length_i) · Rx(twist_out_i + twist_in_{i+1})``.
"""

from __future__ import annotations

from functools import cache, lru_cache
from importlib import resources
from pathlib import Path
from string import Template

from .catalog import Catalog, Module
from .composition import Composition
from .folder import atomic_write
from .urdf_assembly import assembly_urdf

__all__ = ["composition_urdf", "write_urdf", "PAYLOAD_RADIUS", "link_name"]

PAYLOAD_RADIUS = 0.05
"""Radius of the payload sphere held at ``tool0`` [m] (SPEC §3)."""


@cache
def _template(name: str) -> Template:
    text = resources.files("modular_robots.urdf_templates").joinpath(f"{name}.urdf").read_text("utf-8")
    return Template(text)


def _fill(template: str, /, **values) -> str:
    return _template(template).substitute(values)


def _num(x: float) -> str:
    return repr(float(x))


def _vec(values) -> str:
    return " ".join(_num(v) for v in values)


def link_name(index: int, module: Module) -> str:
    """URDF link name of the module at ``index`` in the chain (0 = base)."""
    return "base_link" if index == 0 else f"m{index}_{module.id}"


@cache  # a module's fragments are the same in every composition
def _inertial(module: Module) -> str:
    if module.mass == 0.0:
        return ""
    ixx, iyy, izz, ixy, ixz, iyz = (_num(v) for v in module.inertia)
    return _fill(
        "inertial", xyz=_vec(module.com), mass=_num(module.mass), ixx=ixx, iyy=iyy, izz=izz, ixy=ixy, ixz=ixz, iyz=iyz
    )


@cache
def _collision(module: Module) -> str:
    if module.collision == "sphere":
        return _fill("sphere", xyz=_vec((0, 0, module.length)), radius=_num(module.radius))
    if module.collision == "capsule":
        return _fill(
            "capsule", xyz=_vec((0, 0, module.length / 2)), radius=_num(module.radius), length=_num(module.length)
        )
    return ""


@cache
def _limit(module: Module) -> str:
    if module.limits is None:
        return ""
    lim = module.limits
    return _fill(
        "limit", lower=_num(lim.lower), upper=_num(lim.upper), velocity=_num(lim.velocity), effort=_num(lim.effort)
    )


def composition_urdf(composition: Composition, catalog: Catalog, payload: float = 0.0, collision: bool = True) -> str:
    """The URDF text of ``composition`` with a payload of ``payload`` kg at ``tool0``.

    Parameters
    ----------
    composition
        A composition of ``catalog`` (see :meth:`Composition.from_name`).
    catalog
        The module catalogue that supplies geometry, inertials, limits and collision shapes.
    payload
        Payload mass [kg], a solid sphere of radius :data:`PAYLOAD_RADIUS` centred at ``tool0``.
    collision
        Include the collision shapes. A Pinocchio model does not read them, and it is built a
        fifth faster from a text without them.
    """
    if catalog.general:
        body = assembly_urdf(composition, catalog, _payload(payload, collision), collision)
        return _fill("robot", name=composition.name, catalog=catalog.name, body=body)
    parts: list[str] = []
    parent: Module | None = None
    joint_index = 0
    for index, module in enumerate(catalog.module(m) for m in composition.modules):
        if module.kind not in ("base", "link") and module.dof:
            joint_index += 1
        parts.append(_module_part(index, module, parent, joint_index, collision))
        parent = module
    parts.append(_payload(payload, collision))
    return _fill("robot", name=composition.name, catalog=catalog.name, body="".join(parts))


@lru_cache(maxsize=4096)  # step B builds thousands of chains from a few modules in a few places
def _module_part(index: int, module: Module, parent: Module | None, joint_index: int, collision: bool) -> str:
    """The URDF of the module at ``index`` in a chain, mounted on ``parent`` (None: the base);
    ``joint_index`` numbers the movable joints so far, this one included."""
    common = dict(
        index=index,
        module=module.id,
        link=link_name(index, module),
        inertial=_inertial(module),
        collision=_collision(module) if collision else "",
    )
    if parent is not None:
        common.update(
            parent=link_name(index - 1, parent),
            xyz=_vec((0, 0, parent.length)),
            rpy=_vec((parent.twist_out + module.twist_in, 0, 0)),
        )
    if module.kind == "base":
        return _fill("base", **common)
    if module.kind == "link":
        return _fill("link", **common)
    joint = f"joint_{joint_index}" if module.dof else f"{common['link']}_mount"
    kind = "effector" if module.kind == "effector" else "joint"
    return _fill(
        kind,
        joint=joint,
        joint_type=module.joint,
        limit=_limit(module),
        tool_xyz=_vec((0, 0, module.length)),
        tool_rpy=_vec((module.twist_out, 0, 0)),
        **common,
    )


@lru_cache(maxsize=64)
def _payload(mass: float, collision: bool) -> str:
    inertial = ""
    if mass > 0.0:
        moment = 0.4 * mass * PAYLOAD_RADIUS**2
        inertial = _fill(
            "inertial",
            xyz="0 0 0",
            mass=_num(mass),
            ixx=_num(moment),
            iyy=_num(moment),
            izz=_num(moment),
            ixy="0",
            ixz="0",
            iyz="0",
        )
    shape = _fill("sphere", xyz="0 0 0", radius=_num(PAYLOAD_RADIUS)) if collision else ""
    return _fill("payload", mass=_num(mass), radius=_num(PAYLOAD_RADIUS), inertial=inertial, collision=shape)


def write_urdf(path: str | Path, composition: Composition, catalog: Catalog, payload: float = 0.0) -> Path:
    """Write :func:`composition_urdf` to ``path`` and return the path: whole or not at all (a full
    disk leaves no truncated file; :func:`~modular_robots.folder.atomic_write`)."""
    path = Path(path)
    atomic_write(path, composition_urdf(composition, catalog, payload))
    return path
