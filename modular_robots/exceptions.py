"""One exception hierarchy for the package: catch :class:`ModularRobotsError` for all of them."""

from __future__ import annotations

__all__ = [
    "ModularRobotsError",
    "InputError",
    "CatalogError",
    "ScenarioError",
    "CompositionError",
    "InfeasibleError",
]


class ModularRobotsError(Exception):
    """Base class of every error raised by modular_robots."""


class InputError(ModularRobotsError, ValueError):
    """A file or value given by the user is invalid.

    The message names the file and line (when known), the key path and what was expected,
    e.g. ``catalog.yaml:14: modules[3].mass: expected a number >= 0, got -1``.
    """


class CatalogError(InputError):
    """A module catalogue file is invalid."""


class ScenarioError(InputError):
    """A scenario file is invalid."""


class CompositionError(InputError):
    """A composition does not exist in the catalogue or breaks its grammar."""


class InfeasibleError(ModularRobotsError):
    """The task cannot be done: no composition (or not the one asked for) passes step B, or every
    candidate's optimisation failed. The message says which test or failure decided it."""
