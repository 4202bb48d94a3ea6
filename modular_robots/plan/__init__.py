"""The results of a run as values, below the solver that makes them.

A candidate's outcome (:class:`CandidateResult`, :class:`CandidateStatus`, :class:`BoundaryPair`),
its plan (:class:`Trajectory`, resampled at a controller rate by :func:`controller_rate`), the
checks of that plan (:class:`Verification`, :class:`Tracking`), and ``result.json``, written and
read back by :mod:`~modular_robots.plan.document` alone. What reports a run (``report``,
``recorder``, ``viewer``, the command's output) needs these and never :mod:`modular_robots.ocp`.
"""

from .boundary import BoundaryPair
from .candidate import CandidateResult, CandidateStatus
from .document import RESULT, STATUSES, read_document
from .records import ResultDocument, WinnerFiles
from .tracking import Tracking, track
from .trajectory import MAX_ROWS, Trajectory, controller_rate, joint_trajectory
from .verification import Verification

__all__ = [
    "BoundaryPair",
    "CandidateResult",
    "CandidateStatus",
    "MAX_ROWS",
    "RESULT",
    "ResultDocument",
    "STATUSES",
    "Tracking",
    "Trajectory",
    "Verification",
    "WinnerFiles",
    "controller_rate",
    "joint_trajectory",
    "read_document",
    "track",
]
