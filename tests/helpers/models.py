"""Robot models built by hand, not from a catalogue: a planar two-link arm whose dynamics and
clearance have closed forms (the tests write them from the constants here), and the UR5 of
example-robot-data (a URDF the package did not generate) with a payload."""

from __future__ import annotations

import importlib.metadata
import math

import numpy as np
import pinocchio as pin

from modular_robots.obstacles import SphereObstacle
from modular_robots.robot import Primitive, RobotModel

# Planar two-link arm in the horizontal plane (joint axes along z, parallel to gravity, so
# gravity does no work): uniform rods of mass M and length L along each link's x axis.
M_LINK, L_LINK, R_LINK = 1.0, 1.0, 0.05
ARM_TAU = np.array([10.0, 10.0])
ARM_VEL = np.array([10.0, 10.0])
#: The planar arm's boundary configurations in the tests [rad].
ARM_START, ARM_GOAL = [-1.2, 0.3], [1.2, -0.3]


def planar_arm() -> RobotModel:
    """The two-link arm; each link carries a capsule primitive on a frame whose z axis runs
    along the link (primitives are capsules along their frame's z)."""
    model = pin.Model()
    model.name = "planar2"
    along_x = pin.utils.rotate("y", np.pi / 2)  # frame z axis -> link x axis
    rod = np.diag([1e-4, M_LINK * L_LINK**2 / 12, M_LINK * L_LINK**2 / 12])
    parent, placement, primitives = 0, pin.SE3.Identity(), []
    for k in range(2):
        joint = model.addJoint(
            parent,
            pin.JointModelRZ(),
            placement,
            f"joint{k + 1}",
            ARM_TAU[k : k + 1],
            ARM_VEL[k : k + 1],
            np.array([-3.0]),
            np.array([3.0]),
        )
        model.appendBodyToJoint(joint, pin.Inertia(M_LINK, np.array([L_LINK / 2, 0.0, 0.0]), rod), pin.SE3.Identity())
        model.addFrame(pin.Frame(f"link{k + 1}", joint, 0, pin.SE3(along_x, np.zeros(3)), pin.FrameType.OP_FRAME))
        primitives.append(Primitive(f"link{k + 1}", f"link{k + 1}", R_LINK, L_LINK, 0.0, k))
        parent, placement = joint, pin.SE3(np.eye(3), np.array([L_LINK, 0.0, 0.0]))
    model.addFrame(pin.Frame("tool0", parent, 0, placement, pin.FrameType.OP_FRAME))
    return RobotModel(model, "tool0", primitives, name="planar2")


def ur5(payload: float) -> RobotModel:
    """The UR5 of example-robot-data with a solid-sphere payload (radius 5 cm) centred at tool0."""
    path = next(
        f.locate()
        for f in importlib.metadata.files("example-robot-data")
        if str(f).endswith("ur_description/urdf/ur5_robot.urdf")
    )
    model = pin.buildModelFromUrdf(str(path))
    tool = model.frames[model.getFrameId("tool0")]
    model.appendBodyToJoint(tool.parentJoint, pin.Inertia.FromSphere(payload, 0.05), tool.placement)
    return RobotModel(model, "tool0", [Primitive("payload", "tool0", 0.05)], name="ur5")


def arm_points(q):
    """Base, elbow and tool positions of the planar arm (closed form)."""
    elbow = L_LINK * np.array([math.cos(q[0]), math.sin(q[0]), 0.0])
    tool = elbow + L_LINK * np.array([math.cos(q[0] + q[1]), math.sin(q[0] + q[1]), 0.0])
    return np.zeros(3), elbow, tool


def arm_clearance(q, obstacle: SphereObstacle) -> float:
    """Closed-form signed distance between the arm's two capsules and a sphere (no FCL)."""
    base, elbow, tool = arm_points(q)
    c = np.asarray(obstacle.center, dtype=float)
    out = np.inf
    for a, b in ((base, elbow), (elbow, tool)):
        t = np.clip(np.dot(c - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        out = min(out, float(np.linalg.norm(c - (a + t * (b - a)))) - R_LINK - obstacle.radius)
    return out
