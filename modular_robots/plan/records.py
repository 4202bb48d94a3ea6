"""``result.json`` as typed values: what :func:`~modular_robots.plan.document.read_document` reads
back from a results folder, checked, for what is made from a finished run (``export``, ``view``,
the command's summary). Units are SI, as written.

Numbers the run writes as ``null`` (not finite: an infinite clearance without obstacles, a cost
never reached) are ``None``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import astuple, dataclass, field, fields
from typing import Any

from ..costs import Design
from ..obstacles import Obstacle
from .boundary import BoundaryPair
from .candidate import CandidateStatus
from .tracking import Tracking

__all__ = [
    "WinnerFiles",
    "TaskRecord",
    "DrawnTask",
    "SettingsRecord",
    "VerificationRecord",
    "CandidateRecord",
    "ApproachRecord",
    "LimitsUsed",
    "WinnerRecord",
    "Totals",
    "ResultDocument",
]


@dataclass(frozen=True)
class WinnerFiles:
    """The winner's files a run wrote into its folder, by kind (``None``: not written)."""

    urdf: str | None = None
    trajectory: str | None = None
    joints_plot: str | None = None
    pruning_plot: str | None = None
    viewer: str | None = None
    #: The CoBRA solution document, for a scenario imported from a CoBRA task.
    cobra_solution: str | None = None

    def by_kind(self) -> dict[str, str]:
        """The written files' names by kind, in the order a run writes them."""
        return {f.name: name for f, name in zip(fields(self), astuple(self)) if name is not None}

    def names(self) -> tuple[str, ...]:
        return tuple(self.by_kind().values())


@dataclass(frozen=True)
class TaskRecord:
    """The task as the run read it: ``payload`` [kg], tool ``start`` and ``goal`` [m, base frame],
    the ``obstacles`` (read back through their shapes' JSON form), the ``cost`` minimised, and
    the positions [m] of the goals between the start and the last one, if several."""

    payload: float
    start: tuple[float, ...]
    goal: tuple[float, ...]
    obstacles: tuple[Obstacle, ...]
    cost: str
    waypoints: tuple[tuple[float, ...], ...] = ()


@dataclass(frozen=True)
class DrawnTask:
    """What a page draws of the task: tool ``start`` and ``goal`` [m, base frame] (``None``: not
    given), the ``obstacles``, the ``clearance_margin`` [m] kept from them, and the positions of
    the goals in between."""

    start: tuple[float, ...] | None
    goal: tuple[float, ...] | None
    obstacles: tuple[Obstacle, ...]
    clearance_margin: float
    waypoints: tuple[tuple[float, ...], ...] = ()


@dataclass(frozen=True)
class SettingsRecord:
    """The run's settings: the ``cost`` minimised, the ``payload`` [kg], the optimizer's
    ``clearance_margin`` [m]; ``optimizer``, ``pruning`` and ``extra`` (``jobs``, ``engine`` or
    ``rule``) as written."""

    cost: str
    payload: float
    clearance_margin: float
    optimizer: Mapping[str, Any] = field(default_factory=dict)
    pruning: Mapping[str, Any] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class VerificationRecord:
    """A verification's figures as written (:class:`~modular_robots.plan.verification.Verification`):
    [m] for ``terminal_error`` and ``min_clearance``, ratios otherwise."""

    terminal_error: float | None
    terminal_speed: float | None
    max_defect: float | None
    min_clearance: float | None
    position_excess: float | None
    velocity_ratio: float | None
    torque_ratio: float | None
    grid_points: int
    substeps: int
    velocity_share: tuple[float, ...]
    effort_share: tuple[float, ...]
    orientation_excess: float
    passed: bool
    duration_excess: float = 0.0
    goal_excess: float = 0.0


@dataclass(frozen=True)
class CandidateRecord:
    """One entry of ``candidates``. The short form a run writes when the whole document no
    longer fits (a full disk) has only ``candidate`` and ``status``; the rest is then ``None``
    (or empty)."""

    candidate: str
    status: CandidateStatus
    composition: str | None = None
    #: What the composition is made of (None in a document written before it was recorded).
    design: Design | None = None
    boundary_pair: BoundaryPair | None = None
    dof: int | None = None
    q_start: tuple[float, ...] = ()
    q_goal: tuple[float, ...] = ()
    reason: str | None = None
    iterations: int | None = None
    seconds: float | None = None
    cost: float | None = None
    tf: float | None = None
    constraint_violation: float | None = None
    pruned_at_iteration: int | None = None
    cost_bound: float | None = None
    substeps: int | None = None
    verification: VerificationRecord | None = None
    cost_history: tuple[float | None, ...] = ()
    violation_history: tuple[float | None, ...] = ()
    refinement_history: tuple[int, ...] = ()


@dataclass(frozen=True)
class ApproachRecord:
    """Where the plan comes closest to an obstacle: ``clearance`` [m] at ``t`` [s], between the
    robot's collision ``primitive`` and ``task.obstacles[obstacle]``."""

    clearance: float
    t: float
    primitive: str
    obstacle: int


@dataclass(frozen=True)
class LimitsUsed:
    """Per joint, the largest share of its ``effort`` and ``velocity`` limit the plan uses."""

    effort: tuple[float, ...]
    velocity: tuple[float, ...]


@dataclass(frozen=True)
class WinnerRecord:
    """The ``winner`` block: the winning candidate's figures (``cost`` in its unit, ``tf`` and
    ``seconds`` [s]), its checks, its drives (``drive``, as :meth:`RobotModel.drive` wrote them)
    and its ``files``."""

    composition: str
    candidate: str
    boundary_pair: BoundaryPair
    dof: int
    cost: float
    tf: float
    iterations: int
    seconds: float
    substeps: int
    verification: VerificationRecord | None
    limits_used: LimitsUsed | None
    tracking: Tracking | None
    closest_approach: ApproachRecord | None
    drive: Mapping[str, Any] | None
    files: WinnerFiles


@dataclass(frozen=True)
class Totals:
    """``optimizer_iterations`` of all candidates and the run's ``wall_seconds`` [s]."""

    optimizer_iterations: int
    wall_seconds: float


@dataclass(frozen=True)
class ResultDocument:
    """A results folder's ``result.json``, read from ``source`` (its path, for messages)."""

    source: str
    scenario: str
    scenario_file: str | None
    status: str
    partial: bool
    message: str
    settings: SettingsRecord
    task: TaskRecord
    counts: Mapping[str, Any]
    seconds: Mapping[str, float]
    candidates: tuple[CandidateRecord, ...]
    winner: WinnerRecord | None
    totals: Totals
