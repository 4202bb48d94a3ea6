"""The mesh obstacle's fast paths against plain references on CoBRA's two machine meshes: the
grouped culling (a two-level hierarchy) against one group of every triangle (brute force), the
winding number counted by a ray's crossings against the generalised winding number (solid
angles of every triangle), and the capsule bounds the collision model culls pairs with against
the distances they bound."""

from __future__ import annotations

import numpy as np
import pytest

from modular_robots.obstacles import MeshObstacle
from modular_robots.obstacles._triangles import is_closed, winding_numbers
from modular_robots.obstacles.mesh import _RAY, _Geometry, _placed

from .helpers.paths import ROOT

MESHES = {
    "DMU": (ROOT / "scenarios" / "cobra" / "assets" / "DMU_125P_compress.stl", (-0.5, 1.95, 1.8)),
    "QUASER": (ROOT / "scenarios" / "cobra" / "assets" / "QUASER_MV205_v3_compressed.stl", (-4.5, 0.25, -1.03)),
}


def _triangles(name: str) -> np.ndarray:
    path, position = MESHES[name]
    g = _placed(MeshObstacle(str(path), 0.001, position))
    return np.stack([g.a, g.b, g.c], axis=1)


def _segments(g: _Geometry, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Segments up to 0.6 m long (some points) in and around the mesh's box."""
    rng = np.random.default_rng(seed)
    start = rng.uniform(g.box_center - 1.1 * g.box_half, g.box_center + 1.1 * g.box_half, (count, 3))
    direction = rng.normal(size=(count, 3)) * rng.uniform(0.0, 0.35, (count, 1))
    direction[: count // 8] = 0.0
    return start, direction


@pytest.mark.parametrize("name", sorted(MESHES))
def test_grouped_queries_equal_one_group_of_every_triangle(name):
    triangles = _triangles(name)
    grouped, plain = _Geometry(triangles), _Geometry(triangles, group_size=len(triangles))
    assert len(grouped.groups.members) > 40 and len(plain.groups.members) == 1
    start, direction = _segments(grouped, 60, seed=3)
    fast, slow = grouped.closest(start, direction), plain.closest(start, direction)
    gap = np.linalg.norm(slow[0] - slow[1], axis=1)
    np.testing.assert_allclose(np.linalg.norm(fast[0] - fast[1], axis=1), gap, atol=1e-12)
    apart = gap > 1e-9  # apart: the same closest points (crossing: any crossing)
    assert apart.sum() > 20
    np.testing.assert_allclose(np.stack(fast)[:, apart], np.stack(slow)[:, apart], atol=1e-9)
    points = start[:40]
    (distance, on, triangle), (slow_distance, slow_on, _) = grouped.nearest(points), plain.nearest(points)
    np.testing.assert_allclose(distance, slow_distance, atol=1e-12)
    np.testing.assert_allclose(on, slow_on, atol=1e-12)
    held = plain.nearest(points[:1], among=triangle[:1])[0]  # the triangle named holds the point (ties: a corner)
    assert held[0] == pytest.approx(distance[0], abs=1e-12)
    crossing = np.flatnonzero(np.any(direction, axis=1) & grouped.inside(start))[:8]
    assert crossing.size > 3, "too few segments start inside the mesh"
    fast, slow = (
        grouped.deepest(start[crossing], direction[crossing]),
        plain.deepest(start[crossing], direction[crossing]),
    )
    np.testing.assert_allclose(fast[0], slow[0], atol=1e-12)  # the deepest point along axes that start inside
    np.testing.assert_array_equal(fast[1], slow[1])
    one = [plain.deepest(start[[n]], direction[[n]]) for n in crossing]  # each on its own: the same search
    np.testing.assert_allclose([t[0] for t, _ in one], slow[0], atol=1e-12)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_ray_crossings_count_the_generalised_winding_number(name):
    triangles = _triangles(name)
    g = _Geometry(triangles)
    assert g.closed
    rng = np.random.default_rng(5)
    off = rng.uniform(g.box_center - g.box_half, g.box_center + g.box_half, (1500, 3))
    counted, reference = g.winding(off), winding_numbers(off, g.a, g.b, g.c)
    assert 0.1 < np.mean(np.abs(reference) > 0.5) < 0.9  # points inside and out
    np.testing.assert_allclose(counted, reference, atol=1e-9)
    assert np.all(counted == np.round(counted))  # a count, where no crossing was ambiguous
    # rays through a corner and points on the surface: ambiguous, measured by the solid angles
    corners = g.a[:: max(1, len(g.a) // 60)]
    away = np.where(corners - g.box_center < 0.0, -_RAY, _RAY)
    through = corners - 1e-3 * away
    on = np.concatenate([corners, (g.a[:30] + g.b[:30] + g.c[:30]) / 3.0])
    for points in (through, on):
        np.testing.assert_allclose(g.winding(points), winding_numbers(points, g.a, g.b, g.c), atol=1e-9)


def test_a_mesh_with_a_hole_is_not_closed_and_keeps_the_solid_angles():
    triangles = _triangles("QUASER")
    assert is_closed(triangles) and not is_closed(triangles[1:])
    g = _Geometry(triangles[1:])
    assert not g.closed
    points = np.random.default_rng(2).uniform(g.box_center - g.box_half, g.box_center + g.box_half, (50, 3))
    np.testing.assert_array_equal(g.winding(points), winding_numbers(points, g.a, g.b, g.c))


@pytest.mark.parametrize("name", sorted(MESHES))
def test_axis_bounds_hold_the_signed_distance_of_the_axis(name):
    g = _Geometry(_triangles(name))
    start, direction = _segments(g, 120, seed=8)
    lower, upper = g.axis_bounds(start, direction)
    mesh = MeshObstacle(str(MESHES[name][0]), 0.001, MESHES[name][1])
    signed = []
    for s, d in zip(start, direction):
        length = float(np.linalg.norm(d))
        axis = d / length if length > 0.0 else np.array([0.0, 0.0, 1.0])
        signed.append(mesh.signed_distance(s + 0.5 * d, axis, length, 0.0)[0])
    signed = np.array(signed)
    assert np.all(lower <= signed + 1e-12) and np.all(signed <= upper + 1e-12)
    assert np.isfinite(lower[signed > 0.0]).mean() > 0.2  # a bound above -inf for axes clear of the mesh


def test_no_capsules_measure_nothing_and_a_shallow_answer_never_understates():
    g = _Geometry(_triangles("QUASER"))
    empty = g.signed_distances(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0))
    assert [a.shape[0] for a in empty] == [0, 0, 0, 0]
    start, direction = _segments(g, 150, seed=4)
    length = np.linalg.norm(direction, axis=1)
    axis = np.where(length[:, None] > 0.0, direction / np.maximum(length, 1e-300)[:, None], [0.0, 0.0, 1.0])
    mid, radius = start + 0.5 * direction, np.full(len(start), 0.05)
    deep = g.signed_distances(mid, axis, length, radius)[0]
    shallow = g.signed_distances(mid, axis, length, radius, deep=False)[0]
    meets = deep < -radius + 1e-12
    assert 10 < meets.sum() < len(deep)  # axes in or across the mesh, and clear of it
    np.testing.assert_array_equal(shallow[~meets], deep[~meets])
    assert np.all(shallow >= deep - 1e-15) and np.all(shallow[meets] <= 1e-9 * g.size - radius[meets])
