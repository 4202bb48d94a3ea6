"""Exact distances to triangles and the winding number of a triangle mesh, vectorised with NumPy
(the mesh obstacle's geometry; every length in metres).

Triangles are arrays ``a, b, c`` ``(T, 3)`` of their corners. The distances follow Ericson,
Real-Time Collision Detection (5.1.5, the closest point of a triangle; a segment's closest points
to a triangle are one of its ends' or lie on one of the triangle's edges, unless the two cross).
Inside and outside is the generalised winding number of Jacobson, Kavan and Sorkine-Hornung
(SIGGRAPH 2013): the triangles' solid angle over 4 pi, which holds for meshes with small gaps or
overlapping parts, and which changes by one where a path crosses a triangle.
"""

from __future__ import annotations

import numpy as np

from ._geometry import segment_parameters

__all__ = [
    "closest_on_triangles",
    "segment_triangles",
    "segment_crossings",
    "ray_crossings",
    "winding_numbers",
    "is_closed",
]

#: Barycentric margin within which a ray is taken to pass through a triangle's edge or corner, or
#: a point to lie on its plane: there a crossing count is ambiguous.
_EDGE = 1e-9


def closest_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The closest point of each triangle to each point: points ``(N, 3)``, triangles ``(T, 3)``
    each, result ``(N, T, 3)`` (Ericson's Voronoi regions: a corner, an edge or the face)."""
    p = p[:, None]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp, cp = p - b, p - c
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        face = a + (vb / denom)[..., None] * ab + (vc / denom)[..., None] * ac
        on_ab = a + (d1 / (d1 - d3))[..., None] * ab
        on_ac = a + (d2 / (d2 - d6))[..., None] * ac
        on_bc = b + ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[..., None] * (c - b)
    # the regions from last to first, so that the first that holds wins (Ericson's order)
    out = np.where(((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0))[..., None], on_bc, face)
    out = np.where(((vb <= 0) & (d2 >= 0) & (d6 <= 0))[..., None], on_ac, out)
    out = np.where(((vc <= 0) & (d1 >= 0) & (d3 <= 0))[..., None], on_ab, out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[..., None], c, out)
    out = np.where(((d3 >= 0) & (d4 <= d3))[..., None], b, out)
    return np.where(((d1 <= 0) & (d2 <= 0))[..., None], a, out)


def segment_crossings(
    start: np.ndarray, direction: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Where the segment ``start + t direction``, ``t`` in [0, 1], passes through each triangle
    (Moeller and Trumbore): the parameters ``t`` ``(T,)`` (NaN where it does not) and the change
    of the winding number there, +1 or -1 (0 where it does not)."""
    e1, e2 = b - a, c - a
    h = np.cross(direction, e2)
    det = _dot(e1, h)
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / det
        s = start - a
        u = inverse * _dot(s, h)
        q = np.cross(s, e1)
        v = inverse * _dot(direction, q)
        t = inverse * _dot(e2, q)
        hit = (det != 0.0) & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t >= 0.0) & (t <= 1.0)
    return np.where(hit, t, np.nan), np.where(hit, np.sign(det), 0.0)


def segment_triangles(
    start: np.ndarray, direction: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The closest points of the segment ``start + t direction`` (``t`` in [0, 1]; a point if
    ``direction`` is zero) and of each triangle: on the segment and on the triangles, ``(T, 3)``
    each; where they cross, the crossing point for both. ``start`` and ``direction`` are one
    segment ``(3,)`` or one a triangle ``(T, 3)``."""
    count = len(a)
    start, direction = np.broadcast_to(start, a.shape), np.broadcast_to(direction, a.shape)
    ends = np.concatenate([start, start + direction])
    corners = np.concatenate([a, b, c])  # the three edges of every triangle, from these corners
    edges = np.concatenate([b, c, a]) - corners
    starts, directions = np.concatenate([start] * 3), np.concatenate([direction] * 3)
    s, t = segment_parameters(starts, directions, corners, edges)
    on_segment = np.concatenate([ends, starts + s[:, None] * directions]).reshape(5, count, 3)
    on_ends = closest_on_triangles(ends, *(np.concatenate([v, v])[:, None] for v in (a, b, c)))[:, 0]
    on_triangle = np.concatenate([on_ends, corners + t[:, None] * edges]).reshape(5, count, 3)
    gap = on_segment - on_triangle  # (5, T, 3): the two ends, the three edges
    best = np.argmin(np.einsum("ktc,ktc->kt", gap, gap), axis=0)
    columns = np.arange(count)
    on_segment, on_triangle = on_segment[best, columns], on_triangle[best, columns]
    crossing, _ = segment_crossings(start, direction, a, b, c)
    hit = ~np.isnan(crossing)
    if hit.any():
        point = start[hit] + crossing[hit, None] * direction[hit]
        on_segment[hit], on_triangle[hit] = point, point
    return on_segment, on_triangle


def ray_crossings(
    points: np.ndarray, ray: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Whether the ray segment ``point + t ray``, ``t`` in [0, 1], from each point ``(P, 3)``
    (``ray`` ``(P, 3)`` or ``(3,)``) crosses the triangle of its row (``a, b, c`` ``(P, 3)``;
    Moeller and Trumbore): the change of the winding number there ``(P,)`` (+1 or -1; 0 where
    it does not cross), and whether the answer is ambiguous ``(P,)``: the ray grazes an edge or
    a corner, runs in the triangle's plane, or starts on it (within :data:`_EDGE`)."""
    e1, e2 = b - a, c - a
    h = np.cross(ray, e2)
    det = _dot(e1, h)
    scale = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) * np.linalg.norm(ray, axis=-1)
    flat = np.abs(det) <= _EDGE * scale
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = np.where(flat, 0.0, 1.0 / np.where(flat, 1.0, det))
        s = points - a
        u = inverse * _dot(s, h)
        q = np.cross(s, e1)
        v = inverse * _dot(q, np.broadcast_to(ray, q.shape))
        t = inverse * _dot(e2, q)
    w = 1.0 - u - v
    within = (u >= -_EDGE) & (v >= -_EDGE) & (w >= -_EDGE) & (t >= -_EDGE) & (t <= 1.0 + _EDGE)
    edge = (np.minimum(np.minimum(u, v), w) <= _EDGE) | (np.abs(t) <= _EDGE)
    hit = within & ~flat & ~edge
    return np.where(hit, np.sign(det), 0.0), flat | (within & edge)


def is_closed(triangles: np.ndarray) -> bool:
    """Whether the triangles ``(T, 3, 3)`` close (equal corners taken as one vertex): each edge
    is run through as often one way as the other, so that the winding number is an integer off
    the surface and a ray's crossings count it."""
    _, index = np.unique(triangles.reshape(-1, 3), axis=0, return_inverse=True)
    index = index.reshape(-1, 3)
    tails, heads = index.ravel(), np.roll(index, -1, axis=1).ravel()
    n = int(index.max()) + 1
    forward, count = np.unique(tails * n + heads, return_counts=True)
    backward, count_back = np.unique(heads * n + tails, return_counts=True)
    return bool(np.array_equal(forward, backward) and np.array_equal(count, count_back))


def winding_numbers(points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The generalised winding number ``(N,)`` of the mesh at each point ``(N, 3)``: its
    triangles' signed solid angles (Van Oosterom and Strackee) over 4 pi; 1 inside a closed mesh
    whose triangles turn counter-clockwise seen from outside, -1 if clockwise, 0 outside."""
    x, y, z = (corner[None] - points[:, None] for corner in (a, b, c))  # (N, T, 3)
    lx, ly, lz = (np.sqrt(_dot(v, v)) for v in (x, y, z))
    volume = (
        x[..., 0] * (y[..., 1] * z[..., 2] - y[..., 2] * z[..., 1])
        + x[..., 1] * (y[..., 2] * z[..., 0] - y[..., 0] * z[..., 2])
        + x[..., 2] * (y[..., 0] * z[..., 1] - y[..., 1] * z[..., 0])
    )
    denominator = lx * ly * lz + _dot(x, y) * lz + _dot(x, z) * ly + _dot(y, z) * lx
    return np.arctan2(volume, denominator).sum(axis=1) / (2.0 * np.pi)


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...c,...c->...", u, v)
