"""MuJoCo as an independent engine: its own URDF importer and its own dynamics, for checks of the
package's models and plans that share no code with the URDF -> Pinocchio path."""

from __future__ import annotations

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


def mj_qadr(mujoco, m, n):
    """qpos/qvel addresses of joint_1..joint_n (so the order never depends on MuJoCo's)."""
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"joint_{i}") for i in range(1, n + 1)]
    assert min(ids) >= 0, "a joint_i is missing in MuJoCo's model"
    return np.array([m.jnt_qposadr[i] for i in ids]), np.array([m.jnt_dofadr[i] for i in ids]), ids
