"""The fence around the project's replacements for parts of SciPy's ``trust-constr``.

trust-constr has no options for the parts the project computes from a shooting problem's
structure, so these modules replace private SciPy names: the installer
(:mod:`~modular_robots.ocp._scipy.trust_constr`, :func:`install`) and one module per
replacement (:mod:`~modular_robots.ocp._scipy.projections` (with
:mod:`~modular_robots.ocp._scipy.banded` and
:mod:`~modular_robots.ocp._scipy.signed_rows`),
:mod:`~modular_robots.ocp._scipy.canonical`, :mod:`~modular_robots.ocp._scipy.sqp`, a copy of
SciPy's SQP loop under SciPy's licence, ``LICENSE-scipy.txt`` beside it, with its stall test
:mod:`~modular_robots.ocp._scipy.stall`,
:mod:`~modular_robots.ocp._scipy.barrier`, :mod:`~modular_robots.ocp._scipy.boxes` and the
sparse products of :mod:`~modular_robots.ocp._scipy.products`), and the checkpoints of a solve
stopped at an iterate (:mod:`~modular_robots.ocp._scipy.checkpoint`, which reads and fills in
SciPy's objects without replacing any code). Nothing outside this package reads SciPy's private
names (the tests aside).

Importing the package replaces nothing: :class:`~modular_robots.ocp.solver.ShootingSolver` calls
:func:`install` before its first solve. A hook installs only on a SciPy of :data:`TESTED_SCIPY`
whose names and signatures are those the replacement was written for; otherwise SciPy's own code
stays and a :class:`ScipyHookWarning` says which hook and why. The replacements act only in a
thread marked as a solver's (:func:`solver_thread`).
"""

from .trust_constr import (
    HOOKS,
    TESTED_SCIPY,
    Installed,
    ScipyHookWarning,
    in_solver_thread,
    install,
    mark_solver_thread,
    solver_thread,
    uninstall,
)

__all__ = [
    "install",
    "uninstall",
    "Installed",
    "ScipyHookWarning",
    "HOOKS",
    "TESTED_SCIPY",
    "solver_thread",
    "mark_solver_thread",
    "in_solver_thread",
]
