"""Distances between a robot's collision primitives and the obstacles around it, with python-fcl.

Robot primitives are FCL capsules (links) and spheres (ports, payload); obstacles are any shape of
:mod:`~modular_robots.obstacles`, each giving its FCL object and the closed forms it has.
Distances are signed: negative when the shapes overlap (penetration depth).
"""

from __future__ import annotations

import itertools
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import fcl
import numpy as np
import pinocchio as pin

from .obstacles import Obstacle, Witness
from .robot import RobotModel
from .self_collision import SelfCollisionModel

__all__ = [
    "CollisionModel",
    "Distances",
    "Approach",
    "closest_approach",
    "PATH_CLEARANCE",
    "CULL_DISTANCE",
    "reach_bound",
]

#: Clearance a joint-space path must keep from every obstacle to count as clear [m] (step C's
#: initial guess).
PATH_CLEARANCE = 0.02
#: Obstacles farther than this from everything the robot can reach [m] are left out of the
#: distance computations (every clearance the package asks for is far smaller).
CULL_DISTANCE = 1.0
#: Margin [m] by which a shape's distance bound must clear a threshold to decide a pair without
#: FCL; FCL measures a capsule or sphere and a sphere in closed form, within 2e-15 m of the exact
#: distance.
_BOUND_SLACK = 1e-9


@dataclass(frozen=True)
class Distances:
    """Signed distances ``(n_primitives, n_obstacles)`` and the witness points on the robot and
    on the obstacle, each ``(n_primitives, n_obstacles, 3)``, in the base frame."""

    distance: np.ndarray
    robot_points: np.ndarray
    obstacle_points: np.ndarray

    @property
    def minimum(self) -> float:
        return float(self.distance.min()) if self.distance.size else float("inf")


class CollisionModel:
    """FCL shapes of one robot's primitives and of the obstacles around it.

    ``primitives`` selects which of the robot's primitives take part (indices into
    ``robot.primitives``; default all of them). Only the obstacles within
    :data:`CULL_DISTANCE` of the robot's reach (:func:`reach_bound`) take part: ``obstacles`` is
    those, in the given order, and every per-obstacle result is indexed by them; a distance to an
    obstacle left out is always larger than :data:`CULL_DISTANCE`. ``cull=False`` keeps them all
    (for primitives placed by hand, out of the robot's reach). ``self_collision=True`` also makes
    :attr:`self_collision`, the robot's own checked pairs
    (:class:`~modular_robots.self_collision.SelfCollisionModel`), for step B to measure alongside.
    """

    def __init__(
        self,
        robot: RobotModel,
        obstacles: Sequence[Obstacle],
        primitives: Sequence[int] | None = None,
        cull: bool = True,
        self_collision: bool = False,
    ):
        self.robot = robot
        self.self_collision = SelfCollisionModel(robot) if self_collision else None
        reach = reach_bound(robot) + CULL_DISTANCE if cull else np.inf
        near = [i for i, o in enumerate(obstacles) if _bounding_gap(o) <= reach]
        self.obstacles = tuple(obstacles[i] for i in near)
        #: For each obstacle kept, its index in the list given.
        self.given_index = tuple(near)
        self.primitive_indices = tuple(range(len(robot.primitives)) if primitives is None else primitives)
        self._primitives = [robot.primitives[i] for i in self.primitive_indices]
        self._frame_ids = [int(robot.model.getFrameId(p.frame)) for p in self._primitives]
        slots: dict[tuple[float, float], int] = {}
        self._robot_objects = []
        for p in self._primitives:
            shape = (p.radius, p.length)
            slots[shape] = slot = slots.get(shape, -1) + 1  # same-shape primitives get objects of their own
            self._robot_objects.append(_shared_object(("primitive", *shape, slot), _primitive_object, p))
        self._prim_radii = np.array([p.radius for p in self._primitives], dtype=float)
        self._prim_lengths = np.array([p.length for p in self._primitives], dtype=float)
        #: Distance from each primitive's frame origin to its axis midpoint, along the frame's z [m].
        self._mid_offsets = np.array([p.offset + 0.5 * p.length for p in self._primitives], dtype=float)
        model = robot.model
        #: (P, nv): True where a joint velocity moves primitive i's frame.
        self._supports = np.zeros((len(self._primitives), robot.nv), dtype=bool)
        for i, fid in enumerate(self._frame_ids):
            for joint in model.supports[model.frames[fid].parentJoint]:
                if joint > 0:
                    start = model.joints[joint].idx_v
                    self._supports[i, start : start + model.joints[joint].nv] = True
        #: The obstacles by shape: each class, the indices of its obstacles and their batch.
        self._groups: list[tuple[type[Obstacle], list[int], Any]] = []
        for cls in dict.fromkeys(type(o) for o in self.obstacles):
            index = [j for j, o in enumerate(self.obstacles) if type(o) is cls]
            self._groups.append((cls, index, cls.batch([self.obstacles[j] for j in index])))
        self._obstacle_objects = [_shared_object(("obstacle", o), _obstacle_object, o) for o in self.obstacles]
        #: The closed-form obstacles that measure many capsules at once (``signed_distances``, as
        #: :meth:`~modular_robots.obstacles.MeshObstacle.signed_distances`), with that method.
        self._batched = [
            (j, o.signed_distances)
            for j, o in enumerate(self.obstacles)
            if o.closed_form and hasattr(o, "signed_distances")
        ]
        #: ``(P, O)``: False for the pairs not measured (see :meth:`_moved_toward`); None when
        #: every pair is.
        self._applies: np.ndarray | None = None
        if any(o.moving_only for o in self.obstacles):
            moved = self._moved_toward()
            applies = np.array([[not o.moving_only for o in self.obstacles]] * len(self._primitives), dtype=bool)
            applies = applies.reshape(len(self._primitives), len(self.obstacles)) | moved
            self._applies = None if applies.all() else applies

    @property
    def measured_pairs(self) -> np.ndarray:
        """``(P, O)``: the (primitive, obstacle) pairs measured; False where an obstacle that is
        ``moving_only`` (the floor) meets a primitive no joint moves toward it."""
        if self._applies is None:
            return np.ones((len(self._primitives), len(self.obstacles)), dtype=bool)
        return self._applies.copy()

    def _moved_toward(self, samples: int = 16) -> np.ndarray:
        """``(P, O)``: whether some configuration within the joint limits changes the primitive's
        distance to the obstacle (by more than 1e-9 m over ``samples`` seeded configurations and the
        zero one). An obstacle that is ``moving_only`` (the floor) is kept from those primitives
        only: what no joint moves toward it (the base, a joint's housing turning about a vertical
        axis) stands on it, at the height its design gives it."""
        if not self._primitives:
            return np.zeros((0, len(self.obstacles)), dtype=bool)
        model = self.robot.model
        low = np.where(np.isfinite(model.lowerPositionLimit), model.lowerPositionLimit, -np.pi)
        high = np.where(np.isfinite(model.upperPositionLimit), model.upperPositionLimit, np.pi)
        qs = np.vstack([np.zeros(self.robot.nv), np.random.default_rng(0).uniform(low, high, (samples, len(low)))])
        rot, mid, _ = self._placements(qs, jacobians=False)
        distances = np.empty((len(qs), len(self._primitives), len(self.obstacles)))
        for cls, index, batch in self._groups:
            distances[..., index] = cls.capsule_bounds(
                batch, rot[..., 2], mid, 0.5 * self._prim_lengths, self._prim_radii
            )[0]
        spread = distances.max(axis=0) - distances.min(axis=0)
        return ~np.isfinite(spread) | (spread > 1e-9)

    def distances(self, q: np.ndarray) -> Distances:
        """Signed distance of every (primitive, obstacle) pair at configuration ``q``."""
        dist, on_robot, on_obstacle = self.distances_many(np.asarray(q, dtype=float)[None])
        return Distances(dist[0], on_robot[0], on_obstacle[0])

    def distances_many(self, qs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`distances` at every row of ``qs`` ``(K, nv)``: signed distances ``(K, P, O)``
        [m] and witness points on the robot and on the obstacle ``(K, P, O, 3)``; a pair that is
        not measured (:meth:`_moved_toward`) is ``inf`` apart, its witnesses NaN. A shape with
        ``signed_distances`` measures all its pairs in one call."""
        qs = np.asarray(qs, dtype=float).reshape(-1, self.robot.nv)
        rot, mid, _ = self._placements(qs, jacobians=False)
        shape = (len(qs), len(self._robot_objects), len(self._obstacle_objects))
        dist = np.full(shape, np.inf)
        on_robot = np.full(shape + (3,), np.nan)
        on_obstacle = np.full(shape + (3,), np.nan)
        measure = np.ones(shape, dtype=bool)
        if self._applies is not None:
            measure &= self._applies
        for j, many in self._batched:
            ks, iis = np.nonzero(measure[:, :, j])
            measure[:, :, j] = False
            if ks.size:
                d, pr, po, _ = many(*self._capsules(mid[ks, iis], rot[ks, iis], iis))
                dist[ks, iis, j], on_robot[ks, iis, j], on_obstacle[ks, iis, j] = d, pr, po
        placed = None
        for k, i, j in zip(*(index.tolist() for index in np.nonzero(measure)), strict=True):
            if placed != (k, i):
                _place(self._robot_objects[i], rot[k, i], mid[k, i])
                placed = (k, i)
            dist[k, i, j], on_robot[k, i, j], on_obstacle[k, i, j], _ = self._pair_distance(i, j, mid[k, i], rot[k, i])
        return dist, on_robot, on_obstacle

    def _pair_distance(self, i: int, j: int, mid: np.ndarray, rot: np.ndarray) -> Witness:
        """Signed distance and witness points of primitive ``i``, placed (its FCL object) with its
        axis midpoint at ``mid`` and the rotation ``rot`` (axis: its third column), and obstacle
        ``j``: the obstacle's closed form
        (:meth:`~modular_robots.obstacles.Obstacle.signed_distance`) for a shape that has one
        everywhere, else FCL's while they are apart and the closed form when FCL reports an
        overlap (a shape without one there: FCL's contact, :func:`_penetration`)."""
        obstacle = self.obstacles[j]
        if obstacle.closed_form:
            exact = obstacle.signed_distance(mid, rot[:, 2], self._prim_lengths[i], self._prim_radii[i])
            assert exact is not None, f"{type(obstacle).__name__} is closed_form and must measure every pair"
            return exact
        result = fcl.DistanceResult()
        d = fcl.distance(self._robot_objects[i], self._obstacle_objects[j], _NEAREST_POINTS, result)
        inside = None
        if d < 0.0:
            inside = obstacle.signed_distance(mid, rot[:, 2], self._prim_lengths[i], self._prim_radii[i])
        if inside is not None:
            return inside
        if d < 0.0:  # FCL's distance is -1 on any overlap: no depth, no witness points
            return _penetration(self._robot_objects[i], self._obstacle_objects[j])
        on_robot, on_obstacle = result.nearest_points  # NumPy arrays, made anew on each read
        return d, on_robot, on_obstacle, None

    def closest(self, q: np.ndarray, derivatives: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """For each obstacle, the signed distance [m] to the closest primitive, ``(n_obstacles,)``,
        and (if asked) its exact gradient with respect to ``q``, ``(n_obstacles, nv)``; one row of
        :meth:`closest_many`."""
        dist, grad = self.closest_many(np.asarray(q, dtype=float)[None], derivatives)
        return dist[0], (None if grad is None else grad[0])

    def closest_many(self, qs: np.ndarray, derivatives: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`closest` at every row of ``qs`` ``(K, nv)``: distances ``(K, n_obstacles)`` [m]
        and gradients ``(K, n_obstacles, nv)``.

        Each shape's bounds on its distance to every primitive (vectorised over all
        configurations; exact for a sphere: the distance from its centre to the axis segment, less
        both radii) pick, per configuration and obstacle, the primitives whose lower bound is
        within :data:`_BOUND_SLACK` of the smallest upper bound (several on a tie, such as a
        joint's sphere and the end of the link capsule beside it); FCL measures those, and the
        smallest of its distances is the answer. The gradient of the distance between a convex
        primitive and a convex obstacle is ``n . dp/dq``: ``n`` the unit direction in which the
        distance grows (the shape's :meth:`~modular_robots.obstacles.Obstacle.normals`; for a
        sphere of centre ``c``, from ``c`` to its witness point), ``p`` the robot's witness point
        moving with its frame. With Pinocchio's world-frame joint Jacobian ``J`` restricted to the
        joints that carry the frame, ``dp/dq = J_v + J_w x p``, so
        ``n . dp/dq = n . J_v + (p x n) . J_w``.
        """
        qs = np.asarray(qs, dtype=float).reshape(-1, self.robot.nv)
        rot, mid, jac = self._placements(qs, derivatives)
        n_obstacles = len(self.obstacles)
        lower, upper = self._bounds(rot, mid)  # (K, P, O)
        measure = lower <= upper.min(axis=1, keepdims=True) + _BOUND_SLACK
        if self._applies is not None:
            measure &= self._applies
        dist = np.full(measure.shape, np.inf)
        on_robot = np.zeros(measure.shape + (3,))
        on_obstacle = np.zeros(measure.shape + (3,))
        given = np.full(measure.shape + (3,), np.nan)  # gradients the shapes give with their distances
        for j, many in self._batched:  # every pair of such a shape at once
            ks, iis = np.nonzero(measure[:, :, j])
            if ks.size:
                measure[ks, iis, j] = False
                d, pr, po, g = many(*self._capsules(mid[ks, iis], rot[ks, iis], iis))
                dist[ks, iis, j], on_robot[ks, iis, j], on_obstacle[ks, iis, j], given[ks, iis, j] = d, pr, po, g
        ks, iis, js = np.nonzero(measure)  # grouped by (k, i): each primitive is placed once
        found, placed = [], None
        for k, i, j in zip(ks.tolist(), iis.tolist(), js.tolist()):
            if placed != (k, i):
                _place(self._robot_objects[i], rot[k, i], mid[k, i])
                placed = (k, i)
            found.append(self._pair_distance(i, j, mid[k, i], rot[k, i]))
        if found:
            d, pr, po, gradients = zip(*found)
            dist[ks, iis, js], on_robot[ks, iis, js], on_obstacle[ks, iis, js] = d, pr, po
            for index, g in enumerate(gradients):
                if g is not None:
                    given[ks[index], iis[index], js[index]] = g
        best = dist.argmin(axis=1)  # (K, O)
        rows = np.arange(len(qs))[:, None]
        closest = dist[rows, best, np.arange(n_obstacles)]
        if not derivatives:
            return closest, None
        p = on_robot[rows, best, np.arange(n_obstacles)]  # (K, O, 3)
        given_best = given[rows, best, np.arange(n_obstacles)]
        has = ~np.isnan(given_best[..., 0])
        if has.all():
            normal = given_best
        else:
            normal = self._normals(p, on_obstacle[rows, best, np.arange(n_obstacles)])
            normal /= np.linalg.norm(normal, axis=2, keepdims=True)
            if has.any():
                normal = np.where(has[..., None], given_best, normal)
        grad = np.einsum("koc,kcv->kov", normal, jac[:, :3]) + np.einsum(
            "koc,kcv->kov", np.cross(p, normal), jac[:, 3:]
        )
        grad = grad * self._supports[best]
        if self._applies is not None:  # an obstacle no primitive here is kept from: no gradient
            grad[~np.isfinite(closest)] = 0.0
        return closest, grad

    def _capsules(self, mid: np.ndarray, rot: np.ndarray, primitives: np.ndarray) -> tuple[np.ndarray, ...]:
        """The capsules of ``primitives`` placed at ``mid`` ``(N, 3)`` and ``rot`` ``(N, 3, 3)``:
        midpoints, axes, lengths and radii, as a shape's ``signed_distances`` takes them."""
        return mid, rot[..., 2], self._prim_lengths[primitives], self._prim_radii[primitives]

    def _bounds(self, rot: np.ndarray, mid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds [m] on the signed distance of every (primitive, obstacle)
        pair, ``(K, P, O)``, from each shape's :meth:`~modular_robots.obstacles.Obstacle.capsule_bounds`."""
        shape = mid.shape[:2] + (len(self.obstacles),)
        if len(self._groups) == 1:  # one shape: its batch is every obstacle, in order
            cls, _, batch = self._groups[0]
            return self._masked(
                *cls.capsule_bounds(batch, rot[..., 2], mid, 0.5 * self._prim_lengths, self._prim_radii)
            )
        lower, upper = np.empty(shape), np.empty(shape)
        for cls, index, batch in self._groups:
            low, up = cls.capsule_bounds(batch, rot[..., 2], mid, 0.5 * self._prim_lengths, self._prim_radii)
            lower[..., index], upper[..., index] = low, up
        return self._masked(lower, upper)

    def _masked(self, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The bounds with the pairs not measured at ``inf``."""
        if self._applies is None:
            return lower, upper
        return np.where(self._applies, lower, np.inf), np.where(self._applies, upper, np.inf)

    def _normals(self, on_robot: np.ndarray, on_obstacle: np.ndarray) -> np.ndarray:
        """Each shape's :meth:`~modular_robots.obstacles.Obstacle.normals` at the witness points
        ``(K, O, 3)``."""
        if len(self._groups) == 1:
            cls, _, batch = self._groups[0]
            return cls.normals(batch, on_robot, on_obstacle)
        normal = np.empty_like(on_obstacle)
        for cls, index, batch in self._groups:
            normal[:, index] = cls.normals(batch, on_robot[:, index], on_obstacle[:, index])
        return normal

    def _placements(self, qs: np.ndarray, jacobians: bool):
        """Frame rotations ``(K, P, 3, 3)`` and axis midpoints ``(K, P, 3)`` of the primitives
        (where their FCL shapes are centred) and, if asked, Pinocchio's world-frame joint Jacobian
        ``(K, 6, nv)`` at every configuration."""
        model, data = self.robot.model, self.robot.data
        frame_ids = self._frame_ids
        poses = np.empty((len(qs), len(frame_ids), 4, 4))
        jac = np.empty((len(qs), 6, self.robot.nv)) if jacobians else None
        for k, q in enumerate(qs):
            if jac is not None:
                pin.computeJointJacobians(model, data, q)
                pin.updateFramePlacements(model, data)
                jac[k] = data.J.reshape(6, -1)  # one joint: Pinocchio gives (6,), not (6, 1)
            else:
                pin.framesForwardKinematics(model, data, q)
            # One copy of every frame's placement: data.oMf[fid] costs about 0.8 us a frame, the
            # whole list 1.6 us (a 5-DOF candidate's 32 configurations: 0.34 ms instead of 0.83 ms).
            placements = data.oMf.tolist()
            poses[k] = [placements[fid].homogeneous for fid in frame_ids]
        rot = poses[:, :, :3, :3]
        mid = poses[:, :, :3, 3] + self._mid_offsets[:, None] * rot[..., 2]
        return rot, mid, jac

    def nearest(self, q: np.ndarray) -> tuple[float, int, int]:
        """The smallest signed distance [m] between the robot and an obstacle at ``q``, and its
        pair (primitive and obstacle indices; inf and -1, -1: no pair measured), as
        :meth:`distances` measures it: the pairs are measured in the order of their shapes' lower
        bounds, until the next bound is above the nearest distance found (a box or cylinder
        measures a pair by a search along the link, so most of them are then never measured); a
        shape that measures many pairs at once (a mesh) first measures all of its pairs whose
        lower bound is below every pair's smallest upper bound."""
        rot, mid, _ = self._placements(np.asarray(q, dtype=float)[None], jacobians=False)
        rot, mid = rot[0], mid[0]
        if not self.obstacles or not len(self._primitives):
            return math.inf, -1, -1
        lower, upper = self._bounds(rot[None], mid[None])
        lower, upper = lower[0], upper[0]
        best, pair = math.inf, (-1, -1)
        for j, many in self._batched:  # every pair that may be nearest at once
            rows = np.flatnonzero(np.isfinite(lower[:, j]) & (lower[:, j] <= upper.min() + _BOUND_SLACK))
            lower[:, j] = math.inf
            if rows.size:
                d = many(*self._capsules(mid[rows], rot[rows], rows))[0]
                if d.min() < best:
                    best, pair = float(d.min()), (int(rows[np.argmin(d)]), j)
        placed = None
        for flat in np.argsort(lower, axis=None, kind="stable").tolist():
            i, j = divmod(flat, lower.shape[1])
            if not lower[i, j] - _BOUND_SLACK < best:
                break
            if placed != i:
                _place(self._robot_objects[i], rot[i], mid[i])
                placed = i
            distance = float(self._pair_distance(i, j, mid[i], rot[i])[0])
            if distance < best:
                best, pair = distance, (i, j)
        return best, pair[0], pair[1]

    def min_distance(self, q: np.ndarray) -> float:
        """Smallest signed distance between the robot and any obstacle [m] (inf: no obstacle)."""
        return self.nearest(q)[0]

    def path_clear(self, path: np.ndarray, clearance: float = PATH_CLEARANCE, samples: int = 24) -> bool:
        """True if the joint-space polyline ``path`` ``(K, nv)``, sampled ``samples`` times per
        segment, keeps ``clearance`` [m] from every obstacle (stops at the first segment that does not)."""
        path = np.asarray(path, dtype=float)
        if not self.obstacles:
            return True
        s = np.linspace(0.0, 1.0, samples + 1)[:, None]
        return all(self._keeps(a + s * (b - a), clearance) for a, b in itertools.pairwise(path))

    def _keeps(self, qs: np.ndarray, clearance: float) -> bool:
        """True if every configuration of ``qs`` ``(K, nv)`` keeps ``clearance`` [m] from every
        obstacle, as :meth:`closest_many` measures it.

        The shapes' distance bounds of :meth:`closest_many` decide most pairs without FCL: a pair
        whose upper bound is below the clearance is too near, one whose lower bound is above it is
        clear. FCL measures only the pairs within :data:`_BOUND_SLACK` of the clearance or between
        the bounds, so the answer is the one that FCL's distances give.
        """
        rot, mid, _ = self._placements(qs, jacobians=False)
        lower, upper = self._bounds(rot, mid)  # (K, P, O)
        if upper.min() < clearance - _BOUND_SLACK:
            return False
        undecided = lower < clearance + _BOUND_SLACK
        for j, many in self._batched:  # an axis that meets the shape need not be measured: too near
            ks, iis = np.nonzero(undecided[:, :, j])
            undecided[:, :, j] = False
            if not ks.size:
                continue
            deep = bool(np.any(-self._prim_radii[iis] >= clearance))
            if np.any(many(*self._capsules(mid[ks, iis], rot[ks, iis], iis), deep)[0] < clearance):
                return False
        placed = None
        for k, i, j in zip(*(index.tolist() for index in np.nonzero(undecided))):
            if placed != (k, i):
                _place(self._robot_objects[i], rot[k, i], mid[k, i])
                placed = (k, i)
            if self._pair_distance(i, j, mid[k, i], rot[k, i])[0] < clearance:
                return False
        return True

    def in_collision(self, q: np.ndarray) -> bool:
        """True if any primitive touches or overlaps any obstacle."""
        return self.min_distance(q) <= 0.0


@dataclass(frozen=True)
class Approach:
    """Where a motion comes closest to an obstacle: the signed ``clearance`` [m] at time ``t``
    [s], between the robot primitive ``primitive`` and ``obstacle`` (its index in the list given)."""

    clearance: float
    t: float
    primitive: str
    obstacle: int


def closest_approach(collision: CollisionModel, times: np.ndarray, qs: np.ndarray) -> Approach | None:
    """The closest approach of the motion ``qs`` ``(K, nv)`` at ``times`` ``(K,)`` [s] to the
    obstacles of ``collision`` (the index is in the list it was given; None: none in reach)."""
    if not collision.obstacles:
        return None
    dist = collision.distances_many(qs)[0]
    k, i, j = (int(n) for n in np.unravel_index(int(np.argmin(dist)), dist.shape))  # the first smallest
    name = collision.robot.primitives[collision.primitive_indices[i]].name
    return Approach(float(dist[k, i, j]), float(times[k]), name, collision.given_index[j])


def reach_bound(robot: RobotModel) -> float:
    """An upper bound on the distance from the base origin of any point of the robot's collision
    primitives, in any configuration [m]: along the chain, each joint placement's offset (plus a
    prismatic joint's largest travel), then the primitive's offset from its frame, its axis and
    its radius."""
    model = robot.model
    reach = np.zeros(model.njoints)
    for j in range(1, model.njoints):
        joint = model.joints[j]
        travel = 0.0
        if joint.shortname().startswith("JointModelP") and joint.nq == 1:
            travel = max(abs(model.lowerPositionLimit[joint.idx_q]), abs(model.upperPositionLimit[joint.idx_q]))
        reach[j] = reach[model.parents[j]] + np.linalg.norm(model.jointPlacements[j].translation) + travel
    out = 0.0
    for p in robot.primitives:
        frame = model.frames[model.getFrameId(p.frame)]
        extent = max(abs(p.offset), abs(p.offset + p.length)) + p.radius
        out = max(out, reach[frame.parentJoint] + np.linalg.norm(frame.placement.translation) + extent)
    return float(out)


# python-fcl (0.7) releases a CollisionObject with free() instead of delete, so the shared_ptr to
# its geometry that the object holds is never destroyed: about 35 bytes lost per object (1.5 MB per
# 50,000 made). Step B makes a collision model for each composition that reaches its collision
# test, so over millions of compositions a worker grew without bound (0.3 kB per nine-joint chain).
# The objects are therefore made once per shape (or obstacle) and slot, and shared by the models
# of a thread: a model places its objects right before every query it makes with them.
_pool = threading.local()
#: Objects a thread keeps for reuse; past this many (obstacles of many scenarios) it starts over.
POOL_SIZE = 4096


def _shared_object(key: tuple, make: Callable, item) -> fcl.CollisionObject:
    objects = getattr(_pool, "objects", None)
    if objects is None or len(objects) >= POOL_SIZE:
        objects = _pool.objects = {}
    found = objects.get(key)
    if found is None:
        found = objects[key] = make(item)
    return found


def _primitive_object(p) -> fcl.CollisionObject:
    return fcl.CollisionObject(fcl.Capsule(p.radius, p.length) if p.length > 0 else fcl.Sphere(p.radius))


def _obstacle_object(o: Obstacle) -> fcl.CollisionObject:
    return o.collision_object()


def _bounding_gap(o: Obstacle) -> float:
    """A lower bound on the distance [m] from the base origin to any point of ``o``."""
    center, radius = o.bounding_sphere()
    return float(np.linalg.norm(center)) - radius


def _place(obj: fcl.CollisionObject, rot: np.ndarray, translation: np.ndarray) -> None:
    """Set ``obj``'s pose: the same transform as ``setTransform(fcl.Transform(rot, translation))``,
    in half the time."""
    obj.setRotation(rot)
    obj.setTranslation(translation)


#: FCL only reads a request, so one serves every query.
_NEAREST_POINTS = fcl.DistanceRequest(enable_nearest_points=True)
_CONTACT = fcl.CollisionRequest(num_max_contacts=1, enable_contact=True)


def _penetration(robot: fcl.CollisionObject, obstacle: fcl.CollisionObject) -> Witness:
    """The signed distance of overlapping FCL objects, minus FCL's penetration depth, and
    witness points on its contact line (the robot's one the depth away from the obstacle's,
    against the contact normal, so that ``on_robot - on_obstacle`` points where the distance
    grows, as it does for shapes apart)."""
    result = fcl.CollisionResult()
    fcl.collide(robot, obstacle, _CONTACT, result)
    if not result.contacts:  # touching, by FCL's distance and not by its collision test: apart
        return (
            0.0,
            np.array(robot.getTranslation(), dtype=float),
            np.array(obstacle.getTranslation(), dtype=float),
            None,
        )
    contact = result.contacts[0]
    normal, depth = np.asarray(contact.normal, dtype=float), float(contact.penetration_depth)
    middle = np.asarray(contact.pos, dtype=float)
    return -depth, middle - 0.5 * depth * normal, middle + 0.5 * depth * normal, None
