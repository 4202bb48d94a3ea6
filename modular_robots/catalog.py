"""Module catalogue: the modules a robot can be built from and the grammar that joins them.

Geometry follows SPEC §3, convention A. Every module maps its input frame to its output frame as

    Rx(twist_in) · M(q) · Tz(length) · Rx(twist_out)

where ``M(q)`` is ``Rz(q)`` for a revolute module, ``Tz(q)`` for a prismatic one and the
identity for a fixed one; each factor acts on the current frame. Units: metres, kilograms,
radians (the YAML states twists in degrees, as ``twist_in_deg``/``twist_out_deg``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Literal, cast

from ._yamlio import Fields, load_yaml
from .exceptions import CatalogError, shorten
from .modules import (
    MAX_ARMATURE,
    MAX_MASS,
    MAX_SIZE,
    AssemblyGrammar,
    GeneralModule,
    _joint_limits,
    _physical_inertia,
    check_grammar_ids,
    read_assembly_grammar,
    read_general_module,
    read_price,
)

__all__ = ["JointLimits", "Module", "Grammar", "Catalog", "load_catalog"]

Kind = Literal["base", "joint", "link", "effector"]
JointType = Literal["fixed", "revolute", "prismatic"]
KINDS: tuple[Kind, ...] = ("base", "joint", "link", "effector")
COLLISION_SHAPES: tuple[str, ...] = ("sphere", "capsule", "none")


@dataclass(frozen=True)
class JointLimits:
    """Limits of a movable module: position interval, |velocity| and |effort| bounds.

    Revolute: rad, rad/s, N m. Prismatic: m, m/s, N.
    """

    lower: float
    upper: float
    velocity: float
    effort: float


@dataclass(frozen=True)
class Module:
    """One catalogue module. ``inertia`` is (ixx, iyy, izz, ixy, ixz, iyz) about ``com``,
    both in the module's body frame (the frame after ``Rx(twist_in) · M(q)``)."""

    id: str
    kind: Kind
    joint: JointType
    length: float
    diameter: float
    mass: float
    com: tuple[float, float, float]
    inertia: tuple[float, float, float, float, float, float]
    twist_in: float = 0.0
    twist_out: float = 0.0
    limits: JointLimits | None = None
    armature: float = 0.0
    collision: str = "sphere"
    #: The module's price in the catalogue's currency (None: not given), for the ``price`` cost.
    price: float | None = None

    @property
    def dof(self) -> int:
        return 0 if self.joint == "fixed" else 1

    @property
    def radius(self) -> float:
        return self.diameter / 2.0


@dataclass(frozen=True)
class Grammar:
    """Allowed compositions: ``B L{links_after_base} (J L{links_after_joint})* E``, with the
    total DOF (joints plus the effector's) in ``dof``. Ranges are inclusive ``(min, max)``."""

    dof: tuple[int, int]
    links_after_joint: tuple[int, int] = (1, 1)
    links_after_base: tuple[int, int] = (0, 0)


@dataclass(frozen=True)
class Catalog:
    """A named set of modules and their grammar. Hashable, so models can be cached on it.

    Either a convention-A catalogue (:class:`Module`, :class:`Grammar`) or a general one
    (:class:`~modular_robots.modules.GeneralModule`,
    :class:`~modular_robots.modules.AssemblyGrammar`; ``general`` is True)."""

    name: str
    modules: tuple[Module, ...] | tuple[GeneralModule, ...]
    grammar: Grammar | AssemblyGrammar
    source: str = field(default="", compare=False)
    notes: tuple[str, ...] = field(default=(), compare=False)

    @property
    def general(self) -> bool:
        """True for a catalogue in the general module model (``format: general``)."""
        return isinstance(self.grammar, AssemblyGrammar)

    @cached_property
    def _by_id(self) -> dict[str, Module | GeneralModule]:
        return {m.id: m for m in self.modules}

    @cached_property
    def _hash(self) -> int:
        return hash((self.name, self.modules, self.grammar))

    def __hash__(self) -> int:
        """The fields' hash, computed once: the models and bounds of step B are cached on
        ``(catalog, ...)`` keys, thousands of times a second, and a catalogue hashes all its
        modules (9 us for the paper's)."""
        return self._hash

    def __getstate__(self) -> dict:
        """Pickled without the cached hash: strings hash differently in another process."""
        return {name: value for name, value in self.__dict__.items() if name != "_hash"}

    def module(self, module_id: str) -> Module:
        """The module ``module_id`` of a convention-A catalogue (``general`` False)."""
        return cast(Module, self._lookup(module_id))  # such a catalogue holds Modules only

    def general_module(self, module_id: str) -> GeneralModule:
        """The module ``module_id`` of a general catalogue (``general`` True)."""
        return cast(GeneralModule, self._lookup(module_id))  # such a catalogue holds GeneralModules only

    def _lookup(self, module_id: str) -> Module | GeneralModule:
        try:
            return self._by_id[module_id]
        except KeyError:
            raise CatalogError(
                f"unknown module {shorten(module_id)} in catalogue {shorten(self.name)} "
                f"(known: {', '.join(list(self._by_id)[:30])}{', ...' if len(self._by_id) > 30 else ''})"
            ) from None

    def of_kind(self, kind: Kind) -> tuple[Module, ...]:
        """The modules of ``kind`` of a convention-A catalogue."""
        return tuple(cast(Module, m) for m in self.modules if m.kind == kind)


def solid_cylinder_inertia(mass: float, diameter: float, length: float) -> tuple[float, ...]:
    """Inertia of a solid cylinder along z about its centre: (ixx, iyy, izz, 0, 0, 0)."""
    r2 = (diameter / 2.0) ** 2
    transverse = mass * (3.0 * r2 + length**2) / 12.0
    return (transverse, transverse, mass * r2 / 2.0, 0.0, 0.0, 0.0)


def load_catalog(path: str | Path) -> Catalog:
    """Read and validate a catalogue YAML file.

    Raises
    ------
    CatalogError
        Naming the file, line and key, and what was expected.
    """
    return catalog_from_fields(load_yaml(Path(path), CatalogError))


def catalog_from_fields(top: Fields) -> Catalog:
    """:func:`load_catalog` on an already parsed file."""
    top = top.reporting(CatalogError)
    if top.raw("format", "convention_a") == "general":
        return _general_catalog(top)
    top.check("format", top.raw("format", "convention_a") == "convention_a", "expected convention_a or general")
    name = top.string("name")
    top.string("description", default="")
    modules: list[Module] = []
    seen: dict[str, int] = {}
    for fields in top.mappings("modules"):
        module = _read_module(fields)
        if module.id in seen:
            raise fields.fail("id", f"duplicate module id {module.id!r} (first at modules[{seen[module.id]}])")
        seen[module.id] = len(modules)
        modules.append(module)
    grammar = _read_grammar(top.mapping("grammar"))
    top.done()
    for kind in KINDS:
        if kind != "link" and not any(m.kind == kind for m in modules):
            raise top.fail("modules", f"expected at least one module of kind {kind!r}")
    wants_links = grammar.links_after_joint[1] > 0 or grammar.links_after_base[1] > 0
    if wants_links and not any(m.kind == "link" for m in modules):
        raise top.fail("grammar", "the grammar asks for links but no module is of kind 'link'")
    return Catalog(name=name, modules=tuple(modules), grammar=grammar, source=str(top.path))


def _general_catalog(top: Fields) -> Catalog:
    name = top.string("name")
    top.string("description", default="")
    notes = top.raw("notes", [])
    top.check("notes", isinstance(notes, list) and all(isinstance(n, str) for n in notes), "expected a list of strings")
    modules: dict[str, GeneralModule] = {}
    where: dict[str, Fields] = {}
    for fields in top.mappings("modules"):
        module = read_general_module(fields)
        fields.check("id", module.id not in modules, f"duplicate module id {module.id!r}")
        modules[module.id], where[module.id] = module, fields
    _warn_unconnectable(modules, where)
    grammar = read_assembly_grammar(top.mapping("grammar"))
    check_grammar_ids(top, grammar, modules)
    top.done()
    for kind in ("base", "effector"):
        if not any(m.kind == kind for m in modules.values()):
            raise top.fail("modules", f"expected at least one module of kind {kind!r}")
    return Catalog(name, tuple(modules.values()), grammar, str(top.path), tuple(notes))


def _warn_unconnectable(modules: dict[str, GeneralModule], where: dict[str, Fields]) -> None:
    """Warn of a module whose input meets no other module's output, or whose output meets no
    input (Timor's rule: type, size and gender): no composition can hold it."""
    for module in modules.values():
        ends = (
            ("inlet", "input", module.inlet, "outlet", "output", module.kind != "base"),
            ("outlet", "output", module.outlet, "inlet", "input", module.kind != "effector"),
        )
        for key, name, connector, other, other_name, needed in ends:
            if needed and not any(getattr(m, other).meets(connector) for m in modules.values() if m is not module):
                where[module.id].warn(
                    key,
                    f"module {module.id}'s {name} ({connector.type} {list(connector.size)}, {connector.gender}) "
                    f"meets no module's {other_name}: no composition holds it (a connector's type or size mistyped?)",
                )


_TURN = "a twist is an angle in degrees; beyond a turn, it is a typo"
#: The longest module id: an id is part of every composition name and URDF link name.
MAX_ID_LENGTH = 100

#: The largest DOF a grammar may ask for: longer chains are not robots anyone builds from modules,
#: and the count of compositions grows as (modules per slot) ** DOF.
MAX_DOF = 20
#: The longest run of links a grammar may ask for between two joints (or after the base).
MAX_LINK_RUN = 10


def _read_grammar(fields: Fields) -> Grammar:
    dof = _int_range(fields, "dof", maximum=MAX_DOF)
    after_joint = _int_range(fields, "links_after_joint", (1, 1), maximum=MAX_LINK_RUN)
    after_base = _int_range(fields, "links_after_base", (0, 0), maximum=MAX_LINK_RUN)
    fields.done()
    return Grammar(dof=dof, links_after_joint=after_joint, links_after_base=after_base)


def _int_range(fields: Fields, key: str, default=None, *, maximum: int) -> tuple[int, int]:
    if default is not None and not fields.has(key):
        fields.raw(key, None)
        return default
    low, high = fields.interval(key)
    fields.check(
        key,
        low >= 0 and low == int(low) and high == int(high),
        f"expected [min, max] of whole numbers >= 0, got [{low:g}, {high:g}]",
    )
    fields.check(key, high <= maximum, f"expected a maximum of at most {maximum}, got {high:g}")
    return int(low), int(high)


def _read_module(f: Fields) -> Module:
    module_id = f.string("id")
    f.check(
        "id",
        module_id.replace("_", "").isalnum() and len(module_id) <= MAX_ID_LENGTH,
        f"expected at most {MAX_ID_LENGTH} letters, digits or '_' (an id is part of composition and URDF link "
        f"names), got {shorten(module_id)}",
    )
    if not f.has("kind") and (f.has("bodies") or f.has("joints")):
        raise f.fail(
            "kind",
            "missing required key; this module has bodies and joints, as in the general module model: "
            "give the catalogue 'format: general' at its top level",
        )
    kind = f.string("kind", choices=KINDS)
    movable: tuple[JointType, ...] = ("revolute", "prismatic")
    joint: JointType
    if kind == "joint":
        joint = f.string("joint", choices=movable)
    elif kind == "effector":
        joint = f.string("joint", choices=("fixed", *movable))
    else:
        joint = "fixed"
        f.check("joint", not f.has("joint"), f"a {kind} module has no joint; remove the key")
    length = f.number("length", default=0.0, minimum=0.0, maximum=MAX_SIZE)
    diameter = f.number("diameter", exclusive_minimum=0.0, maximum=MAX_SIZE)
    # a base may be massless (it never moves); a moving module may not
    if kind == "base":
        mass = f.number("mass", default=0.0, minimum=0.0, maximum=MAX_MASS)
    else:
        mass = f.number("mass", exclusive_minimum=0.0, maximum=MAX_MASS)
    com, inertia = _read_inertia(f, mass, diameter, length)
    limits = None
    if joint != "fixed":
        limits = _read_limits(f.mapping("limits"), joint)
    else:
        f.check("limits", not f.has("limits"), "a module without a joint has no limits; remove the key")
        f.check("armature", not f.has("armature"), "a module without a joint has no armature; remove the key")
    armature = f.number("armature", default=0.0, minimum=0.0, maximum=MAX_ARMATURE)
    collision = f.string("collision", default="capsule" if kind == "link" else "sphere", choices=COLLISION_SHAPES)
    twist_in = math.radians(f.number("twist_in_deg", default=0.0, minimum=-360.0, maximum=360.0, why=_TURN))
    twist_out = math.radians(f.number("twist_out_deg", default=0.0, minimum=-360.0, maximum=360.0, why=_TURN))
    price = read_price(f)
    f.done()
    return Module(
        id=module_id,
        kind=kind,
        joint=joint,
        length=length,
        diameter=diameter,
        mass=mass,
        com=com,
        inertia=inertia,
        twist_in=twist_in,
        twist_out=twist_out,
        limits=limits,
        armature=armature,
        collision=collision,
        price=price,
    )


def _read_inertia(f: Fields, mass: float, diameter: float, length: float):
    if mass == 0.0 and not f.has("inertia"):
        f.check("com", not f.has("com"), "a massless module has no centre of mass; remove the key")
        return (0.0, 0.0, 0.0), (0.0,) * 6
    value = f.raw("inertia")
    if value == "solid_cylinder":
        f.check("com", not f.has("com"), "a solid_cylinder's centre of mass is its centre; remove the key")
        return (0.0, 0.0, length / 2.0), solid_cylinder_inertia(mass, diameter, length)
    com = f.vector("com", 3)
    if isinstance(value, list) and len(value) in (3, 6):
        moments = f.vector("inertia", len(value))
    else:
        raise f.fail(
            "inertia",
            "expected solid_cylinder, [ixx, iyy, izz] or [ixx, iyy, izz, ixy, ixz, iyz] in kg m^2",
        )
    moments = tuple(moments) + (0.0,) * (6 - len(moments))
    f.check(
        "inertia",
        _physical_inertia(moments),
        "expected a positive definite inertia whose principal moments satisfy the triangle inequality "
        f"(no moment above the sum of the other two), got {list(moments)}",
    )
    return com, moments


def _read_limits(f: Fields, joint: str) -> JointLimits:
    lower, upper, velocity, effort = _joint_limits(f, joint == "revolute")
    f.done()
    return JointLimits(lower=lower, upper=upper, velocity=velocity, effort=effort)
