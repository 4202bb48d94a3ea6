"""One exception hierarchy for the package: catch :class:`ModularRobotsError` for all of them."""

from __future__ import annotations

import signal

__all__ = [
    "ModularRobotsError",
    "InputError",
    "CheckpointWarning",
    "CatalogError",
    "ScenarioError",
    "CompositionError",
    "ProblemError",
    "SolverReuseError",
    "InfeasibleError",
    "ResultsFolderError",
    "FolderBusyError",
    "EngineError",
    "Terminated",
    "InputWarning",
    "shorten",
]


class ModularRobotsError(Exception):
    """Base class of every error raised by modular_robots."""


class InputError(ModularRobotsError, ValueError):
    """A file or value given by the user is invalid.

    The message names the file and line (when known), the key path and what was expected,
    e.g. ``catalog.yaml:14: modules[3].mass: expected a number >= 0, got -1``.
    """


class InputWarning(UserWarning):
    """A value given by the user is valid but looks like a mistake (degrees where radians are
    expected); the message names the file, line and key, as :class:`InputError`'s do. The command
    line prints each as one ``Warning: ...`` line."""


class CheckpointWarning(UserWarning):
    """A candidate's checkpoint could not be taken, written or read: the candidate starts from an
    older one or its beginning in the run that goes on (slower, the same result)."""


class CatalogError(InputError):
    """A module catalogue file is invalid."""


class ScenarioError(InputError):
    """A scenario file is invalid."""


class CompositionError(InputError):
    """A composition does not exist in the catalogue or breaks its grammar."""


class ProblemError(ModularRobotsError, ValueError):
    """Step C was asked for something it cannot do: a problem whose boundary configurations are
    outside the joint limits or in collision, an unknown cost, transcription or solver, a
    setting out of range. (Infeasible candidates are results, not errors.)"""


class SolverReuseError(ModularRobotsError, RuntimeError):
    """A step-C solver was asked to run a second time: each solves once."""


class InfeasibleError(ModularRobotsError):
    """The task cannot be done: no composition (or not the one asked for) passes step B, or every
    candidate's optimisation failed. The message says which test or failure decided it."""


class ResultsFolderError(ModularRobotsError):
    """A results folder cannot be used: its lock file is not one this package made (a link, a
    device, a file with other names), or it is held."""


class FolderBusyError(ResultsFolderError):
    """Another process of this package holds the results folder's lock."""


class EngineError(ModularRobotsError):
    """An execution engine cannot be used: Ray is not installed, or its cluster cannot be
    reached."""


class Terminated(KeyboardInterrupt):
    """The process was asked to end by a signal (``SIGTERM``, ``SIGHUP``): raised in the main
    thread while a run is recorded, so the run ends as an interrupted one, like Ctrl-C."""

    def __init__(self, signum: int):
        self.signum = signum
        self.name = signal.Signals(signum).name
        super().__init__(f"terminated by {self.name}")


def shorten(value: object, limit: int = 60, quote: bool = True) -> str:
    """``repr(value)`` (``str`` if not ``quote``), cut to about ``limit`` characters with its
    length said, so that an error message never echoes a huge input; a message (not ``quote``)
    is cut between words where one ends in its last 20 characters."""
    text = repr(value) if quote else str(value)
    if len(text) <= limit:
        return text
    size = f"{len(value)} characters" if isinstance(value, str) else f"{len(text)} characters as text"
    end = limit if quote else next((k for k in range(limit, max(limit - 20, 0), -1) if text[k] == " "), limit)
    return f"{text[:end]}... ({size})"
