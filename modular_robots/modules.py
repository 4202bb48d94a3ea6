"""The general module model: bodies, joints and typed connectors with full poses.

A catalogue in this model (``format: general``) describes each module as Timor does: a list of
bodies (inertial about the centre of mass, collision spheres and capsules with poses), joints
between them (revolute or prismatic about/along the joint frame's z axis, with limits, drive and
friction) and connectors (an SE(3) pose on a body, a type, a size and a gender). Two modules
join where a male output meets a female input of the same type and size; the frames of the two
connectors are then related by ``Rx(pi)`` (both point away from their body). Today's convention
A is one case of this model (:func:`from_convention_a`).

Units: metres, kilograms, seconds, radians. Poses are ``xyz`` [m] and ``rpy`` [rad] (URDF's
fixed-axis roll, pitch, yaw) of the child frame in the parent frame. Nothing here imports a
numerical library: a catalogue is data.
"""

from __future__ import annotations

import math
from contextvars import ContextVar
from dataclasses import dataclass, field

from ._yamlio import Fields

__all__ = [
    "Pose",
    "Shape",
    "Visual",
    "Body",
    "Drive",
    "Joint",
    "Connector",
    "GeneralModule",
    "AssemblyGrammar",
    "RunPattern",
    "read_general_module",
    "read_assembly_grammar",
    "from_convention_a",
]

IDENTITY_XYZ = (0.0, 0.0, 0.0)

#: Bounds on a module's numbers (SI units) in either catalogue format, beyond which no module of a
#: buildable robot lies and the arithmetic of steps B and C breaks down (e.g. a 1e9 m link makes
#: IK's systems singular).
MAX_SIZE = 10.0  # lengths, diameters, radii [m]
MAX_MASS = 1e5  # [kg]
#: The highest price of a module, in any currency: higher is a typo (or a catalogue of ships).
MAX_PRICE = 1e9


def read_price(f: Fields) -> float | None:
    """A module's optional ``price`` (a non-negative number in the catalogue's currency)."""
    return f.number("price", default=None, minimum=0.0, maximum=MAX_PRICE)


MAX_ARMATURE = 1e3  # [kg m^2 | kg]
MAX_POSITION = 100.0  # joint limits [rad | m]
MIN_VELOCITY, MAX_VELOCITY = 1e-3, 1e3  # [rad/s | m/s]
MAX_EFFORT = 1e6  # [N m | N]
MAX_MESH_BYTES = 15_000_000  # a visual mesh file [bytes]: 300,000 triangles of binary STL

#: Mesh files an importer is about to write (absolute paths): the check of the catalogue it is
#: about to write accepts them before they exist (:mod:`~modular_robots.timor`).
PENDING_MESHES: ContextVar[frozenset[str]] = ContextVar("pending_meshes", default=frozenset())


@dataclass(frozen=True)
class Pose:
    """A rigid transform: translation ``xyz`` [m] then rotation ``rpy`` [rad] (URDF convention:
    ``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""

    xyz: tuple[float, float, float] = IDENTITY_XYZ
    rpy: tuple[float, float, float] = IDENTITY_XYZ


@dataclass(frozen=True)
class Shape:
    """A collision primitive on a body: a sphere (``length == 0``) or a capsule whose axis runs
    along the pose's z axis from ``-length/2`` to ``+length/2`` [m], with ``radius`` [m]."""

    radius: float
    length: float = 0.0
    pose: Pose = Pose()


@dataclass(frozen=True)
class Visual:
    """How a body looks: the STL mesh ``file`` (an absolute path), scaled along its axes by
    ``scale``, at ``pose`` in the body frame [m]. RViz and the page draw it; dynamics and
    collision never read it (a body without one is drawn as its collision shapes)."""

    file: str
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    pose: Pose = Pose()


@dataclass(frozen=True)
class Body:
    """A rigid body of a module: ``mass`` [kg], centre of mass ``com`` [m] and ``inertia``
    (ixx, iyy, izz, ixy, ixz, iyz) [kg m^2] about the centre of mass, axes of the body frame;
    ``collision`` shapes and ``visual`` meshes in the body frame."""

    id: str
    mass: float = 0.0
    com: tuple[float, float, float] = IDENTITY_XYZ
    inertia: tuple[float, float, float, float, float, float] = (0.0,) * 6
    collision: tuple[Shape, ...] = ()
    #: Out of ``repr``: what a verdict or search state is of (its fingerprint) never depends on it.
    visual: tuple[Visual, ...] = field(default=(), repr=False)


@dataclass(frozen=True)
class Drive:
    """What a joint's drive adds to rigid-body dynamics, joint side.

    ``armature`` [kg m^2 | kg] is the reflected rotor inertia (``motor_inertia * gear_ratio**2``);
    friction torque is ``coulomb * sign(v) + viscous * v`` [N m | N]."""

    armature: float = 0.0
    coulomb: float = 0.0
    viscous: float = 0.0
    gear_ratio: float = 1.0
    motor_inertia: float = 0.0


@dataclass(frozen=True)
class Joint:
    """A movable joint from body ``parent`` to body ``child``: the joint frame sits at
    ``parent_pose`` in the parent body; the child body frame at ``child_pose`` in the joint frame
    after the motion ``Rz(q)`` (revolute) or ``Tz(q)`` (prismatic). Limits: position [rad | m],
    |velocity| [rad/s | m/s], |effort| [N m | N], |acceleration| [rad/s^2 | m/s^2] or None."""

    id: str
    type: str
    parent: str
    child: str
    lower: float
    upper: float
    velocity: float
    effort: float
    acceleration: float | None = None
    parent_pose: Pose = Pose()
    child_pose: Pose = Pose()
    drive: Drive = Drive()


@dataclass(frozen=True)
class Connector:
    """Where a module meets its neighbour: ``pose`` on body ``body``, pointing away from it.

    ``gender`` is ``"m"`` (output, distal) or ``"f"`` (input, proximal); ``type`` ``"base"``
    marks the base's mount on the world and ``"eef"`` the tool (TCP) frame."""

    id: str
    body: str
    pose: Pose
    gender: str
    type: str
    size: tuple[float, ...] = ()

    def meets(self, other: Connector) -> bool:
        """Timor's rule: a male output meets a female input of the same type and size."""
        return {self.gender, other.gender} == {"m", "f"} and self.type == other.type and self.size == other.size


@dataclass(frozen=True)
class GeneralModule:
    """A module of the general model: a serial chain of bodies and joints from its input
    connector ``inlet`` to its output connector ``outlet``.

    ``kind`` is ``base`` (its inlet is of type ``base``), ``effector`` (its outlet is of type
    ``eef``), ``joint`` (it has joints) or ``link``.
    """

    id: str
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...]
    inlet: Connector
    outlet: Connector
    notes: str = field(default="", compare=False)
    #: The module's price in the catalogue's currency (None: not given), for the ``price`` cost.
    price: float | None = None

    @property
    def dof(self) -> int:
        return len(self.joints)

    @property
    def kind(self) -> str:
        if self.inlet.type == "base":
            return "base"
        if self.outlet.type == "eef":
            return "effector"
        return "joint" if self.joints else "link"

    @property
    def mass(self) -> float:
        return sum(b.mass for b in self.bodies)

    def body(self, body_id: str) -> Body:
        return next(b for b in self.bodies if b.id == body_id)

    def chain(self) -> tuple[tuple[Body, Joint | None], ...]:
        """The bodies from the inlet's to the outlet's, each with the joint that leads to it
        (None for the first)."""
        by_parent = {j.parent: j for j in self.joints}
        out: list[tuple[Body, Joint | None]] = [(self.body(self.inlet.body), None)]
        seen = {self.inlet.body}
        while out[-1][0].id in by_parent:
            joint = by_parent[out[-1][0].id]
            if joint.child in seen:  # a loop (a body its own child): the chain ends; the loader refuses it
                break
            seen.add(joint.child)
            out.append((self.body(joint.child), joint))
        return tuple(out)


@dataclass(frozen=True)
class RunPattern:
    """A whitelist of link runs: one slot after another, each a set of module ids, optional or
    not. ``((("L4", "L5"), True), (("L1",), False))`` allows ``L1``, ``L4-L1`` and ``L5-L1``."""

    slots: tuple[tuple[tuple[str, ...], bool], ...]


@dataclass(frozen=True)
class AssemblyGrammar:
    """Which serial assemblies of a general catalogue count (Timor's ``Science2019`` rules).

    ``dof``: range of the number of joints (inclusive). ``links_between_joints``,
    ``links_before_first_joint`` and ``links_after_last_joint``: ranges of the length of the run
    of link modules between two joint modules, between the base and the first joint module, and
    between the last joint module and the effector. Every neighbour pair must meet
    (:meth:`Connector.meets`). Optional whitelists: ``joint_sequences`` (the allowed sequences
    of joint modules), ``between_joints`` and ``before_end`` (:class:`RunPattern` of the runs
    between joint modules and before the effector; they replace the length ranges).
    """

    dof: tuple[int, int]
    links_between_joints: tuple[int, int] = (0, 3)
    links_before_first_joint: tuple[int, int] = (0, 0)
    links_after_last_joint: tuple[int, int] = (0, 0)
    joint_sequences: tuple[tuple[str, ...], ...] | None = None
    between_joints: RunPattern | None = None
    before_end: RunPattern | None = None


# -- reading ----------------------------------------------------------------------------------
MAX_RUN = 10
MAX_DOF = 40
GENDERS = ("m", "f")
JOINT_TYPES = ("revolute", "prismatic")


def _identifier(f: Fields, key: str) -> str:
    value = f.string(key)
    f.check(
        key, value.replace("_", "").isalnum() and len(value) <= 100, f"expected letters, digits or '_', got {value!r}"
    )
    return value


def _pose(f: Fields, key: str) -> Pose:
    sub = f.mapping(key, None)
    if sub is None:
        return Pose()
    xyz = sub.vector("xyz", 3, IDENTITY_XYZ)
    rpy = sub.rpy(default=IDENTITY_XYZ)
    sub.done()
    return Pose(xyz, rpy)


def _shape(f: Fields) -> Shape:
    kind = f.string("shape", choices=("sphere", "capsule"))
    radius = f.number("radius", exclusive_minimum=0.0, maximum=MAX_SIZE)
    length = f.number("length", exclusive_minimum=0.0, maximum=MAX_SIZE) if kind == "capsule" else 0.0
    pose = _pose(f, "pose")
    f.done()
    return Shape(radius, length, pose)


def _body(f: Fields) -> Body:
    body_id = _identifier(f, "id")
    mass = f.number("mass", default=0.0, minimum=0.0, maximum=MAX_MASS)
    com = f.vector("com", 3, IDENTITY_XYZ)
    inertia = f.vector("inertia", 6, (0.0,) * 6)
    if mass > 0.0:
        f.check(
            "inertia",
            f.has("inertia"),
            f"missing: a body of mass {mass:g} kg needs its [ixx, iyy, izz, ixy, ixz, iyz] about the centre of mass "
            "[kg m^2]",
        )
        f.check(
            "inertia",
            _physical_inertia(inertia),
            "expected [ixx, iyy, izz, ixy, ixz, iyz] about the centre of mass, positive definite, no principal "
            f"moment above the sum of the other two, got {list(inertia)}",
        )
    else:
        f.check("inertia", not any(inertia), "a massless body has no inertia; remove the key")
    shapes = tuple(_shape(s) for s in f.mappings("collision", ()))
    visuals = tuple(v for v in (_visual(v) for v in f.mappings("visual", ())) if v is not None)
    f.done()
    return Body(body_id, mass, com, inertia, shapes, visuals)


def _visual(f: Fields) -> Visual | None:
    """A body's visual mesh; None (with a warning naming the folder looked in) if its file is
    missing: a catalogue copied without its meshes still loads, its bodies drawn as their
    collision shapes."""
    name = f.string("mesh")
    f.check("mesh", name.lower().endswith(".stl"), f"expected an STL file (.stl), got {name!r:.80}")
    path = (f.path.parent / name).resolve()
    scale = f.vector("scale", 3, (1.0, 1.0, 1.0))
    f.check("scale", all(0.0 < c <= 1e3 for c in scale), f"expected 3 numbers in (0, 1000], got {list(scale)}")
    pose = _pose(f, "pose")
    f.done()
    if str(path) not in PENDING_MESHES.get():
        if not path.is_file():
            f.warn(
                "mesh",
                f"no mesh file at {path} (looked in {path.parent}: a relative path is taken from the catalogue's "
                "folder); the body is drawn as its collision shapes",
            )
            return None
        f.check("mesh", path.stat().st_size <= MAX_MESH_BYTES, f"{path}: more than {MAX_MESH_BYTES:,} bytes")
    return Visual(str(path), scale, pose)


def _drive(f: Fields) -> Drive:
    coulomb = f.number("coulomb", default=0.0, minimum=0.0, maximum=1e6)
    viscous = f.number("viscous", default=0.0, minimum=0.0, maximum=1e6)
    if f.has("armature"):
        f.check("gear_ratio", not f.has("gear_ratio"), "give either armature or gear_ratio and motor_inertia")
        return Drive(armature=f.number("armature", minimum=0.0, maximum=MAX_ARMATURE), coulomb=coulomb, viscous=viscous)
    ratio = f.number("gear_ratio", default=1.0, exclusive_minimum=0.0, maximum=1e5)
    inertia = f.number("motor_inertia", default=0.0, minimum=0.0, maximum=1e3)
    return Drive(inertia * ratio * ratio, coulomb, viscous, ratio, inertia)


#: A revolute joint faster than this [rad/s] (about 190 rpm at the output) is warned about: the
#: value looks like degrees per second (1 rad/s is 57.3 deg/s).
DEGREES_LIKE_VELOCITY = 20.0


def _joint_limits(f: Fields, revolute: bool) -> tuple[float, float, float, float]:
    """A joint's ``position: [lower, upper]``, ``velocity`` and ``effort`` limits, in either
    catalogue format, within the module bounds. A revolute joint's limits that look like degrees
    (more than a turn either way, faster than :data:`DEGREES_LIKE_VELOCITY`) are warned about."""
    lower, upper = f.vector("position", 2)
    f.check("position", lower < upper, f"expected [lower, upper] with lower < upper, got [{lower:g}, {upper:g}]")
    degrees = f" (degrees? [{math.radians(lower):.4g}, {math.radians(upper):.4g}] rad)" if revolute else ""
    f.check(
        "position",
        max(-lower, upper) <= MAX_POSITION,
        f"expected limits within +-{MAX_POSITION:g} (rad or m), got [{lower:g}, {upper:g}]{degrees}",
    )
    velocity = f.number("velocity", minimum=MIN_VELOCITY, maximum=MAX_VELOCITY)
    effort = f.number("effort", exclusive_minimum=0.0, maximum=MAX_EFFORT)
    if revolute and max(-lower, upper) > 2 * math.pi + 1e-9:
        f.warn(
            "position",
            f"[{lower:g}, {upper:g}] rad is more than a turn either way: degrees? Expected radians "
            f"([{math.radians(lower):.4g}, {math.radians(upper):.4g}] if these are degrees)",
        )
    if revolute and velocity > DEGREES_LIKE_VELOCITY:
        f.warn(
            "velocity",
            f"{velocity:g} rad/s is {math.degrees(velocity):,.0f} deg/s: degrees per second? Expected rad/s "
            f"({math.radians(velocity):.4g} if this is in deg/s)",
        )
    return lower, upper, velocity, effort


def _joint(f: Fields) -> Joint:
    joint_id = _identifier(f, "id")
    kind = f.string("type", choices=JOINT_TYPES)
    parent, child = _identifier(f, "parent"), _identifier(f, "child")
    limits = f.mapping("limits")
    lower, upper, velocity, effort = _joint_limits(limits, kind == "revolute")
    acceleration = limits.number("acceleration", default=None, exclusive_minimum=0.0, maximum=1e6)
    limits.done()
    parent_pose, child_pose = _pose(f, "parent_pose"), _pose(f, "child_pose")
    drive = _drive(f)
    f.done()
    return Joint(
        joint_id, kind, parent, child, lower, upper, velocity, effort, acceleration, parent_pose, child_pose, drive
    )


def _connector(f: Fields) -> Connector:
    size = f.raw("size", [])
    f.check("size", isinstance(size, list) and len(size) <= 6, "expected a list of numbers (may be empty)")
    out = Connector(
        id=_identifier(f, "id"),
        body=_identifier(f, "body"),
        pose=_pose(f, "pose"),
        gender=f.string("gender", choices=GENDERS),
        type=f.string("type"),
        size=f.vector("size", len(size)) if size else (),
    )
    f.done()
    return out


def read_general_module(f: Fields) -> GeneralModule:
    """One module of a ``format: general`` catalogue (see docs/formats.md).

    Raises
    ------
    CatalogError
        Naming the file, line and key, and what was expected.
    """
    module_id = _identifier(f, "id")
    notes = f.string("notes", default="")
    price = read_price(f)
    bodies = tuple(_body(b) for b in f.mappings("bodies"))
    f.check("bodies", bool(bodies), "expected at least one body")
    names = [b.id for b in bodies]
    f.check("bodies", len(set(names)) == len(names), f"duplicate body ids in {names}")
    joints = tuple(_joint(j) for j in f.mappings("joints", ()))
    inlet = _connector(f.mapping("inlet"))
    outlet = _connector(f.mapping("outlet"))
    f.done()
    for key, connector, gender in (("inlet", inlet, "f"), ("outlet", outlet, "m")):
        f.check(key, connector.body in names, f"body {connector.body!r} is not one of {names}")
        f.check(key, connector.gender == gender, f"expected gender {gender!r} (inputs are female, outputs male)")
    for joint in joints:
        f.check("joints", {joint.parent, joint.child} <= set(names), f"joint {joint.id}: unknown parent or child body")
    module = GeneralModule(module_id, bodies, joints, inlet, outlet, notes, price)
    chain = module.chain()
    f.check(
        "joints",
        len(chain) == len(bodies) == len(joints) + 1 and chain[-1][0].id == outlet.body,
        "expected the joints to chain every body from the inlet's body to the outlet's, each body the child of "
        "one joint (no loop, no branch)",
    )
    return module


def _range(f: Fields, key: str, default: tuple[int, int], maximum: int) -> tuple[int, int]:
    if not f.has(key):
        f.raw(key, None)
        return default
    low, high = f.interval(key)
    f.check(
        key,
        low >= 0 and low == int(low) and high == int(high) and high <= maximum,
        f"expected [min, max] of whole numbers in [0, {maximum}]",
    )
    return int(low), int(high)


def _ids(f: Fields, key: str, value) -> tuple[str, ...]:
    f.check(key, isinstance(value, list) and all(isinstance(v, str) for v in value), "expected a list of module ids")
    return tuple(value)


def _pattern(f: Fields, key: str) -> RunPattern | None:
    value = f.raw(key, None)
    if value is None:
        return None
    f.check(key, isinstance(value, list), "expected a list of slots {one_of: [ids], optional: bool}")
    slots = []
    for item in value:
        f.check(
            key,
            isinstance(item, dict) and set(item) <= {"one_of", "optional"} and "one_of" in item,
            "expected slots {one_of: [ids], optional: bool}",
        )
        f.check(key, isinstance(item.get("optional", False), bool), "optional: expected true or false")
        slots.append((_ids(f, key, item["one_of"]), bool(item.get("optional", False))))
    return RunPattern(tuple(slots))


def read_assembly_grammar(f: Fields) -> AssemblyGrammar:
    """The ``grammar`` of a ``format: general`` catalogue (see :class:`AssemblyGrammar`)."""
    dof = _range(f, "dof", (0, 6), MAX_DOF)
    between = _range(f, "links_between_joints", (0, 3), MAX_RUN)
    before = _range(f, "links_before_first_joint", (0, 0), MAX_RUN)
    after = _range(f, "links_after_last_joint", (0, 0), MAX_RUN)
    sequences = f.raw("joint_sequences", None)
    if sequences is not None:
        f.check("joint_sequences", isinstance(sequences, list), "expected a list of lists of joint-module ids")
        sequences = tuple(_ids(f, "joint_sequences", s) for s in sequences)
    grammar = AssemblyGrammar(
        dof, between, before, after, sequences, _pattern(f, "between_joints"), _pattern(f, "before_end")
    )
    f.done()
    return grammar


def check_grammar_ids(f: Fields, grammar: AssemblyGrammar, modules: dict[str, GeneralModule]) -> None:
    """Every id a whitelist names is a module of the right kind."""
    wanted = [("joint_sequences", "joint", i) for s in grammar.joint_sequences or () for i in s]
    for key in ("between_joints", "before_end"):
        pattern = getattr(grammar, key)
        wanted += [(key, "link", i) for ids, _ in (pattern.slots if pattern else ()) for i in ids]
    for key, kind, module_id in wanted:
        module = modules.get(module_id)
        f.check("grammar", module is not None and module.kind == kind, f"{key}: {module_id!r} is not a {kind} module")


def _physical_inertia(moments: tuple[float, ...]) -> bool:
    """True for a rotational inertia a rigid body can have: positive definite, and its largest
    principal moment at most the sum of the other two (half the trace)."""
    ixx, iyy, izz, ixy, ixz, iyz = moments
    det = ixx * (iyy * izz - iyz * iyz) - ixy * (ixy * izz - iyz * ixz) + ixz * (ixy * iyz - iyy * ixz)
    if not (ixx > 0 and ixx * iyy - ixy * ixy > 0 and det > 0):
        return False
    return _largest_eigenvalue(moments) <= 0.5 * (ixx + iyy + izz) * (1.0 + 1e-9)


def _largest_eigenvalue(moments: tuple[float, ...]) -> float:
    """The largest eigenvalue of the symmetric 3 x 3 matrix ``moments`` (closed form)."""
    ixx, iyy, izz, ixy, ixz, iyz = moments
    off = ixy * ixy + ixz * ixz + iyz * iyz
    if off == 0.0:
        return max(ixx, iyy, izz)
    q = (ixx + iyy + izz) / 3.0
    p = math.sqrt(((ixx - q) ** 2 + (iyy - q) ** 2 + (izz - q) ** 2 + 2.0 * off) / 6.0)
    a, b, c = (ixx - q) / p, (iyy - q) / p, (izz - q) / p
    d, e, g = ixy / p, ixz / p, iyz / p
    r = 0.5 * (a * (b * c - g * g) - d * (d * c - g * e) + e * (d * g - b * e))
    return q + 2.0 * p * math.cos(math.acos(max(-1.0, min(1.0, r))) / 3.0)


# -- convention A as a case of the general model ------------------------------------------------
def from_convention_a(module) -> GeneralModule:
    """The general form of a convention-A :class:`~modular_robots.catalog.Module`.

    The body frame is the module's input frame after ``Rx(twist_in) · M(q)``. A fixed module's
    inlet (pointing away from the body, so flipped by ``Rx(pi)``) sits at ``Rx(pi - twist_in)``
    in its body frame; a joint module holds a massless mount body (inlet ``Rx(pi)``), a joint at
    ``Rx(twist_in)`` on it and the module's mass on the moving body. The outlet is
    ``Tz(length) · Rx(twist_out)`` in the last body's frame. Collision shapes are not carried
    over (convention-A catalogues keep their own code path, so their figures stay bit-identical).
    """
    kind = module.kind
    inlet_pose = Pose(IDENTITY_XYZ, (math.pi - module.twist_in, 0.0, 0.0))
    outlet_pose = Pose((0.0, 0.0, module.length), (module.twist_out, 0.0, 0.0))
    massive = Body("body", module.mass, tuple(module.com), tuple(module.inertia))
    inlet_type = "base" if kind == "base" else "port"
    outlet_type = "eef" if kind == "effector" else "port"
    if module.dof:
        lim = module.limits
        first = Body("mount")
        joint = Joint(
            "joint",
            module.joint,
            "mount",
            "body",
            lim.lower,
            lim.upper,
            lim.velocity,
            lim.effort,
            parent_pose=Pose(IDENTITY_XYZ, (module.twist_in, 0.0, 0.0)),
            drive=Drive(armature=module.armature),
        )
        inlet = Connector("in", "mount", Pose(IDENTITY_XYZ, (math.pi, 0.0, 0.0)), "f", inlet_type)
        return GeneralModule(
            module.id,
            (first, massive),
            (joint,),
            inlet,
            Connector("out", "body", outlet_pose, "m", outlet_type),
            price=module.price,
        )
    inlet = Connector("in", "body", inlet_pose, "f", inlet_type)
    outlet = Connector("out", "body", outlet_pose, "m", outlet_type)
    return GeneralModule(module.id, (massive,), (), inlet, outlet, price=module.price)
