"""Distances between a robot's own collision primitives (self-collision), in closed form.

Every primitive is a segment with a radius (a capsule; a sphere is a segment of zero length), so
the signed distance of two is ``|p_a - p_b| - r_a - r_b``, ``p_a`` and ``p_b`` the closest points
of their axes (:func:`~modular_robots.obstacles._geometry.segment_parameters`): no FCL, and
vectorised over configurations and pairs.

**Which pairs are checked** (:func:`checked_pairs`; ``docs/formats.md``, ``task.self_collision``).
A pair of primitives is checked if and only if

1. both belong to modules of the chain and their modules are at least two apart in it (the
   payload counts as the module after the last): a module's own shapes, and the shapes of two
   directly connected modules, meet at their joint by design;
2. some joint changes their distance: it differs among :data:`PAIR_SAMPLES` seeded random
   configurations within the joint limits and the zero configuration (by more than 1e-9 m).
   Otherwise the pair is as it was built in every configuration, clear or not (a sphere on a roll
   axis and a link along it, say); and
3. they do not overlap in every one of those configurations: such a pair overlaps *by
   construction* (two shapes held together across a short joint), and no motion separates it.

Timor (``PinRobot._remove_home_collisions``) checks every pair of bodies but those in collision in
the home configuration. Rule 1 is the part of that which holds by design; rule 3 asks for an
overlap in every configuration sampled, not only in one, so a pair that merely happens to overlap
at ``q = 0`` (an arm folded onto itself) is still checked. A pair that overlaps in some
configurations only is checked: those are the collisions to find. Primitives that belong to no
module (``module == -1``: a robot from any URDF) are in no pair.

Step C keeps apart only the checked pairs that some configuration within the joint limits could
bring within its clearance margin (:meth:`SelfCollisionModel.within`): a branch and bound over the
joints between a pair's two primitives proves most pairs always farther apart (a link and one
three modules on, along a roll axis); their rows would never bind. Step B and verification
measure every checked pair.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .obstacles._geometry import segment_parameters
from .robot import RobotModel

__all__ = ["SelfCollisionModel", "SelfContact", "checked_pairs", "PAIR_SAMPLES"]

#: Seeded random configurations (besides ``q = 0``) over which a pair's distance must change to
#: be checked, and in which it must overlap to be left out as overlapping by construction.
PAIR_SAMPLES = 32
#: A pair whose sampled distances spread by no more than this [m] does not move.
_STILL = 1e-9
#: Most boxes of joint values :func:`_always_beyond` keeps at once before it gives up (and the
#: pair keeps its rows), and most halvings.
_BOXES, _HALVINGS = 4096, 60


@dataclass(frozen=True)
class SelfContact:
    """The closest checked pair at one configuration: its signed ``distance`` [m] and the names
    of its two primitives."""

    distance: float
    first: str
    second: str


#: Per Pinocchio model (which :func:`~modular_robots.robot.robot_model` shares among the robots of
#: a composition) and primitives: the checked pairs and their largest sampled distances (key None)
#: and, per threshold [m], the pairs that may come within it (:meth:`SelfCollisionModel.within`).
_found: weakref.WeakKeyDictionary[pin.Model, dict] = weakref.WeakKeyDictionary()


def _known(robot: RobotModel) -> dict:
    return _found.setdefault(robot.model, {}).setdefault(robot.primitives, {})


def checked_pairs(robot: RobotModel) -> np.ndarray:
    """The pairs of ``robot``'s primitives that self-collision checks (module docstring), ``(P,
    2)`` indices into ``robot.primitives``, the first earlier in the chain; found once per model
    and primitives."""
    return _selection(robot)[0]


def _selection(robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """:func:`checked_pairs` and each one's largest distance [m] among the configurations sampled."""
    known = _known(robot)
    if None not in known:
        known[None] = _select(robot)
    return known[None]


def _select(robot: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    modules = [p.module for p in robot.primitives]
    candidates = [
        (i, j)
        for i in range(len(modules))
        for j in range(i + 1, len(modules))
        if modules[i] >= 0 and modules[j] >= 0 and abs(modules[i] - modules[j]) >= 2
    ]
    if not candidates:
        return np.zeros((0, 2), dtype=int), np.zeros(0)
    pairs = np.array([(i, j) if modules[i] <= modules[j] else (j, i) for i, j in candidates], dtype=int)
    model = robot.model
    low = np.where(np.isfinite(model.lowerPositionLimit), model.lowerPositionLimit, -np.pi)
    high = np.where(np.isfinite(model.upperPositionLimit), model.upperPositionLimit, np.pi)
    qs = np.vstack([np.zeros(robot.nq), np.random.default_rng(0).uniform(low, high, (PAIR_SAMPLES, robot.nq))])
    distance = SelfCollisionModel(robot, pairs).distances(qs)[0]
    moving = distance.max(axis=0) - distance.min(axis=0) > _STILL
    apart = (distance > 0.0).any(axis=0)
    checked, farthest = pairs[moving & apart], distance.max(axis=0)[moving & apart]
    checked.setflags(write=False)
    farthest.setflags(write=False)
    return checked, farthest


class SelfCollisionModel:
    """Signed distances of pairs of ``robot``'s primitives (``pairs`` ``(P, 2)``; default
    :func:`checked_pairs`) and their exact gradients."""

    def __init__(self, robot: RobotModel, pairs: np.ndarray | None = None):
        self.robot = robot
        self.checked = pairs is None
        self.pairs = checked_pairs(robot) if pairs is None else np.asarray(pairs, dtype=int).reshape(-1, 2)
        #: For the checked pairs: each one's largest distance [m] among the configurations the
        #: rule samples (a bound on the margin step C can ask of it).
        self.farthest = _selection(robot)[1] if pairs is None else None
        used = sorted(set(self.pairs.ravel().tolist()))
        #: The primitives in some pair, and where each pair's two sit among them.
        self._used = used
        local = {p: k for k, p in enumerate(used)}
        self._first = np.array([local[i] for i in self.pairs[:, 0]], dtype=int)
        self._second = np.array([local[j] for j in self.pairs[:, 1]], dtype=int)
        primitives = [robot.primitives[i] for i in used]
        model = robot.model
        self._frame_ids = [int(model.getFrameId(p.frame)) for p in primitives]
        self._offsets = np.array([p.offset for p in primitives], dtype=float)
        self._lengths = np.array([p.length for p in primitives], dtype=float)
        radii = np.array([p.radius for p in primitives], dtype=float)
        self._radii = radii[self._first] + radii[self._second]
        supports = np.zeros((len(primitives), robot.nv), dtype=bool)
        for k, fid in enumerate(self._frame_ids):
            for joint in model.supports[model.frames[fid].parentJoint]:
                if joint > 0:
                    start = model.joints[joint].idx_v
                    supports[k, start : start + model.joints[joint].nv] = True
        #: ``(P, nv)``: True where a joint velocity moves the pair's first (second) primitive.
        self._support_a, self._support_b = supports[self._first], supports[self._second]

    def __len__(self) -> int:
        return len(self.pairs)

    def distances(self, qs: np.ndarray, derivatives: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """Signed distance [m] of every checked pair at every row of ``qs`` ``(K, nq)``,
        ``(K, P)``, and (if asked) its gradient with respect to ``q``, ``(K, P, nv)``.

        With ``p_a``, ``p_b`` the closest points of the two axes and ``n`` the unit vector from
        ``p_b`` to ``p_a``, the gradient is ``n . (dp_a/dq - dp_b/dq)``, each point moving with its
        frame: ``dp/dq = J_v + J_w x p`` over the joints that carry the frame (Pinocchio's
        world-frame joint Jacobian), so ``n . dp/dq = n . J_v + (p x n) . J_w``. When the axes
        cross (``p_a == p_b``, a deep overlap) ``n`` is taken normal to both axes.
        """
        qs = np.asarray(qs, dtype=float).reshape(-1, self.robot.nq)
        shape = (len(qs), len(self.pairs))
        if not len(self.pairs):
            return np.zeros(shape), (np.zeros(shape + (self.robot.nv,)) if derivatives else None)
        start, axis, jac = self._axes(qs, derivatives)
        a0, da = start[:, self._first], axis[:, self._first]
        b0, db = start[:, self._second], axis[:, self._second]
        s, t = segment_parameters(a0, da, b0, db)
        pa, pb = a0 + s[..., None] * da, b0 + t[..., None] * db
        gap = pa - pb
        length = np.linalg.norm(gap, axis=-1)
        distance = length - self._radii
        if not derivatives:
            return distance, None
        assert jac is not None
        normal = _unit_normals(gap, length, da, db)
        jv, jw = jac[:, :3], jac[:, 3:]
        along = np.einsum("kpc,kcv->kpv", normal, jv)
        turn_a = np.einsum("kpc,kcv->kpv", np.cross(pa, normal), jw)
        turn_b = np.einsum("kpc,kcv->kpv", np.cross(pb, normal), jw)
        grad = (along + turn_a) * self._support_a - (along + turn_b) * self._support_b
        return distance, grad

    def _axes(self, qs: np.ndarray, jacobians: bool):
        """Axis start points and axis vectors (start to end) ``(K, U, 3)`` of the primitives in
        some pair and, if asked, the world-frame joint Jacobian ``(K, 6, nv)``."""
        model, data = self.robot.model, self.robot.data
        poses = np.empty((len(qs), len(self._frame_ids), 4, 4))
        jac = np.empty((len(qs), 6, self.robot.nv)) if jacobians else None
        for k, q in enumerate(qs):
            if jac is not None:
                pin.computeJointJacobians(model, data, q)
                pin.updateFramePlacements(model, data)
                jac[k] = data.J.reshape(6, -1)  # one joint: Pinocchio gives (6,), not (6, 1)
            else:
                pin.framesForwardKinematics(model, data, q)
            placements = data.oMf.tolist()
            poses[k] = [placements[fid].homogeneous for fid in self._frame_ids]
        z = poses[:, :, :3, 2]
        start = poses[:, :, :3, 3] + self._offsets[:, None] * z
        return start, self._lengths[:, None] * z, jac

    def min_distance(self, q: np.ndarray) -> float:
        """The smallest signed distance [m] of a checked pair at ``q`` (inf: no pair)."""
        return self.closest(q).distance

    def closest(self, q: np.ndarray) -> SelfContact:
        """The closest checked pair at ``q`` (distance inf and no names: no pair)."""
        if not len(self.pairs):
            return SelfContact(float("inf"), "", "")
        distance = self.distances(np.asarray(q, dtype=float)[None])[0][0]
        k = int(np.argmin(distance))
        first, second = (self.robot.primitives[i].name for i in self.pairs[k])
        return SelfContact(float(distance[k]), first, second)

    def within(self, threshold: float) -> np.ndarray:
        """Indices of the pairs that some configuration within the joint limits may bring
        closer than ``threshold`` [m] (step C's rows; the others never come that close), found
        once per model, primitives and threshold.

        A pair qualifies unless :func:`_always_beyond` proves it farther apart everywhere (the
        pairs with the same joints between them together)."""
        known = _known(self.robot) if self.checked else {}
        if threshold not in known:
            groups: dict[tuple[int, ...], tuple[_Chain, list[int], list[tuple[int, int]]]] = {}
            near = []
            for k in range(len(self.pairs)):
                found = _chain(self.robot, *self.pairs[k])
                if found is None:
                    near.append(k)
                    continue
                chain, first, second = found
                group = groups.setdefault(chain.joints, (chain, [], []))
                group[1].append(k)
                group[2].append((first, second))
            for chain, rows, pairs in groups.values():
                beyond = _always_beyond(self.robot, chain, pairs, threshold)
                near.extend(k for k, far in zip(rows, beyond) if not far)
            known[threshold] = np.array(sorted(near), dtype=int)
        return known[threshold]


def _unit_normals(gap: np.ndarray, length: np.ndarray, da: np.ndarray, db: np.ndarray) -> np.ndarray:
    """``gap / length`` where the closest points differ; where they coincide, a unit vector normal
    to both axes (to the first alone if they are parallel; the x axis if both are points)."""
    crossed = length <= 1e-12
    normal = gap / np.where(crossed, 1.0, length)[..., None]
    if not crossed.any():
        return normal
    fallback = np.cross(da, db)
    for other in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)):
        flat = np.linalg.norm(fallback, axis=-1, keepdims=True) <= 1e-12
        fallback = np.where(flat, np.cross(da, np.array(other)), fallback)
    flat = np.linalg.norm(fallback, axis=-1, keepdims=True) <= 1e-12
    fallback = np.where(flat, np.array([1.0, 0.0, 0.0]), fallback)
    fallback /= np.linalg.norm(fallback, axis=-1, keepdims=True)
    return np.where(crossed[..., None], fallback, normal)


@dataclass(frozen=True)
class _Chain:
    """The joints between two primitives of a serial chain, each 1-DOF about a fixed unit
    ``axis`` of its frame: ``revolute`` or prismatic, its ``low`` and ``high`` values, its
    placement in its parent's frame (rotation transposed, translation) and its ``length``: the
    placement's length plus a prismatic joint's largest stroke."""

    joints: tuple[int, ...]
    axes: np.ndarray
    revolute: np.ndarray
    low: np.ndarray
    high: np.ndarray
    turns: np.ndarray
    shifts: np.ndarray
    lengths: np.ndarray


def _chain(robot: RobotModel, first: int, second: int) -> tuple[_Chain, int, int] | None:
    """The joints between primitives ``first`` and ``second`` and the two, the earlier in the
    chain first; None if they are not on one chain or a joint between is not 1-DOF about a fixed
    axis, or is prismatic without finite limits (a revolute joint without them turns a full
    ``[-pi, pi]``)."""
    model = robot.model
    parents = [model.frames[model.getFrameId(robot.primitives[i].frame)].parentJoint for i in (first, second)]
    before, after = (set(model.supports[j]) for j in parents)
    if not before <= after:
        if not after <= before:
            return None
        first, second, parents, before = second, first, parents[::-1], after
    joints = tuple(k for k in model.supports[parents[1]] if k not in before)
    axes, revolute, low, high, lengths = [], [], [], [], []
    for k in joints:
        joint = model.joints[k]
        if joint.nq != 1 or joint.nv != 1:
            return None
        data = joint.createData()
        joint.calc(data, np.zeros(model.nq))
        motion = np.asarray(data.S, dtype=float).ravel()
        linear, angular = np.linalg.norm(motion[:3]), np.linalg.norm(motion[3:])
        turning = linear < 1e-12 and abs(angular - 1.0) < 1e-12
        if not turning and not (angular < 1e-12 and abs(linear - 1.0) < 1e-12):
            return None
        lo, hi = float(model.lowerPositionLimit[joint.idx_q]), float(model.upperPositionLimit[joint.idx_q])
        if not (np.isfinite(lo) and np.isfinite(hi)):
            if not turning:
                return None
            lo, hi = -np.pi, np.pi
        axes.append(motion[3:] if turning else motion[:3])
        revolute.append(turning)
        low.append(lo)
        high.append(hi)
        stroke = 0.0 if turning else max(-lo, hi)
        lengths.append(float(np.linalg.norm(model.jointPlacements[k].translation)) + stroke)
    chain = _Chain(
        joints,
        np.array(axes, dtype=float).reshape(-1, 3),
        np.array(revolute, dtype=bool),
        np.array(low, dtype=float),
        np.array(high, dtype=float),
        np.array([model.jointPlacements[k].rotation.T for k in joints], dtype=float).reshape(-1, 3, 3),
        np.array([model.jointPlacements[k].translation for k in joints], dtype=float).reshape(-1, 3),
        np.array(lengths, dtype=float),
    )
    return chain, first, second


def _always_beyond(robot: RobotModel, chain: _Chain, pairs: list[tuple[int, int]], threshold: float) -> np.ndarray:
    """For each pair ``(first, second)`` of primitives of ``robot`` with the joints ``chain``
    between them (``first`` before), whether the two are farther apart than ``threshold`` [m] in
    every configuration within the joint limits (False: maybe not).

    Their distance depends only on the joints between them. Over a box of those joints' values it
    is at least its value at the box's centre less ``sum_k L_k w_k``, ``w_k`` the box's half-width
    and ``L_k`` a bound on how fast joint ``k`` moves the second primitive: for a revolute joint,
    the length of the chain from its origin to the primitive's farthest axis point (a point turns
    by at most its distance from the axis per radian); 1 for a prismatic one. Branch and bound:
    boxes are halved along every term at least half the largest while some pair's bound in them
    is below the threshold; a pair is beyond once no box is left for it, and not once a centre
    comes within the threshold, or :data:`_BOXES` boxes or :data:`_HALVINGS` halvings are not
    enough.
    """
    model = robot.model
    starts, directions, ends, radii = [], [], [], []
    for index in (i for pair in pairs for i in pair):
        p = robot.primitives[index]
        placement = model.frames[model.getFrameId(p.frame)].placement
        z = placement.rotation[:, 2]
        start = placement.translation + p.offset * z
        starts.append(start)
        directions.append(p.length * z)
        ends.append(start + p.length * z)
        radii.append(p.radius)
    a0, da = np.array(starts[0::2]), np.array(directions[0::2])  # (P, 3), in the first's joint frame
    ends_b = np.stack([np.array(starts[1::2]), np.array(ends[1::2])], axis=1)  # (P, 2, 3), the second's
    radius = np.array(radii[0::2]) + np.array(radii[1::2])
    farthest = np.linalg.norm(ends_b, axis=2).max(axis=1)
    after = np.concatenate([np.cumsum(chain.lengths[::-1])[::-1][1:], [0.0]])  # placements past joint k
    rates = np.where(chain.revolute, farthest[:, None] + after, 1.0)  # (P, m)

    def distance(q: np.ndarray) -> np.ndarray:
        """``(n, P)`` at the joint values ``q`` ``(n, m)``: the second's axis ends carried back
        through every joint to the first's frame."""
        points = np.broadcast_to(ends_b, (len(q),) + ends_b.shape)
        for k in range(len(chain.joints) - 1, -1, -1):
            axis, angle = chain.axes[k], q[:, k, None, None, None]
            if chain.revolute[k]:  # Rodrigues
                c, s = np.cos(angle), np.sin(angle)
                points = c * points + s * np.cross(axis, points) + (1.0 - c) * (points @ axis)[..., None] * axis
            else:
                points = points + angle * axis
            points = points @ chain.turns[k] + chain.shifts[k]
        b0, db = points[:, :, 0], points[:, :, 1] - points[:, :, 0]
        s, t = segment_parameters(a0, da, b0, db)
        return np.linalg.norm(a0 + s[..., None] * da - b0 - t[..., None] * db, axis=-1) - radius

    beyond = np.zeros(len(pairs), dtype=bool)
    open_ = np.ones(len(pairs), dtype=bool)
    centres, half = ((chain.low + chain.high) / 2)[None], (chain.high - chain.low) / 2
    for _ in range(_HALVINGS):
        d = distance(centres)
        open_ &= ~(d < threshold).any(axis=0)
        short = (d - rates @ half < threshold) & open_
        beyond |= open_ & ~short.any(axis=0)
        open_ &= ~beyond
        centres = centres[short.any(axis=1)]
        if not open_.any():
            break
        terms = rates[open_].max(axis=0) * half
        for k in np.flatnonzero(terms >= 0.5 * terms.max()):
            half[k] /= 2
            step = np.zeros(len(half))
            step[k] = half[k]
            centres = np.concatenate([centres - step, centres + step])
        if len(centres) > _BOXES:
            break
    return beyond
