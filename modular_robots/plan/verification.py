"""The figures of a re-integrated plan (:class:`Verification`) and the tolerances that decide
whether it passes (SPEC §5). They are computed by :func:`~modular_robots.ocp.verification.verify`;
they live here so that what reads a result needs no solver."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "Verification",
    "TERMINAL_TOLERANCE",
    "DEFECT_TOLERANCE",
    "LIMIT_TOLERANCE",
    "CLEARANCE_TOLERANCE",
    "ANGLE_TOLERANCE",
    "GOAL_TOLERANCE",
]

#: Largest terminal tool-position error accepted without refinement [m] (SPEC §5: 1 cm).
TERMINAL_TOLERANCE = 0.01
#: Largest scaled defect of an interval: its sub-steps' re-integration gaps, summed.
DEFECT_TOLERANCE = 1e-3
#: Relative excess over a velocity or torque limit (or over a position limit, relative to the
#: joint's range) still counted as "held" on the dense grid.
LIMIT_TOLERANCE = 1e-3
#: Penetration still counted as clear on the dense grid [m] (solver tolerance, not physics).
CLEARANCE_TOLERANCE = 1e-5
#: Angle beyond an end's orientation tolerance still counted as within it [rad] (rounding).
ANGLE_TOLERANCE = 1e-6
#: What a goal between the start and the end may miss by [m, rad/s | m/s, rad | m]: the
#: solver's constraint tolerance, with room for the rows' scaling.
GOAL_TOLERANCE = 1e-5


@dataclass(frozen=True)
class Verification:
    """Figures of a re-integrated trajectory.

    ``terminal_error`` [m]: re-integrated tool position at ``tf`` vs the plan's last node's
    (whose tool is within the task's tolerance of the goal); ``terminal_speed``: largest
    joint speed at ``tf``; ``max_defect``: largest over intervals of the summed scaled
    gaps between each sub-step's re-integrated end and the plan (the next node for the last
    sub-step), positions over half their range and velocities over their limit;
    ``min_clearance`` [m]: smallest obstacle distance on the grid (inf without obstacles);
    ``position_excess``: largest excursion beyond a position limit, relative to the joint's
    range; ``velocity_ratio``, ``torque_ratio``: largest ``|value| / limit``; ``grid_points``: samples
    checked; ``substeps``: RK4 sub-steps per interval of the solution; ``velocity_share``,
    ``effort_share``: per joint, the largest ``|value| / limit`` on the grid (between the plan's
    rows too, where a torque can exceed its value at the rows); ``orientation_excess`` [rad]: at
    the ends of the plan, by how much the angle between the tool's orientation and the one the
    task asks there exceeds its tolerance (0 within it, or when the task asks none);
    ``duration_excess``: by how much ``tf`` exceeds the task's ``max_time``, relative to it (0
    within it, or when the task sets none); ``goal_excess``: at the goals between the start and
    the end, the largest distance [m] of the tool beyond a goal's position tolerance, joint speed
    where a goal asks rest, or joint distance from the configuration a return asks (0 when all
    hold; :data:`GOAL_TOLERANCE`); the orientation at those goals counts in
    ``orientation_excess``.
    """

    terminal_error: float
    terminal_speed: float
    max_defect: float
    min_clearance: float
    position_excess: float
    velocity_ratio: float
    torque_ratio: float
    grid_points: int
    substeps: int
    velocity_share: tuple[float, ...] = ()
    effort_share: tuple[float, ...] = ()
    orientation_excess: float = 0.0
    duration_excess: float = 0.0
    goal_excess: float = 0.0

    @property
    def goals_ok(self) -> bool:
        return self.goal_excess <= GOAL_TOLERANCE

    @property
    def duration_ok(self) -> bool:
        return self.duration_excess <= LIMIT_TOLERANCE

    @property
    def terminal_ok(self) -> bool:
        return self.terminal_error <= TERMINAL_TOLERANCE

    @property
    def limits_ok(self) -> bool:
        return (
            self.position_excess <= LIMIT_TOLERANCE
            and self.velocity_ratio <= 1.0 + LIMIT_TOLERANCE
            and self.torque_ratio <= 1.0 + LIMIT_TOLERANCE
        )

    @property
    def clearance_ok(self) -> bool:
        return self.min_clearance >= -CLEARANCE_TOLERANCE

    @property
    def orientation_ok(self) -> bool:
        return self.orientation_excess <= ANGLE_TOLERANCE

    @property
    def defect_ok(self) -> bool:
        return self.max_defect <= DEFECT_TOLERANCE

    @property
    def passed(self) -> bool:
        return (
            self.terminal_ok
            and self.defect_ok
            and self.limits_ok
            and self.clearance_ok
            and self.orientation_ok
            and self.duration_ok
            and self.goals_ok
        )
