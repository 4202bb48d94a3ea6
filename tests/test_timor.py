"""Timor module databases: import, enumeration by connector compatibility, collision cover."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from modular_robots.catalog import load_catalog
from modular_robots.composition import Composition, count_compositions, enumerate_compositions
from modular_robots.exceptions import CatalogError, CompositionError
from modular_robots.timor import import_timor, shape_points

ROOT = Path(__file__).resolve().parents[1]
CATALOGS = ROOT / "scenarios" / "catalogs"
IMPROV_JSON = CATALOGS / "timor" / "IMPROV" / "modules.json"
GEOMETRIC_JSON = CATALOGS / "timor" / "geometric_primitive_modules" / "modules.json"


def test_improv_count_matches_timor_science2019_defaults():
    """Timor's Science2019 defaults on the full IMPROV set: 4 effectors; 4 joint modules of 2
    joints; 1 + 7 + 49 + 343 = 400 link runs of 0 to 3 between joint modules."""
    counts = count_compositions(load_catalog(CATALOGS / "improv.yaml"))
    assert counts == {0: 4, 2: 4 * 4, 4: 4**2 * 400 * 4, 6: 4**3 * 400**2 * 4}
    assert counts == {0: 4, 2: 16, 4: 25600, 6: 40960000}
    assert sum(counts.values()) == 40_985_620


def test_science2019_space_lists_32768_distinct_assemblies():
    catalog = load_catalog(CATALOGS / "improv-science2019.yaml")
    names = [c.name for c in enumerate_compositions(catalog)]
    assert len(names) == len(set(names)) == 32768 == sum(count_compositions(catalog).values())
    assert all(Composition.from_name(n, catalog).dof == 6 for n in names[::997])
    # one real link between joint modules, extensions only beside it; only an extension before the end
    assert "base-PB21-L5-L2-L4-PB21-L1-PB23-L6-L3" in names
    with pytest.raises(CompositionError, match="link run"):
        Composition.from_name("base-PB21-L4-L5-PB21-L1-PB23-L3", catalog)


def test_listing_agrees_with_counting_on_a_small_space():
    catalog = load_catalog(CATALOGS / "improv.yaml")
    listed = list(enumerate_compositions(catalog, 4))
    assert len(listed) == len({c.name for c in listed}) == count_compositions(catalog, 4)[4] == 25600


def test_compatibility_refuses_mismatched_connectors():
    catalog = load_catalog(CATALOGS / "improv.yaml")
    # L7's output is an 'eef' connector: it ends a chain
    with pytest.raises(CompositionError, match="does not meet"):
        Composition.from_name("base-PB21-L7-PB21-L3", catalog)


def test_committed_catalogues_are_the_importer_output():
    for name, source in (("improv", IMPROV_JSON), ("geometric", GEOMETRIC_JSON)):
        result = import_timor(source, CATALOGS / "timor" / f"{name}.overrides.yaml")
        assert result.yaml() == (CATALOGS / f"{name}.yaml").read_text("utf-8")


def test_import_names_the_decisions_it_needs(tmp_path):
    with pytest.raises(CatalogError, match=r"module L5, body 7: inertia .* is not physical"):
        import_timor(IMPROV_JSON)
    with pytest.raises(CatalogError, match=r"module J1, joint Prismatic.limits.velocity: \[inf\] is not finite"):
        import_timor(GEOMETRIC_JSON)
    result = import_timor(IMPROV_JSON, CATALOGS / "timor" / "improv.overrides.yaml")
    assert [o.split(":")[0] for o in result.overrides] == ["module L5, body 7"]
    assert any("override: module L5, body 7" in n for n in result.data["notes"])


def _rpy_matrix(rpy):
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def test_collision_primitives_cover_timor_shapes():
    """Points sampled inside every Timor collision shape (sphere, cylinder, box, convex mesh
    piece) lie inside the union of the imported spheres and capsules of that body."""
    rng = np.random.default_rng(7)
    ratios = []
    for source, catalog_name in ((IMPROV_JSON, "improv"), (GEOMETRIC_JSON, "geometric")):
        db = json.loads(source.read_text("utf-8"))["modules"]
        catalog = load_catalog(CATALOGS / f"{catalog_name}.yaml")
        bodies = {b.id: b for m in catalog.modules for b in m.bodies}
        for module in db:
            for body in module["bodies"]:
                shapes = bodies[body["ID"]].collision
                for geometry in body.get("collision", []):
                    pose = np.asarray(geometry["pose"], dtype=float)
                    if geometry["type"] == "sphere":
                        r = geometry["parameters"]["r"]
                        u = rng.normal(size=(200, 3))
                        pieces = [u / np.linalg.norm(u, axis=1)[:, None] * r * rng.random((200, 1)) ** (1 / 3)]
                    else:
                        pieces = shape_points(geometry, source.parent)
                    for piece in pieces:
                        w = rng.dirichlet(np.ones(len(piece)) * 0.3, size=300)  # convex combinations
                        inside = np.vstack([w @ piece, piece]) @ pose[:3, :3].T + pose[:3, 3]
                        assert _covered(inside, shapes).all(), (body["ID"], geometry["type"])
                ratios.append(len(shapes))
    assert ratios


def _covered(points, shapes):
    ok = np.zeros(len(points), dtype=bool)
    for s in shapes:
        rot = _rpy_matrix(s.pose.rpy)
        local = (points - np.asarray(s.pose.xyz)) @ rot
        z = np.clip(local[:, 2], -s.length / 2, s.length / 2)
        dist = np.linalg.norm(local - np.column_stack([0 * z, 0 * z, z]), axis=1)
        ok |= dist <= s.radius * (1 + 1e-9) + 1e-12
    return ok
