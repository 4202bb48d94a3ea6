"""A triangle-mesh obstacle read from an STL file (a machine, a fixture, a cell's housing).

FCL's object for it is a BVH of the triangles (``fcl.BVHModel``), not their convex hull
(``fcl.Convex``): a hull fills a machine's working space or a window's opening, where the robot
must reach, and a mesh obstacle is there to keep those. The distances are not FCL's, though
(:attr:`MeshObstacle.closed_form`): FCL measures to a BVH's surface only, so a link wholly inside
the mesh would be reported clear, and its capsule-triangle distances (GJK) were off by up to
1.2e-4 m and their directions by 2.5e-3 on 200 capsules near the CoBRA machine mesh, which the
gradient would inherit. The shape measures every pair itself, exactly, with NumPy
(:mod:`._triangles`): the distance from the capsule's axis to the nearest triangles (those whose
bounding boxes and spheres may hold the nearest point), and, for an axis that crosses the surface
or lies inside, the depth of its deepest point, found by sampling the axis and golden-section
search. Each query looks at every triangle's bounds, so its time grows with the mesh's size
(0.3 to 0.6 ms a pair for the 748 triangles of CoBRA's machine; :data:`~._stl.MAX_TRIANGLES`).
Inside and outside are the generalised winding number's, which holds for meshes with small gaps
or overlapping parts (a mesh that is not closed has no inside, and there its answer is a guess).

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

from ._geometry import pose_columns, rpy_matrix
from ._json import json_number, json_vector
from ._stl import StlError, read_stl, welded
from ._triangles import closest_on_triangles, segment_crossings, segment_triangles, winding_numbers
from .base import Obstacle, Witness, members
from .box import BoxObstacle

if TYPE_CHECKING:
    import fcl

    from .._yamlio import Fields

__all__ = ["MeshObstacle", "SURFACE_SAMPLES"]

#: Surface points (mesh vertices) whose distance bounds a capsule's from above (capsule_bounds).
SURFACE_SAMPLES = 64
#: Points along a capsule's axis sampled for its deepest point, and the golden-section steps that
#: refine the best two (the bracket shrinks to 0.618^60 = 3e-13 of two samples' spacing).
_AXIS_SAMPLES, _SEARCH_STEPS = 32, 60
#: Triangles measured first (those with the smallest distance bounds), whose nearest distance
#: then bounds which others can be nearer.
_FIRST = 8
#: The most (point, triangle) pairs a query holds in its arrays at once.
_PAIRS = 1_000_000
_GOLD = (math.sqrt(5.0) - 1.0) / 2.0
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
        rpy = f.vector("rpy", 3, default=(0.0, 0.0, 0.0))
        f.done()
        if not np.any(_areas(scale * triangles) > 0.0):
            raise f.fail("file", f"{path}: every triangle has zero area at scale {scale:g}")
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
    def batch(cls, obstacles: Sequence[Obstacle]) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
        """The bounding boxes as :class:`~.box.BoxObstacle`'s batch (centres, rotations, half
        sizes [m]) and :data:`SURFACE_SAMPLES` surface points of each ``(O, S, 3)`` [m]."""
        meshes = [o._geometry for o in members(obstacles, MeshObstacle)]
        boxes = (
            np.array([g.box_center for g in meshes]).reshape(-1, 3),
            np.array([g.box_rotation for g in meshes]).reshape(-1, 3, 3),
            np.array([g.box_half for g in meshes]).reshape(-1, 3),
        )
        return boxes, np.array([g.samples for g in meshes]).reshape(-1, SURFACE_SAMPLES, 3)

    @classmethod
    def capsule_bounds(
        cls, batch: Any, axis: np.ndarray, mid: np.ndarray, half_length: np.ndarray, radius: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Below, the distance to the mesh's bounding box (which holds its inside); above, the
        distance to the nearest of its surface samples."""
        boxes, samples = batch
        lower = BoxObstacle.capsule_bounds(boxes, axis, mid, half_length, radius)[0]
        offset = samples[None, None] - mid[:, :, None, None]  # (K, P, O, S, 3)
        half = half_length[None, :, None, None]
        along = np.clip(np.einsum("kposc,kpc->kpos", offset, axis), -half, half)
        apart = np.linalg.norm(offset - along[..., None] * axis[:, :, None, None], axis=-1)
        return lower, apart.min(axis=-1) - radius[None, :, None]

    def signed_distance(self, mid: np.ndarray, axis: np.ndarray, length: float, radius: float) -> Witness:
        g = self._geometry
        axis = np.asarray(axis, dtype=float)
        start, direction = np.asarray(mid, dtype=float) - 0.5 * length * axis, length * axis
        on_axis, on_mesh = g.closest(start, direction)
        gap = float(np.linalg.norm(on_axis - on_mesh))
        if gap > 1e-9 * g.size and not g.inside(on_axis[None])[0]:  # wholly outside
            normal = (on_axis - on_mesh) / gap
            return gap - radius, on_axis - radius * normal, on_mesh, normal
        t, inside = g.deepest(start, direction)
        point = start + t * direction
        depth, gradient, on_surface = g.gradient(point, inside, direction)
        size = float(np.linalg.norm(gradient))
        across = gradient / size if size > 0.0 else g.normals[g.nearest(point[None])[2][0]]
        return depth - radius, point - radius * across, on_surface, gradient

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

    def __init__(self, triangles: np.ndarray):
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

    def _lower(self, start: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """Lower bounds ``(..., T)`` on the distance from segments (``start`` and ``direction``
        ``(..., 3)``) to each triangle: the larger of the gap between their boxes and the
        distance to the triangle's centroid less its reach."""
        end = start + direction
        low, high = np.minimum(start, end)[..., None, :], np.maximum(start, end)[..., None, :]
        gap = np.maximum(np.maximum(self.low - high, low - self.high), 0.0)
        offset = self.centroid - start[..., None, :]
        span = np.einsum("...c,...c->...", direction, direction)[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip(np.einsum("...tc,...c->...t", offset, direction) / span, 0.0, 1.0)
        t = np.where(span > 0.0, t, 0.0)
        apart = np.linalg.norm(offset - t[..., None] * direction[..., None, :], axis=-1)
        return np.maximum(np.sqrt(np.einsum("...c,...c->...", gap, gap)), apart - self.reach)

    def closest(self, start: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The closest points of a segment and the surface: on the segment and on the surface.
        The triangles with the smallest lower bounds are measured first; their nearest distance
        then leaves only the triangles whose bound is below it to measure."""
        lower = self._lower(start, direction)
        first = np.argpartition(lower, _FIRST)[:_FIRST] if len(lower) > _FIRST else np.arange(len(lower))
        on_segment, on_surface = segment_triangles(start, direction, self.a[first], self.b[first], self.c[first])
        gaps = np.linalg.norm(on_segment - on_surface, axis=1)
        best = int(np.argmin(gaps))
        lower[first] = np.inf
        rest = np.flatnonzero(lower <= gaps[best])
        if rest.size:
            more = segment_triangles(start, direction, self.a[rest], self.b[rest], self.c[rest])
            more_gaps = np.linalg.norm(more[0] - more[1], axis=1)
            k = int(np.argmin(more_gaps))
            if more_gaps[k] < gaps[best]:
                return more[0][k], more[1][k]
        return on_segment[best], on_surface[best]

    def nearest(self, points: np.ndarray, among: np.ndarray | None = None):
        """Distances ``(M,)`` [m] from points ``(M, 3)`` to the surface (``among``: only these
        triangles), the nearest surface points ``(M, 3)`` and the triangles that hold them."""
        chunk = max(1, _PAIRS // len(self.a))
        if len(points) > chunk:  # a few points at a time: arrays of (points, triangles, 3)
            parts = [self.nearest(points[i : i + chunk], among) for i in range(0, len(points), chunk)]
            return tuple(np.concatenate(p) for p in zip(*parts))
        if among is None:
            lower = self._lower(points, np.zeros_like(points))  # (M, T)
            first = np.unique(np.argpartition(lower, _FIRST, axis=1)[:, :_FIRST]) if lower.shape[1] > _FIRST else None
            if first is not None:
                bound = np.linalg.norm(
                    points[:, None] - closest_on_triangles(points, self.a[first], self.b[first], self.c[first]), axis=2
                ).min(axis=1)
                among = np.flatnonzero((lower <= bound[:, None]).any(axis=0))
            else:
                among = np.arange(len(self.a))
        closest = closest_on_triangles(points, self.a[among], self.b[among], self.c[among])  # (M, N, 3)
        distance = np.linalg.norm(points[:, None] - closest, axis=2)
        best = np.argmin(distance, axis=1)
        rows = np.arange(len(points))
        return distance[rows, best], closest[rows, best], among[best]

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Whether each point ``(M, 3)`` is inside: a winding number of magnitude 1/2 or more
        (outside the mesh's box without asking)."""
        out = np.zeros(len(points), dtype=bool)
        near = np.all(np.abs(points - self.box_center) <= self.box_half, axis=1)
        if near.any():
            out[near] = np.abs(winding_numbers(points[near], self.a, self.b, self.c)) >= 0.5
        return out

    def deepest(self, start: np.ndarray, direction: np.ndarray) -> tuple[float, bool]:
        """The parameter in [0, 1] of the segment's point of smallest signed distance, and
        whether that point is inside: the best of :data:`_AXIS_SAMPLES` + 1 samples, refined by
        golden-section search between the neighbours of the two best samples that are local
        minima. Inside and outside along the segment: the winding number at its start, changed
        by one at each triangle the segment crosses."""
        start_winding = float(winding_numbers(start[None], self.a, self.b, self.c)[0])
        if not np.any(direction):
            return 0.0, abs(start_winding) >= 0.5
        crossings, jumps = segment_crossings(start, direction, self.a, self.b, self.c)
        crossed = ~np.isnan(crossings)
        crossings, jumps = crossings[crossed], jumps[crossed]

        def inside(t: np.ndarray) -> np.ndarray:
            return np.abs(start_winding + (jumps * (crossings <= t[:, None])).sum(axis=1)) >= 0.5

        t = np.linspace(0.0, 1.0, _AXIS_SAMPLES + 1)
        distance = self.nearest(start + t[:, None] * direction)[0]
        f = np.where(inside(t), -distance, distance)
        padded = np.concatenate([[np.inf], f, [np.inf]])
        minima = np.flatnonzero((f <= padded[:-2]) & (f <= padded[2:]))
        seeds = minima[np.argsort(f[minima])[:2]]
        low, high = t[np.maximum(seeds - 1, 0)], t[np.minimum(seeds + 1, _AXIS_SAMPLES)]
        # the triangles that may be nearest to a point between two samples' neighbours: nearer
        # than the samples' distance plus half the bracket's length (the distance is 1-Lipschitz)
        within = np.maximum(distance[np.maximum(seeds - 1, 0)], distance[np.minimum(seeds + 1, _AXIS_SAMPLES)])
        within = within + 0.5 * (high - low) * float(np.linalg.norm(direction))
        bracket = self._lower(start + low[:, None] * direction, (high - low)[:, None] * direction)
        among = np.flatnonzero((bracket <= within[:, None]).any(axis=0))

        def along(s: np.ndarray) -> np.ndarray:
            d = self.nearest(start + s[:, None] * direction, among)[0]
            return np.where(inside(s), -d, d)

        a, b = high - _GOLD * (high - low), low + _GOLD * (high - low)
        fa, fb = along(a), along(b)
        for _ in range(_SEARCH_STEPS):
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
        found = np.concatenate([0.5 * (low + high), t[seeds]])
        values = np.concatenate([along(found[: len(seeds)]), f[seeds]])
        best = int(np.argmin(values))
        return float(found[best]), bool(inside(found[best : best + 1])[0])

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
        near = np.flatnonzero(self._lower(point, np.zeros(3)) <= level_with)
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
