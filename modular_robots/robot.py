"""Robot models: a Pinocchio model of a composition (or of any URDF), with its tool frame,
joint limits, collision primitives and dynamics.

Collision primitives are segments with a radius, attached to a frame: a capsule of length
``length`` along the frame's z axis starting at ``offset``; a sphere is a segment of zero length.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache, partial

import numpy as np
import pinocchio as pin

from .catalog import Catalog
from .composition import Composition
from .costs import Design, design_of
from .urdf import PAYLOAD_RADIUS, composition_urdf, link_name
from .urdf_assembly import assembly_shapes

__all__ = ["Primitive", "RobotModel", "robot_from_urdf", "robot_model", "symmetric_from_upper", "COULOMB_SMOOTHING"]

#: Velocity scale of the smooth sign in Coulomb friction, ``coulomb * tanh(v / eps)``
#: [rad/s | m/s]: above 3 eps (0.03 rad/s) the friction is within 0.5 % of its full value.
COULOMB_SMOOTHING = 0.01


@dataclass(frozen=True)
class Primitive:
    """A capsule (``length > 0``) or sphere (``length == 0``) of ``radius`` [m] on ``frame``.

    Its axis runs from ``(0, 0, offset)`` to ``(0, 0, offset + length)`` in the frame.
    ``module`` is the index of the module it belongs to in the chain (-1: not a module).
    """

    name: str
    frame: str
    radius: float
    length: float = 0.0
    offset: float = 0.0
    module: int = -1


class RobotModel:
    """A Pinocchio model with a tool frame and collision primitives.

    Parameters
    ----------
    model
        The Pinocchio model (its joint limits are the robot's limits).
    tool_frame
        Name of the frame whose origin is the tool point (``tool0`` for compositions).
    primitives
        Collision primitives, in chain order.
    name
        A name for messages and files.
    urdf
        The URDF text the model was built from, if any (kept to export it).
    """

    def __init__(
        self,
        model: pin.Model,
        tool_frame: str = "tool0",
        primitives: Sequence[Primitive] = (),
        name: str = "",
        urdf: str | Callable[[], str] | None = None,
        design: Design | None = None,
    ):
        self.model = model
        #: What the robot is made of, for the costs of its design (None: unknown, e.g. a URDF).
        self.design = design
        self.data = model.createData()
        self.name = name or model.name
        self._urdf = urdf
        if not model.existFrame(tool_frame):
            raise ValueError(f"robot {self.name!r} has no frame {tool_frame!r}")
        self.tool_frame = tool_frame
        self.tool_frame_id = model.getFrameId(tool_frame)
        self.primitives = tuple(primitives)
        for p in self.primitives:
            if not model.existFrame(p.frame):
                raise ValueError(f"primitive {p.name!r}: robot {self.name!r} has no frame {p.frame!r}")
        self._primitive_frames = [int(model.getFrameId(p.frame)) for p in self.primitives]
        #: Whether the joints have friction (``model.damping``: viscous, ``model.friction``: Coulomb).
        self.has_friction = bool(np.any(model.damping != 0.0) or np.any(model.friction != 0.0))

    @property
    def urdf(self) -> str | None:
        """The URDF text of the model (written when first asked for: step B never needs it)."""
        if callable(self._urdf):
            self._urdf = self._urdf()
        return self._urdf

    # -- sizes and limits --------------------------------------------------------------------
    @property
    def nq(self) -> int:
        return self.model.nq

    @property
    def nv(self) -> int:
        return self.model.nv

    @property
    def lower(self) -> np.ndarray:
        """Lower position limits [rad or m]."""
        return self.model.lowerPositionLimit.copy()

    @property
    def upper(self) -> np.ndarray:
        """Upper position limits [rad or m]."""
        return self.model.upperPositionLimit.copy()

    @property
    def velocity_limit(self) -> np.ndarray:
        """Symmetric velocity bounds [rad/s or m/s]."""
        return self.model.velocityLimit.copy()

    def travel_time_bound(self, q_a: np.ndarray, q_b: np.ndarray, velocity: np.ndarray | None = None) -> float:
        """No motion from rest at ``q_a`` to ``q_b`` within the velocity limits (or the bounds
        ``velocity``, if given) takes less than ``max_i |q_b,i - q_a,i| / qdot_max,i`` [s]
        (joints without a finite positive limit bound nothing)."""
        velocity = self.velocity_limit if velocity is None else np.asarray(velocity, dtype=float)
        limited = np.isfinite(velocity) & (velocity > 0)
        moves = np.abs(np.asarray(q_b, dtype=float) - np.asarray(q_a, dtype=float))
        return float(np.max(moves[limited] / velocity[limited], initial=0.0))

    def tool_speed_bound(self, velocity: np.ndarray | None = None) -> float:
        """An upper bound on the tool's speed [m/s] in any configuration within the velocity
        limits (or the bounds ``velocity``): each revolute joint's speed times an upper bound on
        the tool's distance from its axis (the distance from its origin: along the chain, each
        joint placement's offset, a prismatic joint's largest travel and the tool's offset), plus
        each prismatic joint's speed. A joint without a finite limit makes it infinite."""
        model = self.model
        velocity = self.velocity_limit if velocity is None else np.asarray(velocity, dtype=float)
        frame = model.frames[self.tool_frame_id]
        chain = []
        j = frame.parentJoint
        while j > 0:
            chain.append(j)
            j = model.parents[j]
        speed, distance = 0.0, float(np.linalg.norm(frame.placement.translation))
        child_offset = 0.0
        for j in chain:  # from the tool's joint toward the base
            joint = model.joints[j]
            distance += child_offset
            prismatic = joint.shortname().startswith("JointModelP")
            if prismatic:
                low, high = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
                distance += max(abs(low), abs(high))
            rate = velocity[joint.idx_v]
            speed += abs(rate) if prismatic else abs(rate) * distance
            child_offset = float(np.linalg.norm(model.jointPlacements[j].translation))
        return float(speed) if np.isfinite(speed) else math.inf

    @property
    def effort_limit(self) -> np.ndarray:
        """Symmetric torque/force bounds [N m or N]."""
        return self.model.effortLimit.copy()

    @property
    def total_mass(self) -> float:
        """Mass of every body, payload included [kg]."""
        return float(sum(inertia.mass for inertia in self.model.inertias))

    def moving_primitives(self) -> tuple[int, ...]:
        """Indices of the primitives that move with some joint (the others never change pose)."""
        return tuple(i for i, fid in enumerate(self._primitive_frames) if self.model.frames[fid].parentJoint != 0)

    @property
    def joint_names(self) -> list[str]:
        """The movable joints' names, in the order of ``q`` (``m<i>_<module>_joint``)."""
        return [str(name) for name in self.model.names[1:]]

    def drive(self) -> dict:
        """What the URDF cannot say about the drives, per joint in ``q`` order: ``armature``
        (reflected rotor inertia [kg m^2 | kg]), Coulomb [N m | N] and viscous [N m s | N s]
        friction (also in the URDF's ``<dynamics>``) and the smoothing velocity of the Coulomb
        term (:data:`COULOMB_SMOOTHING`, None without friction); ``trajectory.csv``'s torques
        include them."""
        return {
            "joints": self.joint_names,
            "armature": [float(a) for a in self.model.armature],
            "coulomb": [float(c) for c in self.model.friction],
            "viscous": [float(c) for c in self.model.damping],
            "coulomb_smoothing": COULOMB_SMOOTHING if self.has_friction else None,
        }

    def friction(self, v) -> np.ndarray:
        """Joint friction torque [N m | N] at velocity ``v``: ``viscous * v + coulomb * tanh(v / eps)``."""
        v = np.asarray(v, dtype=float)
        return self.model.damping * v + self.model.friction * np.tanh(v / COULOMB_SMOOTHING)

    def friction_derivative(self, v) -> np.ndarray:
        """``d friction / d v`` (the diagonal), exact."""
        t = np.tanh(np.asarray(v, dtype=float) / COULOMB_SMOOTHING)
        return self.model.damping + self.model.friction * (1.0 - t * t) / COULOMB_SMOOTHING

    def friction_second_derivative(self, v) -> np.ndarray:
        """``d2 friction / d v2`` (the diagonal), exact."""
        t = np.tanh(np.asarray(v, dtype=float) / COULOMB_SMOOTHING)
        return self.model.friction * (-2.0 * t * (1.0 - t * t)) / COULOMB_SMOOTHING**2

    # -- kinematics -----------------------------------------------------------------------
    def tool_position(self, q: np.ndarray) -> np.ndarray:
        """Position of the tool point in the base frame [m]."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.tool_frame_id].translation.copy()

    def tool_rotation(self, q: np.ndarray) -> np.ndarray:
        """The rotation ``(3, 3)`` of the tool frame in the base frame at ``q``."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.tool_frame_id].rotation.copy()

    def tool_jacobian(self, q: np.ndarray) -> np.ndarray:
        """3 x nv Jacobian of :meth:`tool_position` (base-frame axes)."""
        jacobian = pin.computeFrameJacobian(
            self.model,
            self.data,
            np.asarray(q, dtype=float),
            self.tool_frame_id,
            pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
        )
        return jacobian.reshape(6, -1)[:3].copy()  # one joint: Pinocchio gives (6,), not (6, 1)

    def primitive_axes(
        self, q: np.ndarray | None, indices: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Frame rotations ``(P, 3, 3)`` and axis end points ``a``, ``b`` ``(P, 3)`` in the base
        frame of the primitives ``indices`` (default all). ``q=None`` reuses the frame placements
        already computed in :attr:`data`."""
        if q is not None:
            pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        indices = range(len(self.primitives)) if indices is None else indices
        poses = [self.data.oMf[self._primitive_frames[i]] for i in indices]
        offsets = np.array([self.primitives[i].offset for i in indices], dtype=float)
        lengths = np.array([self.primitives[i].length for i in indices], dtype=float)
        rot = np.array([pose.rotation for pose in poses]).reshape(-1, 3, 3)
        a = np.array([pose.translation for pose in poses]).reshape(-1, 3) + offsets[:, None] * rot[:, :, 2]
        return rot, a, a + lengths[:, None] * rot[:, :, 2]

    def primitive_segments(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """End points ``(a, b)``, each ``(n_primitives, 3)``, of every primitive's axis in the
        base frame; ``a == b`` for spheres."""
        _, a, b = self.primitive_axes(q)
        return a, b

    # -- dynamics ---------------------------------------------------------------------------
    def rnea(self, q, v, a) -> np.ndarray:
        """Inverse dynamics: the drives' joint torques/forces [N m or N] (at the joint, after the
        gear) for ``(q, v, a)``, gravity, armature and friction included; ``(nv,)``, or ``(K, nv)``
        for ``K`` rows of each."""
        tau = self._rows(pin.rnea, q, v, a)
        return tau + self.friction(v) if self.has_friction else tau

    def aba(self, q, v, tau) -> np.ndarray:
        """Forward dynamics: joint accelerations for motor torques ``tau`` at ``(q, v)``; ``(nv,)``,
        or ``(K, nv)`` for ``K`` rows of each."""
        if self.has_friction:
            tau = np.asarray(tau, dtype=float) - self.friction(v)
        return self._rows(pin.aba, q, v, tau)

    def _rows(self, algorithm, q, v, third) -> np.ndarray:
        """``algorithm(model, data, q, v, third)`` at one point or at each of ``K`` rows (a copy:
        Pinocchio returns a view of its data)."""
        q = np.asarray(q, dtype=float)
        if q.ndim == 1:
            return algorithm(self.model, self.data, q, v, third).copy()
        out = np.empty((len(q), self.nv))
        for k, row in enumerate(zip(q, np.asarray(v, dtype=float), np.asarray(third, dtype=float))):
            out[k] = algorithm(self.model, self.data, *row)
        return out

    def rnea_derivatives(self, q, v, a) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(dtau/dq, dtau/dv, dtau/da = M)`` at ``(q, v, a)``."""
        dq, dv, da = pin.computeRNEADerivatives(self.model, self.data, q, v, a)
        da = symmetric_from_upper(da)
        dv = dv.copy()
        if self.has_friction:
            dv[np.diag_indices_from(dv)] += self.friction_derivative(v)
        return dq.copy(), dv, da

    def aba_derivatives(self, q, v, tau) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(dqdd/dq, dqdd/dv, dqdd/dtau = M^-1)`` at ``(q, v, tau)``."""
        if self.has_friction:
            tau = np.asarray(tau, dtype=float) - self.friction(v)
        dq, dv, dtau = pin.computeABADerivatives(self.model, self.data, q, v, tau)
        dtau = symmetric_from_upper(dtau)
        dv = dv.copy()
        if self.has_friction:
            dv -= dtau * self.friction_derivative(v)[None, :]
        return dq.copy(), dv, dtau

    def gravity(self, q) -> np.ndarray:
        """Static joint torques/forces that hold ``q`` against gravity (payload included)."""
        return pin.computeGeneralizedGravity(self.model, self.data, np.asarray(q, dtype=float)).copy()

    def holding_ratios(self, q) -> np.ndarray:
        """``|gravity(q)|`` over each joint's effort limit: above 1, the joint cannot hold ``q``
        (a joint without a positive finite limit is measured against 1)."""
        limit = self.effort_limit
        return np.abs(self.gravity(q)) / np.where(np.isfinite(limit) & (limit > 0.0), limit, 1.0)

    def mass_matrix(self, q) -> np.ndarray:
        """Joint-space mass matrix ``M(q)`` (symmetric)."""
        return symmetric_from_upper(pin.crba(self.model, self.data, np.asarray(q, dtype=float)))


def symmetric_from_upper(upper: np.ndarray) -> np.ndarray:
    """The symmetric matrices ``(..., n, n)`` whose upper triangles Pinocchio filled (its mass
    matrix and its inverse, alone or stacked)."""
    return np.triu(upper) + np.swapaxes(np.triu(upper, 1), -1, -2)


def composition_primitives(composition: Composition, catalog: Catalog) -> list[Primitive]:
    """Collision primitives of a composition: each module's catalogue shape, plus the payload."""
    out = []
    if catalog.general:
        for frame, radius, length, index in assembly_shapes(composition, catalog):
            out.append(Primitive(frame, frame, radius, length, -length / 2, index))
        out.append(Primitive("payload", "payload", PAYLOAD_RADIUS, 0.0, 0.0, len(composition.modules)))
        return out
    for index, module_id in enumerate(composition.modules):
        module = catalog.module(module_id)
        frame = link_name(index, module)
        if module.collision == "sphere":
            out.append(Primitive(f"{frame}_port", frame, module.radius, 0.0, module.length, index))
        elif module.collision == "capsule":
            out.append(Primitive(f"{frame}_capsule", frame, module.radius, module.length, 0.0, index))
    out.append(Primitive("payload", "payload", PAYLOAD_RADIUS, 0.0, 0.0, len(composition.modules)))
    return out


def robot_model(composition: Composition, catalog: Catalog, payload: float = 0.0) -> RobotModel:
    """The :class:`RobotModel` of ``composition`` carrying ``payload`` kg at ``tool0``.

    Built from the generated URDF (nothing is written to disk); module armatures are applied to
    the model. The Pinocchio model is built once per ``(composition, catalog, payload)`` and
    shared, since nothing changes it; every call gets its own :class:`RobotModel`, with its own
    Pinocchio ``Data``, so two users of the same composition never share a workspace.
    """
    model = _pinocchio_model(composition, catalog, payload)
    urdf = partial(composition_urdf, composition, catalog, payload)
    primitives = composition_primitives(composition, catalog)
    return RobotModel(model, "tool0", primitives, composition.name, urdf, design_of(composition.modules, catalog))


@lru_cache(maxsize=256)
def _pinocchio_model(composition: Composition, catalog: Catalog, payload: float) -> pin.Model:
    model = pin.buildModelFromXML(composition_urdf(composition, catalog, payload, collision=False))
    if catalog.general:
        joints = [j for m in composition.modules for j in catalog.general_module(m).joints]
        model.armature = np.array([j.drive.armature for j in joints], dtype=float)
        return model
    joint_modules = [catalog.module(m) for m in composition.modules if catalog.module(m).dof]
    model.armature = np.array([m.armature for m in joint_modules], dtype=float)
    return model


def robot_from_urdf(urdf: str, armature=None, tool_frame: str = "tool0", name: str = "") -> RobotModel:
    """A :class:`RobotModel` (no collision primitives) of a URDF text, e.g. an exported
    ``winner.urdf``, with the drives' ``armature`` (URDF has no field for it; ``result.json``'s
    ``winner.drive`` has it)."""
    model = pin.buildModelFromXML(urdf)
    if armature is not None:
        model.armature = np.asarray(armature, dtype=float)
    return RobotModel(model, tool_frame, (), name, urdf)
