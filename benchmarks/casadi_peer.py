"""The peer: step C's nonlinear program rebuilt in CasADi symbolics and solved by IPOPT.

Everything is read from the project's own objects, nothing is copied by hand: the kinematic tree,
inertias and armature from the Pinocchio model of a :class:`~modular_robots.robot.RobotModel`;
variables, scaling, bounds, constraint rows (their order, scale and which are kept), the initial
guess and the tolerances from a :class:`~modular_robots.ocp.shooting.ShootingProblem` (inverse
transcription, ``time`` cost). ``benchmarks/test_casadi_peer.py`` checks the symbolic RNEA against
Pinocchio's and the constraint vector against the project's at the initial guess.

The PyPI ``pin`` wheel has no ``pinocchio.casadi``, hence the recursive Newton-Euler written here
with spatial algebra in the conventions of Pinocchio (motions ``(v, w)`` and forces ``(f, n)`` in
each joint's frame, ``liMi = placement * joint motion``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from modular_robots.obstacles import PlaneObstacle, SphereObstacle
from modular_robots.ocp.shooting import ShootingProblem
from modular_robots.ocp.solver import complementarity
from modular_robots.robot import RobotModel

__all__ = ["SymbolicRobot", "PeerNLP", "PeerSolution", "PeerSolver", "solve_with_ipopt"]

_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


def _joint_kind(joint) -> tuple[str, np.ndarray]:
    """``("revolute" | "prismatic", axis)`` of a one-DOF Pinocchio joint model."""
    name = joint.shortname()
    if name in ("JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"):
        return ("revolute" if "Revolute" in name else "prismatic"), np.asarray(joint.axis, dtype=float)
    if name[:-1] in ("JointModelR", "JointModelP") and name[-1] in _AXES:
        return ("revolute" if name[-2] == "R" else "prismatic"), np.array(_AXES[name[-1]])
    raise NotImplementedError(f"joint model {name} is not supported by the CasADi peer")


def _rotation(axis: np.ndarray, angle) -> ca.SX:
    """Rodrigues' rotation about the unit ``axis`` by ``angle``."""
    k = ca.DM(axis)
    skew = ca.skew(k)
    return ca.DM.eye(3) + ca.sin(angle) * skew + (1 - ca.cos(angle)) * (skew @ skew)


class SymbolicRobot:
    """Forward kinematics and inverse dynamics of a :class:`RobotModel` as CasADi expressions."""

    def __init__(self, robot: RobotModel):
        self.robot = robot
        model = robot.model
        self.nv = model.nv
        self.joints = [_joint_kind(model.joints[j]) for j in range(1, model.njoints)]
        self.parents = [int(model.parents[j]) for j in range(model.njoints)]
        self.placements = [(np.array(p.rotation), np.array(p.translation)) for p in model.jointPlacements]
        self.inertias = [
            (float(i.mass), np.array(i.lever), np.array(i.inertia)) for i in model.inertias
        ]  # mass, centre of mass, inertia about the centre of mass, in the joint frame
        self.armature = np.array(model.armature, dtype=float)
        self.gravity = np.array(model.gravity.linear, dtype=float)

    def _local(self, j: int, qj):
        """``(R, p)`` of joint ``j`` (1-based) in its parent's frame at ``qj``."""
        rot, trans = self.placements[j]
        kind, axis = self.joints[j - 1]
        if kind == "revolute":
            return ca.DM(rot) @ _rotation(axis, qj), ca.DM(trans)
        return ca.DM(rot), ca.DM(trans) + ca.DM(rot) @ ca.DM(axis) * qj

    def placements_of(self, q) -> list[tuple]:
        """World placements ``(R, p)`` of every joint frame (index 0: the base)."""
        out = [(ca.DM.eye(3), ca.DM.zeros(3))]
        for j in range(1, len(self.parents)):
            rot, trans = self._local(j, q[j - 1])
            prot, ptrans = out[self.parents[j]]
            out.append((prot @ rot, ptrans + prot @ trans))
        return out

    def rnea(self, q, v, a):
        """Joint torques/forces [N m | N] for ``(q, v, a)``, gravity and armature included."""
        n = len(self.parents)
        vel = [(ca.SX.zeros(3), ca.SX.zeros(3))] * n
        acc = [(ca.DM(-self.gravity), ca.DM.zeros(3))] * n
        force = [None] * n
        local = [None] * n
        motion = [None] * n
        for j in range(1, n):
            rot, trans = self._local(j, q[j - 1])
            local[j] = (rot, trans)
            kind, axis = self.joints[j - 1]
            s = (ca.DM.zeros(3), ca.DM(axis)) if kind == "revolute" else (ca.DM(axis), ca.DM.zeros(3))
            motion[j] = s
            pv, pw = vel[self.parents[j]]
            pa, pal = acc[self.parents[j]]
            vj = (rot.T @ (pv - ca.cross(trans, pw)) + s[0] * v[j - 1], rot.T @ pw + s[1] * v[j - 1])
            sv = (s[0] * v[j - 1], s[1] * v[j - 1])
            aj = (
                rot.T @ (pa - ca.cross(trans, pal)) + s[0] * a[j - 1] + ca.cross(vj[1], sv[0]) + ca.cross(vj[0], sv[1]),
                rot.T @ pal + s[1] * a[j - 1] + ca.cross(vj[1], sv[1]),
            )
            vel[j], acc[j] = vj, aj
            hj = self._inertia_times(j, vj)
            fj = self._inertia_times(j, aj)
            force[j] = (fj[0] + ca.cross(vj[1], hj[0]), fj[1] + ca.cross(vj[1], hj[1]) + ca.cross(vj[0], hj[0]))
        tau = [None] * (n - 1)
        for j in range(n - 1, 0, -1):
            f, moment = force[j]
            s = motion[j]
            tau[j - 1] = ca.dot(s[0], f) + ca.dot(s[1], moment) + self.armature[j - 1] * a[j - 1]
            parent = self.parents[j]
            if parent > 0:
                rot, trans = local[j]
                rf = rot @ f
                pf, pm = force[parent]
                force[parent] = (pf + rf, pm + ca.cross(trans, rf) + rot @ moment)
        return ca.vertcat(*tau)

    def _inertia_times(self, j: int, motion):
        mass, com, inertia = self.inertias[j]
        v, w = motion
        linear = mass * (v - ca.cross(ca.DM(com), w))
        return linear, ca.DM(inertia) @ w + ca.cross(ca.DM(com), linear)

    def clearance(self, q, obstacles, primitives, measured) -> ca.SX:
        """Per obstacle, the signed distance [m] to the closest of ``primitives`` (indices into
        ``robot.primitives``) that ``measured`` ``(P, O)`` pairs with it: a sphere-capsule
        distance, exact, as FCL's; a half-space's (the floor), the capsule's lower end's height
        less its radius, as the project's closed form."""
        model, robot = self.robot.model, self.robot
        joints = self.placements_of(q)
        segments = []
        for i in primitives:
            p = robot.primitives[i]
            frame = model.frames[model.getFrameId(p.frame)]
            jrot, jtrans = joints[frame.parentJoint]
            rot = jrot @ ca.DM(np.array(frame.placement.rotation))
            origin = jtrans + jrot @ ca.DM(np.array(frame.placement.translation))
            start = origin + p.offset * rot[:, 2]
            segments.append((start, p.length * rot[:, 2], p.length, p.radius))
        out = []
        for j, obstacle in enumerate(obstacles):
            kept = [segment for i, segment in enumerate(segments) if measured[i, j]]
            if isinstance(obstacle, PlaneObstacle):
                n = ca.DM(np.array(obstacle.normal))
                heights = [
                    ca.fmin(ca.dot(n, start), ca.dot(n, start + direction)) - obstacle.offset - radius
                    for start, direction, _, radius in kept
                ]
                out.append(ca.mmin(ca.vertcat(*heights)))
                continue
            center = ca.DM(np.array(obstacle.center))
            distances = []
            for start, direction, length, radius in kept:
                if length > 0:
                    t = ca.fmin(ca.fmax(ca.dot(center - start, direction) / length**2, 0), 1)
                    closest = start + t * direction
                else:
                    closest = start
                distances.append(ca.norm_2(center - closest) - radius - obstacle.radius)
            out.append(ca.mmin(ca.vertcat(*distances)))
        return ca.vertcat(*out) if out else ca.SX.zeros(0)


@dataclass
class PeerNLP:
    """The project's NLP for ``problem`` as CasADi expressions of the scaled variables ``y``."""

    problem: ShootingProblem
    y: ca.SX
    cost: ca.SX
    constraints: ca.SX
    build_seconds: float

    @classmethod
    def build(cls, problem: ShootingProblem) -> PeerNLP:
        if problem.transcription.name != "inverse" or problem.cost_name != "time":
            raise NotImplementedError("the peer covers the inverse transcription and the time cost")
        start = time.perf_counter()
        sym = SymbolicRobot(problem.robot)
        N, S, nv, n = problem.intervals, problem.substeps, problem.nv, problem.nx
        y = ca.SX.sym("y", problem.n_variables)
        z = y * ca.DM(problem.variable_scale)
        tf = z[0]
        inner = [z[1 + m * n : 1 + (m + 1) * n] for m in range(N - 1)]
        nodes = [ca.DM(problem.x_start), *inner, ca.DM(problem.x_goal)]
        controls = [z[problem._u0 + m * nv : problem._u0 + (m + 1) * nv] for m in range(N)]
        if len(problem.self_collision_rows):
            raise NotImplementedError("the peer does not write self-collision: build the problem without it")
        collision = problem.collision
        obstacles = collision.obstacles if collision else ()
        if any(not isinstance(o, SphereObstacle | PlaneObstacle) for o in obstacles):
            raise NotImplementedError("the peer writes the distance to spheres and half-spaces (the floor) only")
        measured = collision.measured_pairs if collision else np.ones((0, 0), dtype=bool)
        primitives = collision.primitive_indices if collision else ()
        continuity, path, middle, clear, torque = [], [], [], [], []
        for m in range(N):
            q0, v0, u = nodes[m][:nv], nodes[m][nv:], controls[m]
            states = []
            for j in range(S + 1):
                s = tf * j / (N * S)
                states.append((q0 + v0 * s + 0.5 * u * s**2, v0 + u * s))
            continuity.append(ca.vertcat(*states[S]) - nodes[m + 1])
            path += [ca.vertcat(*states[j]) for j in range(1, S)]
            h = tf / (N * S)
            middle += [
                0.5 * (states[j][0] + states[j + 1][0]) + 0.125 * h * (states[j][1] - states[j + 1][1])
                for j in range(S)
            ]
            if obstacles:
                clear += [sym.clearance(states[j][0], obstacles, primitives, measured) for j in range(S)]
            torque += [sym.rnea(states[j][0], states[j][1], u) for j in range(S + 1)]
        blocks = [*continuity, *path, *middle, *clear, *torque]
        full = ca.vertcat(*blocks) / ca.DM(problem.row_scale)
        kept = np.flatnonzero(problem._keep_row)
        constraints = full[kept.tolist()]
        cost = tf / problem.tf_guess
        return cls(problem, y, cost, constraints, time.perf_counter() - start)

    def functions(self) -> ca.Function:
        return ca.Function("nlp", [self.y], [self.cost, self.constraints])


@dataclass(frozen=True)
class PeerSolution:
    """IPOPT's answer: ``status`` (IPOPT's return status), ``iterations``, ``solve_seconds`` (the
    solver only), ``setup_seconds`` (symbolics, derivatives and code set-up), ``y`` the scaled
    optimum, ``cost`` [s] and ``complementarity`` (:func:`~modular_robots.ocp.solver.complementarity`
    of its rows and variables with IPOPT's multipliers)."""

    status: str
    success: bool
    iterations: int
    solve_seconds: float
    setup_seconds: float
    y: np.ndarray
    cost: float
    complementarity: float = float("nan")


class PeerSolver:
    """IPOPT on ``problem``'s NLP, set up once (exact Hessian, MUMPS, the problem's tolerances,
    ``acceptable_iter = 0``: no early "acceptable" stop, and the barrier strategy ``mu_strategy``,
    ``adaptive`` by default, or IPOPT's own default ``monotone``); :meth:`solve` may then be called
    and timed any number of times. ``setup_seconds`` is the symbolics', derivatives' and IPOPT's
    set-up time."""

    def __init__(self, problem: ShootingProblem, mu_strategy: str = "adaptive"):
        settings = problem.settings
        self.problem = problem
        nlp = PeerNLP.build(problem)
        start = time.perf_counter()
        self._solver = ca.nlpsol(
            "peer",
            "ipopt",
            {"x": nlp.y, "f": nlp.cost, "g": nlp.constraints},
            {
                "ipopt": {
                    "tol": settings.tolerance,
                    "constr_viol_tol": settings.constraint_tolerance,
                    "acceptable_iter": 0,
                    "max_iter": settings.max_iterations,
                    "mu_strategy": mu_strategy,
                    "linear_solver": "mumps",
                    "hessian_approximation": "exact",
                    "print_level": 0,
                    "sb": "yes",
                },
                "print_time": False,
            },
        )
        self.setup_seconds = nlp.build_seconds + time.perf_counter() - start

    def solve(self, y0: np.ndarray | None = None) -> PeerSolution:
        """One solve from ``y0`` (default: the problem's initial guess), timed (``solve_seconds``)."""
        problem = self.problem
        x0 = problem.initial_guess() if y0 is None else y0
        start = time.perf_counter()
        out = self._solver(
            x0=x0,
            lbx=problem.variable_lower,
            ubx=problem.variable_upper,
            lbg=problem.constraint_lower,
            ubg=problem.constraint_upper,
        )
        seconds = time.perf_counter() - start
        stats = self._solver.stats()
        y = np.array(out["x"]).ravel()
        slackness = max(
            complementarity(
                np.array(out["g"]).ravel(),
                np.array(out["lam_g"]).ravel(),
                problem.constraint_lower,
                problem.constraint_upper,
            ),
            complementarity(y, np.array(out["lam_x"]).ravel(), problem.variable_lower, problem.variable_upper),
        )
        return PeerSolution(
            status=str(stats["return_status"]),
            success=bool(stats["success"]),
            iterations=int(stats["iter_count"]),
            solve_seconds=seconds,
            setup_seconds=self.setup_seconds,
            y=y,
            cost=float(y[0] * problem.variable_scale[0]),
            complementarity=slackness,
        )


def solve_with_ipopt(problem: ShootingProblem, y0: np.ndarray | None = None, repeats: int = 1) -> PeerSolution:
    """Solve ``problem``'s NLP with IPOPT (:class:`PeerSolver`), timed ``repeats`` times from the
    same start (one set-up); ``solve_seconds`` is the median."""
    peer = PeerSolver(problem)
    runs = [peer.solve(y0) for _ in range(repeats)]
    return replace(runs[-1], solve_seconds=float(np.median([run.solve_seconds for run in runs])))
