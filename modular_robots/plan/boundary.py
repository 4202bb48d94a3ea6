"""Which of step B's boundary pairs a candidate starts from: part of every candidate's name and
result, so a value of its own rather than a detail of the solver."""

from __future__ import annotations

from enum import StrEnum

__all__ = ["BoundaryPair"]


class BoundaryPair(StrEnum):
    """Which of step B's boundary pairs a candidate starts from (see
    :func:`~modular_robots.ocp.candidate.composition_problem`)."""

    #: The IK pair with the smallest velocity-limited travel time.
    FASTEST = "fastest"
    #: The fastest pair whose straight joint-space line clears the obstacles.
    CLEAR = "clear"
