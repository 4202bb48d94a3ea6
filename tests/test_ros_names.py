"""Links and joints are named after their module and place in the chain (``m3_PB21_joint``), so an
integrator can tell which module a joint is; every name is unique in its kind and a valid ROS name
(letters, digits and ``_``, not starting with a digit: what ``rclcpp`` accepts for parameters and
what ``tf2`` frame ids and ``ros2_control`` interfaces are built from)."""

from __future__ import annotations

import io
import itertools
import re
from pathlib import Path

import numpy as np
import pytest
import yourdfpy

from modular_robots.catalog import load_catalog
from modular_robots.composition import enumerate_compositions
from modular_robots.urdf import composition_urdf

from .helpers.paths import ROOT

ROS_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
CATALOGS = ["paper.yaml", "paper-4dof.yaml", "geometric.yaml", "improv-4dof.yaml", "improv.yaml"]


def _spread(catalog, count: int = 12):
    """``count`` compositions from the first 4,000 of the catalogue's order (never the whole space:
    ``geometric.yaml`` holds trillions)."""
    first = list(itertools.islice(enumerate_compositions(catalog), 4000))
    return first[:: max(1, len(first) // count)][:count]


@pytest.mark.parametrize("catalog_file", CATALOGS)
def test_links_and_joints_are_unique_ros_names_naming_their_module_and_place(catalog_file):
    catalog = load_catalog(ROOT / "scenarios" / "catalogs" / catalog_file)

    for composition in _spread(catalog):
        text = composition_urdf(composition, catalog, payload=1.0)
        urdf = yourdfpy.URDF.load(io.StringIO(text), load_meshes=False, build_scene_graph=False)
        links = [link.name for link in urdf.robot.links]
        joints = [joint.name for joint in urdf.robot.joints]
        for names in (links, joints):
            assert len(set(names)) == len(names), composition.name
            assert all(ROS_NAME.fullmatch(n) for n in names), [n for n in names if not ROS_NAME.fullmatch(n)]
        movable = [j for j in urdf.robot.joints if j.type in ("revolute", "prismatic")]
        with_joints = [(i, m) for i, m in enumerate(composition.modules) if _joint_count(catalog, m)]
        # one movable joint per joint of a module, in the chain's order, named after the module
        assert len(movable) == sum(_joint_count(catalog, m) for _, m in with_joints)
        owners = [re.fullmatch(r"m(\d+)_(.+?)(?:_[A-Za-z0-9_]+)?_joint", j.name) for j in movable]
        assert all(owners), [j.name for j in movable]
        places = [(int(o[1]), composition.modules[int(o[1])]) for o in owners if o]
        assert sorted(set(places)) == with_joints
        assert all(j.name.startswith(f"m{i}_{m}_") for j, (i, m) in zip(movable, places))


def _joint_count(catalog, module_id: str) -> int:
    if catalog.general:
        return len(catalog.general_module(module_id).joints)
    return catalog.module(module_id).dof


@pytest.mark.parametrize(
    ("catalog_file", "name"),
    [("paper.yaml", "B-J1-L2-J1-L1-E1"), ("improv.yaml", "base-PB21-L1-PB21-L2-PB23-L3")],
)
def test_every_collision_primitive_is_also_a_visual_in_the_colour_of_its_module_kind(catalog_file, name):
    """Read by urdfdom (Pinocchio's URDF parser), not by the code that wrote it: RViz shows what
    the collision model holds, in the colour the page's legend gives the module's kind."""
    import pinocchio as pin

    from modular_robots.appearance import KIND_COLOURS
    from modular_robots.composition import Composition

    catalog = load_catalog(ROOT / "scenarios" / "catalogs" / catalog_file)
    composition = Composition.from_name(name, catalog)
    text = composition_urdf(composition, catalog, payload=2.0)
    model = pin.buildModelFromXML(text)
    collision = pin.buildGeomFromUrdfString(model, text, pin.GeometryType.COLLISION)
    visual = pin.buildGeomFromUrdfString(model, text, pin.GeometryType.VISUAL)
    assert len(collision.geometryObjects) > 5
    assert all(Path(v.meshPath).is_file() for v in visual.geometryObjects if v.meshPath.endswith(".stl"))
    meshed = {model.frames[v.parentFrame].name for v in visual.geometryObjects if v.meshPath.endswith(".stl")}
    for obj in collision.geometryObjects:
        frame = model.frames[obj.parentFrame].name
        if re.sub(r"_c\d+$", "", frame) in meshed:  # a body with a visual mesh is drawn as it
            continue
        mine = [v for v in visual.geometryObjects if model.frames[v.parentFrame].name == frame]
        same = [
            v
            for v in mine
            if type(v.geometry) is type(obj.geometry)
            and np.allclose(v.placement.homogeneous, obj.placement.homogeneous)
            and np.isclose(v.geometry.radius, obj.geometry.radius)
        ]
        assert same, f"{frame}: no visual like its collision {type(obj.geometry).__name__}"
        module = composition.modules[int(frame[1:].split("_")[0])] if frame.startswith("m") else None
        kind = "payload" if frame == "payload" else "base" if module is None else _kind(catalog, module)
        wanted = [int(KIND_COLOURS[kind][k : k + 2], 16) / 255 for k in (1, 3, 5)]
        for v in mine:
            np.testing.assert_allclose(v.meshColor[:3], wanted, atol=1e-3, err_msg=frame)


def _kind(catalog, module_id: str) -> str:
    module = catalog.general_module(module_id) if catalog.general else catalog.module(module_id)
    return module.kind
