"""trust-constr's state between two iterations, taken and given back: a solve stopped at an
iteration goes on later, in another process, through the very iterates of a solve never stopped.

At each iteration's end the SQP loop (:mod:`~modular_robots.ocp._scipy.sqp`) notes, in the
solver thread's :class:`Session`, what it holds; :meth:`Session.capture` turns that into a
:class:`TrustConstrState` while the solver waits in its callback. The state is what
trust-constr carries from one iteration to the next and cannot compute again:

- the SQP loop's point ``z = (x, s)`` (variables and slacks), trust radius, penalty, and whether
  the last step was refused, with the conjugate-gradient report the iteration's stopping test
  was given;
- the barrier parameter and tolerance of the subproblem in progress, and the barrier function's
  and constraint violation's last values its stall test has seen
  (:mod:`~modular_robots.ocp._scipy.stall`);
- the result SciPy carries (counts, the last accepted point's values and multipliers);
- each quasi-Newton (SR1) matrix, with the point, the multipliers and the point before it that
  its wrapper's next update starts from.

Everything else (values, Jacobians, projections, multipliers at ``z``) is a function of these and
is computed again. Given back (:func:`session` with ``resume``), SciPy's set-up runs as usual
from the state's point, then the SQP loop replaces what it starts from with the state (after its
own first evaluations, whose quasi-Newton updates the restored matrices overwrite) and repeats the
stopping test of the iteration the state was taken at, so that every later decision is taken on
the same numbers: ``tests/test_checkpoint.py`` checks a resumed solve's iterates equal, bit for
bit, an unstopped one's. SciPy's evaluation counters (``nfev``, ``njev``) are reporting only and
restart from the resumption's set-up.

The state is a flat mapping of names to arrays (:attr:`TrustConstrState.arrays`), so that it is
written with :func:`numpy.savez` and read without unpickling.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import sparse
from scipy.optimize import HessianUpdateStrategy
from scipy.optimize._differentiable_functions import ScalarFunction, VectorFunction

from .stall import closure_values

__all__ = ["TrustConstrState", "Session", "session", "current_session"]

_local = threading.local()

#: The numbers of SciPy's result that an iteration carries on (the counters of evaluations aside).
_RESULT_SCALARS = ("nit", "cg_niter", "fun", "optimality", "constr_violation")
_RESULT_ARRAYS = ("x", "grad", "lagrangian_grad")
_RESULT_LISTS = ("v", "constr")
#: What every state holds (a file without one of them is not a state to resume from).
REQUIRED = (
    "z",
    "trust_radius",
    "penalty",
    "last_iteration_failed",
    "cg.niter",
    "cg.stop_cond",
    "cg.hits_boundary",
    "barrier_parameter",
    "barrier_tolerance",
    "stall.window",
    *(f"result.{name}" for name in (*_RESULT_SCALARS, *_RESULT_ARRAYS)),
    "result.v.0",
    "result.constr.0",
)
#: What each quasi-Newton wrapper's state holds, beside its point (``wrapper.<i>.x``).
_WRAPPER_REQUIRED = ("H_updated", "first_iteration")


@dataclass(frozen=True, eq=False)
class TrustConstrState:
    """trust-constr's state at the end of an iteration (module docstring): named arrays."""

    arrays: Mapping[str, Any]

    @property
    def iteration(self) -> int:
        """The iteration it was taken at (trust-constr's count)."""
        return int(self.arrays["result.nit"])

    @property
    def complete(self) -> bool:
        """Whether it holds every part a resumption reads (one read from a damaged file may not)."""
        names = set(self.arrays)
        wrappers = [name[: -len("x")] for name in names if name.startswith("wrapper.") and name.endswith(".x")]
        return all(name in names for name in REQUIRED) and all(
            prefix + part in names for prefix in wrappers for part in _WRAPPER_REQUIRED
        )

    @property
    def x(self) -> np.ndarray:
        """The last accepted point's variables."""
        return np.array(self.arrays["result.x"], dtype=float)

    def scalar(self, name: str) -> float:
        return float(self.arrays[name])


class Session:
    """What the SQP loop of one solve notes at each iteration, and the state it is to resume."""

    def __init__(self, resume: TrustConstrState | None = None):
        self.resume = resume
        self._noted: tuple | None = None
        #: Why the SQP loop ended the solve on a stall (None: it did not).
        self.stalled: str | None = None

    def note(self, z, trust_radius, penalty, last_iteration_failed, cg_info, stop_criteria, state, stall) -> None:
        """The SQP loop's state, before its stopping test (references, taken as they are;
        ``stall`` its :class:`~modular_robots.ocp._scipy.stall.StallTest`)."""
        self._noted = (z, trust_radius, penalty, last_iteration_failed, cg_info, stop_criteria, state, stall)

    def take_resume(self) -> TrustConstrState | None:
        """The state to resume from, once (the first SQP loop of the solve takes it)."""
        resume, self.resume = self.resume, None
        return resume

    def capture(self) -> TrustConstrState | None:
        """The state at the iteration's end, while the solver waits in its callback (None before
        the SQP loop noted one, or where SciPy's objects are not those expected)."""
        if self._noted is None:
            return None
        z, trust_radius, penalty, last_iteration_failed, cg_info, stop_criteria, state, stall = self._noted
        try:
            subproblem = stop_criteria.__self__
            objective, constraints = _wrappers(subproblem.global_stop_criteria)
            arrays: dict[str, Any] = {
                "z": np.array(z, dtype=float),
                "trust_radius": np.float64(trust_radius),
                "penalty": np.float64(penalty),
                "last_iteration_failed": np.bool_(last_iteration_failed),
                "cg.niter": np.int64(cg_info["niter"]),
                "cg.stop_cond": np.int64(cg_info["stop_cond"]),
                "cg.hits_boundary": np.bool_(cg_info["hits_boundary"]),
                "barrier_parameter": np.float64(subproblem.barrier_parameter),
                "barrier_tolerance": np.float64(subproblem.tolerance),
                "stall.window": stall.state(),
            }
            for name in _RESULT_SCALARS:
                arrays[f"result.{name}"] = np.asarray(state[name])
            for name in _RESULT_ARRAYS:
                arrays[f"result.{name}"] = np.array(state[name], dtype=float)
            for name in _RESULT_LISTS:
                for i, value in enumerate(state[name]):
                    arrays[f"result.{name}.{i}"] = np.array(value, dtype=float)
            for i, wrapper in enumerate((objective, *constraints)):
                arrays.update(_wrapper_state(wrapper, f"wrapper.{i}."))
        except (AttributeError, KeyError, TypeError):
            return None
        return TrustConstrState(arrays)

    def restore(self, resume: TrustConstrState, stop_criteria, state) -> None:
        """Give SciPy's wrappers and result ``resume``'s state, as before its iteration's
        stopping test (so that the test, taken again, counts that iteration once)."""
        arrays = resume.arrays
        objective, constraints = _wrappers(stop_criteria.__self__.global_stop_criteria)
        for i, wrapper in enumerate((objective, *constraints)):
            _restore_wrapper(wrapper, arrays, f"wrapper.{i}.")
        for name in _RESULT_SCALARS:
            state[name] = arrays[f"result.{name}"][()]
        for name in _RESULT_ARRAYS:
            state[name] = np.array(arrays[f"result.{name}"])
        for name in _RESULT_LISTS:
            state[name] = [np.array(arrays[f"result.{name}.{i}"]) for i in range(len(state[name]))]
        state["nit"] = int(arrays["result.nit"]) - 1
        state["cg_niter"] = int(arrays["result.cg_niter"]) - int(arrays["cg.niter"])


@contextmanager
def session(resume: TrustConstrState | None = None) -> Iterator[Session]:
    """A :class:`Session` for the solve the calling thread runs in the ``with`` block."""
    previous = getattr(_local, "session", None)
    _local.session = current = Session(resume)
    try:
        yield current
    finally:
        _local.session = previous


def current_session() -> Session | None:
    """The calling thread's :class:`Session`, if a solve runs in one."""
    return getattr(_local, "session", None)


def cg_info(resume: TrustConstrState) -> dict[str, Any]:
    """The conjugate-gradient report the state's iteration gave its stopping test."""
    arrays = resume.arrays
    return {
        "niter": int(arrays["cg.niter"]),
        "stop_cond": int(arrays["cg.stop_cond"]),
        "hits_boundary": bool(arrays["cg.hits_boundary"]),
    }


def stall_window(resume: TrustConstrState) -> np.ndarray:
    """The ``(barrier function, constraint violation)`` pairs the state's stall test had seen."""
    return np.asarray(resume.arrays["stall.window"], dtype=float).reshape(-1, 2)


def _wrappers(global_stop_criteria) -> tuple[Any, list[Any]]:
    """trust-constr's objective and the functions of its constraints, from its stopping test's
    closure (SciPy keeps them nowhere else)."""
    found = closure_values(global_stop_criteria)
    return found["objective"], [c.fun for c in found["prepared_constraints"]]


def _quasi_newton(wrapper) -> HessianUpdateStrategy | None:
    hessian = getattr(wrapper, "_orig_hess", None)
    if isinstance(wrapper, ScalarFunction | VectorFunction) and isinstance(hessian, HessianUpdateStrategy):
        return wrapper.H
    return None


def _wrapper_state(wrapper, prefix: str) -> dict[str, Any]:
    """A wrapper's quasi-Newton state (none for a wrapper without one: its values are functions
    of the point it is asked at)."""
    update = _quasi_newton(wrapper)
    if update is None:
        return {}
    out: dict[str, Any] = {
        prefix + "x": np.array(wrapper.x, dtype=float),
        prefix + "H_updated": np.bool_(wrapper.H_updated),
    }
    if wrapper.x_prev is not None:
        out[prefix + "x_prev"] = np.array(wrapper.x_prev, dtype=float)
    if isinstance(wrapper, VectorFunction):
        out[prefix + "v"] = np.array(wrapper.v, dtype=float)
    for name in ("B", "H"):
        matrix = getattr(update, name, None)
        if matrix is not None:
            out[prefix + "matrix." + name] = np.array(matrix, order="K")
    out[prefix + "first_iteration"] = np.bool_(update.first_iteration)
    return out


def _restore_wrapper(wrapper, arrays: Mapping[str, np.ndarray], prefix: str) -> None:
    """Put a wrapper where :func:`_wrapper_state` found it: its point, the point before it and
    their derivatives (evaluated again), its multipliers and its quasi-Newton matrix."""
    update = _quasi_newton(wrapper)
    if update is None:
        return
    derivative = wrapper.grad if isinstance(wrapper, ScalarFunction) else wrapper.jac
    before = None
    x_prev = arrays.get(prefix + "x_prev")
    if x_prev is not None:
        wrapper.fun(np.array(x_prev))
        before = derivative(np.array(x_prev))
        if sparse.issparse(before) or isinstance(before, np.ndarray):
            before = before.copy()
    x = np.array(arrays[prefix + "x"])
    wrapper.fun(x)
    derivative(x)
    wrapper.x_prev = None if x_prev is None else np.array(x_prev)
    if isinstance(wrapper, ScalarFunction):
        wrapper.g_prev = before
    else:
        wrapper.J_prev = before
        wrapper.v = np.array(arrays[prefix + "v"])
    wrapper.H_updated = bool(arrays[prefix + "H_updated"])
    for name in ("B", "H"):
        matrix = arrays.get(prefix + "matrix." + name)
        setattr(update, name, None if matrix is None else np.array(matrix, order="K"))
    update.first_iteration = bool(arrays[prefix + "first_iteration"])
