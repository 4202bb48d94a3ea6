"""MuJoCo as an independent engine: its own URDF importer and its own dynamics, for checks of the
package's models and plans that share no code with the URDF -> Pinocchio path."""

from __future__ import annotations

from xml.etree import ElementTree

import numpy as np
import pytest


def mujoco_model(urdf_text: str, gravity):
    """Compile the URDF text with MuJoCo's own URDF importer.

    Import settings (changed on the MjSpec before compiling, so nothing is edited in the text):
    * fusestatic = False: MuJoCo would otherwise fuse fixed links (links, tool0, payload) into
      their parents, and tool0 would no longer exist as a body;
    * inertiafromgeom = FALSE: by default ("auto") a link without <inertial> gets an inertia
      inferred from its collision geoms at density 1000; the payload link of a 0 kg payload has
      no <inertial> but a sphere collision, and would silently weigh 0.52 kg. With FALSE only the
      explicit URDF inertials are used (balanceinertia stays off, MuJoCo's default).
    Then contacts and all constraints (joint limits) are disabled, armature, damping, friction
    loss and stiffness are zeroed, and gravity is set to the Pinocchio model's.
    """
    mujoco = pytest.importorskip("mujoco")
    spec = mujoco.MjSpec.from_string(urdf_text)
    spec.compiler.fusestatic = False
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.compiler.balanceinertia = False
    m = spec.compile()
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT | mujoco.mjtDisableBit.mjDSBL_CONSTRAINT
    m.opt.gravity[:] = gravity
    m.dof_armature[:] = 0.0
    m.dof_damping[:] = 0.0
    m.dof_frictionloss[:] = 0.0
    m.jnt_stiffness[:] = 0.0
    return mujoco, m


def urdf_movable_joints(urdf_text: str) -> list[str]:
    """The URDF's revolute and prismatic joints in the order of the file (the chain's order), read
    with the standard library's XML parser."""
    root = ElementTree.fromstring(urdf_text)
    return [j.get("name") for j in root.iter("joint") if j.get("type") in ("revolute", "prismatic", "continuous")]


def mj_qadr(mujoco, m, urdf_text: str):
    """qpos/qvel addresses of the URDF's movable joints in chain order (so the order never
    depends on MuJoCo's)."""
    names = urdf_movable_joints(urdf_text)
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name) for name in names]
    assert ids and min(ids) >= 0, f"a joint of {names} is missing in MuJoCo's model"
    return np.array([m.jnt_qposadr[i] for i in ids]), np.array([m.jnt_dofadr[i] for i in ids]), ids
