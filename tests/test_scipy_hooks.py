"""The fence around the replacements of parts of SciPy's trust-constr (:mod:`modular_robots.ocp._scipy`):
on a SciPy of the pinned range every replacement is installed; nothing is replaced on import; a
replacement whose SciPy names are not what it was written for (a module that cannot be imported,
a name gone, another signature, code that no longer uses the private names, another SQP loop, a
SciPy outside the range) stays SciPy's code with one warning, and the solver still solves; a
replacement that raises at run time ends the solve as failed with the reason."""

from __future__ import annotations

import hashlib
import re
import subprocess
import sys
import threading
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import scipy
from scipy.optimize._differentiable_functions import VectorFunction
from scipy.optimize._trustregion_constr import equality_constrained_sqp as scipy_sqp
from scipy.optimize._trustregion_constr import minimize_trustregion_constr, qp_subproblem, tr_interior_point

import modular_robots.ocp._scipy as package
from modular_robots.ocp._scipy import HOOKS, TESTED_SCIPY, ScipyHookWarning, products, trust_constr
from modular_robots.ocp.solver import ShootingSolver

from .helpers.problems import paper_problem

ROOT = Path(__file__).resolve().parents[1]

#: Where each hook goes: (owner, name, the replacement's name in trust_constr).
PLACES = {
    "projections": (scipy_sqp, "projections", "projections"),
    "canonical constraints": (minimize_trustregion_constr, "CanonicalConstraint", "SolverCanonical"),
    "barrier function": (tr_interior_point.BarrierSubproblem, "_compute_function", "barrier_function"),
    "SQP loop": (tr_interior_point, "equality_constrained_sqp", "sqp_loop"),
    "barrier Jacobian": (tr_interior_point.BarrierSubproblem, "_assemble_sparse_jacobian", "barrier_jacobian"),
    "quasi-Newton update": (VectorFunction, "_update_hess", "hessian_update"),
    "box intersections": (qp_subproblem, "box_intersections", "box_intersections"),
}
#: The hooks whose results are SciPy's bit for bit: without them a solve is the same, iterate for iterate.
BIT_IDENTICAL = {"canonical constraints", "barrier function", "barrier Jacobian", "quasi-Newton update"}
BIT_IDENTICAL |= {"box intersections", trust_constr.KERNELS}


def solve(problem):
    """A solve's outcome and its history: iterations and a digest of every iterate, equal for two
    solves only if they are iterate for iterate the same, bit for bit."""
    solver, digest = ShootingSolver(problem), hashlib.sha1()
    for iterate in solver.iterate():
        digest.update(iterate.y.tobytes())
        digest.update(np.float64(iterate.optimality).tobytes())
    return solver.outcome, (solver.outcome.iterations, digest.hexdigest())


def in_place(hook: str) -> bool:
    owner, name, replacement = PLACES[hook]
    return getattr(owner, name) is getattr(trust_constr, replacement)


@pytest.fixture(scope="module")
def problem():
    return paper_problem()


@pytest.fixture(scope="module")
def hooked(problem):
    """A solve with every replacement in place."""
    assert trust_constr.install().complete
    return solve(problem)


@pytest.fixture(scope="module")
def unhooked(problem):
    """A solve by SciPy's own code only (every hook refused: a SciPy outside the range)."""
    trust_constr.uninstall()
    try:
        with pytest.MonkeyPatch.context() as patch, pytest.warns(ScipyHookWarning):
            patch.setattr(scipy, "__version__", "1.99.0")
            assert trust_constr.install().hooks == ()
            return solve(problem)
    finally:
        trust_constr.uninstall()
        assert trust_constr.install().complete


@pytest.fixture
def reinstalled(monkeypatch):
    """No replacement in place when the test starts; after it (its monkeypatches undone first),
    every one, as a solver puts them."""
    trust_constr.uninstall()
    yield monkeypatch
    trust_constr.uninstall()
    monkeypatch.undo()
    assert trust_constr.install().complete


def test_every_replacement_is_installed_on_this_scipy():
    """Fails if a SciPy of the pinned range lost one of the replacements (its own code would run)."""
    installed = trust_constr.install()
    assert installed.hooks == HOOKS == tuple(PLACES)
    assert installed.fallbacks == {}
    assert installed.scipy_version == scipy.__version__
    assert all(in_place(hook) for hook in HOOKS)
    assert products._sparsetools is not None


def test_the_pin_is_the_tested_range_and_this_scipy_is_in_it():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    (pin,) = [d for d in pyproject["project"]["dependencies"] if re.match(r"scipy\b", d)]
    (low, high) = TESTED_SCIPY
    assert pin == f"scipy>={low[0]}.{low[1]},<{high[0]}.{high[1]}"
    version = tuple(int(part) for part in scipy.__version__.split(".")[:2])
    assert low <= version < high
    (scipy_low,) = re.findall(r"^SCIPY_LOW \?= (\S+)$", (ROOT / "Makefile").read_text(), re.MULTILINE)
    assert tuple(int(part) for part in scipy_low.split(".")[:2]) == low  # make test-scipy-low runs the lowest


def test_importing_the_package_replaces_nothing():
    code = (
        "import modular_robots.ocp, modular_robots.ocp._scipy\n"
        "from scipy.optimize._trustregion_constr import qp_subproblem, tr_interior_point\n"
        "from scipy.optimize._differentiable_functions import VectorFunction\n"
        "assert qp_subproblem.box_intersections.__module__.startswith('scipy.')\n"
        "assert tr_interior_point.equality_constrained_sqp.__module__.startswith('scipy.')\n"
        "assert VectorFunction._update_hess.__module__.startswith('scipy.')\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_a_solver_installs_them_before_its_first_solve(reinstalled, problem):
    assert not any(in_place(hook) for hook in HOOKS)
    ShootingSolver(problem, max_iterations=1).solve()
    assert all(in_place(hook) for hook in HOOKS)


def test_install_is_idempotent_and_thread_safe(reinstalled):
    results, barrier = [], threading.Barrier(4)

    def install():
        barrier.wait()
        results.append(trust_constr.install())

    threads = [threading.Thread(target=install) for _ in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(results) == 4 and all(result is results[0] for result in results)
    assert results[0].complete and len(trust_constr._replaced) == len(HOOKS)
    assert trust_constr.install() is results[0]


def _without_module(patch, name: str) -> None:
    """Make ``from . import name`` in the package raise ImportError."""
    patch.setitem(sys.modules, f"{package.__name__}.{name}", None)
    patch.delattr(package, name, raising=False)


def _delegate_with_renamed_parameter(patch):
    original = tr_interior_point.BarrierSubproblem._compute_function

    def _compute_function(self, f, c_ineq, slacks):
        return original(self, f, c_ineq, slacks)

    patch.setattr(tr_interior_point.BarrierSubproblem, "_compute_function", _compute_function)


def _update_without_private_attributes(patch):
    original = VectorFunction._update_hess

    def _update_hess(self):  # as SciPy 1.15 and older: the update is a closure made per instance
        return original(self)

    patch.setattr(VectorFunction, "_update_hess", _update_hess)


def _another_loop(patch):
    original = tr_interior_point.equality_constrained_sqp

    def equality_constrained_sqp(
        fun_and_constr, grad_and_jac, lagr_hess, x0, fun0, grad0, constr0, jac0, stop_criteria, state,
        initial_penalty, initial_trust_radius, factorization_method, trust_lb=None, trust_ub=None,
        scaling=scipy_sqp.default_scaling,
    ):  # fmt: skip
        return original(
            fun_and_constr, grad_and_jac, lagr_hess, x0, fun0, grad0, constr0, jac0, stop_criteria, state,
            initial_penalty, initial_trust_radius, factorization_method, trust_lb, trust_ub, scaling,
        )  # fmt: skip

    patch.setattr(tr_interior_point, "equality_constrained_sqp", equality_constrained_sqp)


def _loop_copy_without_default_scaling(patch):
    """A SciPy whose SQP module lost a name the copy reads (its default scaling); SciPy's own loop
    bound it when it was defined, so it still runs."""
    patch.delattr(scipy_sqp, "default_scaling")
    patch.delattr(package, "sqp", raising=False)  # imported anew
    patch.delitem(sys.modules, f"{package.__name__}.sqp", raising=False)


def _kernels(**kernels):
    return lambda patch: patch.setattr(products, "_sparsetools", SimpleNamespace(**kernels))


def _raising(*args):
    raise TypeError("csr_matvec() takes 8 arguments")


#: A failure to install, the hooks it leaves as SciPy's code and what the warning says why.
FAILURES = {
    "replacement module not importable": (
        lambda patch: _without_module(patch, "canonical"),
        {"canonical constraints"},
        "ModuleNotFoundError: import of modular_robots.ocp._scipy.canonical halted",
    ),
    "private name gone": (
        _loop_copy_without_default_scaling,
        {"SQP loop"},
        "AttributeError: module 'scipy.optimize._trustregion_constr.equality_constrained_sqp' has no attribute "
        "'default_scaling'",
    ),
    "other parameters": (
        _delegate_with_renamed_parameter,
        {"barrier function"},
        "takes (self, f, c_ineq, slacks), not (self, f, c_ineq, s)",
    ),
    "private attributes unused": (
        _update_without_private_attributes,
        {"quasi-Newton update"},
        "no longer uses H_updated, _orig_hess, _update_jac",
    ),
    "another SQP loop": (_another_loop, {"SQP loop"}, "is not the one sqp.py copies"),
    "kernels gone": (_kernels(csr_matvec=_raising), {trust_constr.KERNELS}, "_sparsetools has no csc_matvec"),
    "kernels raising": (
        _kernels(csr_matvec=_raising, csc_matvec=_raising),
        {trust_constr.KERNELS},
        "TypeError: csr_matvec() takes 8 arguments",
    ),
    "SciPy outside the range": (
        lambda patch: patch.setattr(scipy, "__version__", "1.15.3"),
        set(HOOKS),
        "SciPy 1.15.3 is outside the range they are tested on (>=1.16,<1.18)",
    ),
}


@pytest.mark.parametrize("failure", sorted(FAILURES))
def test_a_hook_that_cannot_be_installed_stays_scipys_with_one_warning(reinstalled, failure, problem, hooked, unhooked):
    breaks, refused, reason = FAILURES[failure]
    breaks(reinstalled)
    before = {hook: getattr(PLACES[hook][0], PLACES[hook][1]) for hook in HOOKS}
    with pytest.warns(ScipyHookWarning) as record:
        installed = trust_constr.install()
    warned = [str(w.message) for w in record if issubclass(w.category, ScipyHookWarning)]
    assert len(warned) == 1 and reason in warned[0], warned
    assert all(hook in warned[0] for hook in refused)
    assert set(installed.fallbacks) == refused and not installed.complete
    assert installed.hooks == tuple(hook for hook in HOOKS if hook not in refused)
    for hook in HOOKS:
        assert in_place(hook) == (hook not in refused), hook
        if hook in refused:  # SciPy's own (or what the test made SciPy's) is left where it was
            assert getattr(PLACES[hook][0], PLACES[hook][1]) is before[hook], hook

    outcome, ours = solve(problem)
    if refused <= BIT_IDENTICAL:  # SciPy's code computes what the replacement did: the same solve
        assert ours == hooked[1]
    elif refused == set(HOOKS):
        assert ours == unhooked[1]
    reference = unhooked[0]
    assert outcome.converged and reference.converged
    assert abs(outcome.final.tf - reference.final.tf) <= 1e-3 * reference.final.tf


def test_a_replacement_that_raises_at_run_time_fails_the_solve_with_the_reason(monkeypatch, problem):
    assert trust_constr.install().complete

    def broken(*args):
        raise RuntimeError("box intersections broke")

    monkeypatch.setattr(trust_constr, "fast_box_intersections", broken)
    outcome = ShootingSolver(problem).solve()
    assert outcome.status == "failed" and outcome.reason == "RuntimeError: box intersections broke"


def test_uninstall_puts_scipys_code_back(reinstalled):
    installed = trust_constr.install()
    assert installed.complete
    trust_constr.uninstall()
    for hook in HOOKS:
        owner, name, _ = PLACES[hook]
        assert getattr(owner, name).__module__.startswith("scipy."), hook


def test_without_rays_private_switch_a_local_instance_warns_and_sets_the_variable_only(monkeypatch):
    ray_engine = pytest.importorskip("modular_robots.ray_engine")
    pytest.importorskip("ray")
    assert ray_engine._cluster_switch() is ray_engine.ray_constants  # this Ray has it
    monkeypatch.setattr(ray_engine, "ray_constants", SimpleNamespace())
    with pytest.warns(ray_engine.RayPrivateNameWarning, match="has no ray._private.ray_constants.ENABLE_RAY_CLUSTER"):
        assert ray_engine._cluster_switch() is None
