"""The installer of the project's replacements for parts of SciPy's ``trust-constr``, and the
replacements' entry points, which act in a solver's thread only.

trust-constr has no options for these, so :func:`install` replaces seven names in SciPy's
private modules (:data:`HOOKS`). Nothing is replaced on import: a
:class:`~modular_robots.ocp.solver.ShootingSolver` calls :func:`install` before its first solve
(idempotent, thread-safe; :func:`uninstall` puts SciPy's own code back). Each replacement acts
only in a thread marked by :func:`mark_solver_thread` or :func:`solver_thread` (a
:class:`~modular_robots.ocp.solver.ShootingSolver`'s); anywhere else it is SciPy's code,
unchanged:

- ``projections`` of its SQP step: from the barrier subproblem's structure
  (:func:`~modular_robots.ocp._scipy.projections.barrier_projections`, about three times cheaper
  than SuperLU on the whole augmented system; a matrix without the structure, singular or
  non-finite goes to SciPy's);
- its canonical constraints, by gathers
  (:class:`~modular_robots.ocp._scipy.canonical.GatheredCanonical`; bit-identical values and
  Jacobians);
- the barrier function's sum of ``log(s)``, vectorised instead of a Python loop over the slacks
  (bit-identical);
- its SQP loop, by :func:`~modular_robots.ocp._scipy.sqp.equality_constrained_sqp`: SciPy's, with
  the second-order correction of a refused step repeated (IPOPT's rule) instead of tried once,
  and a barrier subproblem that has stalled ended (:mod:`~modular_robots.ocp._scipy.stall`);
- the barrier subproblem's Jacobian, by puts into the structure of the last one
  (:class:`~modular_robots.ocp._scipy.barrier.BarrierJacobian`; bit-identical);
- the quasi-Newton update's gradient change ``J^T v - J_prev^T v``, by SciPy's kernel without
  building the transposes (:func:`~modular_robots.ocp._scipy.products.rmatvec`; bit-identical).

The fence. A hook is installed only on a SciPy in :data:`TESTED_SCIPY` (the ``scipy`` pin of
``pyproject.toml``) whose private names are where the replacement expects them: the module and
attribute exist, SciPy's original takes the parameters the replacement takes, and its code still
uses the private names (attributes, globals) the replacement relies on; the SQP loop, a copy, is
installed only where SciPy's loop is the one copied (its source's hash). A hook that fails any
check (or whose replacement module cannot be imported) is left as SciPy's own code, and
:func:`install` says which and why in one :class:`ScipyHookWarning` per reason; the others are
installed. The same for SciPy's compiled sparse kernels that
:mod:`~modular_robots.ocp._scipy.products` calls (``sparse kernels``). At run time, a replacement
that meets what it cannot compute (a matrix without the barrier structure, a NaN) hands it to
SciPy's code, as before; anything else it raises ends the solve as ``failed`` with the reason.

``tests/test_scipy_hooks.py`` checks the fence, ``tests/test_projections.py``,
``tests/test_canonical.py``, ``tests/test_trust_constr.py`` and ``tests/test_sqp.py`` each
replacement against SciPy's own; ``make test-scipy-low`` runs them on the lowest SciPy of the
range.
"""

from __future__ import annotations

import hashlib
import importlib
import inspect
import re
import threading
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy
from scipy import sparse
from scipy.optimize import HessianUpdateStrategy

from . import products
from .barrier import BarrierJacobian
from .products import rmatvec
from .projections import barrier_projections

__all__ = [
    "install",
    "uninstall",
    "Installed",
    "ScipyHookWarning",
    "HOOKS",
    "TESTED_SCIPY",
    "mark_solver_thread",
    "solver_thread",
    "in_solver_thread",
]

#: The SciPy versions the replacements are tested on, ``(lowest, first refused)`` as ``(major,
#: minor)``: ``pyproject.toml``'s ``scipy>=1.16,<1.18`` (``tests/test_scipy_hooks.py`` checks they
#: agree). SciPy 1.15 and older keep the quasi-Newton update in a closure made per instance, so
#: its hook cannot be installed there.
TESTED_SCIPY = ((1, 16), (1, 18))

#: The replacements, in the order they are installed.
HOOKS = (
    "projections",  # once per iteration
    "canonical constraints",  # per solve
    "barrier function",  # once per evaluated point
    "SQP loop",  # per barrier parameter
    "barrier Jacobian",  # once per point whose Jacobian is asked for
    "quasi-Newton update",  # per point
    "box intersections",  # per CG step
)

#: What :mod:`~modular_robots.ocp._scipy.products` falls back from when SciPy's kernels are not there.
KERNELS = "sparse kernels"

#: The sha256 of the source of SciPy's ``equality_constrained_sqp`` that ``sqp.py`` copies
#: (SciPy 1.16.0 to 1.17.1 have this very function).
COPIED_LOOP_SHA256 = "ed50c873077905fc77bbd90dfd4f23aaf64dee316ea0bb0b92744e725776f2f7"

_TRUST_CONSTR = "scipy.optimize._trustregion_constr"


class ScipyHookWarning(UserWarning):
    """A replacement of part of SciPy's trust-constr is not installed; SciPy's own code is used
    (slower, and for the SQP loop without the project's changes to it: :mod:`~modular_robots.ocp._scipy.sqp`)."""


@dataclass(frozen=True, eq=False)
class Installed:
    """What :func:`install` did: the hooks in place, and why the others are SciPy's code."""

    #: The replacements in place, in :data:`HOOKS` order.
    hooks: tuple[str, ...]
    #: Each hook left as SciPy's code (and :data:`KERNELS` if SciPy's sparse kernels are not
    #: used), with the reason.
    fallbacks: dict[str, str] = field(default_factory=dict)
    scipy_version: str = scipy.__version__

    @property
    def complete(self) -> bool:
        """Every hook in place and SciPy's kernels used."""
        return self.hooks == HOOKS and not self.fallbacks

    def __contains__(self, hook: object) -> bool:
        return hook in self.hooks


# -- the solver's thread --------------------------------------------------------------------------

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


# -- the replacements' entry points (SciPy's originals are set by install) ------------------------

scipy_projections: Any = None
ScipyCanonical: Any = None
scipy_barrier_function: Any = None
scipy_sqp_loop: Any = None
scipy_barrier_jacobian: Any = None
scipy_hessian_update: Any = None
scipy_box_intersections: Any = None
#: The replacements imported from modules that read SciPy's private names (set by install).
SolverCanonical: Any = None
sqp: Any = None
fast_box_intersections: Any = None


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


def _solver_canonical(gathered: type) -> type:
    """Canonical constraints by ``gathered``'s gathers in a solver's thread, SciPy's own anywhere else."""

    class SolverCanonical(gathered):
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

    return SolverCanonical


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
    :func:`~modular_robots.ocp._scipy.sqp.equality_constrained_sqp`, SciPy's anywhere else."""
    if in_solver_thread():
        return sqp.equality_constrained_sqp(*args, **kwargs)
    return scipy_sqp_loop(*args, **kwargs)


def barrier_jacobian(self, J_eq, J_ineq, s):
    """trust-constr's ``BarrierSubproblem._assemble_sparse_jacobian``: in a solver's thread by
    puts into the last structure (:class:`~modular_robots.ocp._scipy.barrier.BarrierJacobian`),
    SciPy's anywhere else."""
    if not in_solver_thread():
        return scipy_barrier_jacobian(self, J_eq, J_ineq, s)
    assemble = getattr(_solver_thread, "barrier_jacobian", None)
    if assemble is None:
        assemble = _solver_thread.barrier_jacobian = BarrierJacobian()
    return assemble(J_eq, J_ineq, s, self.n_vars, lambda *args: scipy_barrier_jacobian(self, *args))


def hessian_update(self):
    """SciPy's ``VectorFunction._update_hess``; in a solver's thread, a quasi-Newton update takes
    the gradient change ``J^T v - J_prev^T v`` by
    :func:`~modular_robots.ocp._scipy.products.rmatvec` (SciPy's own kernel, without building the
    transposes)."""
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
    :func:`~modular_robots.ocp._scipy.boxes.box_intersections` (the same results, found faster)."""
    if in_solver_thread():
        return fast_box_intersections(z, d, lb, ub, entire_line)
    return scipy_box_intersections(z, d, lb, ub, entire_line)


# -- the installer --------------------------------------------------------------------------------


class _Mismatch(Exception):
    """SciPy's code is not what a replacement was written for."""


@dataclass(frozen=True)
class _Hook:
    """A replacement ready to go in: ``owner.name`` becomes ``replacement``; ``original`` (SciPy's)
    goes to this module's global ``keep``; ``imported`` sets further globals."""

    owner: Any
    name: str
    original: Any
    replacement: Any
    keep: str
    imported: dict[str, Any] = field(default_factory=dict)


def _private(module: str, *attributes: str) -> Any:
    """SciPy's ``module.attribute...``: ImportError or AttributeError if it moved."""
    found: Any = importlib.import_module(module)
    for attribute in attributes:
        found = getattr(found, attribute)
    return found


def _original(owner, name: str):
    """SciPy's ``owner.name`` (AttributeError if it has none), also once a replacement is there."""
    found = getattr(owner, name)
    return getattr(found, "__scipy_original__", found)


def _expect_parameters(function, names: tuple[str, ...]) -> None:
    found = tuple(inspect.signature(function).parameters)
    if found != names:
        raise _Mismatch(f"{_qualified(function)} takes ({', '.join(found)}), not ({', '.join(names)})")


def _expect_uses(function, names: tuple[str, ...]) -> None:
    """``function``'s code names (attributes, globals) include ``names``: the private names the
    replacement reads are still SciPy's."""
    function = inspect.unwrap(getattr(function, "__func__", function))
    missing = [name for name in names if name not in function.__code__.co_names]
    if missing:
        raise _Mismatch(f"{_qualified(function)} no longer uses {', '.join(missing)}")


def _expect_closure(function, nested: str, names: tuple[str, ...]) -> None:
    """``function`` defines a function ``nested`` whose closure holds ``names`` (the stall test
    reads them from trust-constr's stopping test)."""
    code = inspect.unwrap(function).__code__
    found = [c for c in code.co_consts if inspect.iscode(c) and c.co_name == nested]
    if not any(set(names) <= set(c.co_freevars) for c in found):
        raise _Mismatch(f"{_qualified(function)}'s {nested} no longer takes {', '.join(names)} from its closure")


def _qualified(function) -> str:
    return f"{getattr(function, '__module__', '?')}.{getattr(function, '__qualname__', function)}"


def _prepare_projections() -> _Hook:
    module = _private(f"{_TRUST_CONSTR}.equality_constrained_sqp")
    original = _original(module, "projections")
    _expect_parameters(original, ("A", "method", "orth_tol", "max_refin", "tol"))
    _expect_uses(_original(module, "equality_constrained_sqp"), ("projections",))
    return _Hook(module, "projections", original, projections, "scipy_projections")


def _prepare_canonical() -> _Hook:
    module = _private(f"{_TRUST_CONSTR}.minimize_trustregion_constr")
    original = _original(module, "CanonicalConstraint")
    from . import canonical  # subclasses SciPy's CanonicalConstraint from its own private module

    if not issubclass(canonical.GatheredCanonical, original):
        raise _Mismatch("trust-constr's CanonicalConstraint is not canonical_constraint's")
    _expect_parameters(original.from_PreparedConstraint, ("constraint",))
    _expect_parameters(original.concatenate, ("canonical_constraints", "sparse_jacobian"))
    _expect_uses(original.from_PreparedConstraint, ("bounds", "fun"))
    _expect_uses(module._minimize_trustregion_constr, ("CanonicalConstraint",))
    vector_function = _private("scipy.optimize._differentiable_functions", "VectorFunction")
    _expect_uses(vector_function.__init__, ("n",))
    _expect_parameters(vector_function.fun, ("self", "x"))
    _expect_parameters(vector_function.jac, ("self", "x"))
    replacement = _solver_canonical(canonical.GatheredCanonical)
    return _Hook(
        module, "CanonicalConstraint", original, replacement, "ScipyCanonical", {"SolverCanonical": replacement}
    )


def _prepare_barrier_function() -> _Hook:
    owner = _private(f"{_TRUST_CONSTR}.tr_interior_point", "BarrierSubproblem")
    original = _original(owner, "_compute_function")
    _expect_parameters(original, ("self", "f", "c_ineq", "s"))
    _expect_uses(original, ("enforce_feasibility", "barrier_parameter"))
    return _Hook(owner, "_compute_function", original, barrier_function, "scipy_barrier_function")


def _prepare_sqp_loop() -> _Hook:
    module = _private(f"{_TRUST_CONSTR}.tr_interior_point")
    original = _original(module, "equality_constrained_sqp")
    from . import sqp as copy  # reads SciPy's qp_subproblem and equality_constrained_sqp modules

    ours = tuple(inspect.signature(copy.equality_constrained_sqp).parameters)
    _expect_parameters(original, tuple(name for name in ours if name not in copy.EXTRA_PARAMETERS))
    _expect_uses(module.tr_interior_point, ("equality_constrained_sqp",))
    _expect_uses(module.BarrierSubproblem.stop_criteria, ("tolerance", "xtol", "global_stop_criteria"))
    _expect_uses(module.BarrierSubproblem.__init__, ("barrier_parameter", "terminate"))
    _expect_uses(module.tr_interior_point, ("terminate",))
    minimize_module = _private(f"{_TRUST_CONSTR}.minimize_trustregion_constr")
    _expect_closure(minimize_module._minimize_trustregion_constr, "stop_criteria", ("barrier_tol", "gtol"))
    source = hashlib.sha256(inspect.getsource(original).encode()).hexdigest()
    if source != COPIED_LOOP_SHA256:
        raise _Mismatch("SciPy's equality_constrained_sqp is not the one sqp.py copies (SciPy 1.17's)")
    return _Hook(module, "equality_constrained_sqp", original, sqp_loop, "scipy_sqp_loop", {"sqp": copy})


def _prepare_barrier_jacobian() -> _Hook:
    owner = _private(f"{_TRUST_CONSTR}.tr_interior_point", "BarrierSubproblem")
    original = _original(owner, "_assemble_sparse_jacobian")
    _expect_parameters(original, ("self", "J_eq", "J_ineq", "s"))
    _expect_uses(original, ("n_vars",))
    return _Hook(owner, "_assemble_sparse_jacobian", original, barrier_jacobian, "scipy_barrier_jacobian")


def _prepare_hessian_update() -> _Hook:
    owner = _private("scipy.optimize._differentiable_functions", "VectorFunction")
    original = _original(owner, "_update_hess")
    _expect_parameters(original, ("self",))
    _expect_uses(original, ("H_updated", "_orig_hess", "_update_jac", "x", "x_prev", "J", "J_prev", "v", "H"))
    return _Hook(owner, "_update_hess", original, hessian_update, "scipy_hessian_update")


def _prepare_box_intersections() -> _Hook:
    module = _private(f"{_TRUST_CONSTR}.qp_subproblem")
    original = _original(module, "box_intersections")
    _expect_parameters(original, ("z", "d", "lb", "ub", "entire_line"))
    _expect_uses(_original(module, "box_sphere_intersections"), ("box_intersections",))
    from . import boxes  # reads SciPy's qp_subproblem module

    return _Hook(
        module,
        "box_intersections",
        original,
        box_intersections,
        "scipy_box_intersections",
        {"fast_box_intersections": boxes.box_intersections},
    )


_PREPARE: dict[str, Callable[[], _Hook]] = {
    "projections": _prepare_projections,
    "canonical constraints": _prepare_canonical,
    "barrier function": _prepare_barrier_function,
    "SQP loop": _prepare_sqp_loop,
    "barrier Jacobian": _prepare_barrier_jacobian,
    "quasi-Newton update": _prepare_hessian_update,
    "box intersections": _prepare_box_intersections,
}


def _check_kernels() -> None:
    """SciPy's ``csr_matvec`` and ``csc_matvec``, which ``products`` calls, there and computing
    SciPy's products on a probe matrix."""
    if products._sparsetools is None:
        raise _Mismatch("scipy.sparse._sparsetools is not there")
    missing = [name for name in ("csr_matvec", "csc_matvec") if not hasattr(products._sparsetools, name)]
    if missing:
        raise _Mismatch(f"scipy.sparse._sparsetools has no {', '.join(missing)}")
    probe = sparse.csr_array(np.array([[1.5, 0.0, -2.0], [0.0, 3.0, 0.25]]))
    x, v = np.array([0.5, -1.0, 2.0]), np.array([-1.0, 4.0])
    if not (np.array_equal(products.MatVec(probe)(x), probe @ x) and np.array_equal(rmatvec(probe, v), probe.T @ v)):
        raise _Mismatch("scipy.sparse._sparsetools' matvec kernels compute otherwise")


def _version_refusal() -> str | None:
    """Why this SciPy is not one the replacements are tested on (None if it is)."""
    (low, high), version = TESTED_SCIPY, scipy.__version__
    match = re.match(r"(\d+)\.(\d+)", version)
    if match is None or not low <= (int(match[1]), int(match[2])) < high:
        return f"SciPy {version} is outside the range they are tested on (>={low[0]}.{low[1]},<{high[0]}.{high[1]})"
    return None


_lock = threading.Lock()
_state: Installed | None = None
#: What install changed, to put back: (owner, name, SciPy's original), in installation order.
_replaced: list[tuple[Any, str, Any]] = []
_kernels: Any = None


def install() -> Installed:
    """Put the replacements in SciPy's place (once; later calls return the same answer).

    A hook whose SciPy names are not where the replacement expects them stays SciPy's code, and
    one :class:`ScipyHookWarning` per reason says which hooks and why (module docstring).
    """
    state = _state
    if state is not None:
        return state
    with _lock:
        return _install_locked()


def _install_locked() -> Installed:
    global _state, _kernels
    if _state is not None:
        return _state
    refused: dict[str, str] = {}
    hooks: list[str] = []
    version_refusal = _version_refusal()
    for label, prepare in _PREPARE.items():
        if version_refusal is not None:
            refused[label] = version_refusal
            continue
        try:
            hook = prepare()
        except Exception as exc:  # ImportError, AttributeError, a signature or code mismatch
            refused[label] = _reason(exc)
            continue
        hook.replacement.__scipy_original__ = hook.original
        globals()[hook.keep] = hook.original
        globals().update(hook.imported)
        setattr(hook.owner, hook.name, hook.replacement)
        _replaced.append((hook.owner, hook.name, hook.original))
        hooks.append(label)
    _kernels = products._sparsetools
    try:
        if hooks:  # the kernels serve the replacements only
            _check_kernels()
    except Exception as exc:
        refused[KERNELS] = _reason(exc)
        products._sparsetools = None  # MatVec takes SciPy's products
    by_reason: dict[str, list[str]] = {}
    for label, reason in refused.items():
        by_reason.setdefault(reason, []).append(label)
    for reason, labels in by_reason.items():
        warnings.warn(
            f"SciPy's own code is used for trust-constr's {', '.join(labels)} (not the project's "
            f"replacement{'s' if len(labels) > 1 else ''}): {reason}",
            ScipyHookWarning,
            stacklevel=3,  # install's caller
        )
    _state = Installed(tuple(hooks), refused)
    return _state


def _reason(exc: Exception) -> str:
    return str(exc) if isinstance(exc, _Mismatch) else f"{type(exc).__name__}: {exc}"


def uninstall() -> None:
    """Put SciPy's own code back where :func:`install` replaced it; the next :func:`install`
    checks and installs anew (for tests)."""
    global _state
    with _lock:
        while _replaced:
            owner, name, original = _replaced.pop()
            setattr(owner, name, original)
        if _state is not None:
            products._sparsetools = _kernels
        _state = None
