"""Second derivatives of the inverse transcription's constraints, for the Lagrangian Hessian that
trust-constr is given instead of a quasi-Newton estimate.

On one interval with parameters ``p = (q0, v0, u, tf)`` (``u`` the acceleration), the sub-step
states are ``q_j = q0 + v0 s_j + u s_j^2 / 2`` and ``v_j = v0 + u s_j`` with ``s_j = tf f_j``:
polynomials whose second derivatives are written out here exactly. The torques
``tau_j = RNEA(q_j, v_j, u)`` add Pinocchio's curvature: the second derivatives of RNEA, which the
PyPI ``pin`` wheel does not expose, are taken by central differences of its analytical first
derivatives (``computeRNEADerivatives``), contracted with the multipliers first, so one difference
per coordinate and sub-step serves every row: central in ``q`` (an error of order
:data:`RNEA_STEP` squared), one-sided in ``v`` for ``d2 / dv2`` (``dtau/dv`` is linear in ``v``,
so that difference is exact to rounding).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..robot import RobotModel

__all__ = ["RNEA_STEP", "kinematic_hessians", "rnea_curvature"]

#: Central-difference step [rad | m, rad/s | m/s] for RNEA's second derivatives.
RNEA_STEP = 1e-5


def kinematic_hessians(
    fractions: np.ndarray, tf: float | np.ndarray, u: np.ndarray, weight_q: np.ndarray, weight_v: np.ndarray
) -> np.ndarray:
    """``sum_j weight_q[j] . d2 q_j / dp2 + weight_v[j] . d2 v_j / dp2`` per interval.

    Parameters
    ----------
    fractions
        ``f_j = s_j / tf`` of the sub-steps ``(J,)``.
    tf
        Final time [s], or each interval's ``(N,)`` (its phase's duration).
    u
        Controls (accelerations) ``(N, nv)``.
    weight_q, weight_v
        Weights ``(N, J, nv)`` of the sub-step positions and velocities.

    Returns
    -------
    ``(N, P, P)`` with ``P = 3 nv + 1`` in the order ``(q0, v0, u, tf)``.
    """
    N, nv = u.shape
    P = 3 * nv + 1
    H = np.zeros((N, P, P))
    f = np.asarray(fractions, dtype=float)
    tfs = np.broadcast_to(np.asarray(tf, dtype=float), (N,))
    v0_tf = np.einsum("j,mjk->mk", f, weight_q)  # d2 q_j / dv0 dtf = f_j
    u_tf = np.einsum("m,j,mjk->mk", tfs, f**2, weight_q) + np.einsum("j,mjk->mk", f, weight_v)
    tf_tf = np.einsum("j,mjk,mk->m", f**2, weight_q, u)  # d2 q_j / dtf2 = u f_j^2
    for block, values in ((1, v0_tf), (2, u_tf)):
        cols = block * nv + np.arange(nv)
        H[:, cols, -1] = values
        H[:, -1, cols] = values
    H[:, -1, -1] = tf_tf
    return H


def rnea_curvature(
    robot: RobotModel, q: np.ndarray, v: np.ndarray, a: np.ndarray, weight: np.ndarray, step: float = RNEA_STEP
) -> tuple[np.ndarray, ...]:
    """Second derivatives of ``weight . RNEA(q, v, a)`` at each of ``K`` points (rows ``(K, nv)``).

    Returns ``(qq, vv, qv, qa, grad_q, grad_v)``: ``(K, nv, nv)`` blocks ``d2 / dq dq``,
    ``d2 / dv dv``, ``d2 / dq dv`` (rows ``q``), ``d2 / dq da`` (rows ``q``), and the first
    derivatives ``weight . dtau/dq`` and ``weight . dtau/dv`` ``(K, nv)``.
    """
    model, data = robot.model, robot.data
    K, nv = q.shape
    upper = np.triu(np.ones((nv, nv)))  # Pinocchio fills the mass matrix's upper triangle
    strict = np.triu(np.ones((nv, nv)), 1)

    def contracted(qk, vk, ak, w):
        dq, dv, m = pin.computeRNEADerivatives(model, data, qk, vk, ak)
        return w @ dq, w @ dv, w @ (m * upper) + (m * strict) @ w

    qq, vv, qv, qa = (np.empty((K, nv, nv)) for _ in range(4))
    grad_q, grad_v = np.empty((K, nv)), np.empty((K, nv))
    eye = np.eye(nv) * step
    for k in range(K):
        w = weight[k]
        grad_q[k], grad_v[k], _ = contracted(q[k], v[k], a[k], w)
        for i in range(nv):
            plus = contracted(q[k] + eye[i], v[k], a[k], w)
            minus = contracted(q[k] - eye[i], v[k], a[k], w)
            qq[k, :, i] = (plus[0] - minus[0]) / (2 * step)
            qv[k, i, :] = (plus[1] - minus[1]) / (2 * step)
            qa[k, i, :] = (plus[2] - minus[2]) / (2 * step)
            # dtau/dv is linear in v: a one-sided difference is exact to rounding.
            vv[k, :, i] = (contracted(q[k], v[k] + eye[i], a[k], w)[1] - grad_v[k]) / step
    qq = 0.5 * (qq + np.swapaxes(qq, 1, 2))
    vv = 0.5 * (vv + np.swapaxes(vv, 1, 2))
    return qq, vv, qv, qa, grad_q, grad_v


def torque_hessians(
    fractions: np.ndarray,
    tf: float | np.ndarray,
    u: np.ndarray,
    velocities: np.ndarray,
    curvature: tuple[np.ndarray, ...],
) -> np.ndarray:
    """The curvature of ``weight . RNEA`` at the sub-steps pulled back to the interval parameters.

    ``velocities`` ``(N, J, nv)`` at the sub-steps; ``curvature`` the first four blocks of
    :func:`rnea_curvature` with ``K = N J`` points. The terms with RNEA's first derivatives
    belong to :func:`kinematic_hessians` (add ``grad_q``/``grad_v`` to its weights).
    Returns ``(N, P, P)``.
    """
    N, nv = u.shape
    J = len(fractions)
    P = 3 * nv + 1
    f = np.asarray(fractions, dtype=float)
    s = np.broadcast_to(np.asarray(tf, dtype=float), (N,))[:, None] * f  # (N, J)
    eye = np.eye(nv)
    Jq = np.zeros((N, J, nv, P))
    Jq[:, :, :, :nv] = eye
    Jq[:, :, :, nv : 2 * nv] = s[:, :, None, None] * eye
    Jq[:, :, :, 2 * nv : 3 * nv] = 0.5 * (s**2)[:, :, None, None] * eye
    Jq[:, :, :, -1] = velocities * f[None, :, None]
    Jv = np.zeros((N, J, nv, P))
    Jv[:, :, :, nv : 2 * nv] = eye
    Jv[:, :, :, 2 * nv : 3 * nv] = s[:, :, None, None] * eye
    Jv[:, :, :, -1] = u[:, None, :] * f[None, :, None]
    qq, vv, qv, qa = (c.reshape(N, J, nv, nv) for c in curvature[:4])
    H = np.einsum("mjap,mjab,mjbr->mpr", Jq, qq, Jq)
    H += np.einsum("mjap,mjab,mjbr->mpr", Jv, vv, Jv)
    cross = np.einsum("mjap,mjab,mjbr->mpr", Jq, qv, Jv)
    cross[:, :, 2 * nv : 3 * nv] += np.einsum("mjap,mjab->mpb", Jq, qa)
    return H + cross + np.swapaxes(cross, 1, 2)
