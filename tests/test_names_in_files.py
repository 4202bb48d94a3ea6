"""Names from a catalogue reach the URDF only as text: any catalogue name (they are free text:
``paper--v2``, or one written to close the comment it lands in and start another robot) gives a
well-formed URDF of the composition asked for, which yourdfpy and Pinocchio read as that robot."""

from __future__ import annotations

import dataclasses
import io
import xml.etree.ElementTree as ET

import pytest
import yourdfpy

from modular_robots.catalog import load_catalog
from modular_robots.composition import Composition, enumerate_compositions
from modular_robots.robot import robot_from_urdf
from modular_robots.urdf import composition_urdf
from modular_robots.xml_text import xml_attribute, xml_comment

from .helpers.paths import ROOT

HOSTILE_NAMES = [
    "paper--v2",
    "tiny -- v2",
    "ends with a dash-",
    'x --><robot name="injected"><link name="only_link"/></robot><!-- y',
    'quotes " and <tags> & ampersands',
    "control \x01 characters \x7f\x0b",
]


@pytest.mark.parametrize("catalog_file", ["paper.yaml", "improv.yaml"])
@pytest.mark.parametrize("name", HOSTILE_NAMES)
def test_a_catalogue_name_never_changes_the_robot_its_urdf_describes(catalog_file, name):
    catalog = load_catalog(ROOT / "scenarios" / "catalogs" / catalog_file)
    composition = (
        Composition.from_name("B-J1-L2-J1-L1-E1", catalog)
        if not catalog.general
        else next(iter(enumerate_compositions(catalog)))
    )
    plain = composition_urdf(composition, catalog, 1.0)
    text = composition_urdf(composition, dataclasses.replace(catalog, name=name), 1.0)
    root = ET.fromstring(text.encode("utf-8"))  # well-formed, or this raises
    assert root.tag == "robot" and root.get("name") == composition.name
    assert [e.tag for e in root].count("link") == [e.tag for e in ET.fromstring(plain.encode())].count("link")
    assert ET.tostring(root) == ET.tostring(ET.fromstring(plain.encode()))  # comments aside, the same robot
    robot = robot_from_urdf(text)
    assert robot.nv == robot_from_urdf(plain).nv and robot.model.existFrame("tool0")
    assert yourdfpy.URDF.load(io.BytesIO(text.encode("utf-8")), load_meshes=False).robot.name == composition.name


@pytest.mark.parametrize(
    ("text", "comment"),
    [
        ("paper--v2", "paper- -v2"),
        ("a---b", "a- - -b"),
        ("x -->", "x - ->"),
        ("ends-", "ends- "),
        ("-", "- "),
        ("control \x01\x0b", "control ??"),
        ("a - b", "a - b"),
    ],
)
def test_comment_text_never_holds_a_double_dash_nor_ends_with_one(text, comment):
    assert xml_comment(text) == comment
    assert ET.fromstring(f"<r><!--{xml_comment(text)}--></r>").tag == "r"


@pytest.mark.parametrize("text", HOSTILE_NAMES + ["", "--"])
def test_an_attribute_reads_back_as_the_text_given(text):
    expected = text.replace("\x01", "?").replace("\x0b", "?")
    assert ET.fromstring(f'<r a="{xml_attribute(text)}"/>').get("a") == expected
