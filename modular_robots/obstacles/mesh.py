"""A triangle-mesh obstacle read from an STL file (a machine, a fixture, a cell's housing).

FCL's object for it is a BVH of the triangles (``fcl.BVHModel``), not their convex hull
(``fcl.Convex``): a hull fills a machine's working space or a window's opening, where the robot
must reach, and a mesh obstacle is there to keep those. The distances are not FCL's, though
(:attr:`MeshObstacle.closed_form`): FCL measures to a BVH's surface only, so a link wholly inside
the mesh would be reported clear, and its capsule-triangle distances (GJK) were off by up to
1.2e-4 m and their directions by 2.5e-3 on 200 capsules near the CoBRA machine mesh, which the
gradient would inherit. The shape measures every pair itself, exactly, with NumPy
(:mod:`._triangles`): the distance from the capsule's axis to the nearest triangles, and, for an
axis that crosses the surface or lies inside, the depth of its deepest point, found by sampling
the axis and golden-section search. Which triangles may be nearest is decided by bounds, first on
groups of 16 neighbouring triangles, then on the triangles of the groups left
(:mod:`._culling`), best first; the collision model asks for all the capsules of a query at once
(:meth:`MeshObstacle.signed_distances`), so that NumPy's cost per call is paid once a query, not
once a pair. Inside and outside are the generalised winding number's, which holds for meshes
with small gaps or overlapping parts (a mesh that is not closed has no inside, and there its
answer is a guess); for a closed mesh, the winding number is counted by a ray's crossings of the
triangles near it, and by the solid angles of all of them only where a crossing is ambiguous.

A signed distance is thus the smallest signed distance from the mesh of the capsule's axis,
less the capsule's radius, as for the box and the cylinder; its gradient comes with it.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ._culling import group_triangles, segment_lower_bounds
from ._geometry import pose_columns, rpy_matrix
from ._json import json_number, json_vector
from ._stl import StlError, read_stl, welded
from ._triangles import (
    closest_on_triangles,
    is_closed,
    ray_crossings,
    segment_crossings,
    segment_triangles,
    winding_numbers,
)
from .base import Obstacle, Witness, members
from .box import BoxObstacle

if TYPE_CHECKING:
    import fcl

    from .._yamlio import Fields

__all__ = ["MeshObstacle", "SURFACE_SAMPLES"]

#: A mesh larger than this across [m] is warned about: a file in millimetres without its scale.
LARGEST_EXPECTED = 100.0
#: Surface points (mesh vertices) whose distance bounds a capsule's from above (capsule_bounds).
SURFACE_SAMPLES = 64
#: Points along a capsule's axis sampled for its deepest point, and the golden-section steps that
#: refine the best two (the bracket shrinks to 0.618^60 = 3e-13 of two samples' spacing).
_AXIS_SAMPLES, _SEARCH_STEPS = 32, 60
#: Steps after which the search culls the triangles anew for its shrunk brackets.
_RECULL = 8
#: Triangles in a group of :mod:`._culling`'s hierarchy; a query measures first the group with
#: the smallest bound, whose nearest distance then bounds which others can be nearer.
GROUP_SIZE = 16
#: Groups a segment's query measures at once, nearest bound first.
_BATCH = 4
#: The most (point, triangle) pairs a query holds in its arrays at once.
_PAIRS = 1_000_000
_GOLD = (math.sqrt(5.0) - 1.0) / 2.0
#: The direction of the rays whose crossings count a closed mesh's winding number: oblique, so
#: that it seldom runs along a machine's axis-aligned edges and faces.
_RAY = np.array([0.8017, 0.3361, 0.4943]) / np.linalg.norm([0.8017, 0.3361, 0.4943])
#: Triangles read, by (file, SHA-256): each file is parsed once per process.
_read: dict[tuple[str, str], np.ndarray] = {}
_read_lock = threading.Lock()


@dataclass(frozen=True)
class MeshObstacle:
    """The triangles of the STL file ``file`` (an absolute path), scaled by ``scale`` (the file's
    unit in metres), turned by ``rpy`` (fixed-axis roll, pitch, yaw [rad]) and moved to
    ``position`` [m], in the base frame. ``sha256`` is the file's digest, so that a changed file
    is not taken for the one read (empty: read the file now)."""

    file: str
    scale: float = 1.0
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sha256: str = ""
    kind: ClassVar[str] = "mesh"
    closed_form: ClassVar[bool] = True  # every pair measured here: FCL's BVH distance has no inside
    moving_only: ClassVar[bool] = False

    def __post_init__(self) -> None:  # any sequences of numbers in, a hashable value out
        object.__setattr__(self, "file", str(self.file))
        object.__setattr__(self, "scale", float(self.scale))
        for name in ("position", "rpy"):
            object.__setattr__(self, name, tuple(float(c) for c in getattr(self, name)))
        if not self.sha256:
            object.__setattr__(self, "sha256", _remember(Path(self.file))[1])

    @classmethod
    def from_fields(cls, f: Fields) -> MeshObstacle:
        name = f.string("file")
        path = (f.path.parent / name).resolve()  # relative to the scenario's folder
        if not path.exists():
            raise f.fail(
                "file",
                f"no mesh file at {path} (looked in {path.parent}: a relative path is taken from the "
                "scenario's folder)",
            )
        try:
            triangles, sha256 = _remember(path)
        except StlError as e:
            raise f.fail("file", str(e)) from None
        scale = f.number("scale", 1.0, exclusive_minimum=0.0)
        position = f.vector("position", 3, default=(0.0, 0.0, 0.0))
        rpy = f.rpy(default=(0.0, 0.0, 0.0))
        f.done()
        if not np.any(_areas(scale * triangles) > 0.0):
            raise f.fail("file", f"{path}: every triangle has zero area at scale {scale:g}")
        vertices = triangles.reshape(-1, 3)
        extent = scale * float(np.max(vertices.max(axis=0) - vertices.min(axis=0)))
        if extent > LARGEST_EXPECTED:
            f.warn(
                "file",
                f"the mesh is {extent:.4g} m across at scale {scale:g}: millimetres? (scale: {scale / 1000:g} makes it "
                f"{extent / 1000:.4g} m)",
            )
        return cls(str(path), scale, position, rpy, sha256)

    @classmethod
    def from_json(cls, data: Any) -> MeshObstacle:
        keys = {"file", "scale", "position", "rpy", "sha256"}
        if not isinstance(data, dict) or set(data) != keys:
            raise ValueError("expected a mapping of file, scale, position, rpy and sha256")
        file, sha256 = data["file"], data["sha256"]
        if not isinstance(file, str) or not file:
            raise ValueError(f"file: expected the mesh file's path, got {file!r:.60}")
        if not isinstance(sha256, str) or len(sha256) != 64 or any(c not in "0123456789abcdef" for c in sha256):
            raise ValueError(f"sha256: expected 64 hexadecimal digits, got {sha256!r:.80}")
        scale = json_number(data["scale"], "scale")
        if not scale > 0.0:
            raise ValueError(f"scale: expected a number > 0, got {scale!r}")
        position, rpy = json_vector(data["position"], 3, "position"), json_vector(data["rpy"], 3, "rpy")
        try:
            found = _remember(Path(file))[1]
        except StlError as e:
            raise ValueError(f"file: {e}") from None
        if found != sha256:
            raise ValueError(f"file: {file} has changed since it was read (its SHA-256 is {found}, not {sha256})")
        return cls(file, scale, position, rpy, sha256)  # type: ignore[arg-type]

    def to_json(self) -> dict[str, Any]:
        return {
            "file": self.file,
            "scale": self.scale,
            "position": list(self.position),
            "rpy": list(self.rpy),
            "sha256": self.sha256,
        }

    def describe(self) -> str:
        return (
            f"{Path(self.file).name} ({len(self._geometry.a)} triangles), scale {self.scale:g}, "
            f"position {list(self.position)}, rpy {list(self.rpy)}"
        )

    @property
    def _geometry(self) -> _Geometry:
        return _placed(self)  # cached by obstacle, not held: a pickled obstacle stays its fields

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        g = self._geometry
        return g.sphere_center.copy(), g.sphere_radius

    def contains(self, point: Sequence[float]) -> bool:
        p = np.asarray(point, dtype=float).reshape(1, 3)
        return bool(self._geometry.nearest(p)[0][0] == 0.0 or self._geometry.inside(p)[0])

    def collision_object(self) -> fcl.CollisionObject:
        import fcl  # never measured with FCL (closed_form); an object for whoever asks

        g = self._geometry
        vertices, faces = np.unique(np.stack([g.a, g.b, g.c], 1).reshape(-1, 3), axis=0, return_inverse=True)
        model = fcl.BVHModel()
        model.beginModel(len(vertices), len(g.a))
        model.addSubModel(vertices, faces.reshape(-1, 3).astype(np.int32))
        model.endModel()
        return fcl.CollisionObject(model, fcl.Transform())

    @classmethod
    def batch(cls, obstacles: Sequence[Obstacle]) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray, list]:
        """The bounding boxes as :class:`~.box.BoxObstacle`'s batch (centres, rotations, half
        sizes [m]), :data:`SURFACE_SAMPLES` surface points of each ``(O, S, 3)`` [m], and the
        meshes' geometries."""
        meshes = [o._geometry for o in members(obstacles, MeshObstacle)]
        boxes = (
            np.array([g.box_center for g in meshes]).reshape(-1, 3),
            np.array([g.box_rotation for g in meshes]).reshape(-1, 3, 3),
            np.array([g.box_half for g in meshes]).reshape(-1, 3),
        )
        return boxes, np.array([g.samples for g in meshes]).reshape(-1, SURFACE_SAMPLES, 3), meshes

    @classmethod
    def capsule_bounds(
        cls, batch: Any, axis: np.ndarray, mid: np.ndarray, half_length: np.ndarray, radius: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Below, the larger of the distance to the mesh's bounding box (which holds its inside)
        and, for an axis that clear of the surface and outside, the groups' bound
        (:meth:`_Geometry.axis_bounds`); above, the distance to the nearest of the surface
        samples and of the corners of the group nearest in bound."""
        boxes, samples, meshes = batch
        lower = BoxObstacle.capsule_bounds(boxes, axis, mid, half_length, radius)[0]
        offset = samples[None, None] - mid[:, :, None, None]  # (K, P, O, S, 3)
        half = half_length[None, :, None, None]
        along = np.clip(np.einsum("kposc,kpc->kpos", offset, axis), -half, half)
        apart = np.linalg.norm(offset - along[..., None] * axis[:, :, None, None], axis=-1)
        upper = apart.min(axis=-1) - radius[None, :, None]
        start = (mid - half_length[None, :, None] * axis).reshape(-1, 3)
        direction = (2.0 * half_length[None, :, None] * axis).reshape(-1, 3)
        for o, g in enumerate(meshes):
            below, above = (b.reshape(mid.shape[:2]) - radius for b in g.axis_bounds(start, direction))
            lower[..., o], upper[..., o] = np.maximum(lower[..., o], below), np.minimum(upper[..., o], above)
        return lower, upper

    def signed_distance(self, mid: np.ndarray, axis: np.ndarray, length: float, radius: float) -> Witness:
        one = (np.reshape(mid, (1, 3)), np.reshape(axis, (1, 3)), np.array([length]), np.array([radius]))
        distance, on_robot, on_mesh, gradient = self.signed_distances(*one)
        return float(distance[0]), on_robot[0], on_mesh[0], gradient[0]

    def signed_distances(
        self, mid: np.ndarray, axis: np.ndarray, length: np.ndarray, radius: np.ndarray, deep: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`signed_distance` of ``N`` capsules at once (``mid``, ``axis`` ``(N, 3)``,
        ``length``, ``radius`` ``(N,)``): distances ``(N,)``, witness points on the robot and on
        the mesh and gradients ``(N, 3)``. The axes clear of the surface are measured together;
        one that crosses it or lies inside, on its own (:meth:`_Geometry.deepest`), or, if not
        ``deep``, not at all: its distance is then ``-radius`` (or the touching axis's gap less
        the radius), no smaller than its own, and its witnesses and gradient NaN."""
        return self._geometry.signed_distances(mid, axis, length, radius, deep)

    @classmethod
    def normals(cls, batch: Any, on_robot: np.ndarray, on_obstacle: np.ndarray) -> np.ndarray:
        """From the mesh's witness point to the robot's (:meth:`signed_distance` gives every
        gradient, so the collision model asks this only for a batch of mixed shapes' sake)."""
        return on_robot - on_obstacle

    def page(self, grow: float = 0.0) -> list[dict[str, Any]]:
        """The welded triangles in the mesh's frame, scaled; grown along the vertex normals."""
        g = self._geometry
        local = (np.stack([g.a, g.b, g.c], 1) - self.position) @ rpy_matrix(self.rpy)
        vertices, faces = welded(local)
        if grow:
            normals = np.zeros_like(vertices)
            for corner in range(3):  # area-weighted, outward
                np.add.at(normals, faces[:, corner], g.orientation * 0.5 * _cross(local))
            lengths = np.linalg.norm(normals, axis=1, keepdims=True)
            vertices = vertices + grow * np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
        return [
            {
                "type": "mesh",
                "vertices": np.round(vertices, 5).tolist(),
                "faces": faces.tolist(),
                "origin": pose_columns(rpy_matrix(self.rpy), np.asarray(self.position)),
            }
        ]


class _Geometry:
    """A mesh obstacle's triangles in the base frame and the queries the obstacle makes of them."""

    def __init__(self, triangles: np.ndarray, group_size: int = GROUP_SIZE):
        triangles = triangles[_areas(triangles) > 0.0]  # a triangle of no area holds no point its edges miss
        self.a, self.b, self.c = (np.ascontiguousarray(triangles[:, i]) for i in range(3))
        volume = float(np.einsum("tc,tc->", self.a, np.cross(self.b, self.c))) / 6.0
        #: 1 if the triangles' normals (right-hand rule) point out of the mesh, -1 if in.
        self.orientation = 1.0 if volume >= 0.0 else -1.0
        cross = _cross(triangles)
        self.normals = self.orientation * cross / np.linalg.norm(cross, axis=1, keepdims=True)
        self.centroid = triangles.mean(axis=1)
        self.reach = np.linalg.norm(triangles - self.centroid[:, None], axis=2).max(axis=1)
        self.low, self.high = triangles.min(axis=1), triangles.max(axis=1)  # each triangle's box
        vertices = np.unique(triangles.reshape(-1, 3), axis=0)
        low, high = vertices.min(axis=0), vertices.max(axis=0)
        self.box_center, self.box_rotation = 0.5 * (low + high), np.eye(3)
        self.box_half = np.maximum(0.5 * (high - low), 1e-9)  # a flat mesh: a box of some thickness
        self.size = float(np.linalg.norm(high - low))
        self.sphere_center = self.box_center
        self.sphere_radius = float(np.linalg.norm(vertices - self.box_center, axis=1).max())
        self.samples = _spread(vertices, SURFACE_SAMPLES)
        self.groups = group_triangles(triangles, group_size)
        #: Whether the mesh closes (:func:`._triangles.is_closed`): then a ray's crossings count
        #: its winding number, and only the triangles near the ray are asked.
        self.closed = is_closed(triangles)

    def signed_distances(
        self, mid: np.ndarray, axis: np.ndarray, length: np.ndarray, radius: np.ndarray, deep: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`MeshObstacle.signed_distances` (this mesh's triangles)."""
        mid, axis = np.asarray(mid, dtype=float), np.asarray(axis, dtype=float)
        length, radius = np.asarray(length, dtype=float), np.asarray(radius, dtype=float)
        start, direction = mid - 0.5 * length[:, None] * axis, length[:, None] * axis
        on_axis, on_mesh = self.closest(start, direction)
        gap = np.linalg.norm(on_axis - on_mesh, axis=1)
        outside = gap > 1e-9 * self.size
        outside[outside] = ~self.inside(on_axis[outside])
        normal = np.zeros_like(on_axis)
        normal[outside] = (on_axis - on_mesh)[outside] / gap[outside, None]
        distance, on_robot, gradient = gap - radius, on_axis - radius[:, None] * normal, normal
        meets = np.flatnonzero(~outside)
        if not deep:
            touching = gap[meets] <= 1e-9 * self.size  # crossing (gap 0) or touching from outside
            distance[meets] = np.where(touching, gap[meets], 0.0) - radius[meets]
            on_robot[meets], on_mesh[meets], gradient[meets] = np.nan, np.nan, np.nan
            return distance, on_robot, on_mesh, gradient
        at, within = self.deepest(start[meets], direction[meets]) if meets.size else (np.empty(0), np.empty(0, bool))
        for n, t, inside in zip(meets, at, within):  # wholly outside: as above; else its deepest point
            point = start[n] + t * direction[n]
            depth, gradient[n], on_mesh[n] = self.gradient(point, inside, direction[n])
            size = float(np.linalg.norm(gradient[n]))
            across = gradient[n] / size if size > 0.0 else self.normals[self.nearest(point[None])[2][0]]
            distance[n], on_robot[n] = depth - radius[n], point - radius[n] * across
        return distance, on_robot, on_mesh, gradient

    def _near(self, start: np.ndarray, direction: np.ndarray, limit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The (segment, triangle) pairs, two index arrays, whose triangle may lie within
        ``limit`` ``(M,)`` [m] of the segment (``start``, ``direction`` ``(M, 3)``): those whose
        group's bound and own bound are both within it (:mod:`._culling`); a triangle once."""
        g = self.groups
        bound = segment_lower_bounds(start, direction, g.low, g.high, g.centre, g.reach)
        row, group = np.nonzero(bound <= limit[:, None])
        pair = np.unique(np.repeat(row, g.members.shape[1]) * len(self.a) + g.members[group].ravel())
        row, triangle = np.divmod(pair, len(self.a))
        box = (v[triangle][:, None] for v in (self.low, self.high, self.centroid, self.reach))
        keep = segment_lower_bounds(start[row], direction[row], *box)[:, 0] <= limit[row]
        return row[keep], triangle[keep]

    def closest(self, start: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The closest points of segments ``start``, ``direction`` ``(N, 3)`` and the surface:
        on the segments and on the surface ``(N, 3)`` each (:meth:`_pairs`)."""

        def measure(row: np.ndarray, triangle: np.ndarray):
            on = segment_triangles(start[row], direction[row], self.a[triangle], self.b[triangle], self.c[triangle])
            return np.linalg.norm(on[0] - on[1], axis=1), on

        row, (on_segment, on_surface) = self._pairs(start, direction, measure)
        return on_segment[row], on_surface[row]

    def nearest(self, points: np.ndarray, among: np.ndarray | None = None):
        """Distances ``(M,)`` [m] from points ``(M, 3)`` to the surface (``among``: only these
        triangles), the nearest surface points ``(M, 3)`` and the triangles that hold them."""
        if among is None:

            def measure(row: np.ndarray, triangle: np.ndarray):
                on = closest_on_triangles(points[row], *(v[triangle][:, None] for v in (self.a, self.b, self.c)))[:, 0]
                return np.linalg.norm(points[row] - on, axis=1), (on, triangle)

            head, (distance, (on, triangle)) = self._pairs(points, np.zeros_like(points), measure, both=True)
            return distance[head], on[head], triangle[head]
        chunk = max(1, _PAIRS // max(1, len(among)))
        if len(points) > chunk:  # a few points at a time: arrays of (points, triangles, 3)
            parts = [self.nearest(points[i : i + chunk], among) for i in range(0, len(points), chunk)]
            return tuple(np.concatenate(p) for p in zip(*parts))
        closest = closest_on_triangles(points, self.a[among], self.b[among], self.c[among])  # (M, N, 3)
        distance = np.linalg.norm(points[:, None] - closest, axis=2)
        best = np.argmin(distance, axis=1)
        rows = np.arange(len(points))
        return distance[rows, best], closest[rows, best], among[best]

    def _pairs(self, start: np.ndarray, direction: np.ndarray, measure, both: bool = False):
        """Each segment's (``start``, ``direction`` ``(N, 3)``) nearest triangle, by
        ``measure(rows, triangles)`` (distances of the pairs and what goes with them, a tuple of
        arrays). Best first: each segment's groups in the order of their bounds, one group, then
        two, four and so on at a time, those whose bound is within the nearest distance found so
        far, and of them the triangles whose own bound is. Returns the index of each segment's
        nearest pair and what ``measure`` gave (with the distances if ``both``)."""
        g, size = self.groups, self.groups.members.shape[1]
        if not len(start):
            empty = measure(np.zeros(0, dtype=int), np.zeros(0, dtype=int))
            return np.zeros(0, dtype=int), (empty if both else empty[1])
        bound = segment_lower_bounds(start, direction, g.low, g.high, g.centre, g.reach)  # (N, G)
        order = np.argsort(bound, axis=1)
        bound = np.take_along_axis(bound, order, axis=1)
        limit = np.full(len(start), np.inf)
        rows, distances, founds = [], [], []
        column, width = 0, 1
        while column < bound.shape[1]:
            window = slice(column, column + width)
            row, k = np.nonzero(bound[:, window] <= limit[:, None])
            if not row.size:
                break  # every segment's next group is farther than what it has found
            row, triangle = np.repeat(row, size), g.members[order[:, window][row, k]].ravel()
            box = (v[triangle][:, None] for v in (self.low, self.high, self.centroid, self.reach))
            keep = segment_lower_bounds(start[row], direction[row], *box)[:, 0] <= limit[row]
            row, triangle = row[keep], triangle[keep]
            distance, found = measure(row, triangle)
            np.minimum.at(limit, row, distance + 1e-12 * self.size)  # a bound rounded above its distance
            rows.append(row)
            distances.append(distance)
            founds.append(found)
            column, width = column + width, 2 * width
        row, distance = np.concatenate(rows), np.concatenate(distances)
        found = tuple(np.concatenate(part) for part in zip(*founds))
        order = np.lexsort((distance, row))
        head = order[np.flatnonzero(np.diff(row[order], prepend=-1))]  # each segment's nearest
        return head, ((distance, found) if both else found)

    def axis_bounds(self, start: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds ``(N,)`` [m] on the signed distance of segments ``start``, ``direction``
        ``(N, 3)`` from the mesh: below, the smallest of the groups' bounds where it is above 0
        and the segment's start outside (then the whole segment is: it meets no triangle), else
        ``-inf``; above, the distance to the nearest corner of the group nearest in bound."""
        g = self.groups
        bound = segment_lower_bounds(start, direction, g.low, g.high, g.centre, g.reach)
        nearest = np.argmin(bound, axis=1)
        lower = bound[np.arange(len(bound)), nearest]
        clear = lower > 0.0
        clear[clear] = ~self.inside(start[clear])
        corners = np.concatenate([v[g.members[nearest]] for v in (self.a, self.b, self.c)], axis=1)  # (N, 3S, 3)
        span = np.einsum("nc,nc->n", direction, direction)[:, None]
        offset = corners - start[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(span > 0.0, np.clip(np.einsum("nsc,nc->ns", offset, direction) / span, 0.0, 1.0), 0.0)
        upper = np.linalg.norm(offset - t[..., None] * direction[:, None], axis=2).min(axis=1)
        return np.where(clear, lower, -np.inf), upper

    def winding(self, points: np.ndarray) -> np.ndarray:
        """The winding number ``(M,)`` at each point ``(M, 3)``: of a closed mesh, the crossings
        of a ray from the point out of the mesh's box (the generalised winding number where a
        crossing is ambiguous); else the generalised winding number."""
        if not self.closed:
            return winding_numbers(points, self.a, self.b, self.c)
        offset = points - self.box_center
        ray = np.where(offset < 0.0, -_RAY, _RAY)  # away from the centre: out of the box soonest
        room = np.maximum(self.box_half - np.abs(offset), 0.0) / _RAY
        ray = ray * (room.min(axis=1) + 1e-3 * self.size)[:, None]  # to just beyond the box
        point, triangle = self._near(points, ray, np.zeros(len(points)))  # a crossing is at no distance
        corners = (self.a[triangle], self.b[triangle], self.c[triangle])
        change, ambiguous = ray_crossings(points[point], ray[point], *corners)
        out = -np.bincount(point, weights=change, minlength=len(points))
        unsure = np.unique(point[ambiguous])
        if unsure.size:
            out[unsure] = winding_numbers(points[unsure], self.a, self.b, self.c)
        return out

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Whether each point ``(M, 3)`` is inside: a winding number of magnitude 1/2 or more
        (outside the mesh's box without asking)."""
        out = np.zeros(len(points), dtype=bool)
        near = np.all(np.abs(points - self.box_center) <= self.box_half, axis=1)
        if near.any():
            out[near] = np.abs(self.winding(points[near])) >= 0.5
        return out

    def deepest(self, start: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For segments ``start``, ``direction`` ``(M, 3)``, the parameter in [0, 1] of each one's
        point of smallest signed distance and whether that point is inside, ``(M,)`` each: the
        best of :data:`_AXIS_SAMPLES` + 1 samples, refined by golden-section search between the
        neighbours of the two best samples that are local minima (all segments' searches in
        step). Inside and outside along a segment: the winding number at its start, changed by
        one at each triangle the segment crosses."""
        count, length = len(start), np.linalg.norm(direction, axis=1)
        start_winding = self.winding(start)
        row, triangle = self._near(start, direction, np.zeros(count))  # a crossing is at no distance
        at, jump = segment_crossings(start[row], direction[row], self.a[triangle], self.b[triangle], self.c[triangle])
        crossed = ~np.isnan(at)
        row, at, jump = row[crossed], at[crossed], jump[crossed]

        def inside(rows: np.ndarray, t: np.ndarray) -> np.ndarray:
            passed = (row[None] == rows[:, None]) & (at[None] <= t[:, None])
            return np.abs(start_winding[rows] + passed @ jump) >= 0.5

        t = np.linspace(0.0, 1.0, _AXIS_SAMPLES + 1)
        every = np.repeat(np.arange(count), len(t))
        distance = self.nearest((start[:, None] + t[:, None] * direction[:, None]).reshape(-1, 3))[0]
        f = np.where(inside(every, np.tile(t, count)), -distance, distance).reshape(count, -1)
        distance = distance.reshape(count, -1)
        padded = np.pad(f, ((0, 0), (1, 1)), constant_values=np.inf)
        minimum = (f <= padded[:, :-2]) & (f <= padded[:, 2:])
        ranked = np.argsort(np.where(minimum, f, np.inf), axis=1, kind="stable")[:, :2]
        seeds = np.where(minimum[np.arange(count)[:, None], ranked], ranked, ranked[:, :1])  # one minimum: twice
        seeds = seeds.ravel()
        owner = np.repeat(np.arange(count), 2)
        before, after = np.maximum(seeds - 1, 0), np.minimum(seeds + 1, _AXIS_SAMPLES)
        low, high = t[before], t[after]
        # the triangles that may be nearest to a point between two samples' neighbours: nearer
        # than the samples' distance plus half the bracket's length (the distance is 1-Lipschitz)
        within = np.maximum(distance[owner, before], distance[owner, after]) + 0.5 * (high - low) * length[owner]
        at_start, along_axis = start[owner], direction[owner]
        pairs = self._near(at_start + low[:, None] * along_axis, (high - low)[:, None] * along_axis, within)

        def along(s: np.ndarray) -> np.ndarray:
            bracket, tri = pairs
            points = at_start[bracket] + s[bracket, None] * along_axis[bracket]
            on = closest_on_triangles(points, *(v[tri][:, None] for v in (self.a, self.b, self.c)))[:, 0]
            d = np.full(len(s), np.inf)
            np.minimum.at(d, bracket, np.linalg.norm(points - on, axis=1))
            return np.where(inside(owner, s), -d, d)

        a, b = high - _GOLD * (high - low), low + _GOLD * (high - low)
        fa, fb = along(a), along(b)
        for step in range(1, _SEARCH_STEPS + 1):
            if step % _RECULL == 0:  # the brackets have shrunk: fewer triangles can be nearest
                within = np.minimum(np.abs(fa), np.abs(fb)) + (high - low) * length[owner]
                pairs = self._near(at_start + low[:, None] * along_axis, (high - low)[:, None] * along_axis, within)
            left = fa <= fb
            high, low = np.where(left, b, high), np.where(left, low, a)
            new = np.where(left, high - _GOLD * (high - low), low + _GOLD * (high - low))
            fnew = along(new)
            a, b, fa, fb = (
                np.where(left, new, b),
                np.where(left, a, new),
                np.where(left, fnew, fb),
                np.where(left, fa, fnew),
            )
        middle = 0.5 * (low + high)
        found = np.concatenate([middle.reshape(count, 2), t[seeds].reshape(count, 2)], axis=1)
        values = np.concatenate([along(middle).reshape(count, 2), f[owner, seeds].reshape(count, 2)], axis=1)
        best = found[np.arange(count), np.argmin(values, axis=1)]
        best = np.where(length > 0.0, best, 0.0)
        return best, inside(np.arange(count), best)

    def gradient(self, point: np.ndarray, inside: bool, direction: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """The signed distance [m] at ``point``, an axis's deepest point, its gradient with respect
        to a translation of the axis, and the nearest surface point. Inside, the signed distance
        is the largest of the triangles' ``-distance``, and along the axis it is usually smallest
        where two of them cross: there the gradient is the combination of theirs that keeps them
        crossing (as for the box's faces); elsewhere the nearest triangle's."""
        distance, on_surface, triangle = (v[0] for v in self.nearest(point[None]))
        distance = float(distance)
        if distance == 0.0:  # on the surface: the triangle's outward normal
            return 0.0, self.normals[triangle].copy(), on_surface
        if not inside:
            return distance, (point - on_surface) / distance, on_surface
        level_with = distance + 1e-9 * max(1.0, self.size)  # the search's point is as near the kink
        near = self._near(point[None], np.zeros((1, 3)), np.array([level_with]))[1]
        closest = closest_on_triangles(point[None], self.a[near], self.b[near], self.c[near])[0]
        gaps = np.linalg.norm(closest - point, axis=1)
        toward = (closest - point) / gaps[:, None]  # the gradients of the triangles' -distance
        first = toward[np.argmin(gaps)]
        slope = float(first @ direction)
        level = gaps <= level_with
        crossing = level & (toward @ direction * slope < 0.0)  # another face, sloping the other way
        if not crossing.any():
            return -distance, first, on_surface
        other = toward[np.flatnonzero(crossing)[np.argmin(gaps[crossing])]]
        other_slope = float(other @ direction)
        weight = other_slope / (other_slope - slope)
        return -distance, weight * first + (1.0 - weight) * other, on_surface


@lru_cache(maxsize=32)
def _placed(obstacle: MeshObstacle) -> _Geometry:
    """The obstacle's triangles in the base frame, with what its queries need (once per obstacle)."""
    triangles = _read.get((obstacle.file, obstacle.sha256))
    if triangles is None:  # another process: read again, and check it is the same file
        triangles, found = _remember(Path(obstacle.file))
        if found != obstacle.sha256:
            raise StlError(f"{obstacle.file} has changed since it was read (SHA-256 {found}, not {obstacle.sha256})")
    rotation = rpy_matrix(obstacle.rpy)
    return _Geometry(obstacle.scale * triangles @ rotation.T + np.asarray(obstacle.position))


def _remember(path: Path) -> tuple[np.ndarray, str]:
    """The triangles of the STL file at ``path`` and its SHA-256, kept for :func:`_placed`."""
    triangles, sha256 = read_stl(path)
    with _read_lock:
        if len(_read) >= 32:
            _read.clear()
        _read[(str(path), sha256)] = triangles
    return triangles, sha256


def _cross(triangles: np.ndarray) -> np.ndarray:
    """Each triangle's ``(b - a) x (c - a)`` ``(T, 3)``: twice its area along its normal."""
    return np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])


def _areas(triangles: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(_cross(triangles), axis=1)


def _spread(points: np.ndarray, count: int) -> np.ndarray:
    """``count`` of ``points`` spread over them by farthest-point sampling (repeated if fewer)."""
    chosen = [0]
    distance = np.linalg.norm(points - points[0], axis=1)
    while len(chosen) < min(count, len(points)):
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return points[np.resize(np.array(chosen), count)]
