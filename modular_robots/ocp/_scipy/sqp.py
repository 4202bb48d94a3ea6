"""trust-constr's Byrd-Omojokun SQP loop, with repeated second-order corrections and a stall test.

SciPy's ``equality_constrained_sqp`` (SciPy 1.17, ``scipy/optimize/_trustregion_constr/
equality_constrained_sqp.py``; Copyright (c) 2001-2002 Enthought, Inc., 2003 SciPy Developers;
BSD-3-Clause, ``LICENSE-scipy.txt`` beside this file), which trust-constr's interior-point method
calls once per barrier parameter, with two changes, each a parameter of the loop:

- ``max_corrections``. When the merit function refuses a step, SciPy tries one second-order
  correction (a least-norm step back onto the linearised constraints, ``-Y c(x + d)``) and gives
  up if the merit function refuses that too. Here the correction is repeated, each from the
  constraint values at the last corrected point, up to :data:`MAX_CORRECTIONS` times in all,
  while each one shrinks the constraint violation by at least :data:`CONTRACTION` (IPOPT's
  ``max_soc`` and ``kappa_soc``). Near the optimum a step along the constraints' null space bends
  inactive torque rows by more than one correction removes, so the step was refused and the trust
  radius cut to a tenth, and a solve crawled (``docs/design-notes.md``).
- ``stall_iterations``. A barrier subproblem that no longer makes progress ends
  (:class:`~modular_robots.ocp._scipy.stall.StallTest`), as SciPy's ``xtol`` test ends one whose
  trust radius has collapsed, sooner.

With ``max_corrections=1`` and ``stall_iterations=0`` the loop is SciPy's, iterate for iterate
(``tests/test_sqp.py``). The optimality's ``A^T v`` is taken by SciPy's kernel without building
``A^T`` (:func:`~modular_robots.ocp._scipy.products.rmatvec`, bit for bit the same).

The projections are looked up in SciPy's module at each call, so
:mod:`~modular_robots.ocp._scipy.trust_constr`'s replacement applies here as it does in SciPy's
loop. Its installer puts this loop in place only where SciPy's loop is the one copied here (the
same source, as in SciPy 1.16.0 to 1.17.1); elsewhere SciPy's own loop runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.linalg import norm
from scipy.optimize._trustregion_constr import equality_constrained_sqp as _scipy_sqp
from scipy.optimize._trustregion_constr.qp_subproblem import modified_dogleg, projected_cg

from . import checkpoint
from .boxes import box_intersections
from .products import rmatvec
from .stall import STALL_ITERATIONS, StallTest

__all__ = [
    "equality_constrained_sqp",
    "MAX_CORRECTIONS",
    "CONTRACTION",
    "STALL_ITERATIONS",
    "EXTRA_PARAMETERS",
]

#: Second-order corrections tried per refused step, the first (SciPy's) included: IPOPT's ``max_soc``.
MAX_CORRECTIONS = 4
#: A further correction is tried only if the last one cut the constraint violation's norm to at
#: most this share of the one before: IPOPT's ``kappa_soc``.
CONTRACTION = 0.99
#: The loop's parameters that SciPy's has not (each with SciPy's behaviour at one value).
EXTRA_PARAMETERS = ("max_corrections", "stall_iterations")

# The constants of SciPy's loop, unchanged (references in SciPy's source).
PENALTY_FACTOR = 0.3
LARGE_REDUCTION_RATIO = 0.9
INTERMEDIARY_REDUCTION_RATIO = 0.3
SUFFICIENT_REDUCTION_RATIO = 1e-8
TRUST_ENLARGEMENT_FACTOR_L = 7.0
TRUST_ENLARGEMENT_FACTOR_S = 2.0
MAX_TRUST_REDUCTION = 0.5
MIN_TRUST_REDUCTION = 0.1
SOC_THRESHOLD = 0.1
TR_FACTOR = 0.8
BOX_FACTOR = 0.5


def equality_constrained_sqp(
    fun_and_constr,
    grad_and_jac,
    lagr_hess,
    x0,
    fun0,
    grad0,
    constr0,
    jac0,
    stop_criteria,
    state,
    initial_penalty,
    initial_trust_radius,
    factorization_method,
    trust_lb=None,
    trust_ub=None,
    scaling=_scipy_sqp.default_scaling,
    max_corrections: int = MAX_CORRECTIONS,
    stall_iterations: int = STALL_ITERATIONS,
):
    """SciPy's ``equality_constrained_sqp`` (same arguments and result) with up to
    ``max_corrections`` second-order corrections per refused step, and the subproblem ended on a
    stall of ``stall_iterations`` iterations (module docstring)."""
    projections = _scipy_sqp.projections
    (n,) = np.shape(x0)
    if trust_lb is None:
        trust_lb = np.full(n, -np.inf)
    if trust_ub is None:
        trust_ub = np.full(n, np.inf)

    session = checkpoint.current_session()
    resume = session.take_resume() if session is not None else None
    x = np.copy(x0)
    trust_radius = initial_trust_radius
    penalty = initial_penalty
    f, c, b, A = fun0, grad0, constr0, jac0
    if resume is not None:  # (checkpoint.py) from where a stopped solve was: its values there
        x = np.array(resume.arrays["z"])
        trust_radius, penalty = resume.scalar("trust_radius"), resume.scalar("penalty")
        f, b = fun_and_constr(x)
        c, A = grad_and_jac(x)
    S = scaling(x)
    try:
        Z, LS, Y = projections(A, factorization_method)
    except ValueError as e:
        if str(e) == "expected square matrix":
            raise ValueError(
                "The 'expected square matrix' error can occur if there are"
                " more equality constraints than independent variables."
                " Consider how your constraints are set up, or use"
                " factorization_method='SVDFactorization'."
            ) from e
        raise
    v = -LS.dot(c)  # least-squares Lagrange multipliers
    H = lagr_hess(x, v)
    optimality = norm(c + rmatvec(A, v), np.inf)
    constr_violation = norm(b, np.inf) if len(b) > 0 else 0
    cg_info = {"niter": 0, "stop_cond": 0, "hits_boundary": False}

    last_iteration_failed = False
    subproblem = getattr(stop_criteria, "__self__", None)  # SciPy's BarrierSubproblem
    if resume is not None:
        assert session is not None  # (it gave the state)
        session.restore(resume, stop_criteria, state)
        last_iteration_failed = bool(resume.arrays["last_iteration_failed"])
        cg_info = checkpoint.cg_info(resume)
    stall = StallTest(subproblem, stall_iterations, checkpoint.stall_window(resume) if resume is not None else ())
    while True:
        if session is not None:
            session.note(x, trust_radius, penalty, last_iteration_failed, cg_info, stop_criteria, state, stall)
        if stop_criteria(state, x, last_iteration_failed, optimality, constr_violation, trust_radius, penalty, cg_info):
            break
        if stall.stalled(float(f), float(constr_violation), trust_radius):
            if subproblem is not None and stall.ends_solve(float(constr_violation)):
                subproblem.terminate, state.status = True, 2  # nothing left to decrease: SciPy's end by xtol
                if session is not None:
                    session.stalled = stall.describe()
            break
        # Normal step: minimise ||A dn + b|| within a shrunk trust region and box.
        dn = modified_dogleg(A, Y, b, TR_FACTOR * trust_radius, BOX_FACTOR * trust_lb, BOX_FACTOR * trust_ub)
        # Tangential step: the quadratic model in the null space of A.
        c_t = H.dot(dn) + c
        b_t = np.zeros_like(b)
        trust_radius_t = np.sqrt(trust_radius**2 - np.linalg.norm(dn) ** 2)
        dt, cg_info = projected_cg(H, c_t, Z, Y, b_t, trust_radius_t, trust_lb - dn, trust_ub - dn)
        d = dn + dt

        quadratic_model = 1 / 2 * (H.dot(d)).dot(d) + c.T.dot(d)
        linearized_constr = A.dot(d) + b
        vpred: Any = max(1e-16, norm(b) - norm(linearized_constr))  # a float, NumPy's stubs aside
        previous_penalty = penalty
        if quadratic_model > 0:
            penalty = max(penalty, quadratic_model / ((1 - PENALTY_FACTOR) * vpred))
        predicted_reduction = -quadratic_model + penalty * vpred

        merit_function = f + penalty * norm(b)
        x_next = x + S.dot(d)
        f_next, b_next = fun_and_constr(x_next)
        merit_function_next = f_next + penalty * norm(b_next)
        reduction_ratio = (merit_function - merit_function_next) / predicted_reduction

        if reduction_ratio < SUFFICIENT_REDUCTION_RATIO and norm(dn) <= SOC_THRESHOLD * norm(dt):
            step, b_last = d, b_next
            for _ in range(max_corrections):
                y = -Y.dot(b_last)
                _, t, intersect = box_intersections(step, y, trust_lb, trust_ub)
                step = step + t * y
                x_soc = x + S.dot(step)
                f_soc, b_soc = fun_and_constr(x_soc)
                reduction_ratio_soc = (merit_function - (f_soc + penalty * norm(b_soc))) / predicted_reduction
                if intersect and reduction_ratio_soc >= SUFFICIENT_REDUCTION_RATIO:
                    x_next, f_next, b_next = x_soc, f_soc, b_soc
                    reduction_ratio = reduction_ratio_soc
                    break
                if not intersect or not norm(b_soc) <= CONTRACTION * norm(b_last):  # NaN stops too
                    break
                b_last = b_soc

        # The trust region, from the reduction ratio.
        if reduction_ratio >= LARGE_REDUCTION_RATIO:
            trust_radius = max(TRUST_ENLARGEMENT_FACTOR_L * norm(d), trust_radius)
        elif reduction_ratio >= INTERMEDIARY_REDUCTION_RATIO:
            trust_radius = max(TRUST_ENLARGEMENT_FACTOR_S * norm(d), trust_radius)
        elif reduction_ratio < SUFFICIENT_REDUCTION_RATIO:
            trust_reduction = (1 - SUFFICIENT_REDUCTION_RATIO) / (1 - reduction_ratio)
            new_trust_radius = trust_reduction * norm(d)
            if new_trust_radius >= MAX_TRUST_REDUCTION * trust_radius:
                trust_radius *= MAX_TRUST_REDUCTION
            elif new_trust_radius >= MIN_TRUST_REDUCTION * trust_radius:
                trust_radius = new_trust_radius
            else:
                trust_radius *= MIN_TRUST_REDUCTION

        if reduction_ratio >= SUFFICIENT_REDUCTION_RATIO:
            x = x_next
            f, b = f_next, b_next
            c, A = grad_and_jac(x)
            S = scaling(x)
            Z, LS, Y = projections(A, factorization_method)
            v = -LS.dot(c)
            H = lagr_hess(x, v)
            last_iteration_failed = False
            optimality = norm(c + rmatvec(A, v), np.inf)
            constr_violation = norm(b, np.inf) if len(b) > 0 else 0
        else:
            penalty = previous_penalty
            last_iteration_failed = True

    return x, state
