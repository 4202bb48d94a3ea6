"""Distances of many capsules at once (``signed_distances``, what the collision model calls for
all of a query's pairs of a shape) for the sphere, the plane, a turned box and a turned cylinder, against
independent references: FCL's plain distance for the sphere where apart (python-fcl measures a
capsule and a sphere exactly when asked for no signed distance, as the collision model did; its
signed query iterates GJK and misses by up to 30 um), and the smallest distance of 4,001 points
along each capsule's axis, computed here from each shape's definition (sampling can only
overestimate, by at most the samples' spacing where the distance has a kink)."""

from __future__ import annotations

import fcl
import numpy as np
import pytest

from modular_robots.obstacles import BoxObstacle, CylinderObstacle, PlaneObstacle, SphereObstacle
from modular_robots.obstacles._geometry import rpy_matrix

CENTER = np.array([0.4, -0.2, 0.9])
SPHERE = SphereObstacle(tuple(CENTER), 0.3)
PLANE = PlaneObstacle((0.0, 0.1, 0.75), (0.2, -0.1, 1.0))
BOX = BoxObstacle(tuple(CENTER), (0.5, 0.3, 0.4), (0.3, -0.2, 0.5))
CYLINDER = CylinderObstacle(tuple(CENTER), 0.2, 0.6, (-0.4, 0.1, 0.7))
SAMPLES = 4001


def capsules(seed: int, count: int = 300):
    """Capsules within 0.8 m of the shapes' centre: lengths 0 (spheres) to 0.5 m, radii 2-8 cm."""
    rng = np.random.default_rng(seed)
    mid = CENTER + rng.uniform(-0.8, 0.8, (count, 3))
    axis = rng.normal(size=(count, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    length = rng.uniform(0.0, 0.5, count)
    length[::7] = 0.0
    return mid, axis, length, rng.uniform(0.02, 0.08, count)


def point_distance(shape, points: np.ndarray) -> np.ndarray:
    """Signed distance of points ``(..., 3)`` to ``shape``, from its definition."""
    if shape is SPHERE:
        return np.linalg.norm(points - CENTER, axis=-1) - SPHERE.radius
    if shape is PLANE:
        return (points - np.asarray(PLANE.point)) @ np.asarray(PLANE.normal)
    if shape is CYLINDER:
        local = (points - CENTER) @ rpy_matrix(CYLINDER.rpy)  # into its frame, its axis z
        excess = np.stack(
            [np.hypot(local[..., 0], local[..., 1]) - CYLINDER.radius, np.abs(local[..., 2]) - 0.5 * CYLINDER.length],
            -1,
        )
    else:
        local = (points - CENTER) @ rpy_matrix(BOX.rpy)  # into the box's frame
        excess = np.abs(local) - 0.5 * np.asarray(BOX.size)
    return np.linalg.norm(np.maximum(excess, 0.0), axis=-1) + np.minimum(excess.max(axis=-1), 0.0)


@pytest.mark.parametrize("shape", [SPHERE, PLANE, BOX, CYLINDER], ids=["sphere", "plane", "box", "cylinder"])
def test_many_at_once_against_points_along_each_axis(shape):
    mid, axis, length, radius = capsules(0)
    d, on_robot, on_shape, _ = shape.signed_distances(mid, axis, length, radius)
    assert (d < 0).any() and (d > 0).any()  # overlaps and gaps both exercised
    s = np.linspace(-0.5, 0.5, SAMPLES)
    points = mid[:, None] + (s[None, :, None] * length[:, None, None]) * axis[:, None]
    sampled = point_distance(shape, points).min(axis=1) - radius
    assert np.all(sampled >= d - 1e-12)
    spacing = length / (SAMPLES - 1)  # a kink (inside the box) is missed by at most a spacing, slope 1
    assert np.all(sampled - d <= spacing + 1e-9), np.max(sampled - d - spacing)
    np.testing.assert_allclose(point_distance(shape, on_shape[d > 0]), 0.0, atol=1e-12)  # on the surface
    outside = d > 0
    gap = np.linalg.norm(on_robot - on_shape, axis=1)
    np.testing.assert_allclose(gap[outside], d[outside], atol=1e-9)  # apart by the distance


def test_one_capsule_is_the_batch_of_one():
    mid, axis, length, radius = capsules(2, 5)
    for shape in (SPHERE, PLANE, BOX, CYLINDER):
        many = shape.signed_distances(mid, axis, length, radius)
        for n in range(5):
            one = shape.signed_distance(mid[n], axis[n], length[n], radius[n])
            assert one[0] == pytest.approx(many[0][n], abs=1e-15)
            np.testing.assert_allclose(one[1], many[1][n], rtol=0, atol=1e-15)
            np.testing.assert_allclose(one[2], many[2][n], rtol=0, atol=1e-15)


def test_sphere_distances_equal_fcls_where_apart():
    mid, axis, length, radius = capsules(1)
    d, on_robot, on_sphere, _ = SPHERE.signed_distances(mid, axis, length, radius)
    obstacle = fcl.CollisionObject(fcl.Sphere(SPHERE.radius), fcl.Transform(CENTER))
    apart = np.flatnonzero(d > 1e-3)
    assert len(apart) > 100
    for n in apart:
        z = axis[n]
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
        x /= np.linalg.norm(x)
        rotation = np.column_stack([x, np.cross(z, x), z])
        shape = fcl.Capsule(radius[n], length[n]) if length[n] > 0 else fcl.Sphere(radius[n])
        capsule = fcl.CollisionObject(shape, fcl.Transform(rotation, mid[n]))
        result = fcl.DistanceResult()
        request = fcl.DistanceRequest(enable_nearest_points=True)
        assert fcl.distance(capsule, obstacle, request, result) == pytest.approx(d[n], abs=1e-12)
        np.testing.assert_allclose(result.nearest_points[0], on_robot[n], rtol=0, atol=1e-12)
        np.testing.assert_allclose(result.nearest_points[1], on_sphere[n], rtol=0, atol=1e-12)
