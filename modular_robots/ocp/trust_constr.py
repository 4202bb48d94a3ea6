"""Where the project takes over parts of SciPy's ``trust-constr``, in a solver's thread only.

trust-constr has no options for these, so importing this module replaces seven names in SciPy's
modules (:data:`INSTALLED` lists those it found; a SciPy laid out otherwise keeps its own
code). Each replacement acts only in a thread marked by :func:`mark_solver_thread` (a
:class:`~modular_robots.ocp.solver.ShootingSolver`'s); anywhere else it is SciPy's code,
unchanged:

- ``projections`` of its SQP step: from the barrier subproblem's structure
  (:func:`~modular_robots.ocp.projections.barrier_projections`, about three times cheaper than
  SuperLU on the whole augmented system; a matrix without the structure, singular or non-finite
  goes to SciPy's);
- its canonical constraints, by gathers (:class:`~modular_robots.ocp.canonical.GatheredCanonical`;
  bit-identical values and Jacobians);
- the barrier function's sum of ``log(s)``, vectorised instead of a Python loop over the slacks
  (bit-identical);
- its SQP loop, by :func:`~modular_robots.ocp.sqp.equality_constrained_sqp`: SciPy's, with the
  second-order correction of a refused step repeated (IPOPT's rule) instead of tried once;
- the barrier subproblem's Jacobian, by puts into the structure of the last one
  (:class:`~modular_robots.ocp.barrier.BarrierJacobian`; bit-identical);
- the quasi-Newton update's gradient change ``J^T v - J_prev^T v``, by SciPy's kernel without
  building the transposes (:func:`~modular_robots.ocp.products.rmatvec`; bit-identical).

``tests/test_projections.py``, ``tests/test_canonical.py``, ``tests/test_trust_constr.py`` and
``tests/test_sqp.py`` check each against SciPy's own.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
from scipy import sparse
from scipy.optimize import HessianUpdateStrategy

from .barrier import BarrierJacobian
from .products import rmatvec
from .projections import barrier_projections

try:  # SciPy's private modules: a SciPy that lays trust-constr out otherwise keeps its own code
    from scipy.optimize._trustregion_constr import equality_constrained_sqp as _sqp
    from scipy.optimize._trustregion_constr import minimize_trustregion_constr as _minimize_module
    from scipy.optimize._trustregion_constr import qp_subproblem as _qp
    from scipy.optimize._trustregion_constr import tr_interior_point as _interior_point
except ImportError:  # pragma: no cover (the SciPy the tests run on has them)
    _sqp = _minimize_module = _interior_point = _qp = None
try:  # the quasi-Newton Hessian's update lives in SciPy's VectorFunction
    from scipy.optimize._differentiable_functions import VectorFunction as _VectorFunction
except ImportError:  # pragma: no cover
    _VectorFunction = None
try:  # builds on SciPy's CanonicalConstraint (a private module too): without it, only this hook goes
    from .canonical import GatheredCanonical
except ImportError:  # pragma: no cover
    _minimize_module, GatheredCanonical = None, object
try:  # a copy of SciPy's loop that calls into its private modules: without them, SciPy's loop stays
    from . import sqp
except ImportError:  # pragma: no cover
    sqp = None
try:  # reads SciPy's own box_intersections from its private module: without it, SciPy's stays
    from .boxes import box_intersections as fast_box_intersections
except ImportError:  # pragma: no cover
    _qp = None

__all__ = ["INSTALLED", "mark_solver_thread", "solver_thread", "in_solver_thread"]

logger = logging.getLogger(__name__)

_solver_thread = threading.local()


def mark_solver_thread(n_variables: int) -> None:
    """Mark the calling thread as a solver's, for a problem of ``n_variables`` variables."""
    _solver_thread.n_variables = n_variables


@contextmanager
def solver_thread(n_variables: int) -> Iterator[None]:
    """Mark the calling thread as a solver's (:func:`mark_solver_thread`) for the ``with`` block,
    and give it back its previous mark after."""
    previous = getattr(_solver_thread, "n_variables", None)
    _solver_thread.n_variables = n_variables
    try:
        yield
    finally:
        _solver_thread.n_variables = previous


def in_solver_thread() -> bool:
    """True in a thread marked by :func:`mark_solver_thread`."""
    return getattr(_solver_thread, "n_variables", None) is not None


def projections(A, method=None, orth_tol=1e-12, max_refin=3, tol=1e-15):
    """SciPy's ``projections`` (null-space, least-squares and row-space operators of ``A``); in a
    solver's thread, from the barrier subproblem's structure when ``A`` has it."""
    n_variables = getattr(_solver_thread, "n_variables", None)
    if n_variables is not None and method in (None, "AugmentedSystem") and sparse.issparse(A):
        try:
            return barrier_projections(A, n_variables, max_refin)
        except ValueError:  # not the barrier structure, or singular: SciPy's general path
            pass
    return scipy_projections(A, method, orth_tol, max_refin, tol)


class SolverCanonical(GatheredCanonical):
    """Canonical constraints by gathers in a solver's thread, SciPy's own anywhere else."""

    @classmethod
    def from_PreparedConstraint(cls, constraint):
        if not in_solver_thread():
            return ScipyCanonical.from_PreparedConstraint(constraint)
        return super().from_PreparedConstraint(constraint)

    @classmethod
    def concatenate(cls, canonical_constraints, sparse_jacobian):
        if not in_solver_thread():
            return ScipyCanonical.concatenate(canonical_constraints, sparse_jacobian)
        return super().concatenate(canonical_constraints, sparse_jacobian)


def barrier_function(self, f, c_ineq, s):
    """trust-constr's barrier function ``f - mu * sum(log(s))`` (the log of an ``s <= 0`` taken
    as ``-inf``, so the function is ``+inf``), from ``BarrierSubproblem._compute_function``, with
    the logarithms taken at once."""
    if not in_solver_thread():
        return scipy_barrier_function(self, f, c_ineq, s)
    s[self.enforce_feasibility] = -c_ineq[self.enforce_feasibility]
    positive = s > 0
    log_s = np.full(s.shape, -np.inf)
    np.log(s, out=log_s, where=positive)
    return f - self.barrier_parameter * np.sum(log_s)


def sqp_loop(*args, **kwargs):
    """trust-constr's SQP loop for one barrier parameter: in a solver's thread
    :func:`~modular_robots.ocp.sqp.equality_constrained_sqp`, SciPy's anywhere else."""
    if in_solver_thread():
        return sqp.equality_constrained_sqp(*args, **kwargs)
    return scipy_sqp_loop(*args, **kwargs)


def barrier_jacobian(self, J_eq, J_ineq, s):
    """trust-constr's ``BarrierSubproblem._assemble_sparse_jacobian``: in a solver's thread by
    puts into the last structure (:class:`~modular_robots.ocp.barrier.BarrierJacobian`), SciPy's
    anywhere else."""
    if not in_solver_thread():
        return scipy_barrier_jacobian(self, J_eq, J_ineq, s)
    assemble = getattr(_solver_thread, "barrier_jacobian", None)
    if assemble is None:
        assemble = _solver_thread.barrier_jacobian = BarrierJacobian()
    return assemble(J_eq, J_ineq, s, self.n_vars, lambda *args: scipy_barrier_jacobian(self, *args))


def hessian_update(self):
    """SciPy's ``VectorFunction._update_hess``; in a solver's thread, a quasi-Newton update takes
    the gradient change ``J^T v - J_prev^T v`` by :func:`~modular_robots.ocp.products.rmatvec`
    (SciPy's own kernel, without building the transposes)."""
    quasi_newton = isinstance(self._orig_hess, HessianUpdateStrategy) and not callable(self._orig_hess)
    if self.H_updated or not in_solver_thread() or not quasi_newton:
        return scipy_hessian_update(self)
    self._update_jac()
    if self.x_prev is not None and self.J_prev is not None:
        delta_x = self.x - self.x_prev
        delta_g = rmatvec(self.J, self.v) - rmatvec(self.J_prev, self.v)
        self.H.update(delta_x, delta_g)
    self.H_updated = True


def box_intersections(z, d, lb, ub, entire_line=False):
    """SciPy's ``box_intersections``; in a solver's thread
    :func:`~modular_robots.ocp.boxes.box_intersections` (the same results, found faster)."""
    if in_solver_thread():
        return fast_box_intersections(z, d, lb, ub, entire_line)
    return scipy_box_intersections(z, d, lb, ub, entire_line)


def _original(owner, name: str):
    """SciPy's ``owner.name`` (None if it has none), also after this module is imported again."""
    found = getattr(owner, name, None)
    return getattr(found, "__scipy_original__", found)


scipy_projections = _original(_sqp, "projections")
ScipyCanonical = _original(_minimize_module, "CanonicalConstraint")
scipy_barrier_function = _original(getattr(_interior_point, "BarrierSubproblem", None), "_compute_function")
scipy_sqp_loop = _original(_interior_point, "equality_constrained_sqp") if sqp is not None else None
scipy_barrier_jacobian = _original(getattr(_interior_point, "BarrierSubproblem", None), "_assemble_sparse_jacobian")
scipy_hessian_update = _original(_VectorFunction, "_update_hess")
scipy_box_intersections = _original(_qp, "box_intersections")

#: The replacements in place, by name; each needs SciPy's original to exist.
INSTALLED: tuple[str, ...] = ()
for _label, _owner, _name, _replacement, _original_found in (
    ("projections", _sqp, "projections", projections, scipy_projections),  # once per iteration
    ("canonical constraints", _minimize_module, "CanonicalConstraint", SolverCanonical, ScipyCanonical),  # per solve
    (
        "barrier function",
        getattr(_interior_point, "BarrierSubproblem", None),
        "_compute_function",
        barrier_function,
        scipy_barrier_function,
    ),  # once per evaluated point
    ("SQP loop", _interior_point, "equality_constrained_sqp", sqp_loop, scipy_sqp_loop),  # per barrier parameter
    (
        "barrier Jacobian",
        getattr(_interior_point, "BarrierSubproblem", None),
        "_assemble_sparse_jacobian",
        barrier_jacobian,
        scipy_barrier_jacobian,
    ),  # once per point whose Jacobian is asked for
    ("quasi-Newton update", _VectorFunction, "_update_hess", hessian_update, scipy_hessian_update),  # per point
    ("box intersections", _qp, "box_intersections", box_intersections, scipy_box_intersections),  # per CG step
):
    if _original_found is None:
        logger.warning("trust-constr has no %s here; SciPy's own code is used", _label)
        continue
    _replacement.__scipy_original__ = _original_found
    setattr(_owner, _name, _replacement)
    INSTALLED += (_label,)
