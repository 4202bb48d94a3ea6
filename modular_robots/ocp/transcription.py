"""How one shooting interval maps its start state and control to states along the interval.

Two transcriptions share one interface (SPEC §5):

* :class:`ForwardDynamics` (the paper's): the control is the joint torque ``tau``, constant on the
  interval; the state ``x = (q, qdot)`` follows ``xdot = (qdot, ABA(q, qdot, tau))``, integrated by
  fixed-step RK4.
* :class:`InverseDynamics`: the control is the joint acceleration ``qddot``, constant on the
  interval; the motion is integrated exactly (a parabola) and the torque it needs,
  ``tau = RNEA(q, qdot, qddot)``, is what the torque limits bound.

Every function works on all intervals at once: ``x0`` is ``(N, 2 nv)``, ``u`` is ``(N, nv)``,
``tf`` a duration [s] shared by all or one per interval ``(N,)`` (its phase's: an interval lasts
``tf / intervals``). Sensitivities are taken with respect to the interval's own parameters
``p = (x0, u, tf)``
(``2 nv + nv + 1`` columns) and are exact: Pinocchio's analytical derivatives chained through
the integrator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..exceptions import ProblemError
from ..robot import RobotModel, symmetric_from_upper

__all__ = ["Propagation", "Transcription", "ForwardDynamics", "InverseDynamics", "transcription"]


@dataclass(frozen=True)
class Propagation:
    """States ``(N, S + 1, 2 nv)`` at the sub-step points ``j = 0..S`` of every interval, the
    torques ``(N, S + 1, nv)`` applied there, and (when asked) their sensitivities
    ``(N, S + 1, 2 nv, p)`` and ``(N, S + 1, nv, p)`` to the interval parameters."""

    states: np.ndarray
    torques: np.ndarray
    state_sens: np.ndarray | None = None
    torque_sens: np.ndarray | None = None


class Transcription:
    """Interface of a transcription (see the module docstring)."""

    name: str = ""
    #: True when the controls are torques, so the torque limits are plain variable bounds.
    controls_are_torques: bool = False
    #: True when the velocity is linear in time within each interval, so that its limits at the
    #: nodes hold everywhere and the sub-steps need none.
    velocity_linear_in_time: bool = False

    def propagate(
        self,
        robot: RobotModel,
        x0: np.ndarray,
        u: np.ndarray,
        tf: float | np.ndarray,
        intervals: int,
        substeps: int,
        derivatives: bool,
    ) -> Propagation:
        raise NotImplementedError

    def control_scale(self, robot: RobotModel, tf: float, intervals: int) -> np.ndarray:
        """Characteristic control magnitude, used to scale the decision variables."""
        raise NotImplementedError

    def initial_controls(self, robot: RobotModel, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """Controls ``(N, nv)`` that realise node accelerations ``a`` from node states ``(q, v)``."""
        raise NotImplementedError

    def torque(self, robot: RobotModel, node: np.ndarray, u: np.ndarray, s) -> np.ndarray:
        """The torque applied ``s`` seconds into an interval that starts at planned state ``node``
        with control ``u`` (the control law that verification re-integrates): ``(nv,)``, or
        ``(B, nv)`` for ``B`` such points at once (``node`` ``(B, 2 nv)``, ``u`` ``(B, nv)``,
        ``s`` ``(B,)``)."""
        raise NotImplementedError

    def plan_dynamics(self, robot: RobotModel, nodes: np.ndarray, controls: np.ndarray, starts: np.ndarray):
        """``xdot(s, x)`` of ``B`` states at once under the plan's control law (:meth:`torque`),
        ``x`` the states ``(B, 2 nv)`` flattened: state ``b`` is ``starts[b] + s`` seconds into the
        interval that starts at ``nodes[b]`` with control ``controls[b]``. What verification and
        the forward transcription's dense rows re-integrate."""
        nv = robot.nv

        def rhs(s, flat):
            x = flat.reshape(len(nodes), 2 * nv)
            qdd = robot.aba(x[:, :nv], x[:, nv:], self.torque(robot, nodes, controls, starts + s))
            return np.concatenate([x[:, nv:], qdd], axis=1).ravel()

        return rhs


class ForwardDynamics(Transcription):
    """``u = tau``; ``xdot = (qdot, ABA(q, qdot, tau))`` by RK4 with ``S`` steps per interval."""

    name = "forward"
    controls_are_torques = True

    def control_scale(self, robot, tf, intervals):
        return positive_or_one(robot.effort_limit)

    def initial_controls(self, robot, q, v, a):
        return robot.rnea(q, v, a)

    def torque(self, robot, node, u, s):
        return np.array(u, dtype=float)

    def propagate(self, robot, x0, u, tf, intervals, substeps, derivatives):
        n_int, n = x0.shape
        nv = n // 2
        p = n + nv + 1
        h = (np.broadcast_to(np.asarray(tf, dtype=float), (n_int,)) / (intervals * substeps))[:, None]
        dh = 1.0 / (intervals * substeps)  # d h / d tf
        states = np.empty((n_int, substeps + 1, n))
        states[:, 0] = x0
        sens = None
        if derivatives:
            sens = np.zeros((n_int, substeps + 1, n, p))
            sens[:, 0, :, :n] = np.eye(n)
        x = x0
        X = sens[:, 0] if sens is not None else None
        for j in range(substeps):
            k1, K1 = self._f(robot, x, X, u, derivatives)
            x2 = x + 0.5 * h * k1
            X2 = _stage(X, K1, k1, 0.5 * h, 0.5 * dh) if derivatives else None
            k2, K2 = self._f(robot, x2, X2, u, derivatives)
            x3 = x + 0.5 * h * k2
            X3 = _stage(X, K2, k2, 0.5 * h, 0.5 * dh) if derivatives else None
            k3, K3 = self._f(robot, x3, X3, u, derivatives)
            x4 = x + h * k3
            X4 = _stage(X, K3, k3, h, dh) if derivatives else None
            k4, K4 = self._f(robot, x4, X4, u, derivatives)
            k = (k1 + 2.0 * k2 + 2.0 * k3 + k4) / 6.0
            x = x + h * k
            states[:, j + 1] = x
            if sens is not None:
                X = _stage(X, (K1 + 2.0 * K2 + 2.0 * K3 + K4) / 6.0, k, h, dh)
                sens[:, j + 1] = X
        torques = np.repeat(u[:, None, :], substeps + 1, axis=1)
        torque_sens = None
        if derivatives:
            torque_sens = np.zeros((n_int, substeps + 1, nv, p))
            torque_sens[:, :, :, n : n + nv] = np.eye(nv)
        return Propagation(states, torques, sens, torque_sens)

    @staticmethod
    def _f(robot, x, X, u, derivatives):
        """``f(x, u)`` for every interval and, with ``X = dx/dp``, ``df/dp``."""
        model, data = robot.model, robot.data
        n_int, n = x.shape
        nv = n // 2
        xdot = np.empty_like(x)
        xdot[:, :nv] = x[:, nv:]
        if robot.has_friction:  # the joints get the motor torque less friction
            u = u - robot.friction(x[:, nv:])
        if not derivatives:
            for i in range(n_int):
                xdot[i, nv:] = pin.aba(model, data, x[i, :nv], x[i, nv:], u[i])
            return xdot, None
        dq = np.empty((n_int, nv, nv))
        dv = np.empty((n_int, nv, nv))
        minv = np.empty((n_int, nv, nv))
        for i in range(n_int):
            dq[i], dv[i], minv[i] = pin.computeABADerivatives(model, data, x[i, :nv], x[i, nv:], u[i])
            xdot[i, nv:] = data.ddq
        minv = symmetric_from_upper(minv)
        if robot.has_friction:
            dv -= minv * robot.friction_derivative(x[:, nv:])[:, None, :]
        K = np.empty_like(X)
        K[:, :nv] = X[:, nv:]
        K[:, nv:] = dq @ X[:, :nv] + dv @ X[:, nv:]
        K[:, nv:, n : n + nv] += minv
        return xdot, K


def _stage(X, K, k, h, dh):
    """Sensitivity of ``x + h k`` where ``h`` ``(N, 1)`` depends on ``tf`` (the last parameter)."""
    out = X + h[:, :, None] * K
    out[:, :, -1] += dh * k
    return out


class InverseDynamics(Transcription):
    """``u = qddot``: exact parabolic motion, ``tau = RNEA(q, qdot, qddot)`` at every sub-step."""

    name = "inverse"
    controls_are_torques = False
    velocity_linear_in_time = True  # v(t) = v_m + u_m t

    def control_scale(self, robot, tf, intervals):
        return positive_or_one(robot.velocity_limit) * intervals / tf

    def initial_controls(self, robot, q, v, a):
        return np.asarray(a, dtype=float).copy()

    def torque(self, robot, node, u, s):
        nv = robot.nv
        s = np.asarray(s, dtype=float)[..., None]
        q = node[..., :nv] + node[..., nv:] * s + 0.5 * u * s * s
        v = node[..., nv:] + u * s
        return robot.rnea(q, v, np.broadcast_to(u, q.shape))

    def propagate(self, robot, x0, u, tf, intervals, substeps, derivatives):
        n_int, n = x0.shape
        nv = n // 2
        p = n + nv + 1
        frac = np.arange(substeps + 1) / (intervals * substeps)  # s / tf at each sub-step
        s = np.broadcast_to(np.asarray(tf, dtype=float), (n_int,))[:, None] * frac  # (N, S + 1)
        q0, v0 = x0[:, None, :nv], x0[:, None, nv:]
        a = u[:, None, :]
        v = v0 + a * s[:, :, None]
        q = q0 + v0 * s[:, :, None] + 0.5 * a * (s**2)[:, :, None]
        states = np.concatenate([q, v], axis=2)
        torques = np.empty((n_int, substeps + 1, nv))
        model, data = robot.model, robot.data
        if not derivatives:
            for i in range(n_int):
                for j in range(substeps + 1):
                    torques[i, j] = pin.rnea(model, data, q[i, j], v[i, j], u[i])
            if robot.has_friction:
                torques += robot.friction(v)
            return Propagation(states, torques)
        eye = np.eye(nv)
        sens = np.zeros((n_int, substeps + 1, n, p))
        sens[:, :, :nv, :nv] = eye
        sens[:, :, :nv, nv:n] = s[:, :, None, None] * eye
        sens[:, :, :nv, n : n + nv] = 0.5 * (s**2)[:, :, None, None] * eye
        sens[:, :, :nv, -1] = v * frac[None, :, None]
        sens[:, :, nv:, nv:n] = eye
        sens[:, :, nv:, n : n + nv] = s[:, :, None, None] * eye
        sens[:, :, nv:, -1] = a * frac[None, :, None]
        dq = np.empty((n_int, substeps + 1, nv, nv))
        dv = np.empty_like(dq)
        mass = np.empty_like(dq)
        for i in range(n_int):
            for j in range(substeps + 1):
                dq[i, j], dv[i, j], mass[i, j] = pin.computeRNEADerivatives(model, data, q[i, j], v[i, j], u[i])
                torques[i, j] = data.tau
        mass = symmetric_from_upper(mass)
        torque_sens = dq @ sens[:, :, :nv] + dv @ sens[:, :, nv:]
        torque_sens[:, :, :, n : n + nv] += mass
        if robot.has_friction:  # motor torque: friction at the sub-step's velocity
            torques += robot.friction(v)
            torque_sens += robot.friction_derivative(v)[..., None] * sens[:, :, nv:]
        return Propagation(states, torques, sens, torque_sens)


def positive_or_one(values: np.ndarray) -> np.ndarray:
    """``values`` with non-finite or non-positive entries replaced by 1 (for scales)."""
    values = np.asarray(values, dtype=float)
    return np.where(np.isfinite(values) & (values > 0.0), values, 1.0)


_TRANSCRIPTIONS = {"forward": ForwardDynamics, "inverse": InverseDynamics}


def transcription(name: str) -> Transcription:
    """The transcription called ``name`` (``forward`` or ``inverse``)."""
    try:
        return _TRANSCRIPTIONS[name]()
    except KeyError:
        raise ProblemError(f"unknown transcription {name!r}; expected one of {sorted(_TRANSCRIPTIONS)}") from None
