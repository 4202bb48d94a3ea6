"""URDF of an assembly of general modules (Timor's frames).

World = ``base_link``, Timor's world for a serial assembly: the base's input connector sits at
``Rx(pi)`` in it. Each body is a URDF link ``m<i>_<module>_<body>``; where a module's output
connector meets the next module's input, the next inlet body sits at
``outlet_pose · Rx(pi) · inlet_pose^-1`` in the outlet body (both connectors point away from
their bodies). A joint sits at ``parent_pose`` in its parent body (URDF link
``m<i>_<module>_<joint>``, moving about/along its z axis) and its child body at ``child_pose``
in the moved joint frame. Movable joints are named after their module and place (:func:`joint_name`), with the drive's
friction in ``<dynamics damping="viscous" friction="coulomb"/>`` (URDF has no armature field).
``tool0`` is the last module's free output connector (Timor's TCP); the payload sits there.
Each collision shape gets a frame ``<body link>_c<k>`` whose z axis is the capsule's axis, and the same
primitive as its ``<visual>`` in the colour of the module's kind.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np

from .appearance import material, visual_shapes
from .catalog import Catalog
from .composition import Composition
from .modules import GeneralModule, Pose
from .xml_text import xml_attribute, xml_comment

__all__ = [
    "assembly_urdf",
    "assembly_shapes",
    "assembly_reach",
    "matrix",
    "rpy_from_matrix",
    "body_link",
    "joint_name",
]

RX_PI = np.diag([1.0, -1.0, -1.0, 1.0])


def matrix(pose: Pose) -> np.ndarray:
    """4 x 4 homogeneous matrix of a pose (URDF ``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    r, p, y = pose.rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    out = np.eye(4)
    out[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    out[:3, 3] = pose.xyz
    return out


def rpy_from_matrix(rotation: np.ndarray) -> tuple[float, float, float]:
    """URDF roll, pitch, yaw of a rotation matrix (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    r = np.asarray(rotation, dtype=float)
    cos_pitch = math.hypot(r[0, 0], r[1, 0])
    pitch = math.atan2(-r[2, 0], cos_pitch)
    if cos_pitch > 1e-9:
        return math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])
    return 0.0, pitch, math.atan2(-r[0, 1], r[1, 1])


def _origin(transform: np.ndarray) -> str:
    xyz = " ".join(repr(float(x)) for x in transform[:3, 3])
    rpy = " ".join(repr(float(x)) for x in rpy_from_matrix(transform[:3, :3]))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def body_link(index: int, module: GeneralModule, body_id: str) -> str:
    """URDF link name of body ``body_id`` of the module at ``index`` in the chain."""
    return f"m{index}_{module.id}_{body_id}"


def joint_name(index: int, module: GeneralModule, joint_id: str) -> str:
    """URDF name of joint ``joint_id`` of the module at ``index`` in the chain: ``m3_PB21_joint``
    for a module of one joint, ``m3_<module>_<joint>_joint`` for one of several."""
    if len(module.joints) == 1:
        return f"m{index}_{module.id}_joint"
    return f"m{index}_{module.id}_{joint_id}_joint"


def _fixed(name: str, parent: str, child: str, transform: np.ndarray) -> str:
    return (
        f'  <joint name="{name}" type="fixed">\n    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
        f"    {_origin(transform)}\n  </joint>\n"
    )


def _link(name: str, body=None, collision: bool = True, kind: str = "link") -> str:
    inner = _meshes(body, kind) if collision and body is not None else ""
    if body is not None and body.mass > 0:
        ixx, iyy, izz, ixy, ixz, iyz = (repr(float(v)) for v in body.inertia)
        com = " ".join(repr(float(c)) for c in body.com)
        inner += (
            f'    <inertial>\n      <origin xyz="{com}" rpy="0 0 0"/>\n      <mass value="{body.mass!r}"/>\n'
            f'      <inertia ixx="{ixx}" iyy="{iyy}" izz="{izz}" ixy="{ixy}" ixz="{ixz}" iyz="{iyz}"/>\n'
            "    </inertial>\n"
        )
    return f'  <link name="{name}">\n{inner}  </link>\n'


def _meshes(body, kind: str) -> str:
    """The body's visual meshes, each a ``file://`` URI of the catalogue's STL (a writer that puts
    the URDF in a folder copies them beside it: :func:`~modular_robots.urdf.localise_meshes`)."""
    out = ""
    for visual in body.visual:
        scale = " ".join(repr(float(c)) for c in visual.scale)
        uri = xml_attribute(Path(visual.file).as_uri())
        out += (
            f"    <visual>\n      {_origin(matrix(visual.pose))}\n"
            f'      <geometry><mesh filename="{uri}" scale="{scale}"/></geometry>\n'
            f"      {material(kind)}\n    </visual>\n"
        )
    return out


def _shapes(link: str, body, collision: bool, kind: str) -> str:
    out = ""
    for k, shape in enumerate(body.collision):
        frame = f"{link}_c{k}"
        geometry = (
            f'<sphere radius="{shape.radius!r}"/>'
            if shape.length == 0
            else f'<cylinder radius="{shape.radius!r}" length="{shape.length!r}"/>'
        )
        inner = ""
        if collision:
            inner = f"    <collision>\n      <geometry>{geometry}</geometry>\n    </collision>\n"
            if not body.visual:  # a body with meshes is drawn as its meshes
                inner += visual_shapes(shape.radius, shape.length, kind)
        out += _fixed(f"{frame}_mount", link, frame, matrix(shape.pose))
        out += f'  <link name="{frame}">\n{inner}  </link>\n'
    return out


def assembly_urdf(composition: Composition, catalog: Catalog, payload_part: str, collision: bool = True) -> str:
    """The URDF body of ``composition`` of a general catalogue up to ``tool0``, followed by
    ``payload_part`` (the payload's URDF, mounted on ``tool0``)."""
    parts = ['  <link name="base_link"/>\n']
    previous: GeneralModule | None = None
    for index, module_id in enumerate(composition.modules):
        module = catalog.general_module(module_id)
        parts.append(_module_urdf(index, module, previous, collision))
        previous = module
    parent, at = _entry(len(composition.modules), previous)
    parts.append(_fixed("tool0_mount", parent, "tool0", at @ RX_PI))
    parts.append('  <link name="tool0"/>\n')
    parts.append(payload_part)
    return "".join(parts)


def _entry(index: int, previous: GeneralModule | None) -> tuple[str, np.ndarray]:
    """Where the module at ``index`` is mounted: the link of the ``previous`` module's outlet body
    (``base_link`` for the first) and that outlet composed with ``Rx(pi)``, in it."""
    if previous is None:
        return "base_link", RX_PI
    return body_link(index - 1, previous, previous.outlet.body), matrix(previous.outlet.pose) @ RX_PI


@lru_cache(maxsize=4096)  # step B builds thousands of chains from a few modules in a few places
def _module_urdf(index: int, module: GeneralModule, previous: GeneralModule | None, collision: bool) -> str:
    """The URDF of the module at ``index`` in a chain, after ``previous`` (None: the first)."""
    parent, at = _entry(index, previous)
    parts = [f"  <!-- {xml_comment(f'module {index}: {module.id} ({module.kind})')} -->\n"]
    for body, joint in module.chain():
        link = body_link(index, module, body.id)
        if joint is None:
            mount = at @ np.linalg.inv(matrix(module.inlet.pose))
            parts.append(_fixed(f"{link}_mount", parent, link, mount))
        else:
            frame = f"m{index}_{module.id}_{joint.id}"
            lim, drive = joint, joint.drive
            parts.append(
                f'  <joint name="{joint_name(index, module, joint.id)}" type="{joint.type}">\n'
                f'    <parent link="{parent}"/>\n'
                f'    <child link="{frame}"/>\n    {_origin(matrix(joint.parent_pose))}\n'
                '    <axis xyz="0 0 1"/>\n'
                f'    <limit lower="{lim.lower!r}" upper="{lim.upper!r}" velocity="{lim.velocity!r}" '
                f'effort="{lim.effort!r}"/>\n'
                f'    <dynamics damping="{drive.viscous!r}" friction="{drive.coulomb!r}"/>\n  </joint>\n'
            )
            parts.append(_link(frame))
            parts.append(_fixed(f"{frame}_child", frame, link, matrix(joint.child_pose)))
        parts.append(_link(link, body, collision, module.kind))
        parts.append(_shapes(link, body, collision, module.kind))
        parent = link
    return "".join(parts)


def assembly_shapes(composition: Composition, catalog: Catalog) -> list[tuple[str, float, float, int]]:
    """Each collision shape of the assembly as ``(frame, radius, length, module index)``; the
    capsule's axis runs along the frame's z axis from ``-length/2`` to ``+length/2``."""
    out = []
    for index, module_id in enumerate(composition.modules):
        module = catalog.general_module(module_id)
        for body in module.bodies:
            link = body_link(index, module, body.id)
            out += [(f"{link}_c{k}", s.radius, s.length, index) for k, s in enumerate(body.collision)]
    return out


def assembly_reach(composition: Composition, catalog: Catalog) -> float:
    """Upper bound on the tool's distance from the world origin [m]: along the chain, the
    distances between consecutive points fixed in one body (inlet, joint origins, outlet) plus
    each prismatic joint's largest stroke; the base's inlet sits at the origin."""
    total = 0.0
    for module_id in composition.modules:
        for term in _reach_terms(catalog.general_module(module_id)):
            total += term
    return total


@lru_cache(maxsize=1024)
def _reach_terms(module: GeneralModule) -> tuple[float, ...]:
    """A module's terms of :func:`assembly_reach`, in chain order (added one by one there)."""
    terms = []
    entry = matrix(module.inlet.pose)[:3, 3]  # the inlet, in the inlet body
    for _, joint in module.chain()[1:]:
        assert joint is not None  # only the chain's first body has no joint
        terms.append(float(np.linalg.norm(matrix(joint.parent_pose)[:3, 3] - entry)))
        if joint.type == "prismatic":
            terms.append(max(abs(joint.lower), abs(joint.upper)))
        entry = np.linalg.inv(matrix(joint.child_pose))[:3, 3]  # the joint origin, in the child body
    terms.append(float(np.linalg.norm(matrix(module.outlet.pose)[:3, 3] - entry)))
    return tuple(terms)
