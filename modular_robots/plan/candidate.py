"""How one candidate's optimisation ended (:class:`CandidateResult`, :class:`CandidateStatus`):
the unit step D ranks and step E reports, a value that outlives the solver that made it."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any

import numpy as np

from .boundary import BoundaryPair
from .trajectory import Trajectory
from .verification import Verification

__all__ = ["CandidateResult", "CandidateStatus"]


class CandidateStatus(StrEnum):
    """How a candidate's optimisation ended."""

    #: Converged and verified.
    OPTIMAL = "optimal"
    #: The solver failed (iteration limit, infeasible, non-finite) or verification failed.
    FAILED = "failed"
    #: Closed before it ended (by the caller, or when a run stops).
    STOPPED = "stopped"
    #: Discarded by the pruning manager.
    PRUNED = "pruned"


@dataclass(frozen=True, kw_only=True)
class CandidateResult:
    """How one candidate's optimisation ended (SPEC §7's per-candidate record).

    ``name`` names the candidate (unique in a run), ``composition`` its composition and
    ``boundary_pair`` the boundary pair it started from. ``cost`` in its unit [s], ``tf`` [s],
    ``cost_history`` and ``violation_history`` the cost and scaled constraint violation after
    every iteration, ``seconds`` spent in the solver and in verification. ``cost_bound`` is the
    problem's lower bound on the cost (:attr:`~modular_robots.ocp.shooting.ShootingProblem.cost_bound`).
    ``y`` is the last scaled decision vector and ``waypoints`` the joint-space path of the initial
    guess it is scaled by. An optimal result also carries what the report needs, in SI units:
    ``trajectory``, the plan sampled at every integration sub-step, and ``urdf``, the robot's URDF.
    """

    name: str
    dof: int
    status: CandidateStatus
    reason: str
    iterations: int = 0
    seconds: float = 0.0
    cost: float = float("nan")
    tf: float = float("nan")
    constraint_violation: float = float("nan")
    cost_history: tuple[float, ...] = ()
    violation_history: tuple[float, ...] = ()
    #: Per iteration, how many times the sub-steps had been refined (0: the first solve).
    refinement_history: tuple[int, ...] = ()
    verification: Verification | None = None
    substeps: int = 0
    pruned_at_iteration: int | None = None
    cost_bound: float = 0.0
    composition: str = ""
    boundary_pair: BoundaryPair = BoundaryPair.FASTEST
    #: The rest configurations it moves between [rad | m] (empty if it never started).
    q_start: tuple[float, ...] = ()
    q_goal: tuple[float, ...] = ()
    #: Among several goals, when each move ends [s]: at each goal that moves, in order (a pause
    #: there starts then); empty for a single move.
    stop_times: tuple[float, ...] = ()
    y: np.ndarray | None = field(default=None, repr=False, compare=False)
    waypoints: np.ndarray | None = field(default=None, repr=False, compare=False)
    trajectory: Trajectory | None = field(default=None, repr=False, compare=False)
    urdf: str | None = field(default=None, repr=False, compare=False)
    #: The drives' armature and friction, which URDF cannot hold (:meth:`RobotModel.drive`).
    drive: dict | None = field(default=None, repr=False, compare=False)
    #: Where a candidate stopped at an iterate stands (a
    #: :class:`~modular_robots.ocp.resume.CandidateCheckpoint`), for a later run to go on from;
    #: None otherwise (a pruned result drops it).
    checkpoint: Any = field(default=None, repr=False, compare=False)

    @classmethod
    def never_started(cls, name: str, reason: str = "stopped before it started") -> CandidateResult:
        """The result of a candidate stopped before its first iteration."""
        return cls(name=name, dof=0, status=CandidateStatus.STOPPED, reason=reason, cost_bound=float("nan"))

    @property
    def pruned_by_bound(self) -> bool:
        """Whether it was pruned by a lower bound on its cost (safe: it could not win), not by the
        ratio rule (a heuristic): the bound rule's reasons start ``bound:``."""
        return self.status == CandidateStatus.PRUNED and " by the bound: " in self.reason

    def pruned(self, iteration: int, reason: str = "") -> CandidateResult:
        """This result, pruned at ``iteration`` for ``reason`` (which rule, which bound or ratio)."""
        return replace(
            self,
            checkpoint=None,
            status=CandidateStatus.PRUNED,
            reason=f"pruned at iteration {iteration}" + (f" by the {reason}" if reason else ""),
            pruned_at_iteration=iteration,
        )
