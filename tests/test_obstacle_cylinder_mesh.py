"""Cylinder and triangle-mesh obstacles: distances against independent computations (points
sampled densely along the links: the cylinder's signed distance per point; for a mesh, the
nearest of all its triangles by brute force, signed by ray parity per closed body), gradients
against central differences inside and outside, STL files read alike in ASCII and binary, every
bad mesh input named with its file, line and key, the scenario and JSON forms, and a time-optimal
motion of the planar arm round each shape, checked with the independent distance."""

from __future__ import annotations

import itertools
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from modular_robots.collision import CollisionModel
from modular_robots.exceptions import InputWarning, ScenarioError
from modular_robots.obstacles import (
    BoxObstacle,
    CylinderObstacle,
    MeshObstacle,
    obstacle_from_json,
    obstacle_to_json,
)
from modular_robots.obstacles._geometry import rpy_matrix
from modular_robots.obstacles._stl import StlError, read_stl
from modular_robots.ocp.candidate import Candidate
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.scenario import OptimizerSettings, load_scenario

from .helpers.models import ARM_GOAL, ARM_START, R_LINK, arm_points, planar_arm
from .helpers.paths import PAPER_5KG, ROOT

CYLINDERS = [
    CylinderObstacle((1.3, 0.9, 0.0), 0.15, 0.6),  # a column standing in the arm's plane
    CylinderObstacle((0.6, -1.1, 0.2), 0.2, 1.0, (0.3, 1.2, -0.4)),  # a tilted drum
    CylinderObstacle((-0.9, 0.5, -0.05), 0.3, 0.8, (np.pi / 2, 0.0, 0.3)),  # lying across the plane
]
#: CoBRA's CNC machine (ASCII STL, millimetres, ten closed bodies), placed as in its PTP_3 task but
#: 3 cm lower: the arm's plane then runs 3 cm above the front apron (the links' capsules overlap
#: it with their axes outside), through the table's walls, and clear of the rest.
MACHINE_FILE = ROOT / "scenarios" / "meshes" / "QUASER_MV205_v3_compressed.stl"


def _machine() -> MeshObstacle:
    return MeshObstacle(str(MACHINE_FILE), 0.001, (-4.5, 0.25, -1.03))


def _l_prism(width: float = 0.3, depth: float = 0.4, arm: float = 0.12, height: float = 0.4) -> np.ndarray:
    """The triangles ``(20, 3, 3)`` [m] of an L-shaped prism (not convex), its normals out: the L
    of an ``width`` by ``depth`` rectangle less its corner beyond the arms of ``arm``."""
    outline = np.array([(0, 0), (width, 0), (width, arm), (arm, arm), (arm, depth), (0, depth)], dtype=float)
    bottom = np.column_stack([outline, np.full(6, -0.5 * height)])
    top = np.column_stack([outline, np.full(6, 0.5 * height)])
    fan = [(3, 4, 5), (3, 5, 0), (3, 0, 1), (3, 1, 2)]  # from the inner corner, counter-clockwise
    triangles = [top[list(f)] for f in fan] + [bottom[list(f[::-1])] for f in fan]
    for i in range(6):
        j = (i + 1) % 6
        triangles += [np.array([bottom[i], bottom[j], top[j]]), np.array([bottom[i], top[j], top[i]])]
    return np.array(triangles)


def _box_triangles(size: np.ndarray) -> np.ndarray:
    """The twelve triangles of a box of side lengths ``size`` centred at the origin, normals out."""
    corners = np.array(list(itertools.product((-0.5, 0.5), repeat=3))) * size
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array([corners[[a, b, c]] for a, b, c, d in faces] + [corners[[a, c, d]] for a, b, c, d in faces])


def _write_ascii(path, triangles: np.ndarray) -> None:
    lines = ["solid test"]
    for t in triangles:
        lines += ["  facet normal 0 0 0", "    outer loop"]
        lines += [f"      vertex {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in t]
        lines += ["    endloop", "  endfacet"]
    path.write_text("\n".join([*lines, "endsolid test", ""]))


def _write_binary(path, triangles: np.ndarray) -> None:
    body = b"".join(struct.pack("<12fH", 0, 0, 0, *t.ravel(), 0) for t in triangles)
    path.write_bytes(b"solid but binary".ljust(80, b" ") + struct.pack("<I", len(triangles)) + body)


def _placed(mesh: MeshObstacle) -> np.ndarray:
    """The mesh's triangles in the base frame: the corners as the package reads them (which
    ``test_ascii_and_binary_stl_read_alike`` checks), scaled, turned and moved here."""
    corners, _ = read_stl(Path(mesh.file))
    return mesh.scale * corners @ rpy_matrix(mesh.rpy).T + np.asarray(mesh.position)


# -- independent distances -------------------------------------------------------------------------
def _cylinder_clearance(q, cylinder: CylinderObstacle, samples: int = 20001) -> float:
    """Brute force: the smallest signed distance of points along the links to the cylinder
    (outside, to the nearest point of the (radius, height) rectangle; inside, minus the depth
    below the nearer of the side and the ends)."""
    rotation, center, h = rpy_matrix(cylinder.rpy), np.asarray(cylinder.center), 0.5 * cylinder.length
    s = np.linspace(0.0, 1.0, samples)[:, None]
    best = np.inf
    for a, b in itertools.pairwise(arm_points(q)):
        local = (a + s * (b - a) - center) @ rotation
        rho, z = np.hypot(local[:, 0], local[:, 1]), np.abs(local[:, 2])
        outside = np.hypot(np.maximum(rho - cylinder.radius, 0.0), np.maximum(z - h, 0.0))
        depth = np.minimum(cylinder.radius - rho, h - z)
        best = min(best, float(np.where(outside > 0.0, outside, -depth).min()))
    return best - R_LINK


def _point_triangle_distances(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The distance from each point to the nearest triangle, by every pair: the foot on the
    triangle's plane where it falls inside all three edges, else the nearest point of an edge."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    out = np.empty(len(points))
    for rows in np.array_split(np.arange(len(points)), max(1, len(points) // 64)):
        x = points[rows, None]  # (N, 1, 3)
        height = np.einsum("ntc,tc->nt", x - a, n)
        foot = x - height[..., None] * n
        within = np.ones(height.shape, dtype=bool)
        best = np.full(height.shape, np.inf)
        for p, q in ((a, b), (b, c), (c, a)):
            within &= np.einsum("ntc,tc->nt", np.cross(q - p, foot - p), n) >= 0.0
            t = np.clip(np.einsum("ntc,tc->nt", x - p, q - p) / np.einsum("tc,tc->t", q - p, q - p), 0.0, 1.0)
            best = np.minimum(best, np.linalg.norm(x - p - t[..., None] * (q - p), axis=-1))
        out[rows] = np.where(within, np.abs(height), best).min(axis=1)
    return out


def _bodies(triangles: np.ndarray) -> list[np.ndarray]:
    """The triangles of each connected body (triangles that share corners)."""
    _, index = np.unique(triangles.reshape(-1, 3), axis=0, return_inverse=True)
    index = index.reshape(-1, 3)
    parent = list(range(int(index.max()) + 1))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j, k in index:
        for other in (j, k):
            parent[root(int(other))] = root(int(i))
    labels = np.array([root(int(i)) for i in index[:, 0]])
    return [triangles[labels == label] for label in np.unique(labels)]


def _inside(points: np.ndarray, bodies: list[np.ndarray]) -> np.ndarray:
    """Inside one of the closed bodies: an odd number of crossings of a ray from the point."""
    ray = np.array([1.0, 0.0123, 0.0311])
    inside = np.zeros(len(points), dtype=bool)
    for body in bodies:
        a, e1, e2 = body[:, 0], body[:, 1] - body[:, 0], body[:, 2] - body[:, 0]
        h = np.cross(ray, e2)
        det = np.einsum("tc,tc->t", e1, h)
        s = points[:, None] - a
        u = np.einsum("ntc,tc->nt", s, h) / det
        qv = np.cross(s, e1)
        v = np.einsum("ntc,c->nt", qv, ray) / det
        t = np.einsum("ntc,tc->nt", qv, e2) / det
        inside |= ((u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)).sum(axis=1) % 2 == 1
    return inside


def _mesh_clearance(q, triangles: np.ndarray, bodies: list[np.ndarray], coarse: int = 201, fine: int = 401) -> float:
    """Brute force: the smallest signed distance of points along the links to the mesh, from
    ``coarse`` points a link and ``fine`` points round its two best local minima."""

    def signed(points: np.ndarray) -> np.ndarray:
        d = _point_triangle_distances(points, triangles)
        return np.where(_inside(points, bodies), -d, d)

    best = np.inf
    step = 1.0 / (coarse - 1)
    for a, b in itertools.pairwise(arm_points(q)):
        s = np.linspace(0.0, 1.0, coarse)
        f = signed(a + s[:, None] * (b - a))
        padded = np.concatenate([[np.inf], f, [np.inf]])
        minima = np.flatnonzero((f <= padded[:-2]) & (f <= padded[2:]))
        for j in minima[np.argsort(f[minima])[:2]]:
            window = np.linspace(max(s[j] - step, 0.0), min(s[j] + step, 1.0), fine)
            best = min(best, float(signed(a + window[:, None] * (b - a)).min()))
        best = min(best, float(f.min()))
    return best - R_LINK


def _configurations(obstacle, count: int = 8) -> np.ndarray:
    """Random configurations and, toward the obstacle, a fan that reaches into it."""
    towards = np.asarray(obstacle.bounding_sphere()[0])
    heading = float(np.arctan2(towards[1], towards[0]))
    fan = [(heading + a, b) for a in (-0.5, -0.2, 0.1, 0.4) for b in (-0.8, -0.3, 0.2, 0.7)]
    return np.vstack([np.random.default_rng(11).uniform(-2.8, 2.8, (count, 2)), fan])


# -- cylinder ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("cylinder", CYLINDERS, ids=["column", "tilted-drum", "lying"])
def test_cylinder_distance_matches_points_sampled_along_the_links(cylinder):
    model = CollisionModel(planar_arm(), [cylinder])
    configurations = _configurations(cylinder)
    distances = model.closest_many(configurations)[0][:, 0]
    expected = np.array([_cylinder_clearance(q, cylinder) for q in configurations])
    assert expected.min() < 0.0 < expected.max()  # both sides of contact
    assert np.all(distances <= expected + 1e-12)  # sampling can only overestimate, by about a step
    np.testing.assert_allclose(distances, expected, atol=6e-5)
    exact = [model.distances(q).minimum for q in configurations]  # the pairwise path agrees
    np.testing.assert_allclose(exact, distances, atol=1e-12)


def test_cylinder_bounds_are_its_distances_and_its_page_is_a_cylinder():
    cylinder = CYLINDERS[1]
    model = CollisionModel(planar_arm(), [cylinder])
    configurations = _configurations(cylinder)
    rot, mid, _ = model._placements(configurations, jacobians=False)
    lower, upper = model._bounds(rot, mid)
    np.testing.assert_allclose(lower.min(axis=1)[:, 0], model.closest_many(configurations)[0][:, 0], atol=1e-12)
    np.testing.assert_array_equal(lower, upper)
    (part,) = cylinder.page(0.02)
    assert part["type"] == "cylinder" and part["radius"] == pytest.approx(0.22) and part["length"] == 1.04
    np.testing.assert_allclose(np.reshape(part["origin"], (4, 4)).T[:3, 2], rpy_matrix(cylinder.rpy)[:, 2])


# -- mesh -------------------------------------------------------------------------------------------
def test_ascii_and_binary_stl_read_alike(tmp_path):
    ascii_corners, ascii_digest = read_stl(MACHINE_FILE)
    assert ascii_corners.shape == (748, 3, 3)
    _write_binary(tmp_path / "machine.stl", ascii_corners)
    binary_corners, binary_digest = read_stl(tmp_path / "machine.stl")
    np.testing.assert_allclose(binary_corners, ascii_corners, rtol=1e-7)  # binary holds float32
    assert binary_digest != ascii_digest
    prism = _l_prism().astype(np.float32).astype(float)  # exact in both forms
    _write_ascii(tmp_path / "a.stl", prism)
    _write_binary(tmp_path / "b.stl", prism)
    np.testing.assert_array_equal(read_stl(tmp_path / "a.stl")[0], prism)
    np.testing.assert_array_equal(read_stl(tmp_path / "b.stl")[0], prism)
    a, b = (
        MeshObstacle(tmp_path / "a.stl", position=(1.8, 0.0, 0.0)),
        MeshObstacle(tmp_path / "b.stl", 1.0, (1.8, 0, 0)),
    )
    qs = _configurations(a)
    np.testing.assert_array_equal(
        CollisionModel(planar_arm(), [a]).closest_many(qs)[0], CollisionModel(planar_arm(), [b]).closest_many(qs)[0]
    )


def test_mesh_distance_matches_brute_force_over_every_triangle():
    machine = _machine()
    triangles = _placed(machine)
    bodies = _bodies(triangles)
    model = CollisionModel(planar_arm(), [machine])
    # some of the random configurations and of the fan (the brute force takes 0.5 s for each),
    # and one whose upper link crosses a wall of the table, its deepest point between two faces
    configurations = np.vstack([_configurations(machine, count=4)[[0, 1, 2, 3, 4, 7, 9, 12, 14, 17]], [[1.31, -2.16]]])
    distances = model.closest_many(configurations)[0][:, 0]
    expected = np.array([_mesh_clearance(q, triangles, bodies) for q in configurations])
    assert expected.min() < -R_LINK < 0.0 < expected.max()  # apart, overlapping, and an axis inside
    assert np.all(distances <= expected + 1e-12)
    np.testing.assert_allclose(distances, expected, atol=3e-5)
    pairs = np.array([model.distances(q).distance for q in configurations])  # (K, P, 1)
    np.testing.assert_allclose(pairs.min(axis=1)[:, 0], distances, atol=1e-12)
    rot, mid, _ = model._placements(configurations, jacobians=False)
    lower, upper = model._bounds(rot, mid)
    assert np.all(lower <= pairs + 1e-12) and np.all(pairs <= upper + 1e-12)


def test_a_mesh_of_a_box_measures_as_the_box_and_a_non_convex_one_keeps_its_notch(tmp_path):
    box = BoxObstacle((1.4, 0.6, 0.0), (0.4, 0.3, 0.5), (0.2, 0.1, 0.7))
    _write_ascii(tmp_path / "box.stl", _box_triangles(np.asarray(box.size)))
    mesh = MeshObstacle(tmp_path / "box.stl", 1.0, box.center, box.rpy)
    qs = _configurations(box)
    d_box, g_box = CollisionModel(planar_arm(), [box]).closest_many(qs, derivatives=True)
    d_mesh, g_mesh = CollisionModel(planar_arm(), [mesh]).closest_many(qs, derivatives=True)
    assert d_box.min() < -R_LINK < 0.0 < d_box.max()
    np.testing.assert_allclose(d_mesh, d_box, atol=1e-9)
    np.testing.assert_allclose(g_mesh, g_box, atol=1e-6)
    _write_ascii(tmp_path / "prism.stl", _l_prism())
    prism = MeshObstacle(tmp_path / "prism.stl", 2.0, (1.0, 0.0, 0.0))  # 0.6 by 0.8 m, the notch at x, y > 1.24, 0.24
    notch = np.array([1.45, 0.55, 0.0])
    assert not prism.contains(notch) and prism.contains((1.1, 0.7, 0.0)) and not prism.contains((0.9, 0.0, 0.0))
    distance, _, on_prism, gradient = prism.signed_distance(notch, np.array([1.0, 0.0, 0.0]), 0.0, 0.05)
    assert distance == pytest.approx(0.21 - 0.05)  # to the nearer arm's inner face, at x = 1.24
    np.testing.assert_allclose(on_prism, [1.24, 0.55, 0.0], atol=1e-12)
    np.testing.assert_allclose(gradient, [1.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("which", ["machine", "prism"])
def test_mesh_gradient_matches_central_differences_inside_and_outside(which, tmp_path):
    if which == "machine":
        mesh = _machine()
    else:
        _write_binary(tmp_path / "prism.stl", _l_prism())
        mesh = MeshObstacle(tmp_path / "prism.stl", 1.0, (1.55, -0.2, 0.0), (0.0, 0.0, 0.3))
    model = CollisionModel(planar_arm(), [mesh])
    h, checked, inside = 1e-6, 0, 0
    for q in _configurations(mesh):
        d, grad = model.closest(q, derivatives=True)
        fd = [(model.closest(q + e)[0][0] - model.closest(q - e)[0][0]) / (2 * h) for e in h * np.eye(2)]
        if abs(fd[0] - (model.closest(q + h * np.eye(2)[0])[0][0] - d[0]) / h) > 1e-4:  # a kink
            continue
        np.testing.assert_allclose(grad[0], fd, atol=1e-5)
        checked += 1
        inside += d[0] < -R_LINK
    assert checked >= 12 and inside >= 2


# -- scenario, JSON, page and bad input -------------------------------------------------------------
def _scenario(tmp_path, obstacles: str):
    """paper-5kg with ``obstacles`` instead of its spheres, in ``tmp_path``; the line of the first."""
    text = PAPER_5KG.read_text().replace("catalog: catalogs/", f"catalog: {PAPER_5KG.parent}/catalogs/")
    body = "\n".join(line for line in text.splitlines() if not line.strip().startswith("- sphere"))
    path = tmp_path / "s.yaml"
    path.write_text(body.replace("  obstacles:", "  obstacles:\n" + obstacles, 1))
    line = 1 + path.read_text().splitlines().index("  obstacles:") + 1
    return path, line


def test_the_scenario_reads_both_shapes_with_the_mesh_file_relative_to_it(tmp_path):
    (tmp_path / "meshes").mkdir()
    _write_binary(tmp_path / "meshes" / "prism.stl", _l_prism())
    path, _ = _scenario(
        tmp_path,
        "    - cylinder: {center: [1.5, -1.3, 1.1], radius: 0.3, length: 0.5, rpy: [0, 0.5, 0]}\n"
        "    - mesh: {file: meshes/prism.stl, scale: 2, position: [-1.2, 2.1, 0.5], rpy: [0, 0, 0.5]}\n"
        "    - mesh: {file: meshes/../meshes/prism.stl, position: [0.5, -2.0, 0]}\n",
    )
    task = load_scenario(path).task
    cylinder, mesh, plain = task.obstacles
    assert cylinder == CylinderObstacle((1.5, -1.3, 1.1), 0.3, 0.5, (0.0, 0.5, 0.0))
    assert mesh == MeshObstacle(tmp_path / "meshes" / "prism.stl", 2.0, (-1.2, 2.1, 0.5), (0.0, 0.0, 0.5))
    assert plain.file == str((tmp_path / "meshes" / "prism.stl").resolve()) and plain.scale == 1.0
    assert hash(mesh) != hash(plain) and len({mesh, plain, cylinder}) == 3
    for o in task.obstacles:
        assert obstacle_from_json(obstacle_to_json(o)) == o
    (part,) = mesh.page()
    assert part["type"] == "mesh" and len(part["faces"]) == 20 and len(part["vertices"]) == 12
    np.testing.assert_allclose(np.max(part["vertices"], axis=0), [0.6, 0.8, 0.4])  # the scaled L, its frame
    np.testing.assert_allclose(
        np.reshape(part["origin"], (4, 4)).T[:3], np.column_stack([rpy_matrix(mesh.rpy), mesh.position])
    )
    grown = np.array(mesh.page(0.02)[0]["vertices"])
    assert np.all(np.abs(grown).max(axis=0) > [0.6, 0.8, 0.4])
    _write_binary(tmp_path / "meshes" / "prism.stl", _l_prism(width=0.5))
    with pytest.raises(ValueError, match=r"^mesh\.file: .*prism\.stl has changed since it was read"):
        obstacle_from_json(obstacle_to_json(mesh))


def test_bad_mesh_input_is_refused_with_its_file_line_and_key(tmp_path):
    (tmp_path / "note.stl").write_text("not a mesh\n")
    (tmp_path / "empty.stl").write_text("solid empty\nendsolid empty\n")
    (tmp_path / "empty-binary.stl").write_bytes(b"\0" * 80 + struct.pack("<I", 0))
    _write_ascii(tmp_path / "nan.stl", _l_prism())
    (tmp_path / "nan.stl").write_text((tmp_path / "nan.stl").read_text().replace("vertex 0.0 ", "vertex nan ", 1))
    _write_ascii(tmp_path / "prism.stl", _l_prism())
    _write_ascii(tmp_path / "flat.stl", np.zeros((2, 3, 3)))
    bad = {
        "{file: missing.stl}": ("file", r"no mesh file at .*missing\.stl"),
        "{file: note.stl}": ("file", r".*/note\.stl is not an STL file"),
        "{file: empty.stl}": ("file", r".*/empty\.stl holds no triangle"),
        "{file: empty-binary.stl}": ("file", r".*/empty-binary\.stl holds no triangle"),
        "{file: nan.stl}": ("file", r".*/nan\.stl: triangle \d+ has a corner that is not a finite number: .*nan"),
        "{file: flat.stl}": ("file", r".*/flat\.stl: every triangle has zero area"),
        "{file: prism.stl, scale: 0}": ("scale", r"expected a number > 0, got 0"),
        "{file: prism.stl, scale: -0.001}": ("scale", r"expected a number > 0, got -0\.001"),
        "{file: prism.stl, rpy: [0, .inf, 0]}": ("rpy", r"item 1: expected a finite number, got inf"),
        "{file: prism.stl, position: [0, .nan, 0]}": ("position", r"item 1: expected a finite number, got nan"),
        "{file: prism.stl, colour: red}": ("colour", r"unknown key \(expected one of: file, position, rpy, scale\)"),
        "{scale: 1}": ("file", r"missing required key"),
    }
    for fields, (key, message) in bad.items():
        path, line = _scenario(tmp_path, f"    - mesh: {fields}\n")
        with pytest.raises(ScenarioError, match=rf"^{path}:{line}: task\.obstacles\[0\]\.mesh\.{key}: {message}"):
            load_scenario(path)
    path, line = _scenario(tmp_path, "    - cylinder: {center: [1, 1, 1], radius: 0.2, length: 0}\n")
    with pytest.raises(
        ScenarioError, match=rf"^{path}:{line}: task\.obstacles\[0\]\.cylinder\.length: expected a number > 0"
    ):
        load_scenario(path)
    path, _ = _scenario(tmp_path, "    - cylinder: {center: [0, 0, 0.5], radius: 0.2, length: 1.2}\n")
    with pytest.raises(ScenarioError, match=r"cylinder: the obstacle contains the robot's base at the origin"):
        load_scenario(path)
    path, _ = _scenario(tmp_path, "    - mesh: {file: prism.stl, scale: 2, position: [-0.1, -0.1, -0.3]}\n")
    with pytest.raises(ScenarioError, match=r"mesh: the obstacle contains the robot's base at the origin"):
        load_scenario(path)


def test_the_cell_mesh_scenario_reads_its_mesh(tmp_path):
    """Read without a warning; its mesh, in millimetres, without its ``scale: 0.001`` would be
    kilometres across, out of every robot's reach, and is warned about (it was taken silently)."""
    path = ROOT / "scenarios" / "cell-mesh.yaml"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scenario = load_scenario(path)
    (machine,) = scenario.task.obstacles
    assert isinstance(machine, MeshObstacle) and machine.file == str(MACHINE_FILE.resolve())
    assert machine.describe().startswith("QUASER_MV205_v3_compressed.stl (748 triangles), scale 0.001")
    text = path.read_text()
    assert text.count(", scale: 0.001") == 1 and "file: meshes/" in text
    unscaled = tmp_path / "cell.yaml"
    unscaled.write_text(
        text.replace(", scale: 0.001", "")
        .replace("file: meshes/", f"file: {MACHINE_FILE.parent}/")
        .replace("catalog: catalogs/", f"catalog: {ROOT / 'scenarios' / 'catalogs'}/")
    )
    with pytest.warns(
        InputWarning,
        match=r"mesh.file: the mesh is 6002 m across at scale 1: millimetres\? "
        r"\(scale: 0.001 makes it 6.002 m\)$",
    ):
        load_scenario(unscaled)


# -- a motion round each shape ----------------------------------------------------------------------
@pytest.mark.parametrize("shape", ["cylinder", "mesh"])
def test_the_time_optimal_motion_goes_round_each_shape(shape, tmp_path):
    """The stretched arm sweeps through x = 2 on its straight line: a cylinder standing there, or
    the L-prism turned into the way, blocks it. The verified plan keeps clear at every 10 ms by
    the independent distance."""
    if shape == "cylinder":
        obstacle = CylinderObstacle((1.75, 0.0, 0.0), 0.12, 0.6)
        independent = lambda q: _cylinder_clearance(q, obstacle, samples=4001)  # noqa: E731
    else:
        _write_binary(tmp_path / "prism.stl", _l_prism(0.3, 0.3, 0.1))
        obstacle = MeshObstacle(tmp_path / "prism.stl", 1.0, (1.65, -0.15, 0.0), (0.0, 0.0, 0.2))
        triangles = _placed(obstacle)
        bodies = _bodies(triangles)
        independent = lambda q: _mesh_clearance(q, triangles, bodies, coarse=101, fine=101)  # noqa: E731
    line = [np.asarray(ARM_START) + s * (np.asarray(ARM_GOAL) - ARM_START) for s in np.linspace(0, 1, 101)]
    assert min(independent(q) for q in line[40:61:4]) < -0.05
    problem = ShootingProblem(
        planar_arm(), ARM_START, ARM_GOAL, [obstacle], "time", OptimizerSettings(nodes=8, substeps=4)
    )
    result = Candidate(problem).solve()
    assert result.status == "optimal", result.reason
    assert result.verification.passed and result.verification.min_clearance >= 0.0
    qs = result.trajectory.at(np.arange(0.0, result.tf, 1e-2))[0]
    assert min(independent(q) for q in qs) >= -1e-6


def test_an_ascii_stl_cut_short_at_a_facet_is_refused(tmp_path):
    """An interrupted copy of the machine's ASCII STL, cut after a whole facet, was read as 481 of
    its 748 triangles without a word: collisions against part of the machine."""
    data = MACHINE_FILE.read_bytes()
    assert read_stl(MACHINE_FILE)[0].shape == (748, 3, 3)
    cut = tmp_path / "cut.stl"
    cut.write_bytes(data[: data.index(b"endfacet", len(data) * 2 // 3) + len(b"endfacet")] + b"\r\n")
    with pytest.raises(StlError, match=r"cut\.stl: an ASCII STL cut short \(it does not end with 'endsolid'\)"):
        read_stl(cut)
