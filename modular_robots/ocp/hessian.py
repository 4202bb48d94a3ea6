"""Second derivatives of the inverse transcription's constraints, for the Lagrangian Hessian that
trust-constr is given instead of a quasi-Newton estimate.

On one interval with parameters ``p = (q0, v0, u, tf)`` (``u`` the acceleration), the sub-step
states are ``q_j = q0 + v0 s_j + u s_j^2 / 2`` and ``v_j = v0 + u s_j`` with ``s_j = tf f_j``:
polynomials whose second derivatives are written out here exactly. The torques
``tau_j = RNEA(q_j, v_j, u)`` add Pinocchio's curvature: the second derivatives of RNEA, which the
PyPI ``pin`` wheel does not expose, are taken by differences of its analytical first
derivatives (``computeRNEADerivatives``), contracted with the multipliers, so one difference per
coordinate and sub-step serves every row: forward differences, in ``q`` with an error of order
:data:`RNEA_STEP` (about 1e-7 relative), in ``v`` over a unit step, exact to rounding (``dtau/dv``
is linear in ``v``).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..robot import RobotModel

__all__ = ["RNEA_STEP", "kinematic_hessians", "rnea_curvature"]

#: Forward-difference step [rad | m, rad/s | m/s] for RNEA's second derivatives: about
#: ``sqrt(eps)`` times the joints' range, where the truncation and the rounding errors meet.
RNEA_STEP = 1e-7


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
    derivatives ``weight . dtau/dq`` and ``weight . dtau/dv`` ``(K, nv)``. Pinocchio's first
    derivatives are gathered at the ``2 nv + 1`` points of each ``K`` first and contracted with
    the weights in one product: the calls are the cost, not the arithmetic.
    """
    model, data = robot.model, robot.data
    K, nv = q.shape
    shifted = 1 + np.arange(nv)  # the evaluations at q + step e_i, then at v + e_i
    dtau_dq, mass = np.empty((2, K, 1 + nv, nv, nv))
    dtau_dv = np.empty((K, 1 + 2 * nv, nv, nv))
    eye = np.eye(nv) * step
    # dtau/dv is linear in v: a difference over a unit step in v is exact, with the least rounding.
    unit = np.eye(nv)
    for k in range(K):
        qk, vk, ak = q[k], v[k], a[k]
        dtau_dq[k, 0], dtau_dv[k, 0], mass[k, 0] = pin.computeRNEADerivatives(model, data, qk, vk, ak)
        for i in range(nv):
            dtau_dq[k, 1 + i], dtau_dv[k, 1 + i], mass[k, 1 + i] = pin.computeRNEADerivatives(
                model, data, qk + eye[i], vk, ak
            )
            dtau_dv[k, 1 + nv + i] = pin.computeRNEADerivatives(model, data, qk, vk + unit[i], ak)[1]
    mass = np.triu(mass) + np.swapaxes(np.triu(mass, 1), 2, 3)  # Pinocchio may fill only the upper triangle
    by_q, by_v, by_a = (np.einsum("ka,knab->knb", weight, d) for d in (dtau_dq, dtau_dv, mass))

    def difference(g, rows, h=step):  # row i: (g at the i-th shifted point - g at the point) / h
        return (g[:, rows] - g[:, :1]) / h

    qq = np.swapaxes(difference(by_q, shifted), 1, 2)
    vv = np.swapaxes(difference(by_v, nv + shifted, 1.0), 1, 2)
    qv, qa = difference(by_v, shifted), difference(by_a, shifted)
    qq = 0.5 * (qq + np.swapaxes(qq, 1, 2))
    vv = 0.5 * (vv + np.swapaxes(vv, 1, 2))
    return qq, vv, qv, qa, by_q[:, 0], by_v[:, 0]


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
    f = np.asarray(fractions, dtype=float)
    s = np.broadcast_to(np.asarray(tf, dtype=float), (N,))[:, None] * f  # (N, J)
    # d q_j / d(q0, v0, u) = c_q I and d v_j / d(q0, v0, u) = c_v I, blocks scaled by (3, N, J)
    # coefficients; d / dtf are the vectors t_q, t_v (N, J, nv).
    c_q = np.stack([np.ones_like(s), s, 0.5 * s**2])
    c_v = np.stack([np.zeros_like(s), np.ones_like(s), s])
    t_q = velocities * f[None, :, None]
    t_v = u[:, None, :] * f[None, :, None]
    qq, vv, qv, qa = (c.reshape(N, len(f), nv, nv) for c in curvature[:4])
    H = _pulled_back(c_q, t_q, qq, c_q, t_q) + _pulled_back(c_v, t_v, vv, c_v, t_v)
    cross = _pulled_back(c_q, t_q, qv, c_v, t_v)
    cross[:, :-1, 2 * nv : 3 * nv] += np.einsum("amj,mjkl->makl", c_q, qa).reshape(N, 3 * nv, nv)
    cross[:, -1, 2 * nv : 3 * nv] += np.einsum("mjk,mjkl->ml", t_q, qa)
    return H + cross + np.swapaxes(cross, 1, 2)


def _pulled_back(c_x, t_x, A, c_y, t_y) -> np.ndarray:
    """``sum_j J_x[j]^T A[j] J_y[j]`` ``(N, P, P)`` for the sub-step Jacobians
    ``J[j] = [c[0, j] I, c[1, j] I, c[2, j] I, t[j]]`` of :func:`torque_hessians`."""
    N, _, nv, _ = A.shape
    H = np.empty((N, 3 * nv + 1, 3 * nv + 1))
    H[:, :-1, :-1] = np.einsum("amj,bmj,mjkl->makbl", c_x, c_y, A).reshape(N, 3 * nv, 3 * nv)
    H[:, :-1, -1] = np.einsum("amj,mjkl,mjl->mak", c_x, A, t_y).reshape(N, 3 * nv)
    H[:, -1, :-1] = np.einsum("mjk,mjkl,bmj->mbl", t_x, A, c_y).reshape(N, 3 * nv)
    H[:, -1, -1] = np.einsum("mjk,mjkl,mjl->m", t_x, A, t_y)
    return H
